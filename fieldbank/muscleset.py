"""The muscles of S ≥ 1 parameter sets of one arm geometry, and the one evaluation of the
muscle equations from the joints to the hand: :class:`MuscleSet` and :func:`endpoint_field`.

One compiled arm (:class:`fieldbank.model.Arm`) is the set of one; a fit's samples
(:class:`fieldbank.armbatch.ArmBatch`) are S sets over the same geometry. Both evaluate their
fields with the same code in the same order: :meth:`fieldbank.model.Arm.field_of` takes the
hand's joint state from the geometry, :meth:`MuscleSet.lengths` the muscle lengths,
:meth:`MuscleSet.tensions` (or :meth:`MuscleSet.forces`, the value only) the equations of
:mod:`fieldbank.muscle`, and :func:`endpoint_field` (or :func:`hand_force`) carries the
tensions to the hand. Every muscle array has a leading set axis, (S, 6); lengths and tensions
are (S, N, 6), forces (S, N, 2), stiffness and damping (S, N, 2, 2).

The compiled tick kernels (:mod:`fieldbank.armkernel`, the 1-4 kHz haptic tick, and
:mod:`fieldbank.fitting.kernels`, the fit's reflex basis) evaluate the same equations per
sample in compiled code: there the cost of a call from Python is the point.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from dataclasses import field as dataclass_field

import numpy as np
from numpy.typing import NDArray

from fieldbank.errors import ParameterError
from fieldbank.muscle import passive_force, passive_tension, reflex_force, reflex_tension
from fieldbank.params import ArmParams

FloatArray = NDArray[np.float64]
#: Four same-shaped arrays: the entries of a 2 × 2 matrix per point, row by row.
Quad = tuple[FloatArray, FloatArray, FloatArray, FloatArray]


@dataclass(frozen=True, eq=False)
class MuscleSet:
    """The muscle values of S parameter sets over one geometry; every array read-only.

    Attributes
    ----------
    q_rest : ndarray, shape (S, 2), rad
    lam_rest, lam_slack, lam_min, lam_max, excursion : ndarray, shape (S, 6), m
        λ_rest, the length where the passive force starts, λ_min and λ_max over the range of
        motion, ℓ = λ_max - λ_min.
    km, alpha, beta : ndarray, shape (S, 6); N/m, N, dimensionless
    ldot_max : ndarray, shape (6,), m/s
        The geometry's λ̇_max (the same for every set).
    w : float
        Passive smoothing width, m.
    same_lengths : bool
        Every set has the same rest posture, rest and slack lengths (a fit's samples of Km, α
        and β; one arm): at joint angles every set shares, their muscle lengths are one set's
        (:meth:`lengths` returns them broadcast), and so is everything the equations compute
        from the lengths alone - computed once and scaled per set: the same numbers, a
        fraction of the work.
    """

    q_rest: FloatArray
    lam_rest: FloatArray
    lam_slack: FloatArray
    lam_min: FloatArray
    lam_max: FloatArray
    excursion: FloatArray
    km: FloatArray
    alpha: FloatArray
    beta: FloatArray
    ldot_max: FloatArray
    w: float
    same_lengths: bool
    _row: dict[str, FloatArray] = dataclass_field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_row", {n: getattr(self, n)[0] for n in _MUSCLE_ARRAYS})

    @classmethod
    def of(cls, sets: Sequence[ArmParams], jl: FloatArray, ldot_max: FloatArray) -> MuscleSet:
        """The muscles of ``sets`` over the geometry of muscle-length Jacobian ``jl`` (6, 2),
        whose range of motion, smoothing width and λ̇_max (``ldot_max``) every set shares.

        Raises
        ------
        ParameterError
            A muscle would reach a non-positive length within the range of motion.
        """
        return cls.from_values(sets[0], {
            "q_rest_rad": np.array([p.q_rest_rad for p in sets], dtype=float),
            "rest_length_m": np.array([p.rest_length_m for p in sets], dtype=float),
            "slack_offset_m": np.array([p.slack_offset_m for p in sets], dtype=float),
            **_values(sets)}, jl, ldot_max)

    @classmethod
    def from_values(cls, p0: ArmParams, values: dict[str, FloatArray], jl: FloatArray,
                    ldot_max: FloatArray) -> MuscleSet:
        """The muscles of the sets whose values are ``values`` - ``q_rest_rad`` (S, 2),
        ``rest_length_m`` and ``slack_offset_m`` (S, 6), ``km``, ``alpha``, ``beta`` (S, 6),
        checked already - over the geometry of ``p0`` (its range of motion and smoothing
        width), ``jl`` and ``ldot_max`` (:meth:`of`).

        Raises
        ------
        ParameterError
            A muscle would reach a non-positive length within the range of motion.
        """
        q_rest = np.array(values["q_rest_rad"], dtype=float)
        lam_rest = np.array(values["rest_length_m"], dtype=float)
        corners = np.array([[a, b] for a in p0.shoulder_range_rad for b in p0.elbow_range_rad])
        # λ is linear in q, so its extremes over the box are at corners
        lam_corners = lam_rest[:, None, :] + (corners[None, :, :] - q_rest[:, None, :]) @ jl.T
        lam_min = lam_corners.min(axis=1)
        lam_max = lam_corners.max(axis=1)
        if np.any(lam_min <= 0):
            k, i = np.unravel_index(int(np.argmin(lam_min)), lam_min.shape)
            where = f"In parameter set {int(k)}, muscle" if len(q_rest) > 1 else "Muscle"
            raise ParameterError(
                f"{where} {int(i)} would reach a non-positive length ({lam_min[k, i]:.4g} m) "
                "within the range of motion; raise rest_length_m or shrink the range.")
        slack = lam_rest + np.asarray(values["slack_offset_m"], dtype=float)
        arrays = {"q_rest": q_rest, "lam_rest": lam_rest, "lam_slack": slack,
                  "lam_min": lam_min, "lam_max": lam_max, "excursion": lam_max - lam_min,
                  **{k: np.array(values[k], dtype=float) for k in ("km", "alpha", "beta")}}
        for a in arrays.values():
            a.setflags(write=False)
        same = all(np.array_equal(a, a[:1].repeat(len(a), axis=0))
                   for a in (q_rest, lam_rest, slack))
        return cls(ldot_max=ldot_max, w=p0.passive_smoothing_m, same_lengths=same, **arrays)

    def with_values(self, p: ArmParams) -> MuscleSet:
        """The set of one with ``p``'s Km, α, β and slack offset on this set's lengths (the
        muscles of :meth:`fieldbank.model.Arm.with_muscles`)."""
        slack = self.lam_rest + np.array([p.slack_offset_m], dtype=float)
        slack.setflags(write=False)
        vals = _values([p])
        for a in vals.values():
            a.setflags(write=False)
        return MuscleSet(self.q_rest, self.lam_rest, slack, self.lam_min, self.lam_max,
                         self.excursion, ldot_max=self.ldot_max, w=self.w,
                         same_lengths=self.same_lengths, **vals)

    def __len__(self) -> int:
        return len(self.km)

    def lengths(self, q: FloatArray, jl: FloatArray) -> FloatArray:
        """λ (S, N, 6), m, at joint angles q: (N, 2) shared by every set, or (S, N, 2). With
        :attr:`same_lengths` and shared angles, one set's lengths broadcast (read-only)."""
        if self.same_lengths and q.ndim == 2:
            lam = self.lam_rest[0] + (q - self.q_rest[0]) @ jl.T
            n = len(self)  # a new unit axis is a broadcast one already, and costs less
            return lam[None] if n == 1 else np.broadcast_to(lam, (n, *lam.shape))
        return self.lam_rest[:, None, :] + (q - self.q_rest[:, None, :]) @ jl.T

    def one(self, lam: FloatArray) -> bool:
        """λ is one set's lengths broadcast to every set (:meth:`lengths`)."""
        return self.same_lengths and lam.ndim == 3 and lam.strides[0] == 0

    def columns(self, lam: FloatArray, cols: NDArray[np.intp]) -> FloatArray:
        """The muscles ``cols`` (indices, (k,)) of λ (S, N, 6): (S, N, k), broadcast as λ is."""
        if self.one(lam):
            return np.broadcast_to(lam[:1][..., cols], (*lam.shape[:2], len(cols)))
        return lam[..., cols]

    def against(self, lam: FloatArray) -> tuple[FloatArray, dict[str, FloatArray]]:
        """λ (S, N, 6) as the equations take it, and the muscle arrays (name -> array) that
        broadcast against it: the set of one its row (6,) against (N, 6) - no unit set axis
        to broadcast, the arithmetic of one arm -; S sets (S, 1, 6) against (S, N, 6), the
        terms of the lengths alone once, (1, 1, 6) against (1, N, 6), when λ is one set's
        broadcast (:meth:`lengths`)."""
        if len(self.km) == 1:
            return lam[0], self._row
        r = slice(0, 1) if self.one(lam) else slice(None)
        arrays = {n: getattr(self, n)[r, None, :] for n in _LENGTH_ARRAYS}
        arrays.update((n, getattr(self, n)[:, None, :]) for n in _VALUE_ARRAYS)
        return lam[r], arrays

    def tensions(self, lam: FloatArray, ldot: FloatArray
                 ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """Ψ, ∂Ψ/∂λ, Φ, ∂Φ/∂λ, ∂Φ/∂λ̇ for λ (S, N, 6) and λ̇ (N, 6): each (S, N, 6), or (N, 6)
        for the set of one (:meth:`against`)."""
        lam, a = self.against(lam)
        psi, dpsi = passive_tension(lam, a["lam_slack"], a["km"], a["excursion"], self.w)
        phi, dphi_l, dphi_ld = reflex_tension(lam, ldot, self.ldot_max, a["alpha"], a["beta"],
                                              a["excursion"], a["lam_rest"], a["lam_min"],
                                              a["lam_max"])
        return psi, dpsi, phi, dphi_l, dphi_ld

    def forces(self, lam: FloatArray, ldot: FloatArray) -> FloatArray:
        """Ψ + Φ, N, value only, for λ (S, N, 6) and λ̇ (N, 6): (S, N, 6), or (N, 6) for the
        set of one (whose few points gain nothing from :meth:`reflex`'s selection)."""
        if len(self.km) > 1:
            return self.passive(lam) + self.reflex(lam, ldot)
        lam, a = self.against(lam)
        return (passive_force(lam, a["lam_slack"], a["km"], a["excursion"], self.w)
                + reflex_force(lam, ldot, self.ldot_max, a["alpha"], a["beta"], a["excursion"],
                               a["lam_rest"], a["lam_min"], a["lam_max"]))

    def passive(self, lam: FloatArray, groups: NDArray[np.intp] | None = None) -> FloatArray:
        """Ψ (S, N, 6), N, for λ (S, N, 6), value only. ``groups`` (indices): λ holds only
        these muscle groups' columns, and so does Ψ."""
        g = slice(None) if groups is None else groups
        if self.one(lam):  # the shape once, Km per set
            return passive_force(lam[:1], self.lam_slack[:1, None, g], self.km[:, None, g],
                                 self.excursion[:1, None, g], self.w)
        return passive_force(lam, self.lam_slack[:, None, g], self.km[:, None, g],
                             self.excursion[:, None, g], self.w)

    def reflex(self, lam: FloatArray, ldot: FloatArray) -> FloatArray:
        """Φ (S, N, 6), N, for λ (S, N, 6) and λ̇ (N, 6) shared by every set, value only.
        Computed only where λ̇ > 0: elsewhere the reflex is exactly zero (u = 0), and about
        half the muscles shorten at any motion. Those (point, muscle) pairs are the same for
        every set: whole muscles when each lengthens at every point or none (a joint
        stretch), else the pairs by one flat index; each value the one the equations give."""
        s = len(self)
        live = ldot > 0
        one = self.one(lam)
        r = slice(0, 1) if one else slice(None)
        lengths = lam[:1] if one else np.broadcast_to(lam, (s, *ldot.shape))
        phi = np.zeros((s, *ldot.shape))
        cols = np.flatnonzero(live.any(axis=0))
        if live[:, cols].all():  # whole muscles
            phi[..., cols] = reflex_force(
                lengths[..., cols], ldot[:, cols], self.ldot_max[cols],
                self.alpha[:, None, cols], self.beta[:, None, cols],
                self.excursion[r, None, cols], self.lam_rest[r, None, cols],
                self.lam_min[r, None, cols], self.lam_max[r, None, cols])
            return phi
        at = np.flatnonzero(live)  # (point, muscle) pairs, flat
        m = at % ldot.shape[1]
        phi.reshape(s, -1)[:, at] = reflex_force(
            lengths.reshape(lengths.shape[0], -1)[:, at], ldot.reshape(-1)[at],
            self.ldot_max[m], self.alpha[:, m], self.beta[:, m], self.excursion[r, m],
            self.lam_rest[r, m], self.lam_min[r, m], self.lam_max[r, m])
        return phi


#: The muscle arrays of a set that depend on the lengths alone, and the muscle values.
_LENGTH_ARRAYS = ("lam_rest", "lam_slack", "lam_min", "lam_max", "excursion")
_VALUE_ARRAYS = ("km", "alpha", "beta")
_MUSCLE_ARRAYS = _LENGTH_ARRAYS + _VALUE_ARRAYS


def _values(sets: Sequence[ArmParams]) -> dict[str, FloatArray]:
    return {"km": np.array([p.km_n_per_m for p in sets], dtype=float),
            "alpha": np.array([p.alpha_n for p in sets], dtype=float),
            "beta": np.array([p.beta for p in sets], dtype=float)}


def velocities(qd: tuple[FloatArray, FloatArray], jl: FloatArray) -> FloatArray:
    """λ̇ (N, 6), m/s, of the joint velocities (q̇1, q̇2), each (N,)."""
    return np.outer(qd[0], jl[:, 0]) + np.outer(qd[1], jl[:, 1])


def hand_force(f: FloatArray, jl: FloatArray, ia: FloatArray, ib: FloatArray, ic: FloatArray,
               id_: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The hand force (F_x, F_y), N, of muscle tensions f (…, N, 6), N: τ = -J_λᵀ f, then
    F = J⁻ᵀ τ with J⁻¹ = [[ia, ib], [ic, id]] (each (N,)); leading axes of f carry through."""
    tau = -f @ jl
    t1, t2 = tau[..., 0], tau[..., 1]
    return ia * t1 + ic * t2, ib * t1 + id_ * t2


def endpoint_field(psi: FloatArray, dpsi: FloatArray, phi: FloatArray, dphi_l: FloatArray,
                   dphi_ld: FloatArray, jl: FloatArray, prod: FloatArray, jac: Quad, jinv: Quad,
                   qd: tuple[FloatArray, FloatArray]
                   ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Hand force F (…, N, 2), stiffness K = -∂F/∂x and damping B = -∂F/∂v (…, N, 2, 2), model
    frame, of muscle tensions Ψ + Φ and their slopes (each (…, N, 6)) at the joint state of
    :meth:`fieldbank.model.Arm.hand_state` (``jac``, ``jinv``, ``qd``: each entry (N,));
    ``prod`` the products of J_λ's columns (``Arm._jl_products``)."""
    a, b, c, d = jac
    ia, ib, ic, id_ = jinv
    qd1, qd2 = qd
    fx, fy = hand_force(psi + phi, jl, ia, ib, ic, id_)
    force = np.stack([fx, fy], axis=-1)
    # J_λᵀ diag(g) J_λ as (g @ P) with P the products of J_λ's columns
    a00, a01, a11 = np.moveaxis((dpsi + dphi_l) @ prod, -1, 0)
    b00, b01, b11 = np.moveaxis(dphi_ld @ prod, -1, 0)
    # ∂J/∂q1 = [[-c, -d], [a, b]], ∂J/∂q2 = [[-d, -d], [b, b]]
    # (∂J/∂q_k) q̇ and then Q = -J⁻¹ [(∂J/∂q1) q̇, (∂J/∂q2) q̇]
    u1x, u1y = -c * qd1 - d * qd2, a * qd1 + b * qd2
    u2x, u2y = -d * (qd1 + qd2), b * (qd1 + qd2)
    q11 = -(ia * u1x + ib * u1y)
    q21 = -(ic * u1x + id_ * u1y)
    q12_ = -(ia * u2x + ib * u2y)
    q22 = -(ic * u2x + id_ * u2y)
    # ∂τ/∂q = -A - B Q ; G column k = (∂J/∂q_k)ᵀ F ; inner = ∂τ/∂q - G
    g11 = -c * fx + a * fy
    g21 = -d * fx + b * fy
    g12 = -d * fx + b * fy
    g22 = -d * fx + b * fy
    m11 = -a00 - (b00 * q11 + b01 * q21) - g11
    m12 = -a01 - (b00 * q12_ + b01 * q22) - g12
    m21 = -a01 - (b01 * q11 + b11 * q21) - g21
    m22 = -a11 - (b01 * q12_ + b11 * q22) - g22
    # K = -J⁻ᵀ M J⁻¹ ; B = J⁻ᵀ Bm J⁻¹  (J⁻ᵀ = [[ia, ic], [ib, id]])
    stiff = -_sandwich(ia, ib, ic, id_, m11, m12, m21, m22)
    damp = _sandwich(ia, ib, ic, id_, b00, b01, b01, b11)
    return force, stiff, damp


def _sandwich(ia: FloatArray, ib: FloatArray, ic: FloatArray, id_: FloatArray,
              m11: FloatArray, m12: FloatArray, m21: FloatArray, m22: FloatArray) -> FloatArray:
    """J⁻ᵀ M J⁻¹ for J⁻¹ = [[ia, ib], [ic, id]], component-wise, shape (…, N, 2, 2)."""
    # R = M J⁻¹
    r11 = m11 * ia + m12 * ic
    r12 = m11 * ib + m12 * id_
    r21 = m21 * ia + m22 * ic
    r22 = m21 * ib + m22 * id_
    out = np.empty((*np.broadcast_shapes(ia.shape, r11.shape), 2, 2))
    out[..., 0, 0] = ia * r11 + ic * r21
    out[..., 0, 1] = ia * r12 + ic * r22
    out[..., 1, 0] = ib * r11 + id_ * r21
    out[..., 1, 1] = ib * r12 + id_ * r22
    return out
