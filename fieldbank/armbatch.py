"""Many parameter sets of one arm geometry evaluated together: :class:`ArmBatch`.

A fit's uncertainty is carried as parameter samples that differ only in their muscle values
(:data:`SAMPLED_FIELDS`); the geometry (J_λ, λ̇_max, segment lengths, range of motion) is the
same for all of them. :class:`ArmBatch` compiles that geometry once and evaluates every set's
forces with the equations of :mod:`fieldbank.model` (:func:`~fieldbank.model.passive_force`,
:func:`~fieldbank.model.reflex_force`), so that S samples cost one vectorised pass instead of S
compiled arms (the prediction intervals of a what-if and of a report).

Sets given as arrays (:meth:`ArmBatch.from_arrays`: a fit's samples, the prior's table) are
checked once, as arrays, against the bounds table of :class:`~fieldbank.params.ArmParams`
(:data:`fieldbank.params.BOUNDS`) - the same bounds and messages a record would get, without a
record per set.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from dataclasses import fields as dataclass_fields
from operator import attrgetter

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fieldbank.errors import ParameterError
from fieldbank.model import Arm, FloatArray, endpoint_field, hand_force
from fieldbank.muscle import passive_force, passive_tension, reflex_force, reflex_tension
from fieldbank.params import BOUNDS, ArmParams, field_label
from fieldbank.validation import number_problem

#: ArmParams fields that may differ between the parameter sets of one :class:`ArmBatch`: every
#: muscle value a fit or its uncertainty can move (Km, α, β per group, slack offsets, rest
#: lengths and the rest posture). Everything else - segment lengths and masses, moment arms,
#: range of motion, the λ̇_max circle, the smoothing width, the side - is the shared geometry.
SAMPLED_FIELDS: tuple[str, ...] = ("km_n_per_m", "alpha_n", "beta", "slack_offset_m",
                                   "rest_length_m", "q_rest_rad")


@dataclass(frozen=True, eq=False)
class ArmBatch:
    """S parameter sets of one arm geometry, evaluated together.

    The geometry (``geometry``: J_λ, λ̇_max, segment lengths, the range of motion) is compiled
    once; the muscle values of :data:`SAMPLED_FIELDS` are arrays with a leading sample axis.
    What each set gives is what :meth:`Arm.from_params` of that set would give, evaluated
    with the same equations (:func:`passive_force`, :func:`reflex_force`); forces only, no
    stiffness. Build with :meth:`from_params`; every array is read-only.

    Attributes
    ----------
    geometry : Arm
        The compiled arm of the first parameter set.
    size : int
        S, the number of parameter sets.
    q_rest : ndarray, shape (S, 2), rad
    lam_rest, lam_slack, lam_min, lam_max, excursion : ndarray, shape (S, 6), m
    km, alpha, beta : ndarray, shape (S, 6); N/m, N, dimensionless
    same_lengths : bool
        Every set has the same rest posture, rest and slack lengths (a fit's samples of Km, α
        and β; the prior's table): at joint angles every set shares, their muscle lengths are
        one set's (:meth:`muscle_lengths` returns them broadcast), and so is everything the
        equations compute from the lengths alone - the passive force's shape, the reflex's
        position term - computed once and scaled per set: the same numbers, a fraction of the
        work.
    """

    geometry: Arm
    size: int
    q_rest: FloatArray
    lam_rest: FloatArray
    lam_slack: FloatArray
    lam_min: FloatArray
    lam_max: FloatArray
    excursion: FloatArray
    km: FloatArray
    alpha: FloatArray
    beta: FloatArray
    same_lengths: bool = False

    @classmethod
    def from_params(cls, params: Sequence[ArmParams], geometry: Arm | None = None) -> ArmBatch:
        """Compile ``params`` (S ≥ 1 sets) over one geometry (default: the first set's).

        Raises
        ------
        ParameterError
            A set differs from the geometry in a field outside :data:`SAMPLED_FIELDS` (it
            needs its own :meth:`Arm.from_params`), or a muscle would reach a non-positive
            length within the range of motion.
        """
        sets = tuple(params)
        if not sets:
            raise ParameterError("ArmBatch needs at least one parameter set.")
        geo = geometry if geometry is not None else Arm.from_params(sets[0])
        key = _geometry_key(geo.params)
        for k, p in enumerate(sets):
            if _geometry_key(p) != key:
                other = [f for f in _GEOMETRY_FIELDS if getattr(p, f) != getattr(geo.params, f)]
                raise ParameterError(
                    f"ArmBatch: parameter set {k} differs from the geometry in "
                    f"{', '.join(other)}, not only in muscle values; compile it with "
                    "Arm.from_params.")
        return cls._build(geo, {name: np.array([getattr(p, name) for p in sets], dtype=float)
                                for name in SAMPLED_FIELDS})

    @classmethod
    def from_arrays(cls, geometry: Arm, size: int, **values: ArrayLike) -> ArmBatch:
        """``size`` parameter sets of ``geometry``'s arm that differ from its parameters in the
        fields of :data:`SAMPLED_FIELDS` given as arrays, (S, 6) or (S, 2) for ``q_rest_rad``
        (a row per set; a single row is shared by every set); a field not given is the
        geometry's own. Each value is checked against :data:`fieldbank.params.BOUNDS`, as
        :class:`~fieldbank.params.ArmParams` checks it, once for all sets.

        Raises
        ------
        ParameterError
            An unknown field, an array of the wrong shape, a value outside its bounds (naming
            the set, the field and the group), or a muscle reaching a non-positive length.
        """
        unknown = sorted(set(values) - set(SAMPLED_FIELDS))
        if unknown:
            raise ParameterError(f"ArmBatch: {', '.join(unknown)} cannot differ between the "
                                 f"sets of one batch; only {', '.join(SAMPLED_FIELDS)} can.")
        if isinstance(size, bool) or not isinstance(size, int) or size < 1:
            raise ParameterError(f"ArmBatch needs at least one parameter set; got {size!r}.")
        p0 = geometry.params
        arrays: dict[str, FloatArray] = {}
        for name in SAMPLED_FIELDS:
            own = np.asarray(getattr(p0, name), dtype=float)
            given = values.get(name)
            a = own[None, :] if given is None else np.asarray(given, dtype=float)
            if a.ndim != 2 or a.shape[1] != own.size or a.shape[0] not in (1, size):
                raise ParameterError(f"ArmBatch: {name} must have shape ({size}, {own.size}); "
                                     f"got {a.shape}.")
            if given is not None:
                _check_bounds(name, a)
            arrays[name] = np.broadcast_to(a, (size, own.size))
        if "q_rest_rad" in values:  # the relation a record checks: the rest posture in range
            for j, rng in enumerate(("shoulder_range_rad", "elbow_range_rad")):
                lo, hi = getattr(p0, rng)
                bad = np.flatnonzero((arrays["q_rest_rad"][:, j] < lo)
                                     | (arrays["q_rest_rad"][:, j] > hi))
                if bad.size:
                    k = int(bad[0])
                    raise ParameterError(
                        f"ArmBatch: parameter set {k}: the 'q_rest_rad[{j}]' parameter must lie "
                        f"in the range of motion [{lo:g}, {hi:g}] rad; got "
                        f"{arrays['q_rest_rad'][k, j]:g} instead.")
        return cls._build(geometry, arrays)

    @classmethod
    def _build(cls, geo: Arm, values: dict[str, FloatArray]) -> ArmBatch:
        """The batch of the sampled fields ``values`` ((S, k) each, checked) over ``geo``."""
        q_rest = np.array(values["q_rest_rad"], dtype=float)
        lam_rest = np.array(values["rest_length_m"], dtype=float)
        p0 = geo.params
        corners = np.array([[a, b] for a in p0.shoulder_range_rad for b in p0.elbow_range_rad])
        # as Arm.from_params, per set: λ is linear in q, its extremes lie at the box corners
        lam_corners = lam_rest[:, None, :] + (corners[None, :, :] - q_rest[:, None, :]) @ geo.jl.T
        lam_min = lam_corners.min(axis=1)
        lam_max = lam_corners.max(axis=1)
        if np.any(lam_min <= 0):
            where = np.unravel_index(int(np.argmin(lam_min)), lam_min.shape)
            raise ParameterError(
                f"ArmBatch: in parameter set {int(where[0])}, muscle {int(where[1])} would "
                f"reach a non-positive length ({lam_min[where]:.4g} m) within the range of "
                "motion.")
        arrays = {
            "q_rest": q_rest, "lam_rest": lam_rest,
            "lam_slack": lam_rest + np.asarray(values["slack_offset_m"], dtype=float),
            "lam_min": lam_min, "lam_max": lam_max, "excursion": lam_max - lam_min,
            "km": np.array(values["km_n_per_m"], dtype=float),
            "alpha": np.array(values["alpha_n"], dtype=float),
            "beta": np.array(values["beta"], dtype=float),
        }
        for a in arrays.values():
            a.setflags(write=False)
        same = all(np.array_equal(a, a[:1].repeat(len(a), axis=0))
                   for a in (q_rest, lam_rest, arrays["lam_slack"]))
        return cls(geometry=geo, size=len(q_rest), same_lengths=same, **arrays)

    def __len__(self) -> int:
        return self.size

    def muscle_lengths(self, q: ArrayLike) -> FloatArray:
        """λ (S, N, 6), m, at joint angles q: (N, 2) shared by every set, or (S, N, 2). With
        :attr:`same_lengths` and shared angles, one set's lengths broadcast (read-only)."""
        qa = np.asarray(q, dtype=float)
        if self.same_lengths and qa.ndim == 2:
            lam = self.lam_rest[0] + (qa - self.q_rest[0]) @ self.geometry.jl.T
            return np.broadcast_to(lam, (self.size, *lam.shape))
        return self.lam_rest[:, None, :] + (qa - self.q_rest[:, None, :]) @ self.geometry.jl.T

    def columns(self, lam: FloatArray, cols: NDArray[np.intp]) -> FloatArray:
        """The muscles ``cols`` (indices, (k,)) of λ (S, N, 6): (S, N, k), broadcast as λ is."""
        if self._one(lam):
            return np.broadcast_to(lam[:1][..., cols], (*lam.shape[:2], len(cols)))
        return lam[..., cols]

    def _one(self, lam: FloatArray) -> bool:
        """λ is one set's lengths broadcast to every set (:meth:`muscle_lengths`)."""
        return self.same_lengths and lam.ndim == 3 and lam.strides[0] == 0

    def passive_force(self, lam: FloatArray, groups: ArrayLike | None = None) -> FloatArray:
        """Ψ (S, N, 6), N, for λ (S, N, 6): :meth:`Arm.passive_forces` of each set, value only.
        ``groups`` (indices): λ holds only these muscle groups' columns, and so does Ψ."""
        g = slice(None) if groups is None else np.asarray(groups)
        if self._one(lam):  # the shape once, Km per set
            return passive_force(lam[:1], self.lam_slack[:1, None, g], self.km[:, None, g],
                                 self.excursion[:1, None, g], self.geometry.w)
        return passive_force(lam, self.lam_slack[:, None, g], self.km[:, None, g],
                             self.excursion[:, None, g], self.geometry.w)

    def reflex_force(self, lam: FloatArray, ldot: FloatArray) -> FloatArray:
        """Φ (S, N, 6), N, for λ (S, N, 6) and λ̇ (N, 6) shared by every set: the value of
        :meth:`Arm.reflex_forces` of each set. Computed only where λ̇ > 0: elsewhere the
        reflex is exactly zero (u = 0), and about half the muscles shorten at any motion.
        Those (point, muscle) pairs are the same for every set: whole muscles when each
        lengthens at every point or none (a joint stretch), else the pairs by one flat index;
        each value the one the equations give for it."""
        g = self.geometry
        s = self.size
        live = ldot > 0
        one = self._one(lam)
        r = slice(0, 1) if one else slice(None)
        lengths = lam[:1] if one else np.broadcast_to(lam, (s, *ldot.shape))
        phi = np.zeros((s, *ldot.shape))
        cols = np.flatnonzero(live.any(axis=0))
        if live[:, cols].all():  # whole muscles
            phi[..., cols] = reflex_force(
                lengths[..., cols], ldot[:, cols], g.ldot_max[cols], self.alpha[:, None, cols],
                self.beta[:, None, cols], self.excursion[r, None, cols],
                self.lam_rest[r, None, cols], self.lam_min[r, None, cols],
                self.lam_max[r, None, cols])
            return phi
        at = np.flatnonzero(live)  # (point, muscle) pairs, flat
        m = at % ldot.shape[1]
        phi.reshape(s, -1)[:, at] = reflex_force(
            lengths.reshape(lengths.shape[0], -1)[:, at], ldot.reshape(-1)[at], g.ldot_max[m],
            self.alpha[:, m], self.beta[:, m], self.excursion[r, m], self.lam_rest[r, m],
            self.lam_min[r, m], self.lam_max[r, m])
        return phi

    def endpoint_force(self, x: ArrayLike, v: ArrayLike | None = None) -> FloatArray:
        """Force each set's arm exerts on the handle, (S, N, 2), N, at hand positions x
        (N, 2), m, and velocity v ((2,) or (N, 2), m/s): :meth:`Arm.endpoint_force` per set."""
        geo = self.geometry
        q, _, (ia, ib, ic, id_), (qd1, qd2) = geo.hand_state(x, v)
        lam = self.muscle_lengths(q)
        return geo._out_vec(self._force(self.passive_force(lam), lam, ia, ib, ic, id_, qd1, qd2))

    def field(self, x: ArrayLike, v: ArrayLike | None = None
              ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """:meth:`Arm.field` of every set: force (S, N, 2), stiffness K = -∂F/∂x and damping
        B = -∂F/∂v (S, N, 2, 2) at hand positions x (N, 2), m, and velocity v ((2,) or
        (N, 2), m/s; None: static). The same equations in the same order as one arm's
        (:func:`fieldbank.model.endpoint_field`), so each set's values are those of its own
        compiled arm to the last bit (``tests/test_armbatch_field.py``)."""
        geo = self.geometry
        q, jac, jinv, qd = geo.hand_state(x, v)
        jl = geo.jl
        lam = self.muscle_lengths(q)
        ldot = np.outer(qd[0], jl[:, 0]) + np.outer(qd[1], jl[:, 1])
        one = slice(0, 1) if self._one(lam) else slice(None)
        psi, dpsi = passive_tension(lam[one], self.lam_slack[one, None, :], self.km[:, None, :],
                                    self.excursion[one, None, :], geo.w)
        phi, dphi_l, dphi_ld = reflex_tension(
            lam[one], ldot, geo.ldot_max, self.alpha[:, None, :], self.beta[:, None, :],
            self.excursion[one, None, :], self.lam_rest[one, None, :], self.lam_min[one, None, :],
            self.lam_max[one, None, :])
        force, stiff, damp = endpoint_field(psi, dpsi, phi, dphi_l, dphi_ld, jl,
                                            geo._jl_products, jac, jinv, qd)
        return geo._out_vec(force), geo._out_mat(stiff), geo._out_mat(damp)

    def grid_force(self, x: ArrayLike, velocities: ArrayLike) -> FloatArray:
        """:meth:`endpoint_force` at every hand position x (N, 2), m, with every velocity of
        ``velocities`` (D, 2), m/s: (S, N, D, 2), N. The passive force depends on the
        position only, so it is computed once per position, not once per velocity."""
        geo = self.geometry
        vel = np.atleast_2d(np.asarray(velocities, dtype=float))
        q, _, (ia, ib, ic, id_), _ = geo.hand_state(x)
        lam = self.muscle_lengths(q)
        psi = self.passive_force(lam)
        out = []
        for v in vel:
            _, _, _, (qd1, qd2) = geo.hand_state(x, v)
            out.append(self._force(psi, lam, ia, ib, ic, id_, qd1, qd2))
        return geo._out_vec(np.stack(out, axis=2))

    def _force(self, psi: FloatArray, lam: FloatArray, ia: FloatArray, ib: FloatArray,
               ic: FloatArray, id_: FloatArray, qd1: FloatArray, qd2: FloatArray) -> FloatArray:
        """Model-frame hand force (S, N, 2) of passive force ψ and the reflex at q̇."""
        jl = self.geometry.jl
        ldot = np.outer(qd1, jl[:, 0]) + np.outer(qd2, jl[:, 1])
        fx, fy = hand_force(psi + self.reflex_force(lam, ldot), jl, ia, ib, ic, id_)
        return np.stack([fx, fy], axis=-1)


#: Every ArmParams field but the sampled ones and the document header.
_GEOMETRY_FIELDS: tuple[str, ...] = tuple(
    f.name for f in dataclass_fields(ArmParams) if f.name not in SAMPLED_FIELDS)


#: The geometry fields of a set, as one tuple (a copy made by ``with_group`` shares their
#: objects, so comparing two keys is mostly identity checks).
_geometry_key: Callable[[ArmParams], tuple[object, ...]] = attrgetter(*_GEOMETRY_FIELDS)


def _check_bounds(name: str, values: FloatArray) -> None:
    """Every entry of ``values`` (S, k) of field ``name`` inside its interval of
    :data:`fieldbank.params.BOUNDS` (a NaN or an infinity is not); else the message a record
    would give for the first bad entry, naming its set."""
    iv = BOUNDS[name]
    low = -np.inf if iv.low is None else iv.low
    high = np.inf if iv.high is None else iv.high
    ok = np.isfinite(values)
    ok &= (values >= low) if iv.low_closed else (values > low)
    ok &= (values <= high) if iv.high_closed else (values < high)
    if ok.all():
        return
    k, i = (int(v) for v in np.argwhere(~ok)[0])
    msg = number_problem(field_label(name, i), float(values[k, i]), iv)
    raise ParameterError(f"ArmBatch: parameter set {k}: {msg}")
