"""Safety layer: the force limit, rate limit, passivity controller and the fault state machine."""

from __future__ import annotations

import math
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldbank.errors import ParameterError
from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.protocol import FORCE_FMT, FaultCode
from fieldbank.haptic.safety import ForceLimiter, Mode, PassivityController, Safety, SafetyConfig

forces = st.floats(allow_nan=True, allow_infinity=True, width=64)


@settings(max_examples=500)
@given(st.lists(st.tuples(forces, forces), min_size=1, max_size=30))
def test_force_limit_is_never_exceeded_on_the_wire(seq: list[tuple[float, float]]) -> None:
    lim = ForceLimiter(40.0, 1e9, 1e-3)  # no rate limit: saturation alone must hold
    for fx, fy in seq:
        ox, oy = lim(fx, fy)
        assert math.isfinite(ox) and math.isfinite(oy)
        # what the robot receives: float32 on the wire
        wx, wy = struct.unpack("<ff", FORCE_FMT.pack(ox, oy))
        assert math.hypot(wx, wy) <= 40.0


@given(st.lists(st.tuples(st.floats(-1e6, 1e6), st.floats(-1e6, 1e6)), min_size=2, max_size=40))
def test_rate_limit_bounds_every_step(seq: list[tuple[float, float]]) -> None:
    lim = ForceLimiter(40.0, 10_000.0, 1e-3)
    px = py = 0.0
    for fx, fy in seq:
        ox, oy = lim(fx, fy)
        assert math.hypot(ox - px, oy - py) <= 10.0 + 1e-9
        assert math.hypot(ox, oy) <= 40.0
        px, py = ox, oy


def test_nan_force_becomes_zero_and_is_flagged() -> None:
    lim = ForceLimiter(40.0, 1e4, 1e-3)
    assert lim(float("nan"), 1.0) == (0.0, 0.0)
    assert lim.nan_seen


def _run_active_environment(passivity: bool, seconds: float = 3.0) -> tuple[float, float]:
    """1-D handle (mass 1 kg, held by a soft operator spring) on an *active* environment
    F = +b v (negative damping): without the passivity controller the motion grows."""
    dt = 1e-3
    s = Safety(SafetyConfig(passivity=passivity, force_rate_n_per_s=1e9,
                            workspace_m=(-100, 100, -100, 100), speed_limit_m_per_s=100.0), dt)
    s.rearm((0.0, 0.0, 0.0, 0.0))
    x, v = 0.01, 0.0
    m, k_op = 1.0, 50.0
    vmax = 0.0
    for _ in range(int(seconds / dt)):
        fx, _ = s.output(8.0 * v, 0.0, v, 0.0)
        a = (fx - k_op * x) / m
        v += dt * a
        x += dt * v
        vmax = max(vmax, abs(v))
    return vmax, s.passivity.energy_j


def test_passivity_controller_stabilises_an_active_environment() -> None:
    v_off, _ = _run_active_environment(False)
    v_on, energy = _run_active_environment(True)
    assert v_off > 1.0            # grows without the controller (to ~44 m/s, capped by 40 N)
    assert v_on < 0.08            # stays near the initial 0.07 m/s with it
    assert energy >= -1e-3        # the observer's energy is kept (nearly) non-negative


def test_passivity_controller_leaves_a_passive_spring_alone() -> None:
    pc = PassivityController(1e-3, 60.0)
    x, v = 0.0, 0.1
    for _ in range(2000):
        f = -200.0 * x               # a spring: passive, returns only what it stored
        fx, _ = pc.correct(f, 0.0, v, 0.0)
        pc.observe(fx, 0.0, v, 0.0)
        v += 1e-3 * (fx - 20.0 * x)  # operator spring
        x += 1e-3 * v
    assert pc.active_ticks < 20      # sampling effects only


def test_fault_latches_zeroes_and_needs_rearm() -> None:
    s = Safety(SafetyConfig(), 1e-3)
    assert s.output(5.0, 0.0, 0.0, 0.0) == (0.0, 0.0)  # disarmed
    s.rearm((0.0, 0.4, 0.0, 0.0))
    assert s.mode == Mode.ARMED
    assert s.output(5.0, 0.0, 0.0, 0.0) != (0.0, 0.0)
    s.trip(FaultCode.CRC, 1.0, "test")
    assert s.mode == Mode.FAULT
    assert s.output(5.0, 0.0, 0.0, 0.0) == (0.0, 0.0)
    s.trip(FaultCode.CRC, 1.1, "again")
    assert len(s.log_records) == 1        # a latched fault is logged once
    with pytest.raises(HapticError, match="outside the workspace"):
        s.rearm((5.0, 0.4, 0.0, 0.0))
    assert s.mode == Mode.FAULT
    s.rearm((0.0, 0.4, 0.0, 0.0))
    assert s.mode == Mode.ARMED and s.latched == 0


@pytest.mark.parametrize("state,code", [
    ((float("nan"), 0.4, 0, 0), FaultCode.NAN),
    ((0.0, 0.4, float("inf"), 0), FaultCode.NAN),
    ((0.9, 0.4, 0, 0), FaultCode.WORKSPACE),
    ((0.0, 0.4, 3.0, 0), FaultCode.SPEED),
    ((0.0, 0.4, 0.5, 0.5), 0),
])
def test_handle_checks(state: tuple[float, float, float, float], code: int) -> None:
    assert Safety(SafetyConfig(), 1e-3).check_handle(*state)[0] == code


def test_crc_leaky_bucket() -> None:
    s = Safety(SafetyConfig(crc_error_limit=5, crc_leak_per_s=1.0), 1e-3)
    assert not s.check_crc(5)
    assert s.check_crc(6)
    s2 = Safety(SafetyConfig(crc_error_limit=5, crc_leak_per_s=1.0), 1e-3)
    total = 0
    for _ in range(20):  # one error every 1.5 s is forgiven
        total += 1
        assert not s2.check_crc(total)
        for _ in range(1500):
            s2.check_crc(total)


def test_config_validation_names_the_field() -> None:
    with pytest.raises(ParameterError, match="force_limit_n"):
        SafetyConfig(force_limit_n=-1)
    with pytest.raises(ParameterError, match="workspace_m"):
        SafetyConfig(workspace_m=(1, 0, 0, 1))


@pytest.mark.parametrize("field,value,expected", [
    ("force_limit_n", 0.0, r"'force_limit_n' safety parameter must be a finite number in "
                           r"\(0, inf\) N; got 0\.0"),
    ("state_timeout_ms", float("nan"), r"'state_timeout_ms' .* \(0, inf\) ms; got nan"),
    ("crc_error_limit", -1, r"'crc_error_limit' .* \[0, inf\) errors"),
    ("max_seq_gap", "3", r"'max_seq_gap' safety parameter must be a number .* got '3' \(str\)"),
    ("workspace_m", (0.0, 1.0, float("inf"), 1.0), r"'workspace_m\[2\] \(ymin\)'"),
    ("workspace_m", (0.0, 1.0), r"'workspace_m' .* must have 4 entries"),
])
def test_safety_bounds_table_generates_the_message(field: str, value: object,
                                                   expected: str) -> None:
    with pytest.raises(ParameterError, match=expected):
        SafetyConfig(**{field: value})  # type: ignore[arg-type]


def test_simulated_robot_config_bounds() -> None:
    from fieldbank.haptic.simrobot import SIM_BOUNDS, SimRobotConfig

    with pytest.raises(ParameterError, match=r"'substep_s' sim parameter .* \(0, inf\) s"):
        SimRobotConfig(substep_s=0.0)
    with pytest.raises(ParameterError, match=r"'x0_m' sim parameter .* got nan"):
        SimRobotConfig(x0_m=float("nan"))
    assert set(SIM_BOUNDS) <= {f for f in SimRobotConfig.__dataclass_fields__}
