"""The workspace's renderer process: ``python -m fieldbank.haptic.workspace`` (started by
:class:`haptic.workspace.host.RendererHost`).

Reads its configuration as one JSON line on standard input, renders with
:func:`fieldbank.haptic.session.serve` (control socket and loop snapshot where the host said,
the session recorded in the database as the account that asked), and stops - writing its trace
- on a ``stop`` command or when its standard input closes (the workspace is gone).
"""

from __future__ import annotations

import json
import logging
import sys
import threading

from fieldbank.errors import FieldbankError
from fieldbank.haptic import session
from fieldbank.haptic.client import ControlClient
from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.safety import SafetyConfig
from fieldbank.params import ArmParams
from fieldbank.storage import Database


def main() -> int:
    try:
        cfg = json.loads(sys.stdin.readline())
        before = ArmParams.from_dict(cfg["before"], where="model A")
        after = ArmParams.from_dict(cfg["after"], where="model B")
    except (ValueError, TypeError, KeyError) as exc:
        print(f"renderer: bad configuration on standard input: {exc}", file=sys.stderr)
        return 2
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="renderer %(levelname)s %(message)s")
    socket_path = cfg["socket"]

    def watch_stdin(rd: Renderer) -> None:
        def run() -> None:
            sys.stdin.read()  # returns at EOF: the workspace is gone or closed the pipe
            try:
                ControlClient(socket_path, timeout_s=5.0).request("stop")
            except HapticError:
                pass

        threading.Thread(target=run, name="renderer-parent", daemon=True).start()

    db_url, actor = cfg["db_url"], cfg.get("actor") or None
    try:
        res = session.serve(
            cfg["robot"], before, after, model_ids=(cfg["model_ids"][0], cfg["model_ids"][1]),
            patient_code=cfg.get("patient"), model_info=cfg.get("model_info"),
            config=RendererConfig(rate_hz=int(cfg["rate_hz"])),
            safety=SafetyConfig(force_limit_n=float(cfg["force_limit_n"])),
            socket_path=socket_path, trace_dir=cfg["trace_dir"],
            db=lambda: Database.open(db_url, actor=actor, create=False),
            say=lambda line: print(line, file=sys.stderr, flush=True),
            on_renderer=watch_stdin, snapshot_dir=cfg["snapshot_dir"])
    except FieldbankError as exc:
        print(f"renderer: {exc}", file=sys.stderr)
        return 1
    print(f"renderer: session ended, {res.database or res.trace_file}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
