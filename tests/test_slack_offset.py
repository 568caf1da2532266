"""The per-group slack offset: passive onset moves, the field stays a gradient field, the
1 kHz tick agrees with the vectorised model, and documents without the field still load."""

from __future__ import annotations

import json

import numpy as np

from fieldbank.dynamics import inertia
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.sim import ArmSim


def _slack_arm() -> Arm:
    p = ArmParams.from_anthropometry().with_group("ef", slack_offset_m=0.01)
    return Arm.from_params(p.with_group("be", slack_offset_m=-0.005))


def test_passive_force_is_shifted_by_the_offset() -> None:
    base = Arm.from_params(ArmParams.from_anthropometry())
    arm = _slack_arm()
    lam = base.lam_rest + np.linspace(-0.02, 0.03, 41)[:, None]
    psi0, _ = base.passive_forces(lam)
    psi1, _ = arm.passive_forces(lam + np.array([0, 0, 0.01, 0, 0, -0.005]))
    np.testing.assert_allclose(psi1, psi0, rtol=1e-12, atol=1e-12)


def test_field_is_minus_gradient_of_potential_with_offset() -> None:
    arm = _slack_arm()
    x = np.array([[0.05, 0.45], [0.15, 0.35], [-0.05, 0.5]])
    h = 1e-6
    grad = np.empty_like(x)
    for j in range(2):
        e = np.zeros(2)
        e[j] = h
        grad[:, j] = (arm.potential(x + e) - arm.potential(x - e)) / (2 * h)
    np.testing.assert_allclose(arm.endpoint_force(x), -grad, rtol=1e-5, atol=1e-6)


def test_tick_matches_model_torque_with_offset() -> None:
    arm = _slack_arm()
    q = np.array([0.6, 0.9])
    sim = ArmSim(arm, dt_s=1e-3)
    sim.reset(q=(float(q[0]), float(q[1])))
    hand = arm.fk(q)[0]
    # Handle held at the hand: no coupling force, so one semi-implicit Euler tick from rest
    # gives q̇ = dt · H⁻¹ τ_muscle.
    sim.tick(float(hand[0]), float(hand[1]), 0.0, 0.0)
    tau = arm.joint_torque(q)[0]
    base = Arm.from_params(ArmParams.from_anthropometry())
    assert np.linalg.norm(tau - base.joint_torque(q)[0]) > 0.05  # the offsets matter here
    expected = 1e-3 * np.linalg.solve(inertia(arm, q).reshape(2, 2), tau)
    np.testing.assert_allclose([sim.state.qd1, sim.state.qd2], expected, rtol=1e-6)


def test_version1_document_without_offset_loads() -> None:
    d = ArmParams.from_anthropometry().to_dict()
    del d["slack_offset_m"]
    p = ArmParams.from_json(json.dumps(d))
    assert p.slack_offset_m == (0.0,) * 6
