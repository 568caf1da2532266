"""The station process: ``python -m fieldbank.haptic.station`` (started by
:class:`haptic.station.launch.StationProcess`).

Reads its configuration as one JSON line on standard input (so the token never appears on a
command line), prints ``LISTENING host port`` once it serves, and exits when its standard input
closes - that is, when the process that started it ends, however it ends.

A station with a panel (:mod:`haptic.station.panel`) is the panel's own program, whose
``main`` calls :func:`main` with the panel's factory.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import os
import sys
import threading
from collections.abc import Callable

from fieldbank.errors import FieldbankError
from fieldbank.haptic.station.config import StationConfig
from fieldbank.haptic.station.panel import Panel
from fieldbank.haptic.station.server import serve

#: The station yields the processor to the loop's process (niceness added).
NICENESS = 5


def main(make_panel: Callable[[StationConfig], Panel] | None = None) -> int:
    """Serve the station of the configuration read on standard input, with the panel
    ``make_panel`` makes of it (None: no panel)."""
    line = sys.stdin.readline()
    try:
        config = StationConfig.from_dict(json.loads(line))
        panel = make_panel(config) if make_panel is not None else None
    except (ValueError, TypeError, KeyError, FieldbankError) as exc:
        print(f"station: bad configuration on standard input: {exc}", file=sys.stderr)
        return 2
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr,
                        format="station %(levelname)s %(message)s")
    with contextlib.suppress(OSError):
        os.nice(NICENESS)

    async def run() -> None:
        loop = asyncio.get_running_loop()
        task = asyncio.current_task()
        assert task is not None

        def watch_stdin() -> None:
            sys.stdin.read()  # returns at EOF: the parent is gone or closed the pipe
            loop.call_soon_threadsafe(task.cancel)

        threading.Thread(target=watch_stdin, name="station-parent", daemon=True).start()

        def ready(host: str, port: int) -> None:
            print(f"LISTENING {host} {port}", flush=True)

        with contextlib.suppress(asyncio.CancelledError):
            await serve(config, ready, panel)

    with contextlib.suppress(KeyboardInterrupt):
        asyncio.run(run())
    return 0


if __name__ == "__main__":
    sys.exit(main())
