"""The fit's cost, with everything that does not depend on the parameters computed once.

Design
------
Only Km, α, β (and optionally q_rest and the slack offsets) change during a fit; the measured
positions and
velocities do not. So the inverse kinematics, the endpoint Jacobian J and J⁻¹, the joint
velocities q̇ = J⁻¹v, J_λq and λ̇ = J_λq̇ are computed once per measured point
(:meth:`FitProblem.from_maps`).

Every measured value is then a fixed linear combination of three per-muscle quantities at its
point, the muscle tension f_i and its derivatives f_λ,i = ∂f_i/∂λ_i and f_λ̇,i = ∂f_i/∂λ̇_i
(the model's ``Arm.field``)::

    F  = Σ_i A_i f_i                                  A_i = -J⁻ᵀ J_λ,iᵀ
    K  = Σ_i f_λ,i M1_i + f_λ̇,i M2_i + f_i M3_i        M1_i = J⁻ᵀ J_λ,iᵀ J_λ,i J⁻¹,
                                                      M2_i = J⁻ᵀ J_λ,iᵀ J_λ,i Q J⁻¹,
                                                      M3_i = J⁻ᵀ G(A_i) J⁻¹

with Q = -J⁻¹(∂J/∂q_k)q̇ and G(F)[:, k] = (∂J/∂q_k)ᵀF. The tension is linear in Km and in α:
f_i = Km_i·P_i(λ) + α_i·R_i(λ, λ̇; β_i), so the predicted values are ``X(β, q_rest) @ [Km; α]``
with a design matrix X of 12 columns. The passive columns P_i depend on the slack offset δ_i
of the group (the passive force acts on λ - λ_rest - δ): a contracture (δ < 0) moves the onset of
the passive force earlier in the range. The cost is the whitened χ² of all measured values plus
the prior (see :mod:`fieldbank.fitting.space`).

Variable projection: for given β, q_rest and δ the best Km and α solve a small bounded linear
least-squares problem (12 unknowns), so the global search runs over β (and q_rest and δ) only.
The gradient of the projected cost follows from the envelope theorem, -2 rᵀ W (∂X/∂φ) θ_lin;
∂X/∂φ comes from central differences of X alone (no extra solves; the reflex column i depends
only on β_i, the passive column i only on δ_i).

Noise: each value is whitened by its map's sd; where a map has no sd, by
:data:`DEFAULT_RELATIVE_SD` (5%, an assumption) × the size of the measured force or stiffness at
that position (:func:`relative_scale`).

Evaluation: the reflex columns, the projection and the gradient over β run as compiled calls
(:mod:`fieldbank.fitting.kernels`); a problem built inside
:func:`fieldbank.fitting.reference.reference_kernels` evaluates with the numpy formulas of
:mod:`fieldbank.fitting.reference` instead, the reference the compiled path is held to.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fieldbank.fitting import kernels, reference
from fieldbank.fitting.betapath import H_BETA, BetaPath
from fieldbank.fitting.space import ParamSpace
from fieldbank.maps import FieldMap
from fieldbank.model import Arm, FloatArray

#: Relative noise assumed for a map without sd columns (see :func:`relative_scale`).
DEFAULT_RELATIVE_SD = 0.05
#: Floor of the per-position scale, as a fraction of the map's RMS value.
SCALE_FLOOR_FRACTION = 0.1
#: Floor on any sd, as a fraction of the map's RMS value (an sd of 0 would weigh infinitely).
SD_FLOOR_FRACTION = 1e-3


def relative_scale(values: FloatArray) -> FloatArray:
    """Size of a map's value at each position, shape (N,), in the values' unit.

    The RMS of the entries at the position (force components or stiffness entries), floored at
    :data:`SCALE_FLOOR_FRACTION` × the RMS over the whole map, so that a position where the
    force vanishes (the rest posture) is not given an sd of zero.
    """
    n = values.shape[0]
    per = np.sqrt(np.mean(values.reshape(n, -1) ** 2, axis=1))
    rms = float(np.sqrt(np.mean(values**2)))
    return np.maximum(per, SCALE_FLOOR_FRACTION * rms)


def map_sd(m: FieldMap) -> FloatArray:
    """The standard deviation of each of a map's values, shape (N, k), in the values' unit.

    The map's own sd where it has one, else :data:`DEFAULT_RELATIVE_SD` × the size of the value
    at its position (:func:`relative_scale`); floored at :data:`SD_FLOOR_FRACTION` × the map's
    RMS value. The one weighting of the fit, its goodness of fit and of prediction checks.
    """
    n = m.n
    values = m.values.reshape(n, -1)
    if m.sd is not None:
        sd = np.array(m.sd, dtype=float).reshape(n, -1)
    else:
        sd = np.repeat(DEFAULT_RELATIVE_SD * relative_scale(m.values)[:, None], values.shape[1],
                       axis=1)
    rms = float(np.sqrt(np.mean(values**2))) or 1.0
    return np.asarray(np.maximum(sd, SD_FLOOR_FRACTION * rms), dtype=float)


#: No fixed block of the Gram matrix (:func:`fieldbank.fitting.kernels.solve_normal`).
_NO_GRAM = np.zeros((0, 0))

#: Central-difference steps of the search's gradient (q_rest, rad; slack, m; β: H_BETA).
_H_Q = 1e-6
_H_SLACK = 1e-7


@dataclass(frozen=True)
class Projection:
    """Result of the inner (linear) solve at fixed nonlinear parameters."""

    cost: float
    theta: FloatArray  # full parameter vector
    r: FloatArray  # whitened data residuals, shape (M,)


@dataclass(eq=False)
class FitProblem:
    """Precomputed measurement geometry and the fast cost (see module docstring).

    Attributes
    ----------
    arm : Arm
        The base model (segment lengths, moment arms, λ̇_max are not fitted).
    space : ParamSpace
    y : ndarray, shape (M,)
        Measured values, arm-on-handle, flattened map by map (F: x, y; K: xx, xy, yx, yy).
    sd : ndarray, shape (M,)
        Their standard deviations.
    map_rows : list of slice
        Rows of each map.
    """

    arm: Arm
    space: ParamSpace
    y: FloatArray
    sd: FloatArray
    map_rows: list[slice]
    row_pt: np.ndarray
    cf: FloatArray
    cl: FloatArray
    cd: FloatArray
    lq: FloatArray  # J_λ q per point, (N, 6)
    lam_above_min: FloatArray  # λ - λ_min per point (independent of q_rest), (N, 6)
    corner_max: FloatArray  # max over the range-of-motion corners of J_λ q, (6,)
    c: FloatArray  # clip(λ̇/λ̇_max, 0, 1), (N, 6)
    dc: FloatArray  # ∂c/∂λ̇ with the model's kink convention, (N, 6)
    n_evals: int = 0
    _xkm_cache: FloatArray | None = None
    #: Evaluate with the compiled kernels (:mod:`fieldbank.fitting.kernels`); False: the numpy
    #: reference path (:mod:`fieldbank.fitting.reference`).
    compiled: bool = field(default_factory=lambda: not reference.active())
    _consts: dict[str, Any] | None = field(default=None, init=False, repr=False)
    _beta: BetaPath | None = field(default=None, init=False, repr=False)

    # --- construction ---------------------------------------------------------------------
    @classmethod
    def from_maps(cls, maps: list[FieldMap], arm: Arm, space: ParamSpace) -> FitProblem:
        """Precompute for validated, arm-on-handle maps in the shoulder frame."""
        mirror = np.array([-1.0, 1.0]) if arm.mirror else np.array([1.0, 1.0])
        ys, sds, rows, pts_rows = [], [], [], []
        cfs, cls_, cds = [], [], []
        lqs, ldots, qs = [], [], []
        start = 0
        n_pts = 0
        jl = arm.jl
        for m in maps:
            vm = np.asarray(m.velocity_m_per_s) * mirror
            q = arm.ik(m.positions_m)
            jac = arm.jacobian(q)
            jinv = np.linalg.inv(jac)
            qdot = jinv @ vm
            n = m.n
            # A[n, c, i]: force component c per unit tension of muscle i
            a_mat = -np.einsum("nij,ki->njk", jinv, jl)
            values = m.values.reshape(n, -1)
            sd = map_sd(m)
            if m.kind == "postural":
                out = mirror  # component sign back to the user's frame
                cf = a_mat * out[None, :, None]
                cl = np.zeros_like(cf)
                cd = np.zeros_like(cf)
            else:
                q1, q12 = q[:, 0], q[:, 0] + q[:, 1]
                s1, c1, s12, c12 = np.sin(q1), np.cos(q1), np.sin(q12), np.cos(q12)
                l1, l2 = arm.l1, arm.l2
                dj = np.empty((n, 2, 2, 2))  # [n, k, i, j] = ∂J_ij/∂q_k
                dj[:, 0, 0, 0] = -l1 * c1 - l2 * c12
                dj[:, 0, 0, 1] = -l2 * c12
                dj[:, 0, 1, 0] = -l1 * s1 - l2 * s12
                dj[:, 0, 1, 1] = -l2 * s12
                dj[:, 1, 0, 0] = -l2 * c12
                dj[:, 1, 0, 1] = -l2 * c12
                dj[:, 1, 1, 0] = -l2 * s12
                dj[:, 1, 1, 1] = -l2 * s12
                djq = np.einsum("nkij,nj->nik", dj, qdot)
                qmat = -np.einsum("nij,njk->nik", jinv, djq)
                jinv_t = np.transpose(jinv, (0, 2, 1))
                outer = np.einsum("ki,kj->kij", jl, jl)  # J_λ,iᵀ J_λ,i per muscle, (6, 2, 2)
                m1 = np.einsum("nab,kbc,ncd->nkad", jinv_t, outer, jinv)
                m2 = np.einsum("nab,kbc,nce,ned->nkad", jinv_t, outer, qmat, jinv)
                g = np.einsum("nkji,njm->nmik", dj, a_mat)  # G(A_m), (n, 6, 2, 2)
                m3 = np.einsum("nab,nmbc,ncd->nmad", jinv_t, g, jinv)
                sgn = np.outer(mirror, mirror)  # D K D for a mirrored arm
                cf = (m3 * sgn).reshape(n, 6, 4).transpose(0, 2, 1)
                cl = (m1 * sgn).reshape(n, 6, 4).transpose(0, 2, 1)
                cd = (m2 * sgn).reshape(n, 6, 4).transpose(0, 2, 1)
            k = values.shape[1]
            ys.append(values.ravel())
            sds.append(sd.ravel())
            cfs.append(cf.reshape(n * k, 6))
            cls_.append(cl.reshape(n * k, 6))
            cds.append(cd.reshape(n * k, 6))
            pts_rows.append(np.repeat(np.arange(n) + n_pts, k))
            rows.append(slice(start, start + n * k))
            start += n * k
            n_pts += n
            qs.append(q)
            lqs.append(q @ jl.T)
            ldots.append(qdot @ jl.T)
        p = arm.params
        corners = np.array([[a, b] for a in p.shoulder_range_rad for b in p.elbow_range_rad])
        lc = corners @ jl.T
        lq = np.vstack(lqs)
        ldot = np.vstack(ldots)
        r = ldot / arm.ldot_max
        c = np.clip(r, 0.0, 1.0)
        dc = np.where((r > 0) & (r < 1), 1.0, 0.0)
        dc = np.where((r == 0) | (r == 1), 0.5, dc) / arm.ldot_max
        return cls(
            arm=arm,
            space=space,
            y=np.concatenate(ys),
            sd=np.concatenate(sds),
            map_rows=rows,
            row_pt=np.concatenate(pts_rows),
            cf=np.vstack(cfs),
            cl=np.vstack(cls_),
            cd=np.vstack(cds),
            lq=lq,
            lam_above_min=lq - lc.min(axis=0),
            corner_max=lc.max(axis=0),
            c=c,
            dc=dc,
        )

    # --- the model, linear in Km and α -------------------------------------------------------
    @property
    def w(self) -> FloatArray:
        return 1.0 / self.sd

    def _passive_basis(self, q_rest: FloatArray, slack: FloatArray) -> FloatArray:
        arm = self.arm
        d = self.lq - q_rest @ arm.jl.T - slack
        wd = arm.w
        z = d / wd
        soft = np.logaddexp(0.0, z)
        sp = wd * soft
        sig = np.exp(z - soft)  # the logistic function, as in fieldbank.model
        ell = arm.excursion
        g = np.exp(-((d / ell) ** 2))
        pb = (sp * g)[self.row_pt]
        pdb = (g * (sig - sp * 2.0 * d / (ell * ell)))[self.row_pt]
        return self.cf * pb + self.cl * pdb

    def kk(self, q_rest: FloatArray) -> FloatArray:
        """λ_rest/λ_max per group at the rest posture ``q_rest``, (6,)."""
        arm = self.arm
        lam_max = arm.lam_rest + self.corner_max - q_rest @ arm.jl.T
        return np.asarray(arm.lam_rest / lam_max, dtype=float)

    def _reflex_basis(self, beta: FloatArray, q_rest: FloatArray) -> FloatArray:
        if self.compiled:
            out = np.empty((self.row_pt.size, 6))
            self._reflex_into(beta, q_rest, out, 0)
            return out
        return reference.reflex_basis(self, beta, q_rest)

    def _reflex_into(self, beta: FloatArray, q_rest: FloatArray, out: FloatArray,
                     col0: int) -> None:
        """The compiled reflex columns for ``beta`` into ``out[:, col0:col0 + 6]``."""
        k = self.consts()
        kk = k["kk"] if not self.space.fit_q_rest else self.kk(q_rest)
        reflex_columns = kernels.load()["reflex_columns"]
        reflex_columns(np.ascontiguousarray(beta, dtype=float), kk, self.lam_above_min,
                       k["ell"], self.c, self.dc, k["row_pt"], self.cf, self.cl, self.cd,
                       k["still"], k["gam0"], k["e0"], out, col0)

    def consts(self) -> dict[str, Any]:
        """What the compiled kernels read that does not change during a fit (built once):
        among it, what the reflex columns do not recompute where a muscle does not lengthen
        (:func:`fieldbank.fitting.kernels.still_terms`; nothing when q_rest is fitted)."""
        if self._consts is None:
            s = self.space
            free = s.fitted[:12]
            pw = s.prior_weight
            kk = self.kk(np.asarray(self.arm.q_rest, dtype=float))
            still = np.zeros(self.c.shape, dtype=np.bool_)
            gam0 = np.zeros(self.c.shape)
            e0 = np.zeros(self.c.shape)
            if not s.fit_q_rest:
                kernels.load()["still_terms"](kk, self.lam_above_min,
                                              np.ascontiguousarray(self.arm.excursion,
                                                                   dtype=float),
                                              self.c, still, gam0, e0)
            self._consts = {
                "still": still, "gam0": gam0, "e0": e0,
                "kk": kk,
                "ell": np.ascontiguousarray(self.arm.excursion, dtype=float),
                "row_pt": np.ascontiguousarray(self.row_pt, dtype=np.int64),
                "w": np.ascontiguousarray(1.0 / self.sd),
                "y": np.ascontiguousarray(self.y, dtype=float),
                "free": np.flatnonzero(free).astype(np.int64),
                "mu": np.ascontiguousarray(s.prior_mean[:12][free]),
                "sdp": np.ascontiguousarray(s.prior_sd[:12][free]),
                "lo": np.ascontiguousarray(s.lower[:12][free]),
                "hi": np.ascontiguousarray(s.upper[:12][free]),
                "nl": np.array([i for i in range(12, s.size) if s.fitted[i]], dtype=int),
                "beta_fitted": np.array([i - 12 for i in range(12, 18) if s.fitted[i]],
                                        dtype=np.int64),
                "pw": np.array(pw),
                "b_lo": np.ascontiguousarray(s.lower[12:18]),
                "b_hi": np.ascontiguousarray(s.upper[12:18]),
            }
        return self._consts

    def passive_columns(self) -> FloatArray:
        """The passive (Km) columns of the design matrix at the base model's rest posture and
        slack offsets, (M, 6): fixed during a fit over β alone (computed once)."""
        if self._xkm_cache is None:
            self._xkm_cache = self._passive_basis(np.asarray(self.arm.q_rest, dtype=float),
                                                  self.base_slack)
        return self._xkm_cache

    def _beta_path(self) -> BetaPath:
        """The compiled evaluation over β alone with what stays fixed kept (built once)."""
        if self._beta is None:
            self._beta = BetaPath.of(self)
        return self._beta

    def design(self, beta: FloatArray, q_rest: FloatArray,
               slack: FloatArray | None = None) -> FloatArray:
        """X(β, q_rest, δ), shape (M, 12): predicted values per unit Km (cols 0-5) and α
        (6-11); δ the slack offsets (default: the base model's)."""
        varies = self.space.fit_q_rest or self.space.fit_slack
        if varies or self._xkm_cache is None:
            xkm = self._passive_basis(q_rest, self.base_slack if slack is None else slack)
            if not varies:
                self._xkm_cache = xkm
        else:
            xkm = self._xkm_cache
        if self.compiled:
            x = np.empty((self.row_pt.size, 12))
            x[:, :6] = xkm
            self._reflex_into(beta, q_rest, x, 6)
            return x
        return np.hstack([xkm, self._reflex_basis(beta, q_rest)])

    # --- parameter vector helpers -------------------------------------------------------------
    @property
    def base_slack(self) -> FloatArray:
        """The base model's slack offsets (6,), m: held when the slack is not fitted."""
        return np.asarray(self.arm.lam_slack - self.arm.lam_rest, dtype=float)

    def split(self, theta: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """(θ_lin = [Km; α] (12,), β (6,), q_rest (2,), slack offsets (6,)) from a full
        vector."""
        s = self.space
        q_rest = theta[18:20] if s.fit_q_rest else self.arm.q_rest
        if s.fit_slack:
            k = 20 if s.fit_q_rest else 18
            slack = np.asarray(theta[k:k + 6], dtype=float)
        else:
            slack = self.base_slack
        return theta[:12], theta[12:18], np.asarray(q_rest, dtype=float), slack

    def predict(self, theta: FloatArray) -> FloatArray:
        """Predicted values, shape (M,), for a full parameter vector."""
        lin, beta, q_rest, slack = self.split(theta)
        return self.design(beta, q_rest, slack) @ lin

    def residuals(self, theta: FloatArray) -> FloatArray:
        """Whitened data residuals (y - ŷ)/sd, shape (M,)."""
        return (self.y - self.predict(theta)) / self.sd

    def prior_cost(self, theta: FloatArray) -> float:
        s = self.space
        z = ((theta - s.prior_mean) / s.prior_sd)[s.fitted]
        return float(s.prior_weight * (z @ z))

    def cost(self, theta: FloatArray) -> float:
        """Data χ² plus prior for a full parameter vector (the objective of every algorithm)."""
        self.n_evals += 1
        r = self.residuals(theta)
        return float(r @ r) + self.prior_cost(theta)

    # --- variable projection -------------------------------------------------------------------
    def nonlinear_index(self) -> np.ndarray:
        """Indices (into the full vector) of the fitted nonlinear parameters."""
        if self.compiled:
            return self.consts()["nl"]
        s = self.space
        return np.array([i for i in range(12, s.size) if s.fitted[i]], dtype=int)

    def full_from_nonlinear(self, phi: FloatArray) -> FloatArray:
        theta = self.space.base.copy()
        theta[self.nonlinear_index()] = phi
        return theta

    def project(self, theta_nl: FloatArray, x: FloatArray | None = None) -> Projection:
        """Best Km and α for the nonlinear entries of ``theta_nl`` (full vector; linear part
        ignored except where not fitted)."""
        if self.compiled:
            return self._project_compiled(theta_nl, x)
        self.n_evals += 1
        theta, r = reference.project(self, theta_nl, x)
        return Projection(float(r @ r) + self.prior_cost(theta), theta, r)

    def _project_compiled(self, theta_nl: FloatArray, x: FloatArray | None) -> Projection:
        """:meth:`project` with the design and the normal equations compiled
        (:func:`fieldbank.fitting.kernels.solve_normal`); the bounded fallback as before."""
        s = self.space
        self.n_evals += 1
        if x is None and not (s.fit_q_rest or s.fit_slack):
            # only β varies: the design and the solve in one compiled call
            return Projection(*self._beta_path().project(theta_nl))
        k = self.consts()
        theta = np.array(theta_nl, dtype=float)
        lin = theta[:12]  # a view: the solve writes the fitted Km and α into theta
        free = k["free"]
        m = self.row_pt.size
        a = np.empty((m, free.size))
        rhs = np.empty(m)
        r = np.empty(m)
        pw = float(k["pw"])
        if x is None:
            _, beta, q_rest, slack = self.split(theta)
            x = self.design(beta, q_rest, slack)
        ok = kernels.load()["solve_normal"](np.ascontiguousarray(x), k["y"], k["w"], free, lin,
                                            pw, k["mu"], k["sdp"], k["lo"], k["hi"], a, rhs, r,
                                            _NO_GRAM, 0)
        if not ok:
            sol = reference.bounded_solve(a, rhs, pw, k["mu"], k["sdp"], k["lo"], k["hi"])
            lin[free] = sol
            r = rhs - a @ sol
        return Projection(float(r @ r) + self.prior_cost(theta), theta, r)

    def design_derivatives(self, theta: FloatArray,
                           step: float | None = None) -> dict[int, FloatArray]:
        """∂X/∂θ_k for each fitted nonlinear entry k (central differences inside the bounds).

        ``step`` replaces the default steps (1e-6 in β and in q_rest, rad; 1e-7 m in the slack
        offsets): a larger step gives the secant slope over that range, which the uncertainty
        estimate compares with the local one to find kinks and jumps of the model
        (:mod:`fieldbank.fitting.uncertainty`); the slack's secant step is a tenth of it (m:
        1e-3 in β is 1e-4 m = 0.1 mm of slack).
        """
        s = self.space
        _, beta, q_rest, slack = self.split(theta)
        h_beta = H_BETA if step is None else step
        h_q = _H_Q if step is None else step
        h_d = _H_SLACK if step is None else 0.1 * step
        out: dict[int, FloatArray] = {}
        bidx = [i for i in range(12, 18) if s.fitted[i]]
        if bidx:
            bp = np.minimum(beta + h_beta, s.upper[12:18])
            bm = np.maximum(beta - h_beta, s.lower[12:18])
            diff = (self._reflex_basis(bp, q_rest) - self._reflex_basis(bm, q_rest)) / (bp - bm)
            for i in bidx:
                col = np.zeros((self.y.size, 12))
                col[:, 6 + i - 12] = diff[:, i - 12]
                out[i] = col
        if s.fit_q_rest:
            for j in range(2):
                k = 18 + j
                if not s.fitted[k]:
                    continue
                qp = q_rest.copy()
                qm = q_rest.copy()
                qp[j] = min(q_rest[j] + h_q, s.upper[k])
                qm[j] = max(q_rest[j] - h_q, s.lower[k])
                xp = np.hstack([self._passive_basis(qp, slack), self._reflex_basis(beta, qp)])
                xm = np.hstack([self._passive_basis(qm, slack), self._reflex_basis(beta, qm)])
                out[k] = (xp - xm) / (qp[j] - qm[j])
        if s.fit_slack:
            first = 20 if s.fit_q_rest else 18
            sidx = [k for k in range(first, first + 6) if s.fitted[k]]
            if sidx:
                lo, hi = s.lower[first:first + 6], s.upper[first:first + 6]
                dp = np.minimum(slack + h_d, hi)
                dm = np.maximum(slack - h_d, lo)
                diff = (self._passive_basis(q_rest, dp) - self._passive_basis(q_rest, dm)) \
                    / (dp - dm)
                for k in sidx:
                    col = np.zeros((self.y.size, 12))
                    col[:, k - first] = diff[:, k - first]
                    out[k] = col
        return out

    def projected_cost_grad(self, phi: FloatArray) -> tuple[float, FloatArray, Projection]:
        """Projected cost and its gradient over the fitted nonlinear entries."""
        if self.compiled and not (self.space.fit_q_rest or self.space.fit_slack):
            return self._projected_cost_grad_compiled(phi)
        theta = self.full_from_nonlinear(phi)
        pr = self.project(theta)
        idx = self.nonlinear_index()
        grad = np.empty(idx.size)
        derivs = self.design_derivatives(pr.theta)
        w = self.w
        s = self.space
        lin = pr.theta[:12]
        for n, k in enumerate(idx):
            dy = derivs[k] @ lin
            grad[n] = -2.0 * float(pr.r @ (dy * w))
            grad[n] += 2.0 * s.prior_weight * (pr.theta[k] - s.prior_mean[k]) / s.prior_sd[k] ** 2
        return pr.cost, grad, pr

    def _projected_cost_grad_compiled(self, phi: FloatArray
                                      ) -> tuple[float, FloatArray, Projection]:
        """:meth:`projected_cost_grad` over β alone: the projection and the derivative
        columns in one compiled call (:meth:`BetaPath.cost_grad`)."""
        self.n_evals += 1
        cost, theta, r, grad = self._beta_path().cost_grad(phi)
        return cost, grad, Projection(cost, theta, r)

    def jacobian(self, theta: FloatArray, step: float | None = None) -> FloatArray:
        """∂r/∂θ of the whitened data residuals, shape (M, P) (zero columns where not fitted).

        ``step``: the difference step of the nonlinear entries (:meth:`design_derivatives`).
        """
        lin, beta, q_rest, slack = self.split(theta)
        x = self.design(beta, q_rest, slack)
        w = self.w
        jac = np.zeros((self.y.size, self.space.size))
        jac[:, :12] = -x * w[:, None]
        for k, dx in self.design_derivatives(theta, step).items():
            jac[:, k] = -(dx @ lin) * w
        jac[:, ~self.space.fitted] = 0.0
        return jac

