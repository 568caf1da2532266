"""How sure a fit is: parameter uncertainty that cannot collapse below what the data support.

The problem
-----------
The Gauss–Newton (Laplace) covariance s²·(JᵀJ + prior)⁻¹ is right when the cost is close to
quadratic around the optimum. This model's is often not: the stretch reflex φ = max(0, ·) and
the clip of λ̇/λ̇_max make the predicted stiffness jump when the reflex starts or stops firing
at a measured point, so a derivative taken across such a jump is enormous, and a β that sits
on one reads as pinned to 1e-8. Inverting that information with a pseudo-inverse then also
zeroes every direction below its cut-off, so Km and α "collapse" with it (about one fit in seven
reported SDs ~1e-8 on parameters 25–450% wrong). A parameter at a bound (α = 0, β = 0 or 1) is
the other case a Gaussian cannot describe.

The choice: Gauss–Newton where it holds, a parametric bootstrap where it does not
-------------------------------------------------------------------------------------
1. **Gauss–Newton, computed so it cannot collapse**: the information is inverted exactly in
   prior-SD units (eigen-decomposition of a positive definite matrix: the prior makes it so; no
   pseudo-inverse cut-off), the nonlinear columns are secant slopes over :data:`STEP_SECANT`
   (a step the data can resolve, not 1e-6), and the residual scale is s² = max(1, χ²/(M − p_eff))
   so a fit that scatters more than its stated sd widens its intervals while one that scatters
   less never narrows them.
2. **Is it valid?** It is not when a nonlinear column changes with the step (the local slope
   and the secant slope differ by more than :data:`KINK_TOLERANCE`: a kink or a jump of the
   model at the optimum), or when an identified parameter lies within :data:`BOUND_SDS` SDs of
   a bound (the Gaussian would cross it).
3. **Parametric bootstrap** then (``method='auto'``; or always with ``'bootstrap'``): the
   fitted model's predictions plus Gaussian noise of the measurement sd (× s) make
   :data:`~fieldbank.fitchoices.DEFAULT_REPLICATES` new data sets; each is refitted with the
   fit's own cost and the
   same held parameters, from the fitted point - β (and q_rest) by a bounded local search, a
   coarse grid scan of each coordinate (:data:`REFIT_SWEEP_POINTS`: the reflex's flat regions
   hide steps from local searches) and a last polish; Km and α by the bounded linear solve of
   the variable projection. Kinks and bounds need no special case: the replicates land where
   the refit lands. A replicate costs a few hundred projected evaluations (≈ 20–40 ms at
   25 + 9 positions), the whole bootstrap ≈ 1 s. A profile likelihood was the alternative; it
   needs a constrained refit per parameter and interval end (≈ 36 refits for 18 parameters,
   each as costly as a replicate) and gives no joint samples, which the what-if needs to carry
   the uncertainty into its predictions.
4. **Floor**: no SD is reported below the *conditional* SD - how far the parameter alone can
   move before the cost rises by s² (exact for Km and α, which enter linearly; a scan for β and
   q_rest). The marginal SD can only be larger, so this never claims more than the data hold.
5. **Intervals**: θ̂ ± 1.96 SD, clipped to the bounds; with the bootstrap widened to contain the
   replicates' 2.5–97.5 percentiles (asymmetric near a bound).

Parameters held at the unimpaired value (not identified, :class:`~fieldbank.fitting.ArmFitter`)
get the interval of their stated prior range (basis 'prior', :mod:`fieldbank.fitting.prior`:
unimpaired to the top of the severity scale's severe band, as far as the maps allow): the
data say nothing more about them. The stored samples keep them at the held value, so the
samples of what the maps identified stay as they are; prediction intervals draw the held
parameters from their range (:func:`fieldbank.fitting.prior.draw`), so a prediction that
rests on a guess is as wide as the guess.

Samples: the bootstrap's replicates, or (Gauss–Newton) as many draws from the Gaussian, clipped
to the bounds. They travel with the fit (:meth:`Uncertainty.to_dict`) so a what-if can apply its
plan to each and report intervals of the predicted metrics.

``tests/test_fitting_uncertainty.py`` checks coverage on 50 seeded synthetic patients and the
floor; ``benchmarks/bench_fit.py`` prints the cost per fit.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from fieldbank.errors import FitError
from fieldbank.fitchoices import DEFAULT_REPLICATES, DEFAULT_UNCERTAINTY, UNCERTAINTY_METHODS
from fieldbank.fitting.problem import FitProblem
from fieldbank.fitting.search import nlopt_run
from fieldbank.fitting.space import PARAM_FIELD
from fieldbank.model import FloatArray
from fieldbank.params import GROUP_INDEX, ArmParams

#: Two-sided 95% normal quantile.
Z95 = 1.959963984540054
#: Secant step of the nonlinear parameters (β dimensionless, q_rest rad).
STEP_SECANT = 1e-3
#: Local and secant slopes differing by more than this (relative, plus one unit of whitened
#: residual) mark a kink or jump of the model at the optimum.
KINK_TOLERANCE = 0.1
#: An identified parameter closer than this many SDs to a bound makes the Gaussian invalid.
BOUND_SDS = 2.0
#: Refit of a replicate: local-search budget and the grid of the coordinate scan.
REFIT_LOCAL_EVALS = 60
REFIT_SWEEP_POINTS = 11
#: Scan of a nonlinear parameter's conditional SD: halvings of the distance to the bound.
FLOOR_HALVINGS = 24


@dataclass(frozen=True)
class ParameterUncertainty:
    """One fitted parameter: value, SD and 95% interval (SI units), and what they rest on.

    ``basis``: 'gauss-newton', 'bootstrap', 'conditional' (the floor set the SD) or 'prior'
    (held at the unimpaired value: not identified).
    """

    name: str
    value: float
    sd: float
    low: float
    high: float
    basis: str

    def to_dict(self) -> dict[str, Any]:
        return {"value": self.value, "sd": self.sd, "low": self.low, "high": self.high,
                "basis": self.basis}


@dataclass(frozen=True, eq=False)
class Uncertainty:
    """The uncertainty of a fit (module docstring).

    Attributes
    ----------
    method : str
        'gauss-newton' or 'bootstrap' (what ran).
    reasons : tuple of str
        Why the Gauss–Newton covariance was not used (empty when it was).
    parameters : tuple of ParameterUncertainty
        Every fitted parameter, in the fit's order.
    names : tuple of str
        The columns of ``samples`` (the fitted parameters).
    samples : ndarray, shape (B, len(names))
        Bootstrap replicates or Gaussian draws, SI units.
    residual_scale : float
        s = √max(1, χ²/(M − p_eff)): the factor on the measurement sd.
    n_evals : int
        Cost evaluations spent (bootstrap refits and scans).
    time_s : float
    """

    method: str
    reasons: tuple[str, ...]
    parameters: tuple[ParameterUncertainty, ...]
    names: tuple[str, ...]
    samples: FloatArray
    residual_scale: float
    n_evals: int
    time_s: float

    def sd(self) -> dict[str, float]:
        return {p.name: p.sd for p in self.parameters}

    def intervals(self) -> dict[str, dict[str, Any]]:
        return {p.name: p.to_dict() for p in self.parameters}

    def summary(self) -> dict[str, Any]:
        """How the uncertainty was obtained (without the numbers per parameter)."""
        return {"method": self.method, "reasons": list(self.reasons),
                "replicates": int(self.samples.shape[0]),
                "residual_scale": self.residual_scale, "n_evals": self.n_evals,
                "time_s": self.time_s, "level": 0.95}

    def samples_dict(self) -> dict[str, Any]:
        """The samples as stored with the fit: names and rows (6 significant digits)."""
        return {"names": list(self.names),
                "values": [[float(f"{v:.6g}") for v in row] for row in self.samples]}


@dataclass(frozen=True, eq=False)
class FitSamples:
    """Parameter samples of a stored fit, read back from its report (for what-ifs)."""

    names: tuple[str, ...]
    values: FloatArray  # (B, len(names))

    @classmethod
    def from_report(cls, report: Mapping[str, Any] | None) -> FitSamples | None:
        """The samples of a fit report, or None when it has none (older fits)."""
        doc = (report or {}).get("samples")
        if not isinstance(doc, Mapping):
            return None
        names = doc.get("names")
        values = doc.get("values")
        if not isinstance(names, list) or not isinstance(values, list) or not values:
            return None
        arr = np.asarray(values, dtype=float)
        if arr.ndim != 2 or arr.shape[1] != len(names) or not np.all(np.isfinite(arr)):
            return None
        return cls(tuple(str(n) for n in names), arr)

    def arrays(self, base: ArmParams, limit: int | None = None) -> dict[str, FloatArray]:
        """The samples (the first ``limit``) as arrays of the ArmParams fields they change,
        the others' entries as in ``base`` (the fitted model): {field: (S, 6) or (S, 2)}."""
        rows = self.values if limit is None else self.values[:limit]
        out: dict[str, FloatArray] = {}
        for k, name in enumerate(self.names):
            kind, _, which = name.rpartition("_")
            if name.startswith("q_rest_"):
                attr, col = "q_rest_rad", 0 if which == "shoulder" else 1
            elif kind in PARAM_FIELD and which in GROUP_INDEX:
                attr, col = PARAM_FIELD[kind], GROUP_INDEX[which]
            else:
                raise FitError(f"fit samples: unknown parameter {name!r}.")
            if attr not in out:
                out[attr] = np.tile(np.asarray(getattr(base, attr), dtype=float),
                                    (rows.shape[0], 1))
            out[attr][:, col] = rows[:, k]
        return out

    def params(self, base: ArmParams, limit: int | None = None) -> list[ArmParams]:
        """Each sample (the first ``limit``) written into ``base`` (the fitted model)."""
        arrays = self.arrays(base, limit)
        size = (self.values if limit is None else self.values[:limit]).shape[0]
        return [base.replace(**{f: tuple(a[k].tolist()) for f, a in arrays.items()})
                for k in range(size)]


def reduced_problem(problem: FitProblem, theta: FloatArray,
                    held: Collection[str] = ()) -> FitProblem:
    """``problem`` with the ``held`` parameters fixed at their values in ``theta``."""
    s = problem.space
    fitted = s.fitted.copy()
    for name in held:
        fitted[s.names.index(name)] = False
    space = dataclasses.replace(s, fitted=fitted, base=np.array(theta, dtype=float))
    return dataclasses.replace(problem, space=space, n_evals=0, _xkm_cache=None)


def _information(problem: FitProblem, theta: FloatArray, fit: np.ndarray,
                 step: float | None) -> tuple[FloatArray, FloatArray]:
    jac = problem.jacobian(theta, step)[:, fit]
    s = problem.space
    h = jac.T @ jac + np.diag(s.prior_weight / s.prior_sd[fit] ** 2)
    return jac, h


def spd_inverse(h: FloatArray, scale: FloatArray) -> FloatArray:
    """Inverse of a symmetric positive (semi-)definite ``h``, computed in the units ``scale``.

    No cut-off to zero (a pseudo-inverse's): with the prior ``h`` is positive definite and is
    inverted exactly (Cholesky); only when it is singular (prior weight 0 and a direction the
    data leave open) are its eigenvalues floored at 1e-15 of the largest, so that direction
    gets a huge variance, never a zero one.
    """
    hw = h * np.outer(scale, scale)
    hw = 0.5 * (hw + hw.T)
    try:
        c = np.linalg.cholesky(hw)
        ci = np.linalg.solve(c, np.eye(hw.shape[0]))
        return np.asarray(ci.T @ ci * np.outer(scale, scale), dtype=float)
    except np.linalg.LinAlgError:
        pass
    w, v = np.linalg.eigh(hw)
    w = np.maximum(w, 1e-15 * max(float(w.max()), np.finfo(float).tiny))
    return np.asarray((v / w) @ v.T * np.outer(scale, scale), dtype=float)


def _kinks(problem: FitProblem, theta: FloatArray, fit: np.ndarray,
           j_secant: FloatArray) -> list[str]:
    """Nonlinear parameters whose local slope differs from the secant slope."""
    s = problem.space
    j_local = problem.jacobian(theta)[:, fit]
    out = []
    for a, k in enumerate(fit):
        if k < 12:
            continue
        diff = float(np.linalg.norm(j_local[:, a] - j_secant[:, a]))
        size = float(np.linalg.norm(j_secant[:, a]))
        if diff > KINK_TOLERANCE * size + 1.0:
            out.append(s.names[k])
    return out


def _conditional_sd(problem: FitProblem, theta: FloatArray, fit: np.ndarray, h: FloatArray,
                    s2: float) -> tuple[FloatArray, int]:
    """How far each parameter alone moves before the cost rises by s² (its conditional SD)."""
    s = problem.space
    out = np.zeros(fit.size)
    n_evals = 0
    base = problem.cost(theta)
    for a, k in enumerate(fit):
        if k < 12:  # Km, α: linear, the cost is exactly quadratic in them
            out[a] = math.sqrt(s2 / max(float(h[a, a]), np.finfo(float).tiny))
            continue
        # each side: the largest of room, room/2, room/4, ... at which the cost stays within
        # s² (a lower bound, within a factor 2, of the conditional half-width on that side)
        widths = []
        for bound in (s.lower[k], s.upper[k]):
            d = float(bound - theta[k])
            width = 0.0
            for _ in range(FLOOR_HALVINGS):
                if abs(d) < 1e-12:
                    break
                t = theta.copy()
                t[k] += d
                n_evals += 1
                if problem.cost(t) - base < s2:
                    width = abs(d)
                    break
                d *= 0.5
            widths.append(width)
        out[a] = 0.5 * (widths[0] + widths[1])
    return out, n_evals


def refit_local(problem: FitProblem, y: FloatArray, theta0: FloatArray,
                seed: int = 0) -> tuple[FloatArray, int]:
    """Refit ``problem``'s fitted parameters to data ``y`` from ``theta0`` (see module doc)."""
    import nlopt  # only when a bootstrap runs (start-up time of everything that imports fits)

    q = dataclasses.replace(problem, y=np.asarray(y, dtype=float), n_evals=0)
    idx = q.nonlinear_index()
    if idx.size == 0:
        pr = q.project(theta0)
        return pr.theta, q.n_evals
    lo = q.space.lower[idx]
    hi = q.space.upper[idx]
    best_cost = [math.inf]
    best_x = [np.array(theta0[idx], dtype=float)]

    def f(x: FloatArray, grad: FloatArray) -> float:
        if grad.size:
            c, g, _ = q.projected_cost_grad(x)
            grad[:] = g
        else:
            c = q.project(q.full_from_nonlinear(x)).cost
        if c < best_cost[0]:
            best_cost[0] = c
            best_x[0] = np.array(x, dtype=float)
        return c

    empty = np.empty(0)
    f(np.clip(theta0[idx], lo, hi), empty)
    nlopt_run(nlopt.LD_LBFGS, None, f, best_x[0], lo, hi, REFIT_LOCAL_EVALS, seed)
    before = best_cost[0]
    for k in range(idx.size):
        start = best_x[0].copy()
        for v in np.linspace(lo[k], hi[k], REFIT_SWEEP_POINTS):
            x = start.copy()
            x[k] = v
            f(x, empty)
    if best_cost[0] < before - 1e-9 * max(1.0, abs(before)):
        nlopt_run(nlopt.LD_LBFGS, None, f, best_x[0], lo, hi, REFIT_LOCAL_EVALS, seed)
    pr = q.project(q.full_from_nonlinear(best_x[0]))
    return pr.theta, q.n_evals


def estimate(problem: FitProblem, theta: FloatArray, held: Collection[str] = (), *,
             unidentified: Collection[str] = (), method: str = DEFAULT_UNCERTAINTY,
             n_replicates: int = DEFAULT_REPLICATES, seed: int = 0,
             held_intervals: Mapping[str, tuple[float, float, float]] | None = None
             ) -> Uncertainty:
    """The uncertainty of the fit ``theta`` of ``problem`` (see the module docstring).

    Parameters
    ----------
    problem : FitProblem
        The fit's problem (every fitted parameter free).
    theta : ndarray, shape (P,)
        The fitted parameter vector.
    held : collection of str
        Parameters held at their (unimpaired) value in ``theta``.
    unidentified : collection of str
        Parameters the maps do not identify (ignored by the bound check).
    method : str
        'auto', 'gauss-newton' or 'bootstrap'.
    n_replicates : int
        Bootstrap replicates, and Gaussian draws kept as samples.
    seed : int
        Seeds the replicates' noise.
    held_intervals : mapping, optional
        (sd, low, high) of held parameters over their stated prior range
        (:mod:`fieldbank.fitting.prior`); a held parameter not in it gets the fit's prior SD
        and ±1.96 SD.
    """
    if method not in UNCERTAINTY_METHODS:
        raise FitError(f"unknown uncertainty method {method!r}; choose one of "
                       f"{', '.join(UNCERTAINTY_METHODS)}.")
    if isinstance(n_replicates, bool) or not isinstance(n_replicates, int) or n_replicates < 2:
        raise FitError(f"replicates must be an integer >= 2; got {n_replicates!r}.")
    t0 = time.perf_counter()
    theta = np.array(theta, dtype=float)
    red = reduced_problem(problem, theta, held)
    s = red.space
    fit = np.flatnonzero(s.fitted)
    names = tuple(s.names[k] for k in fit)
    r = red.residuals(theta)
    jac, h = _information(red, theta, fit, STEP_SECANT)
    cov1 = spd_inverse(h, s.prior_sd[fit])
    p_eff = float(np.trace(jac.T @ jac @ cov1))
    m = r.size
    s2 = max(1.0, float(r @ r) / (m - p_eff)) if m > p_eff + 1.0 else 1.0
    cov = cov1 * s2
    sd_gn = np.sqrt(np.maximum(np.diag(cov), 0.0))
    floor, n_evals = _conditional_sd(red, theta, fit, h, s2)

    reasons = []
    kinks = _kinks(red, theta, fit, jac)
    if kinks:
        reasons.append("the model has a kink or jump at the fitted value of "
                       + ", ".join(kinks) + " (the stretch reflex starts or stops firing at a "
                       "measured point)")
    skip = set(unidentified)
    near = []
    for a, k in enumerate(fit):
        lower, upper = float(s.lower[k]), float(s.upper[k])
        bound = lower if theta[k] - lower <= upper - theta[k] else upper
        if s.names[k] not in skip and abs(theta[k] - bound) < BOUND_SDS * max(sd_gn[a],
                                                                             floor[a]):
            near.append(f"{s.names[k]} = {theta[k]:.3g} (bound {bound:.3g})")
    if near:
        reasons.append("within 2 SD of a bound: " + ", ".join(near))
    use_boot = method == "bootstrap" or (method == "auto" and bool(reasons))
    if method == "bootstrap" and not reasons:
        reasons.append("bootstrap requested")
    lo_b, hi_b = s.lower[fit], s.upper[fit]
    rng = np.random.default_rng(seed)
    if use_boot:
        yhat = red.predict(theta)
        noise = red.sd * math.sqrt(s2)
        reps = np.empty((n_replicates, fit.size))
        for b in range(n_replicates):
            ystar = yhat + rng.normal(size=yhat.size) * noise
            th_b, ne = refit_local(red, ystar, theta, seed + b)
            n_evals += ne
            reps[b] = th_b[fit]
        sd = reps.std(axis=0, ddof=1)
        q_lo, q_hi = np.percentile(reps, [2.5, 97.5], axis=0)
        samples = reps
        basis = "bootstrap"
    else:
        chol_cov = _psd_factor(cov)
        draws = theta[fit] + rng.normal(size=(n_replicates, fit.size)) @ chol_cov.T
        samples = np.clip(draws, lo_b, hi_b)
        sd = sd_gn
        q_lo = q_hi = theta[fit]
        basis = "gauss-newton"
    params = []
    held_set = set(held)
    for a, k in enumerate(fit):
        v = float(theta[k])
        use_floor = floor[a] > sd[a]
        sd_k = float(max(sd[a], floor[a]))
        low = max(float(s.lower[k]), min(v - Z95 * sd_k, float(q_lo[a])))
        high = min(float(s.upper[k]), max(v + Z95 * sd_k, float(q_hi[a])))
        params.append(ParameterUncertainty(s.names[k], v, sd_k, low, high,
                                           "conditional" if use_floor else basis))
    # held parameters: the prior's SD and interval; samples keep the held value
    full = problem.space
    out_params: list[ParameterUncertainty] = []
    by_name = {p.name: p for p in params}
    all_names = []
    for j, name in enumerate(full.names):
        if not full.fitted[j]:
            continue
        all_names.append(name)
        if name in held_set:
            v = float(theta[j])
            if held_intervals is not None and name in held_intervals:
                sd_p, low_p, high_p = held_intervals[name]
                out_params.append(ParameterUncertainty(name, v, sd_p, low_p, high_p, "prior"))
                continue
            sd_p = float(full.prior_sd[j])
            out_params.append(ParameterUncertainty(
                name, v, sd_p, max(float(full.lower[j]), v - Z95 * sd_p),
                min(float(full.upper[j]), v + Z95 * sd_p), "prior"))
        else:
            out_params.append(by_name[name])
    cols = {n: samples[:, a] for a, n in enumerate(names)}
    full_samples = np.column_stack([
        cols[n] if n in cols else np.full(samples.shape[0], theta[full.names.index(n)])
        for n in all_names]) if all_names else np.zeros((samples.shape[0], 0))
    return Uncertainty(
        method="bootstrap" if use_boot else "gauss-newton", reasons=tuple(reasons),
        parameters=tuple(out_params), names=tuple(all_names), samples=full_samples,
        residual_scale=math.sqrt(s2), n_evals=n_evals, time_s=time.perf_counter() - t0)


def _psd_factor(cov: FloatArray) -> FloatArray:
    """A factor L with L Lᵀ = cov for a symmetric positive semi-definite ``cov``."""
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    return np.asarray(v * np.sqrt(np.maximum(w, 0.0)), dtype=float)
