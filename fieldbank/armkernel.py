"""Both virtual arms of a haptic tick and their blend in one compiled call (numba).

:func:`fieldbank.sim.ArmSim.tick` is the reference: plain-float Python, one arm per call,
~3.5 µs. The haptic loop ticks two arms (A before, B after) with the same handle state every
tick and blends their forces; at 4 kHz the whole tick has 250 µs, and the interpreter's share of
the arm arithmetic was the largest piece of it. Here the same arithmetic, in the same order, is
compiled once by numba (LLVM) and called once per tick for both arms and the blend:

    F_A, F_B = coupling forces of arms A and B at the handle (each steps its own dynamics)
    F = g · ((1 − w) F_A + w F_B)

Layout (float64 arrays, so the call passes three buffers and six floats):

* ``params``, shape (2, :data:`NPAR`) - each arm's constants (:func:`pack`): lengths, inertia
  constants, coupling and joint-stop gains, ranges, rest posture, smoothing width, mirror, the
  time step, and ten numbers per muscle;
* ``state``, shape (2, :data:`NSTATE`) - q1, q2 (rad), q̇1, q̇2 (rad/s), t (s), ticks;
* ``out``, shape (6,) - F (blended, N), F_A, F_B (N), on the handle, shoulder frame.

Forces agree with the reference to 1e-12 N (tests/test_armkernel.py): same formulas, same
order, IEEE double without fast-math. The compiled code is cached on disk (numba's
``cache=True``): in the ``__pycache__`` folder beside this module when it is writable, else in
numba's user-wide cache (``$NUMBA_CACHE_DIR``, default ``~/.cache/numba`` on Linux), so only
the first start of an installation compiles (≈ 1-2 s); later starts load the machine code.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from fieldbank.dynamics import inertia_constants
from fieldbank.model import Arm
from fieldbank.sim import ArmSim, CouplingConfig, SimState

#: Numbers per muscle in ``params``: joint-lever rows a, b; Km; 1/excursion; λ_rest − λ_min;
#: α; β; 1/λ̇_max; λ_rest/λ_max; λ_slack − λ_rest (as in :func:`fieldbank.sim._make_tick`).
MUSCLE_FIELDS = 10
#: Index of the first muscle's numbers in a row of ``params``.
M0 = 20
#: Length of one arm's row of ``params``.
NPAR = M0 + 6 * MUSCLE_FIELDS
#: Length of one arm's row of ``state``: q1, q2, qd1, qd2, t_s, ticks.
NSTATE = 6


def pack(arm: Arm, dt_s: float, coupling: CouplingConfig | None = None) -> np.ndarray:
    """One arm's constants as a row of ``params`` (shape (:data:`NPAR`,))."""
    cfg = coupling or CouplingConfig()
    a1, a2, a3, h0 = inertia_constants(arm)
    p = arm.params
    row = np.zeros(NPAR)
    row[:M0] = (
        float(arm.l1), float(arm.l2), a1, a2, a3, h0,
        float(cfg.stiffness_n_per_m), float(cfg.damping_n_s_per_m),
        float(cfg.stop_stiffness_n_m_per_rad), float(cfg.stop_damping_n_m_s_per_rad),
        p.shoulder_range_rad[0], p.shoulder_range_rad[1], p.elbow_range_rad[0],
        p.elbow_range_rad[1], float(arm.q_rest[0]), float(arm.q_rest[1]), float(arm.w),
        -1.0 if arm.mirror else 1.0, float(dt_s), 0.0,
    )
    for i in range(6):
        k = M0 + i * MUSCLE_FIELDS
        row[k:k + MUSCLE_FIELDS] = (
            float(arm.jl[i, 0]), float(arm.jl[i, 1]), float(arm.km[i]),
            1.0 / float(arm.excursion[i]), float(arm.lam_rest[i] - arm.lam_min[i]),
            float(arm.alpha[i]), float(arm.beta[i]), 1.0 / float(arm.ldot_max[i]),
            float(arm.lam_rest[i] / arm.lam_max[i]), float(arm.lam_slack[i] - arm.lam_rest[i]),
        )
    return row


@njit(cache=True, nogil=True)
def _arm_tick(P: np.ndarray, S: np.ndarray, hx: float, hy: float, hvx: float,
              hvy: float) -> tuple[float, float]:  # pragma: no cover - compiled
    l1 = P[0]
    l2 = P[1]
    a1 = P[2]
    a2 = P[3]
    a3 = P[4]
    h0 = P[5]
    kc = P[6]
    bc = P[7]
    ks = P[8]
    bs = P[9]
    s_lo = P[10]
    s_hi = P[11]
    e_lo = P[12]
    e_hi = P[13]
    qr1 = P[14]
    qr2 = P[15]
    w = P[16]
    mirror = P[17]
    dt = P[18]
    q1 = S[0]
    q2 = S[1]
    qd1 = S[2]
    qd2 = S[3]
    c1 = math.cos(q1)
    s1 = math.sin(q1)
    q12 = q1 + q2
    c12 = math.cos(q12)
    s12 = math.sin(q12)
    j12 = -l2 * s12
    j11 = -l1 * s1 + j12
    j22 = l2 * c12
    j21 = l1 * c1 + j22
    fx = kc * (mirror * hx - j21) + bc * (mirror * hvx - j11 * qd1 - j12 * qd2)
    fy = kc * (hy - l1 * s1 - l2 * s12) + bc * (hvy - j21 * qd1 - j22 * qd2)
    t1 = j11 * fx + j21 * fy
    t2 = j12 * fx + j22 * fy
    dq1 = q1 - qr1
    dq2 = q2 - qr2
    for i in range(6):
        k = M0 + i * MUSCLE_FIELDS
        a = P[k]
        b = P[k + 1]
        km = P[k + 2]
        iell = P[k + 3]
        off = P[k + 4]
        alpha = P[k + 5]
        beta = P[k + 6]
        ilm = P[k + 7]
        kk = P[k + 8]
        slack = P[k + 9]
        d = a * dq1 + b * dq2
        ds = d - slack
        z = ds / w
        if z > 35.0:
            f = km * ds * math.exp(-(ds * iell) ** 2)
        elif z > -35.0:
            f = km * w * math.log1p(math.exp(z)) * math.exp(-(ds * iell) ** 2)
        else:
            f = 0.0
        if beta > 0.0:
            ld = a * qd1 + b * qd2
            if ld > 0.0:
                r = ld * ilm
                u = beta * (r if r < 1.0 else 1.0)
                g = (d + off) * iell - kk * (1.0 - u)
                h = alpha * u * g * math.exp(-g * g)
                if h > 0.0:
                    f += h
        t1 -= a * f
        t2 -= b * f
    if q1 < s_lo:
        t1 -= ks * (q1 - s_lo) + bs * qd1
    elif q1 > s_hi:
        t1 -= ks * (q1 - s_hi) + bs * qd1
    if q2 < e_lo:
        t2 -= ks * (q2 - e_lo) + bs * qd2
    elif q2 > e_hi:
        t2 -= ks * (q2 - e_hi) + bs * qd2
    c2 = math.cos(q2)
    hh = h0 * math.sin(q2)
    t1 += hh * qd2 * (2.0 * qd1 + qd2)
    t2 -= hh * qd1 * qd1
    m11 = a1 + 2.0 * h0 * c2
    m12 = a2 + h0 * c2
    det = m11 * a3 - m12 * m12
    qdd1 = (a3 * t1 - m12 * t2) / det
    qdd2 = (m11 * t2 - m12 * t1) / det
    qd1 += dt * qdd1
    qd2 += dt * qdd2
    S[2] = qd1
    S[3] = qd2
    S[0] = q1 + dt * qd1
    S[1] = q2 + dt * qd2
    S[4] += dt
    S[5] += 1.0
    return -mirror * fx, -fy


@njit(cache=True, nogil=True)
def tick_pair(params: np.ndarray, state: np.ndarray, out: np.ndarray, hx: float, hy: float,
              hvx: float, hvy: float, w: float, g: float) -> None:  # pragma: no cover
    """Tick arms A and B with the handle at (hx, hy) m moving at (hvx, hvy) m/s, shoulder
    frame; write F = g((1 − w) F_A + w F_B), F_A and F_B into ``out`` (N)."""
    fax, fay = _arm_tick(params[0], state[0], hx, hy, hvx, hvy)
    fbx, fby = _arm_tick(params[1], state[1], hx, hy, hvx, hvy)
    out[0] = g * ((1.0 - w) * fax + w * fbx)
    out[1] = g * ((1.0 - w) * fay + w * fby)
    out[2] = fax
    out[3] = fay
    out[4] = fbx
    out[5] = fby


@njit(cache=True, nogil=True)
def tick_one(params: np.ndarray, state: np.ndarray, hx: float, hy: float, hvx: float,
             hvy: float) -> tuple[float, float]:  # pragma: no cover - compiled
    """One arm's tick (``params`` and ``state`` one row each): the force on the handle, N."""
    return _arm_tick(params, state, hx, hy, hvx, hvy)


def _field(i: int, kind: type = float) -> property:
    """A property reading and writing element ``i`` of the state row."""

    def get(self: ArrayState) -> float:
        return kind(self._row[i])

    def put(self: ArrayState, v: float) -> None:
        self._row[i] = v

    return property(get, put)


class ArrayState(SimState):
    """A :class:`fieldbank.sim.SimState` kept in one row of a pair's ``state`` array, so the
    compiled tick and the Python side (reset, read-outs) share one copy."""

    __slots__ = ("_row",)

    def __init__(self, row: np.ndarray, q1: float, q2: float) -> None:
        self._row = row
        row[:] = (q1, q2, 0.0, 0.0, 0.0, 0.0)

    q1 = _field(0)
    q2 = _field(1)
    qd1 = _field(2)
    qd2 = _field(3)
    t_s = _field(4)
    ticks = _field(5, int)


class ArmPair(tuple[ArmSim, ArmSim]):
    """Arms A (before) and B (after) behind one handle: ``(arm_a, arm_b)`` and one tick for both.

    ``compiled`` (default): both arms' constants and states live in arrays and :meth:`tick`
    is one call of :func:`tick_pair`; else :meth:`tick` calls each arm's plain-Python
    :meth:`~fieldbank.sim.ArmSim.tick` (the reference) and blends in Python, in the same order.
    """

    params: np.ndarray | None
    state: np.ndarray | None
    out: np.ndarray

    def __new__(cls, a: Arm, b: Arm, dt_s: float, coupling: CouplingConfig | None = None,
                compiled: bool = True) -> ArmPair:
        if compiled:
            state = np.zeros((2, NSTATE))
            arms = tuple(ArmSim(arm, dt_s, coupling,
                                ArrayState(state[k], float(arm.q_rest[0]),
                                           float(arm.q_rest[1])))
                         for k, arm in enumerate((a, b)))
        else:
            arms = (ArmSim(a, dt_s, coupling), ArmSim(b, dt_s, coupling))
        self = super().__new__(cls, arms)
        self.out = np.zeros(6)
        if compiled:
            self.params = np.stack([pack(a, dt_s, coupling), pack(b, dt_s, coupling)])
            self.state = state
            # load (or compile) the machine code now, never on a loop's first tick: on a
            # scratch copy, so the arms' state is untouched
            tick_pair(self.params, state.copy(), self.out, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        else:
            self.params = self.state = None
        return self

    @classmethod
    def of(cls, a: ArmSim, b: ArmSim) -> ArmPair:
        """A pair of arms already built (or of what stands in for them, such as the remote
        link: anything with ArmSim's ``tick``, ``state``, ``reset``), ticked one after the other
        and blended like the reference path."""
        self = super().__new__(cls, (a, b))
        self.out = np.zeros(6)
        self.params = self.state = None
        return self

    @property
    def compiled(self) -> bool:
        return self.params is not None

    def tick(self, hx: float, hy: float, hvx: float, hvy: float, w: float,
             g: float) -> list[float]:
        """Tick both arms; ``[Fx, Fy, FAx, FAy, FBx, FBy]`` (N): the blend
        F = g((1 − w) F_A + w F_B) and each arm's force on the handle."""
        if self.params is not None and self.state is not None:
            out = self.out
            tick_pair(self.params, self.state, out, hx, hy, hvx, hvy, w, g)
            return out.tolist()
        fa_x, fa_y = self[0].tick(hx, hy, hvx, hvy)
        fb_x, fb_y = self[1].tick(hx, hy, hvx, hvy)
        return [g * ((1.0 - w) * fa_x + w * fb_x), g * ((1.0 - w) * fa_y + w * fb_y),
                fa_x, fa_y, fb_x, fb_y]

    def joints(self) -> tuple[float, ...]:
        """q1, q2, q̇1, q̇2 of arm A, then of arm B (rad, rad/s)."""
        if self.state is not None:
            a, b = self.state.tolist()
            return (a[0], a[1], a[2], a[3], b[0], b[1], b[2], b[3])
        sa, sb = self[0].state, self[1].state
        return (sa.q1, sa.q2, sa.qd1, sa.qd2, sb.q1, sb.q2, sb.qd1, sb.qd2)
