"""Simulation state of one virtual arm, stepped one tick at a time for a 1 kHz loop.

:class:`ArmSim` keeps what changes (joint angles and rates, time) apart from what does not (an
:class:`fieldbank.model.Arm`). Each :meth:`ArmSim.tick` takes the handle's position and velocity
(shoulder frame), computes the virtual-coupling force (spring-damper between handle and the
virtual hand; Colgate 1995), steps the arm dynamics of seed eq. 1 under that force with the six
muscles, and returns the force the handle feels (the opposite of the coupling force on the
hand).

The tick is plain-float Python on purpose: numpy on 2×2 arrays costs ~20 µs a call, an order of
magnitude over the budget. It is the reference: the haptic loop ticks both of its arms and their
blend in one call compiled from the same arithmetic (:mod:`fieldbank.armkernel`), tested
against this one. The constants are bound once into a closure (fast cell loads); the
integrator is semi-implicit (symplectic) Euler, stable for ω·dt < 2 and without the energy drift
of explicit Euler. Beyond the range of motion a stiff, damped joint stop holds the virtual arm.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from fieldbank.dynamics import inertia_constants
from fieldbank.errors import ParameterError
from fieldbank.model import Arm
from fieldbank.validation import Interval, check_fields

#: Virtual coupling defaults (assumption): stiff enough to feel the arm's fields, soft enough to
#: stay passive at 1 kHz with ~1.5 kg of apparent hand mass.
DEFAULT_COUPLING_N_PER_M = 1500.0
DEFAULT_COUPLING_N_S_PER_M = 15.0
#: Joint stops beyond the range of motion (assumption).
DEFAULT_STOP_N_M_PER_RAD = 50.0
DEFAULT_STOP_N_M_S_PER_RAD = 1.0


#: The range of each gain of :class:`CouplingConfig`.
COUPLING_BOUNDS: dict[str, Interval] = {
    "stiffness_n_per_m": Interval(0.0, None, "N/m"),
    "damping_n_s_per_m": Interval(0.0, None, "N·s/m"),
    "stop_stiffness_n_m_per_rad": Interval(0.0, None, "N·m/rad"),
    "stop_damping_n_m_s_per_rad": Interval(0.0, None, "N·m·s/rad"),
}


@dataclass(frozen=True)
class CouplingConfig:
    """Virtual coupling and joint-stop gains, SI."""

    stiffness_n_per_m: float = DEFAULT_COUPLING_N_PER_M
    damping_n_s_per_m: float = DEFAULT_COUPLING_N_S_PER_M
    stop_stiffness_n_m_per_rad: float = DEFAULT_STOP_N_M_PER_RAD
    stop_damping_n_m_s_per_rad: float = DEFAULT_STOP_N_M_S_PER_RAD

    def __post_init__(self) -> None:
        check_fields(self, COUPLING_BOUNDS, what="coupling parameter")


class SimState:
    """Mutable state: q1, q2 (rad), qd1, qd2 (rad/s), t_s (s), ticks."""

    __slots__ = ("q1", "q2", "qd1", "qd2", "t_s", "ticks")

    def __init__(self, q1: float, q2: float, qd1: float = 0.0, qd2: float = 0.0) -> None:
        self.q1 = q1
        self.q2 = q2
        self.qd1 = qd1
        self.qd2 = qd2
        self.t_s = 0.0
        self.ticks = 0

    def as_tuple(self) -> tuple[float, float, float, float]:
        return (self.q1, self.q2, self.qd1, self.qd2)


TickFn = Callable[[float, float, float, float], tuple[float, float]]


class ArmSim:
    """A virtual arm coupled to a handle.

    Parameters
    ----------
    arm : Arm
        The compiled model (shared, never modified).
    dt_s : float
        Tick period, s (1e-3 for 1 kHz; 2.5e-4 to 2e-3 accepted).
    coupling : CouplingConfig, optional
    state : SimState, optional
        Where the arm's state lives (default: a new :class:`SimState` at rest); the compiled
        pair (:mod:`fieldbank.armkernel`) passes views into its own state array.
    """

    def __init__(self, arm: Arm, dt_s: float = 1e-3, coupling: CouplingConfig | None = None,
                 state: SimState | None = None):
        if not (isinstance(dt_s, (int, float)) and 1e-6 <= dt_s <= 0.01):
            raise ParameterError(f"The 'dt_s' parameter must be in [1e-6, 0.01] s; got {dt_s!r}.")
        self.arm = arm
        self.dt_s = float(dt_s)
        self.coupling = coupling or CouplingConfig()
        self.state = state if state is not None else SimState(float(arm.q_rest[0]),
                                                               float(arm.q_rest[1]))
        self.tick: TickFn = _make_tick(arm, self.state, self.dt_s, self.coupling)

    def reset(self, q: tuple[float, float] | None = None,
              qd: tuple[float, float] = (0.0, 0.0)) -> None:
        """Put the arm at posture q (default: rest), at rate qd, time 0."""
        q = q if q is not None else (float(self.arm.q_rest[0]), float(self.arm.q_rest[1]))
        s = self.state
        s.q1, s.q2 = float(q[0]), float(q[1])
        s.qd1, s.qd2 = float(qd[0]), float(qd[1])
        s.t_s = 0.0
        s.ticks = 0

    def reset_at_hand(self, x: float, y: float) -> None:
        """Put the arm at rest with its hand at (x, y), m, shoulder frame."""
        q = self.arm.ik([[x, y]])[0]
        self.reset((float(q[0]), float(q[1])))

    def hand(self) -> tuple[float, float, float, float]:
        """Hand position and velocity (x, y, vx, vy) in the shoulder frame, m and m/s."""
        s = self.state
        l1, l2 = self.arm.l1, self.arm.l2
        c1, s1 = math.cos(s.q1), math.sin(s.q1)
        c12, s12 = math.cos(s.q1 + s.q2), math.sin(s.q1 + s.q2)
        x = l1 * c1 + l2 * c12
        y = l1 * s1 + l2 * s12
        vx = (-l1 * s1 - l2 * s12) * s.qd1 - l2 * s12 * s.qd2
        vy = (l1 * c1 + l2 * c12) * s.qd1 + l2 * c12 * s.qd2
        if self.arm.mirror:
            return (-x, y, -vx, vy)
        return (x, y, vx, vy)


def _make_tick(arm: Arm, st: SimState, dt: float, cfg: CouplingConfig) -> TickFn:
    """Bind the arm's constants into a closure that advances ``st`` by one tick."""
    l1 = float(arm.l1)
    l2 = float(arm.l2)
    a1, a2, a3, h0 = inertia_constants(arm)
    kc = float(cfg.stiffness_n_per_m)
    bc = float(cfg.damping_n_s_per_m)
    ks = float(cfg.stop_stiffness_n_m_per_rad)
    bs = float(cfg.stop_damping_n_m_s_per_rad)
    p = arm.params
    s_lo, s_hi = p.shoulder_range_rad
    e_lo, e_hi = p.elbow_range_rad
    qr1, qr2 = float(arm.q_rest[0]), float(arm.q_rest[1])
    w = float(arm.w)
    mirror = -1.0 if arm.mirror else 1.0
    muscles = tuple(
        (
            float(arm.jl[i, 0]),
            float(arm.jl[i, 1]),
            float(arm.km[i]),
            1.0 / float(arm.excursion[i]),
            float(arm.lam_rest[i] - arm.lam_min[i]),
            float(arm.alpha[i]),
            float(arm.beta[i]),
            1.0 / float(arm.ldot_max[i]),
            float(arm.lam_rest[i] / arm.lam_max[i]),
            float(arm.lam_slack[i] - arm.lam_rest[i]),
        )
        for i in range(6)
    )
    exp = math.exp
    log1p = math.log1p
    cos = math.cos
    sin = math.sin

    def tick(hx: float, hy: float, hvx: float, hvy: float) -> tuple[float, float]:
        q1 = st.q1
        q2 = st.q2
        qd1 = st.qd1
        qd2 = st.qd2
        c1 = cos(q1)
        s1 = sin(q1)
        q12 = q1 + q2
        c12 = cos(q12)
        s12 = sin(q12)
        j12 = -l2 * s12
        j11 = -l1 * s1 + j12
        j22 = l2 * c12
        j21 = l1 * c1 + j22
        # virtual coupling (model frame: mirror x for a left arm)
        fx = kc * (mirror * hx - j21) + bc * (mirror * hvx - j11 * qd1 - j12 * qd2)
        fy = kc * (hy - l1 * s1 - l2 * s12) + bc * (hvy - j21 * qd1 - j22 * qd2)
        t1 = j11 * fx + j21 * fy
        t2 = j12 * fx + j22 * fy
        dq1 = q1 - qr1
        dq2 = q2 - qr2
        for a, b, km, iell, off, alpha, beta, ilm, k, slack in muscles:
            d = a * dq1 + b * dq2
            ds = d - slack
            z = ds / w
            if z > 35.0:
                f = km * ds * exp(-(ds * iell) ** 2)
            elif z > -35.0:
                f = km * w * log1p(exp(z)) * exp(-(ds * iell) ** 2)
            else:
                f = 0.0
            if beta > 0.0:
                ld = a * qd1 + b * qd2
                if ld > 0.0:
                    r = ld * ilm
                    u = beta * (r if r < 1.0 else 1.0)
                    g = (d + off) * iell - k * (1.0 - u)
                    h = alpha * u * g * exp(-g * g)
                    if h > 0.0:
                        f += h
            t1 -= a * f
            t2 -= b * f
        # joint stops beyond the range of motion
        if q1 < s_lo:
            t1 -= ks * (q1 - s_lo) + bs * qd1
        elif q1 > s_hi:
            t1 -= ks * (q1 - s_hi) + bs * qd1
        if q2 < e_lo:
            t2 -= ks * (q2 - e_lo) + bs * qd2
        elif q2 > e_hi:
            t2 -= ks * (q2 - e_hi) + bs * qd2
        c2 = cos(q2)
        hh = h0 * sin(q2)
        t1 += hh * qd2 * (2.0 * qd1 + qd2)
        t2 -= hh * qd1 * qd1
        m11 = a1 + 2.0 * h0 * c2
        m12 = a2 + h0 * c2
        det = m11 * a3 - m12 * m12
        qdd1 = (a3 * t1 - m12 * t2) / det
        qdd2 = (m11 * t2 - m12 * t1) / det
        qd1 += dt * qdd1
        qd2 += dt * qdd2
        st.qd1 = qd1
        st.qd2 = qd2
        st.q1 = q1 + dt * qd1
        st.q2 = q2 + dt * qd2
        st.t_s += dt
        st.ticks += 1
        return (-mirror * fx, -fy)

    return tick
