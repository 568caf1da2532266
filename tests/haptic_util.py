"""Shared builders for the haptic tests: arms, simulated robots, renderers."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from pathlib import Path

from fieldbank.evaluate.design import Stroke, equilibrium, severity_candidates
from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic.clock import VirtualClock
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.probe import probe_path
from fieldbank.haptic.recording import write_trace_h5
from fieldbank.haptic.renderer import Renderer, RendererConfig
from fieldbank.haptic.safety import SafetyConfig
from fieldbank.haptic.simrobot import PtyRobot, SimRobotConfig
from fieldbank.model import Arm
from fieldbank.params import ArmParams


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
