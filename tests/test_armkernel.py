"""The compiled tick of both arms and their blend (fieldbank.armkernel) against the plain-Python
reference (fieldbank.sim.ArmSim.tick): forces identical to 1e-12 N, tick after tick, for
right and left arms, inside and beyond the range of motion, and through a whole renderer run."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fieldbank.armkernel import ArmPair, ArrayState, tick_one
from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic.clock import VirtualClock
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.probe import sim_url
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.sim import CouplingConfig

TOL_N = 1e-12


def _pairs(side: str = "right", dt_s: float = 1e-3,
           coupling: CouplingConfig | None = None) -> tuple[ArmPair, ArmPair]:
    a = Arm.from_params(synthesize({"biarticular": "severe", "elbow": "moderate"},
                                   ArmParams.from_anthropometry(side=side)))
    b = Arm.from_params(ArmParams.from_anthropometry(side=side))
    return (ArmPair(a, b, dt_s, coupling, compiled=True),
            ArmPair(a, b, dt_s, coupling, compiled=False))


@pytest.mark.parametrize("side", ["right", "left"])
@pytest.mark.parametrize("dt_s", [1e-3, 2.5e-4])
def test_the_compiled_pair_gives_the_reference_forces(side: str, dt_s: float) -> None:
    compiled, reference = _pairs(side, dt_s)
    assert compiled.compiled and not reference.compiled
    x0, y0, _, _ = reference[0].hand()
    worst = 0.0
    n = 4000
    for k in range(n):
        # a fast, wide stroke: muscles stretched fast enough for the reflex, and at the end
        # past the range of motion (joint stops)
        s = 0.3 * k / n
        hx = x0 + 0.12 * math.sin(9 * s) - 0.25 * s
        hy = y0 - 0.15 * s + 0.06 * math.cos(13 * s)
        hvx, hvy = 0.8 * math.cos(9 * s), -0.5 * math.sin(13 * s)
        w = 0.5 - 0.5 * math.cos(math.pi * k / n)
        g = min(1.0, k / 300)
        got = compiled.tick(hx, hy, hvx, hvy, w, g)
        want = reference.tick(hx, hy, hvx, hvy, w, g)
        worst = max(worst, max(abs(u - v) for u, v in zip(got, want, strict=True)))
    assert worst <= TOL_N, worst
    assert compiled.joints() == pytest.approx(reference.joints(), abs=1e-12)
    assert compiled[0].state.ticks == reference[0].state.ticks == n
    # the stroke reached the joint stops and the reflex: forces were large, not trivially 0
    assert max(abs(v) for v in reference.tick(x0 - 0.3, y0 - 0.2, -1.0, -1.0, 0.5, 1.0)) > 5


def test_the_state_is_shared_with_the_python_side() -> None:
    compiled, reference = _pairs()
    x0, y0, _, _ = reference[0].hand()
    for p in (compiled, reference):
        p[0].reset_at_hand(x0 + 0.02, y0 - 0.01)
        p[1].reset((0.3, 1.2), (0.1, -0.2))
    assert isinstance(compiled[0].state, ArrayState)
    assert compiled.state is not None and compiled.state[1, :4].tolist() == [0.3, 1.2, 0.1, -0.2]
    assert compiled.joints() == reference.joints()
    one = compiled.params[0].copy()  # type: ignore[index]
    st = compiled.state[0].copy()
    f = tick_one(one, st, x0, y0, 0.0, 0.0)
    assert f == pytest.approx(reference[0].tick(x0, y0, 0.0, 0.0), abs=TOL_N)


def test_a_diverging_arm_is_non_finite_in_both() -> None:
    p = ArmParams.from_anthropometry()
    stiff = p.replace(upper_arm_mass_kg=0.05, forearm_mass_kg=0.05,
                      upper_arm_inertia_kg_m2=1e-7, forearm_inertia_kg_m2=1e-7)
    compiled = ArmPair(Arm.from_params(stiff), Arm.from_params(p), 1e-3)
    reference = ArmPair(Arm.from_params(stiff), Arm.from_params(p), 1e-3, compiled=False)
    x0, y0, _, _ = reference[1].hand()
    outcomes = []
    for pair in (compiled, reference):
        try:
            vals = [pair.tick(x0 + 0.3, y0 + 0.3, 5.0, 5.0, 0.0, 1.0) for _ in range(50)]
            outcomes.append(all(math.isfinite(v) for v in np.ravel(vals)))
        except ArithmeticError:
            outcomes.append(False)
    assert outcomes == [False, False]


def _run(compiled: bool) -> np.ndarray:
    before = synthesize({"shoulder": "severe"})
    after = ArmParams.from_anthropometry()
    link = RobotLink.open(sim_url(before, "circle"))
    link.handshake(1000, 20)
    rd = Renderer(link, before, after,
                  RendererConfig(state_wait_s=0.05, realtime_priority=False,
                                 compiled_tick=compiled), clock=VirtualClock())
    rd.start()
    for k in range(1500):
        if k == 400:
            rd.submit("switch", target="B")
        rd.tick()
    trace = rd.finish()
    link.close()
    return np.column_stack([trace.column("fx_n"), trace.column("fy_n"),
                            trace.column("model_fx_n"), trace.column("model_fy_n")])


def test_the_renderer_commands_the_same_forces_compiled_or_not() -> None:
    a, b = _run(True), _run(False)
    assert a.shape == b.shape and np.abs(a).max() > 1.0
    assert np.array_equal(a, b)  # the trace keeps float32 of forces equal to 1e-12 N
