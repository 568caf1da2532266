"""A recorded handle motion replayed on many candidate arms of one geometry at once.

The classifier's ``replay`` predictor drives each candidate's virtual arm with the recorded
handle motion through the virtual coupling, tick by tick (:class:`fieldbank.sim.ArmSim`).
With the open set of candidates (≈ 150 arms: every group, component and level, two groups,
contractures) one plain-float arm per candidate costs seconds per trace. Candidates of one
patient share the arm's geometry - segments, masses, moment arms, range of motion, rest
posture - and differ only in muscle values (Km, α, β, slack offset), so here every candidate
ticks together: the same arithmetic as :func:`fieldbank.sim._make_tick` (semi-implicit Euler,
the smoothed passive ramp, the reflex, the joint stops), each line over an array of candidates.
``tests/test_probe_open.py`` checks it against :class:`~fieldbank.sim.ArmSim` to 1e-9.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fieldbank.dynamics import inertia_constants
from fieldbank.errors import ParameterError
from fieldbank.model import Arm, FloatArray
from fieldbank.sim import CouplingConfig


def same_geometry(arms: Sequence[Arm]) -> bool:
    """Whether every arm differs from the first in muscle values only
    (:attr:`fieldbank.model.Arm.MUSCLE_FIELDS`)."""
    if not arms:
        return False
    first = arms[0]
    for a in arms[1:]:
        try:
            first.with_muscles(a.params)
        except ParameterError:
            return False
    return True


def replay_forces(arms: Sequence[Arm], positions_m: FloatArray, velocities_m_per_s: FloatArray,
                  dt_s: float, reset_m: tuple[float, float],
                  coupling: CouplingConfig | None = None) -> FloatArray:
    """The force (n, T, 2), N, each of ``arms`` (one geometry: :func:`same_geometry`) puts on
    the handle when the handle follows ``positions_m`` / ``velocities_m_per_s`` (T, 2),
    shoulder frame, one tick of ``dt_s`` per sample, each arm at rest with its hand at
    ``reset_m`` first - what an :class:`~fieldbank.sim.ArmSim` per arm gives.

    Raises
    ------
    ParameterError
        The arms do not share one geometry.
    """
    if not same_geometry(arms):
        raise ParameterError("replay_forces: the arms differ in more than muscle values; "
                             "replay them one by one (fieldbank.sim.ArmSim).")
    cfg = coupling or CouplingConfig()
    geo = arms[0]
    n = len(arms)
    l1, l2 = float(geo.l1), float(geo.l2)
    a1, a2, a3, h0 = inertia_constants(geo)
    kc, bc = float(cfg.stiffness_n_per_m), float(cfg.damping_n_s_per_m)
    ks, bs = float(cfg.stop_stiffness_n_m_per_rad), float(cfg.stop_damping_n_m_s_per_rad)
    p = geo.params
    s_lo, s_hi = p.shoulder_range_rad
    e_lo, e_hi = p.elbow_range_rad
    qr1, qr2 = float(geo.q_rest[0]), float(geo.q_rest[1])
    w = float(geo.w)
    mirror = -1.0 if geo.mirror else 1.0
    ja, jb = geo.jl[:, 0], geo.jl[:, 1]
    iell = 1.0 / geo.excursion
    off = geo.lam_rest - geo.lam_min
    ilm = 1.0 / geo.ldot_max
    kk = geo.lam_rest / geo.lam_max
    km = np.array([a.km for a in arms])
    alpha = np.array([a.alpha for a in arms])
    beta = np.array([a.beta for a in arms])
    slack = np.array([a.lam_slack - a.lam_rest for a in arms])
    q0 = geo.ik([list(reset_m)])[0]
    q1 = np.full(n, float(q0[0]))
    q2 = np.full(n, float(q0[1]))
    qd1 = np.zeros(n)
    qd2 = np.zeros(n)
    hx_all = mirror * np.asarray(positions_m[:, 0], dtype=float)
    hy_all = np.asarray(positions_m[:, 1], dtype=float)
    hvx_all = mirror * np.asarray(velocities_m_per_s[:, 0], dtype=float)
    hvy_all = np.asarray(velocities_m_per_s[:, 1], dtype=float)
    out = np.empty((n, len(hx_all), 2))
    for t in range(len(hx_all)):
        c1, s1 = np.cos(q1), np.sin(q1)
        q12 = q1 + q2
        c12, s12 = np.cos(q12), np.sin(q12)
        j12 = -l2 * s12
        j11 = -l1 * s1 + j12
        j22 = l2 * c12
        j21 = l1 * c1 + j22
        fx = kc * (hx_all[t] - j21) + bc * (hvx_all[t] - j11 * qd1 - j12 * qd2)
        fy = kc * (hy_all[t] - l1 * s1 - l2 * s12) + bc * (hvy_all[t] - j21 * qd1 - j22 * qd2)
        t1 = j11 * fx + j21 * fy
        t2 = j12 * fx + j22 * fy
        d = np.outer(q1 - qr1, ja) + np.outer(q2 - qr2, jb)
        ds = d - slack
        f = km * w * np.logaddexp(0.0, ds / w) * np.exp(-(ds * iell) ** 2)
        ld = np.outer(qd1, ja) + np.outer(qd2, jb)
        u = beta * np.minimum(np.maximum(ld, 0.0) * ilm, 1.0)
        g = (d + off) * iell - kk * (1.0 - u)
        h = alpha * u * g * np.exp(-g * g)
        f += np.where((ld > 0.0) & (h > 0.0), h, 0.0)
        t1 -= f @ ja
        t2 -= f @ jb
        t1 -= np.where(q1 < s_lo, ks * (q1 - s_lo) + bs * qd1,
                       np.where(q1 > s_hi, ks * (q1 - s_hi) + bs * qd1, 0.0))
        t2 -= np.where(q2 < e_lo, ks * (q2 - e_lo) + bs * qd2,
                       np.where(q2 > e_hi, ks * (q2 - e_hi) + bs * qd2, 0.0))
        c2 = np.cos(q2)
        hh = h0 * np.sin(q2)
        t1 += hh * qd2 * (2.0 * qd1 + qd2)
        t2 -= hh * qd1 * qd1
        m11 = a1 + 2.0 * h0 * c2
        m12 = a2 + h0 * c2
        det = m11 * a3 - m12 * m12
        qd1 = qd1 + dt_s * (a3 * t1 - m12 * t2) / det
        qd2 = qd2 + dt_s * (m11 * t2 - m12 * t1) / det
        q1 = q1 + dt_s * qd1
        q2 = q2 + dt_s * qd2
        out[:, t, 0] = -mirror * fx
        out[:, t, 1] = -fy
    return out
