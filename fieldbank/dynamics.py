"""Rigid-body dynamics of the two-link arm in the horizontal plane (seed eq. 1).

H(q) q̈ + C(q, q̇) q̇ = J_qᵀ F_ext + τ_muscle, with τ_muscle = -J_λᵀ(Ψ + Φ).

Two point-free links with centres of mass at c1, c2 from their proximal joints and inertias I1,
I2 about those centres (the standard double pendulum without gravity):

    H11 = I1 + m1 c1² + I2 + m2 (l1² + c2² + 2 l1 c2 cos q2)
    H12 = I2 + m2 (c2² + l1 c2 cos q2)
    H22 = I2 + m2 c2²
    C q̇ = h · (-q̇2 (2 q̇1 + q̇2),  q̇1²),  h = m2 l1 c2 sin q2

These array functions are for analysis and tests; the 1 kHz loop uses the unrolled scalar
version in :mod:`fieldbank.sim`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from fieldbank.model import Arm, FloatArray


def inertia_constants(arm: Arm) -> tuple[float, float, float, float]:
    """(a1, a2, a3, h0): H11 = a1 + 2 h0 cos q2, H12 = a2 + h0 cos q2, H22 = a3."""
    p = arm.params
    m1, m2 = p.upper_arm_mass_kg, p.forearm_mass_kg
    c1, c2 = p.upper_arm_com_m, p.forearm_com_m
    i1, i2 = p.upper_arm_inertia_kg_m2, p.forearm_inertia_kg_m2
    l1 = p.upper_arm_length_m
    a3 = i2 + m2 * c2 * c2
    a1 = i1 + m1 * c1 * c1 + a3 + m2 * l1 * l1
    return a1, a3, a3, m2 * l1 * c2


def inertia(arm: Arm, q: ArrayLike) -> FloatArray:
    """Inertia matrix H(q), shape (N, 2, 2), kg·m²."""
    qa = np.atleast_2d(np.asarray(q, dtype=float))
    a1, a2, a3, h0 = inertia_constants(arm)
    c2 = np.cos(qa[:, 1])
    h = np.empty((qa.shape[0], 2, 2))
    h[:, 0, 0] = a1 + 2 * h0 * c2
    h[:, 0, 1] = h[:, 1, 0] = a2 + h0 * c2
    h[:, 1, 1] = a3
    return h


def coriolis(arm: Arm, q: ArrayLike, qdot: ArrayLike) -> FloatArray:
    """Coriolis and centripetal torques C(q, q̇) q̇, shape (N, 2), N·m."""
    qa = np.atleast_2d(np.asarray(q, dtype=float))
    qd = np.atleast_2d(np.asarray(qdot, dtype=float))
    h = inertia_constants(arm)[3] * np.sin(qa[:, 1])
    return np.stack([-h * qd[:, 1] * (2 * qd[:, 0] + qd[:, 1]), h * qd[:, 0] ** 2], axis=1)


def forward_dynamics(
    arm: Arm,
    q: ArrayLike,
    qdot: ArrayLike,
    force_on_hand_n: ArrayLike | None = None,
    muscles: bool = True,
) -> FloatArray:
    """Joint accelerations q̈ (N, 2), rad/s², under an external force on the hand.

    Parameters
    ----------
    force_on_hand_n : array, shape (2,) or (N, 2), N, optional
        Force applied to the hand in the model (right-arm) frame.
    muscles : bool
        Include the muscle torques (passive and reflex).
    """
    qa = np.atleast_2d(np.asarray(q, dtype=float))
    qd = np.atleast_2d(np.asarray(qdot, dtype=float))
    tau = -coriolis(arm, qa, qd)
    if force_on_hand_n is not None:
        f = np.broadcast_to(np.asarray(force_on_hand_n, dtype=float), qa.shape)
        tau = tau + np.einsum("nji,nj->ni", arm.jacobian(qa), f)
    if muscles:
        tau = tau + arm.joint_torque(qa, qd)
    qdd = np.asarray(np.linalg.solve(inertia(arm, qa), tau[..., None])[..., 0], dtype=float)
    return qdd


def kinetic_energy(arm: Arm, q: ArrayLike, qdot: ArrayLike) -> FloatArray:
    """½ q̇ᵀ H q̇, shape (N,), J."""
    qd = np.atleast_2d(np.asarray(qdot, dtype=float))
    return 0.5 * np.einsum("ni,nij,nj->n", qd, inertia(arm, q), qd)
