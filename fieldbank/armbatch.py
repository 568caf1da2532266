"""Many parameter sets of one arm geometry evaluated together: :class:`ArmBatch`.

A fit's uncertainty is carried as parameter samples that differ only in their muscle values
(:data:`SAMPLED_FIELDS`); the geometry (J_λ, λ̇_max, segment lengths, range of motion) is the
same for all of them. :class:`ArmBatch` compiles that geometry once and holds every set's
muscles as one :class:`~fieldbank.muscleset.MuscleSet`, evaluated with the code one arm uses
(:meth:`fieldbank.model.Arm.field_of`: one arm is the set of one), so that S samples cost one
vectorised pass instead of S compiled arms (the prediction intervals of a what-if and of a
report, the prior's table, the spread of a fit's predictions).

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
from numpy.typing import ArrayLike

from fieldbank.errors import ParameterError
from fieldbank.model import Arm, FloatArray
from fieldbank.muscleset import MuscleSet, hand_force, velocities
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
    once; the muscle values of :data:`SAMPLED_FIELDS` are the rows of ``muscles``. What each
    set gives is what :meth:`Arm.from_params` of that set would give, evaluated by the same
    code (:meth:`Arm.field_of`). Build with :meth:`from_params` or :meth:`from_arrays`; every
    array is read-only.

    Attributes
    ----------
    geometry : Arm
        The compiled arm of the first parameter set.
    params : tuple of ArmParams
        The S parameter sets (empty when the sets were given as arrays, :meth:`from_arrays`).
    muscles : MuscleSet
        Their muscle values, (S, 6) each (:attr:`MuscleSet.same_lengths`: every set has the
        same rest posture, rest and slack lengths).
    """

    geometry: Arm
    params: tuple[ArmParams, ...]
    muscles: MuscleSet

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
        return cls(geometry=geo, params=sets, muscles=MuscleSet.of(sets, geo.jl, geo.ldot_max))

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
                q = arrays["q_rest_rad"][:, j]
                bad = np.flatnonzero((q < lo) | (q > hi))
                if bad.size:
                    k = int(bad[0])
                    raise ParameterError(
                        f"ArmBatch: parameter set {k}: the 'q_rest_rad[{j}]' parameter must lie "
                        f"in the range of motion [{lo:g}, {hi:g}] rad; got {q[k]:g} instead.")
        named = {"km": arrays["km_n_per_m"], "alpha": arrays["alpha_n"],
                 "beta": arrays["beta"], **arrays}
        return cls(geometry=geometry, params=(),
                   muscles=MuscleSet.from_values(p0, named, geometry.jl, geometry.ldot_max))

    def __len__(self) -> int:
        return len(self.muscles)

    def endpoint_force(self, x: ArrayLike, v: ArrayLike | None = None) -> FloatArray:
        """Force each set's arm exerts on the handle, (S, N, 2), N, at hand positions x
        (N, 2), m, and velocity v ((2,) or (N, 2), m/s): :meth:`Arm.endpoint_force` per set."""
        return self.geometry.field_of(self.muscles, x, v, derivatives=False)[0]

    def field(self, x: ArrayLike, v: ArrayLike | None = None
              ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """:meth:`Arm.field` of every set: force (S, N, 2), stiffness K = -∂F/∂x and damping
        B = -∂F/∂v (S, N, 2, 2) at hand positions x (N, 2), m, and velocity v ((2,) or
        (N, 2), m/s; None: static), by the code one arm's field runs (:meth:`Arm.field_of`)."""
        return self.geometry.field_of(self.muscles, x, v)

    def grid_force(self, x: ArrayLike, velocities_m_per_s: ArrayLike) -> FloatArray:
        """:meth:`endpoint_force` at every hand position x (N, 2), m, with every velocity of
        ``velocities_m_per_s`` (D, 2), m/s: (S, N, D, 2), N. The passive force depends on the
        position only, so it is computed once per position, not once per velocity."""
        geo, m = self.geometry, self.muscles
        jl = geo.jl
        vel = np.atleast_2d(np.asarray(velocities_m_per_s, dtype=float))
        q, _, jinv, _ = geo.hand_state(x)
        lam = m.lengths(q, jl)
        psi = m.passive(lam)
        out = []
        for v in vel:
            qd = geo.hand_state(x, v)[3]
            fx, fy = hand_force(psi + m.reflex(lam, velocities(qd, jl)), jl, *jinv)
            out.append(np.stack([fx, fy], axis=-1))
        return geo._out_vec(np.stack(out, axis=2))


def by_geometry(arms: Sequence[Arm]) -> list[tuple[list[int], ArmBatch]]:
    """``arms`` grouped by geometry, each group one batch over its first arm's compiled
    geometry: (the group's indices into ``arms``, its batch), in order of first appearance."""
    groups: dict[tuple[object, ...], list[int]] = {}
    for i, a in enumerate(arms):
        groups.setdefault(_geometry_key(a.params), []).append(i)
    return [(idx, ArmBatch.from_params([arms[i].params for i in idx], arms[idx[0]]))
            for idx in groups.values()]


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
