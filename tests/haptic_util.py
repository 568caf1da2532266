"""Shared builders for the haptic tests: arms, simulated robots, renderers."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from fieldbank.evaluate.design import Stroke, equilibrium, severity_candidates
from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic.client import ControlClient
from fieldbank.haptic.clock import VirtualClock
from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.probe import probe_path
from fieldbank.haptic.recording import write_trace_h5
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.safety import SafetyConfig
from fieldbank.haptic.simrobot import PtyRobot, SimRobotConfig
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.storage import Database


class MemoryPort:
    """A serial port in memory: the test appends incoming bytes to ``data`` (or gives them at
    the start); each poll offers ``chunks()`` of them (all, by default); writes are accepted."""

    def __init__(self, data: bytes = b"", chunks: Callable[[], int] | None = None) -> None:
        self.data = bytearray(data)
        self.chunks = chunks

    @property
    def in_waiting(self) -> int:
        n = len(self.data)
        return n if self.chunks is None else min(n, self.chunks())

    def read(self, n: int = 1) -> bytes:
        out = bytes(self.data[:n])
        del self.data[:n]
        return out

    def write(self, b: bytes) -> int:
        return len(b)

    def fileno(self) -> int:
        raise OSError("no fd")

    def close(self) -> None:
        pass


def unimpaired() -> ArmParams:
    return ArmParams.from_anthropometry()


def severe_shoulder() -> ArmParams:
    """The shoulder group at "severe" on the one severity scale (fieldbank.evaluate.severity)."""
    return synthesize({"shoulder": "severe"})


def rest_hand(p: ArmParams) -> tuple[float, float]:
    x, y = Arm.from_params(p).rest_position()
    return float(x), float(y)


@contextlib.contextmanager
def pty_session(
    before: ArmParams,
    after: ArmParams | None = None,
    motion: str = "hold",
    config: RendererConfig | None = None,
    safety: SafetyConfig | None = None,
    **sim: object,
) -> Iterator[tuple[Renderer, PtyRobot]]:
    """Lockstep simulated robot on a pty (device thread) + a renderer on a virtual clock."""
    x0, y0 = rest_hand(before)
    cfg = SimRobotConfig(motion=motion, x0_m=x0, y0_m=y0, **sim)  # type: ignore[arg-type]
    with PtyRobot(cfg).start_thread() as robot:
        link = RobotLink.open(robot.port)
        try:
            link.handshake(1000, 20)
            rd = Renderer(link, before, after or before,
                          config or RendererConfig(state_wait_s=0.5), safety=safety,
                          clock=VirtualClock())
            yield rd, robot
        finally:
            link.close()


def mild_shoulder_trace(path: Path) -> Path:
    """A trace file of a mild shoulder probed once with a stroke from the equilibrium of the
    mild and severe candidates (the classifier's usual test case)."""
    cands = severity_candidates(levels=("mild", "severe"))
    stroke = Stroke(tuple(equilibrium(cands)), -100.0, 0.1, 0.4, 0.2)
    res = probe_path(synthesize({"shoulder": "mild"}), stroke.motion(), seed=1)
    write_trace_h5(res.trace, path)
    return path


class ServeProcess:
    """``fieldbank haptic serve --station`` on ``robot`` in its own process, as a clinician
    starts it (elbow severe before, mild after): the database made first (serve records into
    one, never creates one), the station's address read from its stderr, and the loop running
    before the constructor returns; ``args`` go on its command line."""

    def __init__(self, tmp: Path, robot: str, *args: str) -> None:
        self.sock = tmp / "run" / "h.sock"
        self.db_url = f"sqlite:///{tmp / 'fb.sqlite'}"
        Database.open(self.db_url).close()
        self.trace_dir = tmp / "traces"
        cmd = [sys.executable, "-m", "fieldbank.cli", "haptic", "serve",
               "--robot", robot, "--station",
               "--before-severity", "elbow=severe", "--after-severity", "elbow=mild",
               # long enough for a busy machine; the test stops it when it is done
               "--duration-s", "3600", "--socket", str(self.sock), "--db", self.db_url,
               "--trace-dir", str(self.trace_dir), "--json", *args]
        env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, env=env)
        self.lines: list[str] = []
        self.url: str | None = None
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        deadline = time.time() + 60
        while self.url is None and time.time() < deadline and self.proc.poll() is None:
            time.sleep(0.05)
        if self.url is None:
            self.proc.kill()
            raise AssertionError("serve printed no station address:\n" + "\n".join(self.lines))
        self.client = ControlClient(self.sock)
        while time.time() < deadline:  # the loop is running once status says so
            try:
                if self.client.request("status")["running"]:
                    break
            except HapticError:
                time.sleep(0.05)

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.lines.append(line.rstrip())
            if line.startswith("station: "):
                self.url = line.split(" ", 1)[1].strip()
