"""The neuro-mechanical arm: kinematics, muscle forces and endpoint force fields.

Design
------
:class:`fieldbank.params.ArmParams` is the user's record; :class:`Arm` is the compiled model:
built once from a parameter set (``Arm.from_params``), it holds the derived constants (the
muscle-length Jacobian J_λ, the length extremes over the range of motion, the maximal
lengthening rates λ̇_max) and evaluates everything vectorised over N positions. It holds no
mutable state, so the fitter, the what-if module and the haptic loop share one instance; the
simulation state lives in :class:`fieldbank.sim.ArmSim`.

Its muscle values are a :class:`fieldbank.muscleset.MuscleSet` of one set: :meth:`Arm.field`
is :meth:`Arm.field_of` its own set, the evaluation S parameter sets of the same geometry go
through as well (:class:`fieldbank.armbatch.ArmBatch`: a fit's samples, the intervals).

Conventions (BRIEF §3)
----------------------
Shoulder frame: origin at the shoulder, +x to the patient's right, +y forward. Joint angles
q = (q1, q2): q1 from +x, q2 elbow relative to the upper arm, counter-clockwise = flexion.
Internally the arm is a right arm; for a left arm the public methods mirror x at the edge.
Forces are those the arm exerts on the handle ("arm-on-handle"); stiffness K = -∂F/∂x, damping
B = -∂F/∂v (N/m, N·s/m).

Muscle model (seed eqs. 2-5)
----------------------------
λ = λ_rest + J_λ (q - q_rest); λ̇ = J_λ q̇; joint torque from the muscles τ = -J_λᵀ (Ψ + Φ).

Passive force: ψ = Km · s_w(d) · exp(-(d/ℓ)²), d = λ - λ_rest - δ (δ the group's slack
offset, 0 unless an intervention lengthened or shortened it), ℓ the excursion over the range
of motion. The seed's one-sided ramp max(0, d) is replaced by its logistic smoothing
s_w(d) = w·ln(1 + e^{d/w}), whose slope is the logistic function of steepness 1/w: tension stays
≥ 0, force and stiffness stay continuous (the haptic loop never sees a step), and for |d| ≫ w
it equals the seed's form. At rest length each muscle carries Km·w·ln 2 and has stiffness Km/2,
so an agonist–antagonist pair gives the same stiffness as the one-sided seed model.

Reflex force: u = β·clip(λ̇/λ̇_max, 0, 1), Γ = (λ-λ_min)/ℓ - (λ_rest/λ_max)(1-u),
φ = max(0, α u Γ e^{-Γ²}). At a kink (u at 0 or 1, φ at 0) derivatives take the mean of the
one-sided slopes, the value a central difference measures.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from dataclasses import field as dataclass_field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fieldbank.errors import ParameterError, UnreachableError
from fieldbank.muscle import passive_tension, reflex_tension
from fieldbank.muscleset import MuscleSet, endpoint_field, hand_force, velocities
from fieldbank.params import GROUP_SIGN, ArmParams

FloatArray = NDArray[np.float64]
#: Four same-shaped arrays: the entries of a 2 × 2 matrix per point, row by row.
Quad = tuple[FloatArray, FloatArray, FloatArray, FloatArray]

#: Elbow angles closer than this to 0 or π make the endpoint Jacobian singular.
SINGULAR_ELBOW_RAD = 0.02
#: Gauss-Legendre segments (in units of the smoothing width w) for the potential's
#: smoothing correction: the integrand is analytic with singularities ±iπ away, so short
#: segments near 0 and long ones in the exponentially small tails give ~1e-10 relative error.
_POT_SEGMENTS = ((-30.0, -12.0), (-12.0, -4.0), (-4.0, 0.0), (0.0, 4.0), (4.0, 12.0), (12.0, 30.0))
_GL_X, _GL_W = np.polynomial.legendre.leggauss(16)

#: The fields of a parameter record, in order.
_PARAM_FIELDS: tuple[str, ...] = tuple(f.name for f in fields(ArmParams))


def _as_points(x: ArrayLike, name: str = "positions") -> FloatArray:
    a = np.asarray(x, dtype=float)
    if a.ndim == 1:
        a = a.reshape(1, -1)
    if a.ndim != 2 or a.shape[1] != 2:
        raise ParameterError(f"{name} must have shape (N, 2); got {np.shape(x)}.")
    if not np.all(np.isfinite(a)):
        bad = int(np.argmax(~np.all(np.isfinite(a), axis=1)))
        raise ParameterError(f"{name}[{bad}] is not finite: {a[bad].tolist()}.")
    return a


@dataclass(frozen=True, eq=False)
class Arm:
    """Compiled arm model. Build with :meth:`from_params`; all arrays are read-only.

    Attributes
    ----------
    params : ArmParams
    l1, l2 : float
        Segment lengths, m.
    jl : ndarray, shape (6, 2), m
        Muscle-length Jacobian J_λ (λ̇ = J_λ q̇).
    lam_rest, lam_min, lam_max, excursion : ndarray, shape (6,), m
        λ_rest, λ_min, λ_max over the range of motion, ℓ = λ_max - λ_min.
    lam_slack : ndarray, shape (6,), m
        Length where the passive force starts, λ_rest + slack offset.
    ldot_max : ndarray, shape (6,), m/s
        Largest lengthening rate on the seed's fast circle.
    km, alpha, beta : ndarray, shape (6,)
        N/m, N, dimensionless.
    w : float
        Passive smoothing width, m.
    muscles : MuscleSet
        The muscle values as the set of one (each row above is its row 0): what
        :meth:`field` evaluates, with the code that evaluates S sets (:meth:`field_of`).
    """

    params: ArmParams
    l1: float
    l2: float
    jl: FloatArray
    ldot_max: FloatArray
    w: float
    mirror: bool
    muscles: MuscleSet
    _pot_total: FloatArray  # ∫_{-∞}^{∞} of the smoothing correction per muscle (unit Km)
    _jl_products: FloatArray  # (6, 3): J_λ[:,0]², J_λ[:,0]·J_λ[:,1], J_λ[:,1]²
    # row 0 of ``muscles`` (read-only views, set from it: not given to the constructor)
    q_rest: FloatArray = dataclass_field(init=False)
    lam_rest: FloatArray = dataclass_field(init=False)
    lam_slack: FloatArray = dataclass_field(init=False)
    lam_min: FloatArray = dataclass_field(init=False)
    lam_max: FloatArray = dataclass_field(init=False)
    excursion: FloatArray = dataclass_field(init=False)
    km: FloatArray = dataclass_field(init=False)
    alpha: FloatArray = dataclass_field(init=False)
    beta: FloatArray = dataclass_field(init=False)

    def __post_init__(self) -> None:
        m = self.muscles
        for name in _ROWS:
            object.__setattr__(self, name, getattr(m, name)[0])

    @classmethod
    def from_params(cls, p: ArmParams) -> Arm:
        jl = np.array(
            [
                [s * rs, s * re]
                for s, rs, re in zip(
                    GROUP_SIGN, p.moment_arm_shoulder_m, p.moment_arm_elbow_m, strict=True
                )
            ]
        )
        ldot_max = _circle_ldot_max(p, jl)
        jl.setflags(write=False)
        ldot_max.setflags(write=False)
        muscles = MuscleSet.of([p], jl, ldot_max)  # the set of one
        w = p.passive_smoothing_m
        products = np.stack([jl[:, 0] * jl[:, 0], jl[:, 0] * jl[:, 1], jl[:, 1] * jl[:, 1]],
                            axis=1)
        pot_total = _smoothing_integral(np.full(6, np.inf), muscles.excursion[0], w)
        for a in (products, pot_total):
            a.setflags(write=False)
        return cls(params=p, l1=p.upper_arm_length_m, l2=p.forearm_length_m, jl=jl,
                   ldot_max=ldot_max, w=w, mirror=p.side == "left", muscles=muscles,
                   _pot_total=pot_total, _jl_products=products)

    #: ArmParams fields an arm's compiled geometry does not depend on (:meth:`with_muscles`).
    MUSCLE_FIELDS = ("km_n_per_m", "alpha_n", "beta", "slack_offset_m")

    def with_muscles(self, p: ArmParams) -> Arm:
        """The compiled arm of ``p``, which differs from this arm's parameters only in muscle
        values (Km, α, β, slack offset): it shares every derived constant of the geometry
        (J_λ, length extremes, λ̇_max, the potential's integrals), so nothing is compiled.

        Raises
        ------
        ParameterError
            ``p`` differs in anything else (segments, moment arms, rest posture, range, ...).
        """
        q = self.params
        other = [f for f in _PARAM_FIELDS if f not in self.MUSCLE_FIELDS
                 and getattr(p, f) != getattr(q, f)]
        if other:
            raise ParameterError(
                f"with_muscles: the parameters differ in {', '.join(other)}, not only in "
                "muscle values; compile them with Arm.from_params.")
        muscles = self.muscles.with_values(p)
        return replace(self, params=p, muscles=muscles)

    # --- frames ---------------------------------------------------------------------------
    def _in(self, x: ArrayLike, name: str = "positions") -> FloatArray:
        a = _as_points(x, name)
        if self.mirror:
            a = a * np.array([-1.0, 1.0])
        return a

    def _out_vec(self, f: FloatArray) -> FloatArray:
        return f * np.array([-1.0, 1.0]) if self.mirror else f

    def _out_mat(self, k: FloatArray) -> FloatArray:
        if not self.mirror:
            return k
        m = np.array([[1.0, -1.0], [-1.0, 1.0]])  # diag(-1,1) K diag(-1,1)
        return k * m

    # --- kinematics (model frame, right arm) ------------------------------------------------
    def fk(self, q: ArrayLike) -> FloatArray:
        """Hand position, shape (N, 2), m, for joint angles q (N, 2), rad (shoulder frame)."""
        qa = np.atleast_2d(np.asarray(q, dtype=float))
        q1, q12 = qa[:, 0], qa[:, 0] + qa[:, 1]
        x = np.stack(
            [self.l1 * np.cos(q1) + self.l2 * np.cos(q12),
             self.l1 * np.sin(q1) + self.l2 * np.sin(q12)],
            axis=1,
        )
        return self._out_vec(x)

    def jacobian(self, q: ArrayLike) -> FloatArray:
        """Endpoint Jacobian ∂x/∂q in the model frame, shape (N, 2, 2), m/rad."""
        qa = np.atleast_2d(np.asarray(q, dtype=float))
        q1, q12 = qa[:, 0], qa[:, 0] + qa[:, 1]
        s1, c1, s12, c12 = np.sin(q1), np.cos(q1), np.sin(q12), np.cos(q12)
        j = np.empty((qa.shape[0], 2, 2))
        j[:, 0, 0] = -self.l1 * s1 - self.l2 * s12
        j[:, 0, 1] = -self.l2 * s12
        j[:, 1, 0] = self.l1 * c1 + self.l2 * c12
        j[:, 1, 1] = self.l2 * c12
        return j

    def ik(self, x: ArrayLike, branch: str = "flexed", check_range: bool = False) -> FloatArray:
        """Joint angles (N, 2), rad, placing the hand at x (N, 2), m, in the shoulder frame.

        Parameters
        ----------
        branch : {'flexed', 'extended'}
            Elbow solution: 'flexed' has q2 > 0 (the physiological branch), 'extended' q2 < 0.
        check_range : bool
            Also refuse postures outside the range of motion.

        Raises
        ------
        UnreachableError
            Naming the first offending position and the reachable annulus.
        """
        return self._ik_model(self._in(x), branch, check_range)

    def _ik_model(self, xm: FloatArray, branch: str = "flexed",
                  check_range: bool = False) -> FloatArray:
        if branch not in ("flexed", "extended"):
            raise ParameterError(f"branch must be 'flexed' or 'extended'; got {branch!r}.")
        l1, l2 = self.l1, self.l2
        r2 = np.einsum("ij,ij->i", xm, xm)
        q, cos2 = _ik_flexed(xm, l1, l2)
        s_lim = math.cos(SINGULAR_ELBOW_RAD)
        bad = (cos2 > s_lim) | (cos2 < -s_lim)
        if np.any(bad):
            i = int(np.argmax(bad))
            pos = self._out_vec(xm[i : i + 1])[0]
            r_in = math.sqrt(l1 * l1 + l2 * l2 - 2 * l1 * l2 * s_lim)
            r_out = math.sqrt(l1 * l1 + l2 * l2 + 2 * l1 * l2 * s_lim)
            raise UnreachableError(
                f"Position ({pos[0]:.4f}, {pos[1]:.4f}) m (index {i}; {int(bad.sum())} of "
                f"{len(bad)} positions) is {math.sqrt(r2[i]):.4f} m from the shoulder; this arm "
                f"reaches {r_in:.4f}-{r_out:.4f} m."
            )
        if branch == "extended":
            q2 = -q[:, 1]
            q1 = np.arctan2(xm[:, 1], xm[:, 0]) - np.arctan2(l2 * np.sin(q2), l1 + l2 * np.cos(q2))
            q = np.stack([(q1 + np.pi) % (2 * np.pi) - np.pi, q2], axis=1)
        if check_range:
            self.check_range(q, xm)
        return q

    def check_range(self, q: FloatArray, xm: FloatArray | None = None) -> None:
        """Raise UnreachableError when a posture lies outside the range of motion."""
        p = self.params
        tol = 1e-9
        for j, (name, (lo, hi)) in enumerate(
            (("shoulder", p.shoulder_range_rad), ("elbow", p.elbow_range_rad))
        ):
            out = (q[:, j] < lo - tol) | (q[:, j] > hi + tol)
            if np.any(out):
                i = int(np.argmax(out))
                where = ""
                if xm is not None:
                    pos = self._out_vec(xm[i : i + 1])[0]
                    where = f"Position ({pos[0]:.4f}, {pos[1]:.4f}) m (index {i}) needs "
                raise UnreachableError(
                    f"{where}{name} angle {math.degrees(q[i, j]):.1f}° outside this arm's range "
                    f"of motion {math.degrees(lo):.1f}°..{math.degrees(hi):.1f}° "
                    f"({int(out.sum())} of {len(out)} positions)."
                )

    def reachable(self, x: ArrayLike) -> NDArray[np.bool_]:
        """Mask of positions the arm reaches within its range of motion (flexed branch)."""
        q, cos2 = _ik_flexed(self._in(x), self.l1, self.l2)
        ok = np.abs(cos2) <= math.cos(SINGULAR_ELBOW_RAD)
        q1, q2 = q[:, 0], q[:, 1]
        p = self.params
        ok &= (q1 >= p.shoulder_range_rad[0]) & (q1 <= p.shoulder_range_rad[1])
        ok &= (q2 >= p.elbow_range_rad[0]) & (q2 <= p.elbow_range_rad[1])
        return ok

    # --- muscles ------------------------------------------------------------------------------
    def muscle_lengths(self, q: ArrayLike) -> FloatArray:
        """λ (N, 6), m."""
        qa = np.atleast_2d(np.asarray(q, dtype=float))
        return self.lam_rest + (qa - self.q_rest) @ self.jl.T

    def muscle_velocities(self, qdot: ArrayLike) -> FloatArray:
        """λ̇ (N, 6), m/s."""
        return np.atleast_2d(np.asarray(qdot, dtype=float)) @ self.jl.T

    def passive_forces(self, lam: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Ψ and ∂Ψ/∂λ, each (N, 6): N and N/m."""
        return passive_tension(lam, self.lam_slack, self.km, self.excursion, self.w)

    def reflex_forces(
        self, lam: FloatArray, ldot: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Φ, ∂Φ/∂λ and ∂Φ/∂λ̇, each (N, 6): N, N/m, N·s/m."""
        return reflex_tension(lam, ldot, self.ldot_max, self.alpha, self.beta, self.excursion,
                              self.lam_rest, self.lam_min, self.lam_max)

    def joint_torque(self, q: ArrayLike, qdot: ArrayLike | None = None) -> FloatArray:
        """Muscle torque on the arm τ = -J_λᵀ(Ψ+Φ), shape (N, 2), N·m."""
        qa = np.atleast_2d(np.asarray(q, dtype=float))
        lam = self.muscle_lengths(qa)
        f, _ = self.passive_forces(lam)
        if qdot is not None:
            f = f + self.reflex_forces(lam, self.muscle_velocities(qdot))[0]
        return -f @ self.jl

    # --- endpoint fields (shoulder frame) ---------------------------------------------------
    def endpoint_force(self, x: ArrayLike, v: ArrayLike | None = None) -> FloatArray:
        """Force the arm exerts on the handle, (N, 2), N, at hand positions x and velocity v."""
        return self.field(x, v, derivatives=False)[0]

    def hand_state(
        self, x: ArrayLike, v: ArrayLike | None = None
    ) -> tuple[FloatArray, Quad, Quad, tuple[FloatArray, FloatArray]]:
        """The joint-space state of hand positions x (N, 2), m, and velocity v ((2,) or
        (N, 2), m/s; None: static), shoulder frame, model side: joint angles q (N, 2), rad;
        the endpoint Jacobian's entries (a, b, c, d) = J (m/rad) and (ia, ib, ic, id) = J⁻¹,
        each (N,); and the joint velocities (q̇1, q̇2), each (N,), rad/s. Depends on the
        geometry only (:class:`ArmBatch` shares it across parameter sets)."""
        xm = self._in(x)
        n = xm.shape[0]
        if v is None:
            vm = np.zeros((n, 2))
        else:
            vm = np.broadcast_to(np.asarray(v, dtype=float), (n, 2)).copy()
            if not np.all(np.isfinite(vm)):
                raise ParameterError("velocity must be finite.")
            if self.mirror:
                vm[:, 0] *= -1.0
        q = self._ik_model(xm)
        l1, l2 = self.l1, self.l2
        q1, q12 = q[:, 0], q[:, 0] + q[:, 1]
        s1, c1, s12, c12 = np.sin(q1), np.cos(q1), np.sin(q12), np.cos(q12)
        # J = [[a, b], [c, d]] and its inverse, component-wise over N (2×2 einsums are slow)
        b = -l2 * s12
        a = -l1 * s1 + b
        d = l2 * c12
        c = l1 * c1 + d
        det = a * d - b * c
        ia, ib, ic, id_ = d / det, -b / det, -c / det, a / det
        vx, vy = vm[:, 0], vm[:, 1]
        qd1 = ia * vx + ib * vy
        qd2 = ic * vx + id_ * vy
        return q, (a, b, c, d), (ia, ib, ic, id_), (qd1, qd2)

    def field(
        self, x: ArrayLike, v: ArrayLike | None = None, derivatives: bool = True
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Force F (N,2), stiffness K = -∂F/∂x (N,2,2) and damping B = -∂F/∂v (N,2,2).

        Parameters
        ----------
        x : array, shape (N, 2), m
            Hand positions in the shoulder frame.
        v : array, shape (2,) or (N, 2), m/s, optional
            Endpoint velocity (0 = static). K is taken at this fixed velocity.
        derivatives : bool
            Skip K and B (returned as empty arrays) when False.
        """
        return self._evaluate(self.muscles, x, v, derivatives)

    def field_of(self, muscles: MuscleSet, x: ArrayLike, v: ArrayLike | None = None,
                 derivatives: bool = True) -> tuple[FloatArray, FloatArray, FloatArray]:
        """:meth:`field` of every set of ``muscles`` over this arm's geometry: force
        (S, N, 2), stiffness and damping (S, N, 2, 2) (empty (0, 2, 2) without
        ``derivatives``). The one evaluation of the equations from the hand to the muscles
        and back: one arm is its set of one (:attr:`muscles`), a fit's samples S sets
        (:class:`fieldbank.armbatch.ArmBatch`)."""
        force, stiff, damp = self._evaluate(muscles, x, v, derivatives)
        if len(muscles) == 1:  # the set of one: its unit set axis back
            force = force[None]
            if derivatives:
                stiff, damp = stiff[None], damp[None]
        return force, stiff, damp

    def _evaluate(self, muscles: MuscleSet, x: ArrayLike, v: ArrayLike | None,
                  derivatives: bool) -> tuple[FloatArray, FloatArray, FloatArray]:
        """:meth:`field_of`, the set of one without its unit set axis: its row evaluated
        (N, 6) against (6,) (:meth:`MuscleSet.against`), the arithmetic of one arm."""
        q, jac, jinv, qd = self.hand_state(x, v)
        jl = self.jl
        lam = muscles.lengths(q, jl)
        ldot = velocities(qd, jl)
        if not derivatives:
            fx, fy = hand_force(muscles.forces(lam, ldot), jl, *jinv)
            empty = np.empty((0, 2, 2))
            return self._out_vec(np.stack([fx, fy], axis=-1)), empty, empty
        force, stiff, damp = endpoint_field(*muscles.tensions(lam, ldot), jl,
                                            self._jl_products, jac, jinv, qd)
        return self._out_vec(force), self._out_mat(stiff), self._out_mat(damp)

    def potential(self, x: ArrayLike) -> FloatArray:
        """Passive potential U = Σ ∫ψ_i dλ_i (N,), J, zero with every muscle fully slack.

        The postural field is its negative gradient: F = -∇U.
        """
        q = self._ik_model(self._in(x))
        d = self.muscle_lengths(q) - self.lam_slack
        ell = self.excursion
        ramp = np.where(d > 0, 0.5 * ell * ell * (-np.expm1(-((d / ell) ** 2))), 0.0)
        corr = _smoothing_integral(d, ell, self.w)
        return ((ramp + corr) * self.km).sum(axis=1)

    def rest_position(self) -> FloatArray:
        """Hand position at the rest posture, shape (2,), m, shoulder frame."""
        return self.fk(self.q_rest)[0]


#: The muscle arrays of one arm: row 0 of its set of one (:attr:`Arm.muscles`).
_ROWS = ("q_rest", "lam_rest", "lam_slack", "lam_min", "lam_max", "excursion", "km", "alpha",
         "beta")


def _ik_flexed(xm: FloatArray, l1: float, l2: float) -> tuple[FloatArray, FloatArray]:
    """Flexed-branch joint angles (N, 2) for model-frame positions, and cos q2 (N,) (unclipped,
    so |cos q2| > 1 marks an unreachable position)."""
    cos2 = (np.einsum("ij,ij->i", xm, xm) - l1 * l1 - l2 * l2) / (2 * l1 * l2)
    q2 = np.arccos(np.clip(cos2, -1.0, 1.0))
    q1 = np.arctan2(xm[:, 1], xm[:, 0]) - np.arctan2(l2 * np.sin(q2), l1 + l2 * np.cos(q2))
    q1 = (q1 + np.pi) % (2 * np.pi) - np.pi
    return np.stack([q1, q2], axis=1), cos2


def _smoothing_integral(d: FloatArray, ell: FloatArray, w: float) -> FloatArray:
    """∫_{-∞}^{d} w·ln(1+e^{-|s|/w}) e^{-(s/ℓ)²} ds, elementwise (the softplus correction)."""
    d = np.asarray(d, dtype=float)
    tmax = np.clip(d / w, -1e3, 1e3)
    total = np.zeros(np.broadcast_shapes(d.shape, np.shape(ell)))
    ell_b = np.broadcast_to(ell, total.shape)
    for lo, hi in _POT_SEGMENTS:
        top = np.minimum(tmax, hi)
        live = top > lo
        if not np.any(live):
            continue
        top = np.where(live, top, lo)
        half = 0.5 * (top - lo)
        mid = 0.5 * (top + lo)
        t = mid[..., None] + half[..., None] * _GL_X
        s = w * t
        integrand = np.log1p(np.exp(-np.abs(t))) * np.exp(-((s / ell_b[..., None]) ** 2))
        total += np.where(live, half * (integrand @ _GL_W), 0.0)
    return w * w * total


def _circle_ldot_max(p: ArmParams, jl: FloatArray, samples: int = 1440) -> FloatArray:
    """λ̇_max per muscle: the largest |λ̇| on the seed's fast circle (either direction)."""
    l1, l2 = p.upper_arm_length_m, p.forearm_length_m
    qc1, qc2 = p.circle_centre_rad
    cx = l1 * math.cos(qc1) + l2 * math.cos(qc1 + qc2)
    cy = l1 * math.sin(qc1) + l2 * math.sin(qc1 + qc2)
    rad = 0.5 * p.circle_diameter_m
    om = 2.0 * math.pi * p.circle_frequency_hz
    th = np.linspace(0.0, 2.0 * math.pi, samples, endpoint=False)
    x = np.stack([cx + rad * np.cos(th), cy + rad * np.sin(th)], axis=1)
    xd = np.stack([-rad * om * np.sin(th), rad * om * np.cos(th)], axis=1)
    q, cos2 = _ik_flexed(x, l1, l2)
    if np.any(np.abs(cos2) >= math.cos(SINGULAR_ELBOW_RAD)):
        raise ParameterError(
            f"The λ̇_max circle (diameter {p.circle_diameter_m:g} m around the hand at posture "
            f"{np.degrees(p.circle_centre_rad).round(1).tolist()}°) leaves the reachable "
            "workspace; change circle_diameter_m or circle_centre_rad."
        )
    q1, q2 = q[:, 0], q[:, 1]
    s1, c1 = np.sin(q1), np.cos(q1)
    s12, c12 = np.sin(q1 + q2), np.cos(q1 + q2)
    j11, j12 = -l1 * s1 - l2 * s12, -l2 * s12
    j21, j22 = l1 * c1 + l2 * c12, l2 * c12
    det = j11 * j22 - j12 * j21
    qd1 = (j22 * xd[:, 0] - j12 * xd[:, 1]) / det
    qd2 = (-j21 * xd[:, 0] + j11 * xd[:, 1]) / det
    ldot = np.stack([qd1, qd2], axis=1) @ jl.T
    return np.abs(ldot).max(axis=0)
