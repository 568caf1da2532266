"""Fault injection over a pty: the force goes to zero within the stated time, the fault latches,
the trace records it, and only an explicit re-arm resumes. Also adversarial models and fuzzing."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldbank.haptic.clock import VirtualClock
from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.protocol import FaultCode
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.safety import Mode
from fieldbank.haptic.simrobot import PtyRobot, SimDevice
from fieldbank.params import ArmParams
from tests.haptic_util import MemoryPort, pty_session, severe_shoulder

INJECT_AT = 800  # tick at which the fault is injected (handle moving, force well above zero)


def _inject(kind: str, robot: PtyRobot) -> None:
    dev: SimDevice = robot.device
    if kind == "corrupt":
        dev.corrupt_frames = 6
    elif kind == "drop":
        dev.drop_frames = 4
    elif kind == "freeze":
        dev.frozen = True
    elif kind == "nan":
        dev.nan_frames = 1
    elif kind == "unplug":
        robot.unplug()


#: fault -> (expected code, N): the command is zero from the N-th tick on, counting the first
#: tick that receives an affected frame as 1 (the tick after the injection for device-side
#: faults, since a lockstep device answers each FORCE on the next tick; the injection tick for
#: an unplugged port). Stated times at 1 kHz: CRC errors trip when the leaky bucket passes 5
#: (6th bad frame); a gap of 4 frames is seen on the first good frame after it (5th tick); a
#: frozen device trips after 5 ms without STATE (6th tick); NaN and an unplugged port trip on
#: the tick that sees them.
CASES: dict[str, tuple[FaultCode, int]] = {
    "corrupt": (FaultCode.CRC, 6),
    "drop": (FaultCode.SEQ_GAP, 5),
    "freeze": (FaultCode.TIMEOUT, 6),
    "nan": (FaultCode.NAN, 1),
    "unplug": (FaultCode.DISCONNECT, 1),
}


@pytest.mark.parametrize("kind", list(CASES))
def test_fault_zeroes_force_latches_and_is_recorded(kind: str) -> None:
    code, within = CASES[kind]
    cfg = RendererConfig(state_wait_s=0.2)
    with pty_session(severe_shoulder(), motion="fastpull", config=cfg) as (rd, robot):
        rd.start(expected_ticks=1200)
        first = INJECT_AT if kind == "unplug" else INJECT_AT + 1
        for i in range(INJECT_AT + within + 4):
            if i == INJECT_AT:
                time.sleep(0.05)  # the device has answered the last FORCE: injection is exact
                _inject(kind, robot)
            rd.tick()
            if i == INJECT_AT - 1:
                assert np.hypot(rd.fx, rd.fy) > 1.0  # something to take away
        trace = rd.finish()
        assert rd.safety.mode == Mode.FAULT
        f = np.hypot(trace.column("fx_n"), trace.column("fy_n"))
        assert np.all(f[first + within - 1:] == 0.0), np.flatnonzero(f[INJECT_AT:])[:5]
        assert f[first - 1] > 1.0  # still rendering before the fault could be seen
        # the trace records it: latched bitmask per tick and the fault log
        bits = trace.column("faults").astype(np.int64)
        assert np.all(bits[:INJECT_AT] == 0)
        assert bits[-1] & (1 << (code - 1))
        assert code in [r["code"] for r in trace.faults]
        rec = next(r for r in trace.faults if r["code"] == code)
        assert INJECT_AT * 1e-3 <= rec["t_s"] <= (first + within - 1) * 1e-3 + 1e-9
        assert trace.column("mode")[-1] == float(Mode.FAULT)
        if kind in ("corrupt", "drop", "nan"):
            # the link is healthy again but the fault stays latched until an explicit re-arm
            rd.start(expected_ticks=10)  # restarting does not re-arm a latched fault ...
            assert rd.safety.mode in (Mode.FAULT, Mode.ARMED)


@pytest.mark.parametrize("kind", ["corrupt", "nan"])
def test_only_an_explicit_rearm_resumes(kind: str) -> None:
    cfg = RendererConfig(state_wait_s=0.2, arm_on_start=True)
    with pty_session(severe_shoulder(), motion="hold", config=cfg) as (rd, robot):
        rd.start(expected_ticks=3000)
        for _ in range(100):
            rd.tick()
        _inject(kind, robot)
        for _ in range(300):  # the link recovers, the fault does not clear by itself
            rd.tick()
        assert rd.safety.mode == Mode.FAULT and (rd.fx, rd.fy) == (0.0, 0.0)
        cmd = rd.submit("arm")
        rd.tick()  # commands are applied at the start of a tick
        cmd.wait()
        assert rd.safety.mode == Mode.ARMED
        for _ in range(50):
            rd.tick()
        assert rd.safety.mode == Mode.ARMED
        trace = rd.finish()
    assert [e["event"] for e in trace.events].count("arm") == 2


def test_rearm_refused_while_link_down() -> None:
    with pty_session(severe_shoulder()) as (rd, robot):
        rd.start(expected_ticks=100)
        rd.tick()
        robot.unplug()
        rd.tick()
        cmd = rd.submit("arm")
        rd.tick()
        with pytest.raises(HapticError, match="link is down"):
            cmd.wait()
        rd.finish()


def test_device_watchdog_zeroes_force_when_commands_stop() -> None:
    # realtime device with a fake wall clock: no FORCE for more than 20 ms -> zero, disarmed
    from fieldbank.haptic import protocol as P
    from fieldbank.haptic.simrobot import SimRobotConfig

    now = [0.0]
    dev = SimDevice(SimRobotConfig(mode="realtime", watchdog_ms=20), clock=lambda: now[0])
    dev.feed(P.encode_frame(P.MsgType.HELLO, 0, P.HELLO_FMT.pack(1, 1000, 20)))
    dev.feed(P.encode_frame(P.MsgType.ARM, 1))
    dev.feed(P.encode_frame(P.MsgType.FORCE, 2, P.FORCE_FMT.pack(10.0, 0.0)))
    for k in range(1, 40):
        now[0] = k * 1e-3
        dev.poll_realtime(now[0])
        if k <= 20:
            assert dev.fx_cmd == 10.0
    assert dev.fx_cmd == 0.0 and not dev.armed and dev.watchdog_tripped
    # FORCE is ignored until the host arms again
    dev.feed(P.encode_frame(P.MsgType.FORCE, 3, P.FORCE_FMT.pack(10.0, 0.0)))
    assert dev.fx_cmd == 0.0
    # the host sees the watchdog flag and latches a DEVICE fault
    out = P.FrameReader().feed(dev.take_output())
    flags = [P.STATE_FMT.unpack(f.payload)[5] for f in out if f.type == P.MsgType.STATE]
    assert flags[-1] & P.FLAG_WATCHDOG


def test_device_clamps_to_its_own_force_limit() -> None:
    from fieldbank.haptic import protocol as P
    from fieldbank.haptic.simrobot import SimRobotConfig

    dev = SimDevice(SimRobotConfig(force_limit_n=30.0))
    dev.feed(P.encode_frame(P.MsgType.HELLO, 0, P.HELLO_FMT.pack(1, 1000, 20)))
    dev.feed(P.encode_frame(P.MsgType.ARM, 1))
    dev.feed(P.encode_frame(P.MsgType.FORCE, 2, P.FORCE_FMT.pack(300.0, 400.0)))
    assert np.hypot(dev.fx_cmd, dev.fy_cmd) == pytest.approx(30.0)


# --- adversarial models ---------------------------------------------------------------------
def _adversarial(kind: str) -> ArmParams:
    p = severe_shoulder()
    if kind == "stiff":
        return p.replace(km_n_per_m=(1e6,) * 6, alpha_n=(1e5,) * 6)
    if kind == "light":
        return p.replace(upper_arm_mass_kg=0.05, forearm_mass_kg=0.05,
                         upper_arm_inertia_kg_m2=1e-7, forearm_inertia_kg_m2=1e-7)
    return p.replace(km_n_per_m=(1e6,) * 6, upper_arm_mass_kg=0.05, forearm_mass_kg=0.05,
                     upper_arm_inertia_kg_m2=1e-7, forearm_inertia_kg_m2=1e-7)


@pytest.mark.parametrize("kind", ["stiff", "light", "both"])
def test_force_limit_holds_for_adversarial_models(kind: str) -> None:
    bad = _adversarial(kind)  # at the edges of the parameter bounds
    with pty_session(severe_shoulder(), bad, motion="circle") as (rd, _robot):
        rd.start(expected_ticks=2500)
        for i in range(2500):
            if i == 300:
                rd.submit("switch", target="B")
            if i > 300 and rd.safety.mode == Mode.FAULT and i % 200 == 0:
                cmd = rd.submit("arm")
                rd.tick()
                try:
                    cmd.wait()
                except HapticError:
                    pass
            rd.tick()
        trace = rd.finish()
    f = np.hypot(trace.column("fx_n"), trace.column("fy_n"))
    assert f.max() <= 40.0
    assert np.all(np.isfinite(f))


# --- fuzzing --------------------------------------------------------------------------------
@settings(max_examples=40, deadline=None)
@given(st.binary(min_size=0, max_size=3000), st.integers(1, 64))
def test_random_bytes_on_the_link_never_crash_the_renderer(data: bytes, chunk: int) -> None:
    # a valid STATE first so the renderer starts, then garbage
    from fieldbank.haptic import protocol as P

    head = P.encode_frame(P.MsgType.STATE, 0, P.STATE_FMT.pack(0, 0.05, 0.5, 0.0, 0.0, 1, 0))
    link = RobotLink(MemoryPort(head + data, lambda: chunk))  # type: ignore[arg-type]
    p = severe_shoulder()
    rd = Renderer(link, p, p, RendererConfig(), clock=VirtualClock())
    trace = rd.run(0.3)
    f = np.hypot(trace.column("fx_n"), trace.column("fy_n"))
    assert np.all(np.isfinite(f)) and f.max() <= 40.0
    assert len(trace) == 300


def test_random_bytes_over_a_pty_never_crash_the_renderer() -> None:
    from fieldbank.haptic.simrobot import SimRobotConfig

    with PtyRobot(SimRobotConfig()) as robot:
        link = RobotLink.open(robot.port)
        from fieldbank.haptic import protocol as P
        os.write(robot.master_fd, P.encode_frame(
            P.MsgType.STATE, 0, P.STATE_FMT.pack(0, 0.05, 0.5, 0.0, 0.0, 1, 0)))
        rng = np.random.default_rng(1)
        p = severe_shoulder()
        rd = Renderer(link, p, p, RendererConfig(), clock=VirtualClock())
        rd.start(expected_ticks=500)
        for _ in range(500):
            os.write(robot.master_fd, rng.bytes(int(rng.integers(1, 80))))
            rd.tick()
        trace = rd.finish()
        link.close()
    assert rd.port.decode_errors > 0
    assert np.all(np.hypot(trace.column("fx_n"), trace.column("fy_n")) <= 40.0)


def test_simulated_handle_settles_where_the_operator_spring_balances_the_force() -> None:
    """Independent check of the device physics: a constant 6 N against the operator's 600 N/m
    hand settles at 6/600 = 10 mm from the hold point (friction vanishes at rest)."""
    from fieldbank.haptic import protocol as P
    from fieldbank.haptic.simrobot import SimRobotConfig

    dev = SimDevice(SimRobotConfig(motion="hold", x0_m=0.1, y0_m=0.4))
    dev.feed(P.encode_frame(P.MsgType.HELLO, 0, P.HELLO_FMT.pack(1, 1000, 20)))
    dev.feed(P.encode_frame(P.MsgType.ARM, 1))
    for k in range(3000):
        dev.feed(P.encode_frame(P.MsgType.FORCE, 2 + k, P.FORCE_FMT.pack(6.0, -3.0)))
    assert dev.x - 0.1 == pytest.approx(6.0 / 600.0, rel=1e-3)
    assert dev.y - 0.4 == pytest.approx(-3.0 / 600.0, rel=1e-3)
    assert abs(dev.vx) < 1e-6


@pytest.mark.parametrize("limit,code", [
    ({"workspace_m": (-0.5, 0.6, 0.47, 0.8)}, FaultCode.WORKSPACE),
    ({"speed_limit_m_per_s": 0.4}, FaultCode.SPEED),
])
def test_workspace_and_speed_limits_end_to_end(limit: dict[str, object], code: FaultCode) -> None:
    from fieldbank.haptic.safety import SafetyConfig

    safety = SafetyConfig(**limit)  # type: ignore[arg-type]
    with pty_session(severe_shoulder(), motion="fastpull", safety=safety) as (rd, _robot):
        trace = rd.run(0.9)
    y = trace.column("y_m").astype(float)
    speed = np.hypot(trace.column("vx_m_per_s"), trace.column("vy_m_per_s")).astype(float)
    out = (y < 0.47) if code == FaultCode.WORKSPACE else (speed > 0.4)
    first = int(np.argmax(out))
    assert out.any() and first > 0
    f = np.hypot(trace.column("fx_n"), trace.column("fy_n"))
    assert f[first - 1] > 0.0 and np.all(f[first:] == 0.0)  # zero on the tick it is seen
    assert [r["code"] for r in trace.faults] == [code]
