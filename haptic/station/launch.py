"""Start and stop the station process beside a running renderer.

The station runs in its own process so that nothing it does - HTTP, WebSockets, JSON, drawing
arithmetic - shares the loop's interpreter lock: it reads the loop's snapshot from shared
memory (:mod:`haptic.snapshot`) and talks to the renderer through its control socket. It is
started before the loop enters real-time scheduling (a child would inherit SCHED_FIFO), runs
at a lower priority (``nice``), and ends when its parent does.

Binding: 127.0.0.1 by default; any other address needs ``allow_remote`` (the page then
travels unencrypted over the network, token included: use it only on a trusted link).
"""

from __future__ import annotations

import ipaddress
import json
import os
import select
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field, replace
from typing import IO, Any

from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.station.config import STATION_BOUNDS, StationConfig, check_view, new_token
from fieldbank.validation import check_fields

#: Longest wait for the station process to listen, s: starting Python and the page's web
#: server takes about a second on an idle machine, and twenty or more on a busy one.
START_TIMEOUT_S = 120.0
#: The station's own program (``python -m``).
STATION_PROGRAM = "fieldbank.haptic.station"


def check_program(program: str) -> None:
    """HapticError unless ``program`` names one of fieldbank's modules (the station's process
    runs it)."""
    parts = program.split(".")
    if parts[0] != "fieldbank" or not all(p.isidentifier() for p in parts):
        raise HapticError(f"the station's program must be a fieldbank module; got {program!r}")


@dataclass(frozen=True)
class StationOptions:
    """How a session serves its station (``fieldbank haptic serve --station``).

    Attributes
    ----------
    host : str
        Address to bind (127.0.0.1; another only with ``allow_remote``).
    port : int
        0: any free port.
    allow_remote : bool
    view : str
        'opposite' (the patient faces the clinician, as in the seed) or 'behind'.
    training : dict
        The training protocol the page's 'Start training' begins
        (``TrainingProtocol.to_dict()``; empty: the seed's).
    program : str
        The module run as the station's process (``python -m``): the station itself, or a
        panel's program that serves the station with its panel (:mod:`haptic.station.panel`;
        a remote assessment's: :mod:`haptic.remote.deskstation`).
    panel : dict
        The panel's settings (:attr:`haptic.station.config.StationConfig.panel`; empty: no
        panel).
    """

    host: str = "127.0.0.1"
    port: int = 0
    allow_remote: bool = False
    view: str = "opposite"
    training: dict[str, Any] = field(default_factory=dict)
    program: str = STATION_PROGRAM
    panel: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_fields(self, STATION_BOUNDS, what="station setting", names=("port",))
        check_view(self.view)
        check_program(self.program)


def _loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class StationProcess:
    """The station's process.

    Parameters
    ----------
    snapshot_path, socket_path : str
        The loop's snapshot file and the renderer's control socket.
    host : str
        Address to bind; not a loopback address only with ``allow_remote``.
    port : int
        0: any free port.
    allow_remote : bool
        Allow ``host`` to be reachable from other machines.
    training : dict, optional
        The training protocol the page starts (``TrainingProtocol.to_dict``).
    view : str
        'opposite' (patient faces the clinician, the seed's picture) or 'behind'.
    program : str
        The module run as the process (:attr:`StationOptions.program`).
    panel : dict, optional
        The panel's settings (:attr:`StationOptions.panel`).
    """

    def __init__(self, snapshot_path: str, socket_path: str, host: str = "127.0.0.1",
                 port: int = 0, allow_remote: bool = False,
                 training: dict[str, Any] | None = None, view: str = "opposite",
                 program: str = STATION_PROGRAM, panel: dict[str, Any] | None = None) -> None:
        if not _loopback(host) and not allow_remote:
            raise HapticError(f"the station binds to 127.0.0.1 unless told otherwise; "
                              f"{host!r} is reachable from other machines (pass "
                              f"--station-allow-remote to mean it)")
        self.config = StationConfig(str(snapshot_path), str(socket_path), new_token(), host,
                                    int(port), training=dict(training or {}), view=view,
                                    panel=dict(panel or {}))
        check_program(program)
        self.program = program
        self._proc: subprocess.Popen[bytes] | None = None
        self.host = host
        self.port = 0

    @property
    def url(self) -> str:
        """The page's address with the session's token."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/?token={self.config.token}"

    def start(self, timeout_s: float = START_TIMEOUT_S,
              stderr: IO[Any] | None = None) -> StationProcess:
        """Start the process and wait until it listens; its log goes to ``stderr`` (default:
        this process's)."""
        root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [root, env.get("PYTHONPATH")]))
        proc = subprocess.Popen([sys.executable, "-m", self.program],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=stderr,
                                env=env)
        self._proc = proc
        assert proc.stdin is not None and proc.stdout is not None
        try:
            proc.stdin.write((json.dumps(self.config.to_dict()) + "\n").encode())
            proc.stdin.flush()  # the pipe stays open: the station ends when it closes
        except BrokenPipeError:
            pass  # it ended before reading its settings: its status says why (below)
        line, closed = _readline(proc.stdout, timeout_s)
        if not line.startswith(b"LISTENING "):
            try:  # its output closed: it has ended (or is ending) - its status, not a guess
                ended = proc.wait(timeout=10.0) if closed else proc.poll()
            except subprocess.TimeoutExpired:
                ended = None
            self.stop()
            raise HapticError(_why_not_started(ended, line, timeout_s))
        _, host, port = line.decode().split()
        self.host, self.port = host, int(port)
        self.config = replace(self.config, port=self.port)
        return self

    def stop(self) -> None:
        proc, self._proc = self._proc, None
        if proc is None:
            return
        try:
            if proc.stdin is not None:
                proc.stdin.close()
            proc.wait(timeout=5.0)
        except (OSError, subprocess.TimeoutExpired):
            proc.kill()
            proc.wait()
        if proc.stdout is not None:
            proc.stdout.close()

    def __enter__(self) -> StationProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @classmethod
    def for_session(cls, snapshot_path: str, socket_path: str,
                    options: StationOptions) -> StationProcess:
        return cls(snapshot_path, socket_path, options.host, options.port, options.allow_remote,
                   options.training, options.view, options.program, options.panel)


def _why_not_started(ended: int | None, line: bytes, timeout_s: float) -> str:
    """What happened to a station process that never said it was listening, in words."""
    if ended is None:
        return (f"the station process did not start listening within {timeout_s:g} s (it was "
                "still starting: the machine may be very busy) and was stopped; the session "
                "did not start. Try again, or run without --station.")
    if ended < 0:
        try:
            name = signal.Signals(-ended).name
        except ValueError:
            name = f"signal {-ended}"
        why = f"was ended by {name}" + (" (the system may have run out of memory)"
                                        if -ended == signal.SIGKILL else "")
    else:
        why = f"ended with exit status {ended}"
    said = line.decode(errors="replace").strip()
    return (f"the station process {why} before it listened"
            + (f"; it said: {said!r}" if said else "")
            + (". Any error it printed is on the lines above" if ended > 0 else "")
            + ". The session did not start.")


def _readline(f: IO[bytes], timeout_s: float) -> tuple[bytes, bool]:
    """The first line ``f`` gives within ``timeout_s`` and whether ``f`` closed (its writer
    ended) before it."""
    deadline = time.monotonic() + timeout_s
    buf = b""
    fd = f.fileno()
    while not buf.endswith(b"\n"):
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            break
        chunk = os.read(fd, 256)
        if not chunk:
            return buf.strip(), True
        buf += chunk
    return buf.strip(), False
