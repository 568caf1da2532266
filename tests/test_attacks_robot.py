"""Attacks on the robot link: fault-flagged STATE frames, re-arming into a fault, forged
sequence numbers. The fuzz counts ticks on which the renderer is armed (or commands a force)
after a STATE frame that carries the device-fault flag: there must be none.

The robot here is a scripted port: each tick the test decides which frames arrive (in order,
several per tick, forged numbers, duplicates, flags), so every case is exact and replayable.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldbank.haptic import protocol as P
from fieldbank.haptic.clock import VirtualClock
from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.link import RESYNC_FRAMES, RobotLink
from fieldbank.haptic.protocol import FaultCode
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.safety import Mode
from tests.haptic_util import MemoryPort, rest_hand, severe_shoulder


class Device:
    """Frames as a robot numbers them, plus forgeries."""

    def __init__(self, port: MemoryPort, x: float, y: float) -> None:
        self.port = port
        self.seq = 0
        self.x, self.y = x, y

    def state(self, flags: int = P.FLAG_ARMED, seq: int | None = None) -> None:
        if seq is None:
            seq = self.seq
            self.seq = (self.seq + 1) & 0xFFFF
        payload = P.STATE_FMT.pack(0, self.x, self.y, 0.0, 0.0, flags, 0)
        self.port.data += P.encode_frame(P.MsgType.STATE, seq & 0xFFFF, payload)


def _renderer() -> tuple[Renderer, Device]:
    p = severe_shoulder()
    port = MemoryPort()
    x, y = rest_hand(p)
    dev = Device(port, x + 0.03, y - 0.02)  # off the rest position: the arm pulls (force > 0)
    link = RobotLink(port)  # type: ignore[arg-type]
    rd = Renderer(link, p, p, RendererConfig(rate_hz=1000, realtime_priority=False),
                  clock=VirtualClock())
    dev.state()
    rd.start(expected_ticks=4000)
    return rd, dev


def _settle(rd: Renderer, dev: Device, ticks: int) -> None:
    for _ in range(ticks):
        dev.state()
        rd.tick()


def test_fault_flag_in_a_state_frame_latches_and_zeroes_that_tick() -> None:
    rd, dev = _renderer()
    _settle(rd, dev, 400)  # past the arming ramp
    assert rd.safety.mode == Mode.ARMED and abs(rd.fx) + abs(rd.fy) > 0.01
    dev.state(P.FLAG_ARMED | P.FLAG_FAULT)
    rd.tick()
    assert rd.safety.mode == Mode.FAULT and (rd.fx, rd.fy) == (0.0, 0.0)
    assert rd.safety.latched & (1 << (FaultCode.DEVICE - 1))
    _settle(rd, dev, 50)  # clean frames do not clear a latched fault
    assert rd.safety.mode == Mode.FAULT and (rd.fx, rd.fy) == (0.0, 0.0)
    rd.finish()


def test_a_flag_between_two_clean_frames_of_one_tick_is_not_missed() -> None:
    rd, dev = _renderer()
    _settle(rd, dev, 400)
    dev.state()
    dev.state(P.FLAG_ARMED | P.FLAG_FAULT)
    dev.state()  # the newest STATE is clean; the one before it was not
    rd.tick()
    assert rd.safety.mode == Mode.FAULT and (rd.fx, rd.fy) == (0.0, 0.0)
    rd.finish()


def test_rearm_is_refused_while_the_device_reports_a_fault() -> None:
    rd, dev = _renderer()
    _settle(rd, dev, 100)
    dev.state(P.FLAG_FAULT)
    rd.tick()
    req = rd.submit("arm")
    dev.state(P.FLAG_FAULT)
    rd.tick()
    with pytest.raises(HapticError, match="device fault"):
        req.wait()
    assert rd.safety.mode == Mode.FAULT and (rd.fx, rd.fy) == (0.0, 0.0)
    # the device clears its fault: the operator can re-arm
    _settle(rd, dev, 5)
    req = rd.submit("arm")
    dev.state()
    rd.tick()
    req.wait()
    assert rd.safety.mode == Mode.ARMED
    rd.finish()


def test_rearm_tick_runs_the_safety_checks() -> None:
    rd, dev = _renderer()
    _settle(rd, dev, 100)
    dev.state(P.FLAG_FAULT)
    rd.tick()
    _settle(rd, dev, 3)
    # re-armed on a tick whose frames include a fault-flagged one before a clean one: the
    # arm itself is accepted (the newest state is clean) but the same tick's checks latch
    req = rd.submit("arm")
    dev.state(P.FLAG_FAULT)
    dev.state()
    rd.tick()
    req.wait()
    assert rd.safety.mode == Mode.FAULT and (rd.fx, rd.fy) == (0.0, 0.0)
    # re-armed on a tick that brings a sequence jump: the gap check runs on that tick
    req = rd.submit("arm")
    dev.seq = (dev.seq + 10) & 0xFFFF
    dev.state()
    rd.tick()
    req.wait()
    assert rd.safety.mode == Mode.FAULT and (rd.fx, rd.fy) == (0.0, 0.0)
    assert rd.safety.latched & (1 << (FaultCode.SEQ_GAP - 1))
    rd.finish()


def test_one_forged_sequence_number_does_not_blind_the_host() -> None:
    rd, dev = _renderer()
    _settle(rd, dev, 100)
    states = rd.port.state.states
    dev.state(seq=(dev.seq + 20_000) & 0xFFFF)  # forged, far ahead
    rd.tick()
    assert rd.safety.mode == Mode.FAULT  # the jump is a sequence gap: zero force at once
    ticks_blind = 0
    for _ in range(50):
        before = rd.port.state.states
        dev.state()
        rd.tick()
        if rd.port.state.states == before:
            ticks_blind += 1
    # without resynchronisation every genuine frame would look old for 20,000 frames (20 s)
    assert ticks_blind == RESYNC_FRAMES - 1
    assert rd.port.resyncs == 1 and rd.port.state.states > states + 40
    req = rd.submit("arm")
    dev.state()
    rd.tick()
    req.wait()
    assert rd.safety.mode == Mode.ARMED
    rd.finish()


#: One tick of the robot: (frames: list of (kind, flags)), operator re-arms this tick?
TickScript = tuple[list[tuple[str, int]], bool]
FLAGS = st.sampled_from([P.FLAG_ARMED, P.FLAG_ARMED, P.FLAG_ARMED, 0,
                         P.FLAG_ARMED | P.FLAG_FAULT, P.FLAG_FAULT, P.FLAG_WATCHDOG])
FRAME = st.tuples(st.sampled_from(["next", "next", "next", "next", "duplicate", "forged"]),
                  FLAGS)
TICK = st.tuples(st.lists(FRAME, min_size=0, max_size=3), st.booleans())


def _run_script(script: list[TickScript]) -> Iterator[tuple[bool, Renderer]]:
    """Play the script; yield (a fault-flagged frame arrived since the last accepted re-arm,
    renderer) after every tick."""
    rd, dev = _renderer()
    tainted = False
    for frames, rearm in script:
        req = rd.submit("arm") if rearm else None
        for kind, flags in frames:
            if kind == "next":
                dev.state(flags)
            elif kind == "duplicate":
                dev.state(flags, seq=dev.seq - 1)
            else:
                dev.state(flags, seq=dev.seq + 1000)
        flagged_before = rd.port.state.fault_flag_frames
        rd.tick()
        flagged_now = rd.port.state.fault_flag_frames > flagged_before
        accepted = False
        if req is not None:
            try:
                req.wait()
                accepted = True
            except HapticError:
                pass
        if accepted:
            tainted = False  # the operator re-armed before this tick's frames were judged
        if flagged_now:
            tainted = True
        yield tainted, rd
    rd.finish()


@settings(max_examples=60, deadline=None)
@given(st.lists(TICK, min_size=20, max_size=200))
def test_fuzz_no_armed_tick_after_a_fault_flagged_frame(script: list[TickScript]) -> None:
    armed_after_flag = 0
    flagged = 0
    for tainted, rd in _run_script(script):
        if tainted:
            flagged += 1
            if rd.safety.mode == Mode.ARMED or (rd.fx, rd.fy) != (0.0, 0.0):
                armed_after_flag += 1
    assert armed_after_flag == 0, f"{armed_after_flag} armed tick(s) of {flagged} after a flag"


def test_fuzz_sees_flags_at_all() -> None:
    # the fuzz above is not vacuous: a script with flags produces tainted ticks
    script: list[TickScript] = [([("next", P.FLAG_ARMED)], False)] * 50 + [
        ([("next", P.FLAG_ARMED | P.FLAG_FAULT)], False)] + [([("next", P.FLAG_ARMED)], True)]
    out = [(t, rd.safety.mode) for t, rd in _run_script(script)]
    assert out[49] == (False, Mode.ARMED)
    assert out[50] == (True, Mode.FAULT)
    assert out[51] == (False, Mode.ARMED)  # a clean re-arm resumes
