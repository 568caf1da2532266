"""Arm dynamics against an independent Lagrangian derivation, and energy conservation."""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp

from fieldbank.dynamics import (
    coriolis,
    forward_dynamics,
    hand_inertial_force,
    inertia,
    kinetic_energy,
)
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.sim import ArmSim, CouplingConfig


def _lagrangian_terms():
    """H(q) and C(q, q̇)q̇ of a planar two-link arm from its Lagrangian, derived here in sympy."""
    q1, q2, qd1, qd2 = sp.symbols("q1 q2 qd1 qd2")
    l1, c1, c2, m1, m2, i1, i2 = sp.symbols("l1 c1 c2 m1 m2 i1 i2", positive=True)
    # positions of the two centres of mass
    p1 = sp.Matrix([c1 * sp.cos(q1), c1 * sp.sin(q1)])
    p2 = sp.Matrix([l1 * sp.cos(q1) + c2 * sp.cos(q1 + q2), l1 * sp.sin(q1) + c2 * sp.sin(q1 + q2)])
    q = sp.Matrix([q1, q2])
    qd = sp.Matrix([qd1, qd2])
    v1 = p1.jacobian(q) * qd
    v2 = p2.jacobian(q) * qd
    t = (m1 * v1.dot(v1) + m2 * v2.dot(v2) + i1 * qd1**2 + i2 * (qd1 + qd2) ** 2) / 2
    h = sp.hessian(t, qd).applyfunc(sp.simplify)
    # Euler-Lagrange: d/dt(∂T/∂q̇) - ∂T/∂q = H q̈ + C q̇ ; C q̇ = (dH/dt) q̇ - ∂T/∂q
    hdot = sum((h.diff(v) * d for v, d in zip((q1, q2), (qd1, qd2), strict=True)),
               sp.zeros(2, 2))
    cq = hdot * qd - sp.Matrix([t.diff(q1), t.diff(q2)])
    syms = (q1, q2, qd1, qd2, l1, c1, c2, m1, m2, i1, i2)
    return sp.lambdify(syms, h, "numpy"), sp.lambdify(syms, cq, "numpy")


@pytest.fixture(scope="module")
def lagrange():
    return _lagrangian_terms()


@pytest.mark.parametrize("mass,height", [(75.0, 1.75), (40.0, 1.40), (110.0, 1.95)])
def test_inertia_and_coriolis_match_lagrangian(lagrange, mass, height):
    h_fn, c_fn = lagrange
    p = ArmParams.from_anthropometry(mass, height)
    arm = Arm.from_params(p)
    rng = np.random.default_rng(7)
    for _ in range(20):
        q = rng.uniform([-0.3, 0.0], [2.2, 2.6])
        qd = rng.normal(0, 3, 2)
        args = (*q, *qd, p.upper_arm_length_m, p.upper_arm_com_m, p.forearm_com_m,
                p.upper_arm_mass_kg, p.forearm_mass_kg, p.upper_arm_inertia_kg_m2,
                p.forearm_inertia_kg_m2)
        np.testing.assert_allclose(inertia(arm, q)[0], np.array(h_fn(*args), float),
                                   rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(coriolis(arm, q, qd)[0],
                                   np.array(c_fn(*args), float).ravel(), rtol=1e-10, atol=1e-12)


def _free_arm() -> Arm:
    p = ArmParams.from_anthropometry(km_n_per_m=(0.0,) * 6, alpha_n=(0.0,) * 6)
    return Arm.from_params(p)


def test_unforced_muscle_free_arm_conserves_energy_under_exact_integration():
    arm = _free_arm()

    def rhs(_t, y):
        return np.concatenate([y[2:], forward_dynamics(arm, y[:2], y[2:], muscles=False)[0]])

    y0 = np.array([0.6, 1.2, 2.5, -4.0])
    sol = solve_ivp(rhs, (0.0, 2.0), y0, method="DOP853", rtol=1e-12, atol=1e-12,
                    dense_output=False, t_eval=np.linspace(0, 2, 201))
    ke = kinetic_energy(arm, sol.y[:2].T, sol.y[2:].T)
    drift = np.abs(ke - ke[0]).max() / ke[0]
    assert drift < 1e-6
    # and the motion is not trivial: both joints swept through a real range
    assert np.ptp(sol.y[1]) > 0.5


def test_simulation_tick_conserves_energy_at_a_fine_step():
    arm = _free_arm()
    sim = ArmSim(arm, dt_s=2e-6, coupling=CouplingConfig(0.0, 0.0, 0.0, 0.0))
    sim.reset((0.6, 1.2), (1.0, -1.5))
    ke0 = kinetic_energy(arm, [0.6, 1.2], [1.0, -1.5])[0]
    worst = 0.0
    tick = sim.tick
    for k in range(1_000_000):  # 2 s
        tick(0.0, 0.0, 0.0, 0.0)
        if k % 50_000 == 0:
            s = sim.state
            ke = kinetic_energy(arm, [s.q1, s.q2], [s.qd1, s.qd2])[0]
            worst = max(worst, abs(ke - ke0) / ke0)
    assert sim.state.t_s == pytest.approx(2.0)
    assert worst < 1e-5


def test_tick_equals_forward_dynamics_step():
    p = ArmParams.from_anthropometry(beta=(1.0,) * 6, alpha_n=(3000.0,) * 6,
                                     km_n_per_m=(900.0, 500.0, 4000.0, 700.0, 1200.0, 300.0))
    arm = Arm.from_params(p)
    rng = np.random.default_rng(3)
    cfg = CouplingConfig()
    for _ in range(25):
        sim = ArmSim(arm, dt_s=1e-3, coupling=cfg)
        q = rng.uniform([0.2, 0.4], [1.6, 2.0])
        qd = rng.normal(0, 1.5, 2)
        sim.reset(tuple(q), tuple(qd))
        x, y, vx, vy = sim.hand()
        hand = np.array([x, y, vx, vy]) + rng.normal(0, [0.01, 0.01, 0.2, 0.2])
        f_on_hand = np.array([
            cfg.stiffness_n_per_m * (hand[0] - x) + cfg.damping_n_s_per_m * (hand[2] - vx),
            cfg.stiffness_n_per_m * (hand[1] - y) + cfg.damping_n_s_per_m * (hand[3] - vy),
        ])
        qdd = forward_dynamics(arm, q, qd, f_on_hand)[0]
        felt = sim.tick(*hand)
        np.testing.assert_allclose(felt, -f_on_hand, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose([sim.state.qd1, sim.state.qd2], qd + 1e-3 * qdd, rtol=1e-9,
                                   atol=1e-12)


def test_left_arm_sim_mirrors_right():
    right = Arm.from_params(ArmParams.from_anthropometry())
    left = Arm.from_params(ArmParams.from_anthropometry(side="left"))
    sr, sl = ArmSim(right), ArmSim(left)
    for k in range(200):
        hx = 0.08 + 0.05 * math.sin(k / 30)
        fr = sr.tick(hx, 0.5, 0.1, 0.0)
        fl = sl.tick(-hx, 0.5, -0.1, 0.0)
        assert fl[0] == pytest.approx(-fr[0], abs=1e-12)
        assert fl[1] == pytest.approx(fr[1], abs=1e-12)


@pytest.mark.parametrize("side", ["right", "left"])
def test_hand_inertial_force_is_the_inverse_of_forward_dynamics(side):
    """Joint angles of a hand path by inverse kinematics, their rates by finite differences;
    forward dynamics without muscles under the handle's force (minus the arm's inertial force
    on it) must give those accelerations back."""
    arm = Arm.from_params(ArmParams.from_anthropometry(side=side))
    t = np.linspace(0.0, 0.4, 4001)
    s = 10 * (t / 0.4) ** 3 - 15 * (t / 0.4) ** 4 + 6 * (t / 0.4) ** 5
    start = arm.rest_position()
    sign = -1.0 if side == "left" else 1.0
    x = start + np.c_[sign * 0.08 * s, -0.1 * s + 0.03 * np.sin(np.pi * s)]
    v = np.gradient(x, t, axis=0, edge_order=2)
    a = np.gradient(v, t, axis=0, edge_order=2)
    f = hand_inertial_force(arm, x, v, a)
    q = arm.ik(x)
    qd = np.gradient(q, t, axis=0, edge_order=2)
    qdd = np.gradient(qd, t, axis=0, edge_order=2)
    on_hand = -f * (np.array([-1.0, 1.0]) if arm.mirror else 1.0)  # model frame
    qdd_fd = forward_dynamics(arm, q, qd, on_hand, muscles=False)
    inner = slice(20, -20)
    assert np.abs(qdd_fd[inner] - qdd[inner]).max() < 1e-3 * np.abs(qdd).max()
    assert np.abs(f).max() > 1.0  # a real load: ~10 N for 13 cm in 0.4 s
    assert hand_inertial_force(arm, x[:1], np.zeros((1, 2)), np.zeros((1, 2))) == \
        pytest.approx(np.zeros((1, 2)))
