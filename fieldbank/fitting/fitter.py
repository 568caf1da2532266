"""Estimator-style fitting of a patient's arm model to measured maps.

``ArmFitter(...)`` only stores options; :meth:`ArmFitter.fit` validates the maps, runs the
search and sets the results (trailing underscore). Asking for a result before ``fit`` raises
:class:`~fieldbank.errors.FitError`.

Example::

    fitter = ArmFitter(algorithm="mlsl+lbfgs", seed=1).fit(maps, base)
    fitter.params_        # the fitted ArmParams
    fitter.unidentified_  # what the maps leave open, with reasons
    fitter.status_        # 'good', 'under-determined' or 'poor' (fitting.quality)
    fitter.intervals_     # value, SD and 95% interval per parameter (fitting.uncertainty)
    fitter.report()       # JSON-able summary
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from fieldbank.armbatch import ArmBatch
from fieldbank.errors import FitError
from fieldbank.evaluate.gradebatch import scores
from fieldbank.evaluate.probing import stretch_profiles, unimpaired_reference
from fieldbank.evaluate.severity import (
    SCALE,
    classify,
    ratio_of_score,
    severity_dict,
)
from fieldbank.fitchoices import (
    ALGORITHMS,
    DEFAULT_ALGORITHM,
    DEFAULT_PRIOR_WEIGHT,
    DEFAULT_REPLICATES,
    DEFAULT_UNCERTAINTY,
    FIT_KINDS,
    UNCERTAINTY_METHODS,
)
from fieldbank.fitting.holds import (
    attribution,
    held_intervals,
    hold_unidentified,
    with_attribution,
)
from fieldbank.fitting.identify import Unidentified, identify
from fieldbank.fitting.prior import (
    GuessRange,
    Prior,
    draw,
    fit_ranges,
    prior_dict,
)
from fieldbank.fitting.problem import FitProblem
from fieldbank.fitting.quality import (
    DEFAULT_THRESHOLDS,
    GoodnessOfFit,
    Thresholds,
    assess,
    r2_score,
    status,
)
from fieldbank.fitting.search import Progress, run_dual_annealing, run_nlopt
from fieldbank.fitting.space import ParamSpace
from fieldbank.fitting.uncertainty import (
    FitSamples,
    Uncertainty,
    estimate,
    reduced_problem,
)
from fieldbank.maps import FRAMES, FieldMap
from fieldbank.model import Arm, FloatArray
from fieldbank.params import ArmParams

#: Metadata keys that may state a map's value unit, and the unit each kind must have.
UNIT_KEYS = ("unit", "units", "value_unit", "values_unit", "force_unit", "stiffness_unit")
POSITION_UNIT_KEYS = ("position_unit", "positions_unit")
SI_VALUE_UNIT = {"postural": ("n",), "stiffness": ("n/m", "n m^-1", "n·m^-1")}
#: Metadata keys naming the patient a map belongs to.
PATIENT_KEYS = ("patient", "patient_code")

#: Percentiles of the grade ranges over the fit's samples.
GRADE_PERCENTILES = (2.5, 97.5)

_RESULTS = ("held_", "hold_test_", "params_", "theta_", "cost_", "chi2_", "residuals_", "r2_",
            "uncertainty_", "relative_sd_", "residual_variance_", "unidentified_", "status_",
            "at_bounds_", "n_evals_", "stop_reason_", "time_s_", "cpu_s_", "algorithm_", "seed_",
            "maps_", "severity_", "problem_", "space_", "base_", "goodness_", "intervals_",
            "uncertainty_detail_", "prior_ranges_", "attribution_")


def _unit(value: str) -> str:
    return value.strip().lower().replace(" ", "")


def validate_maps(
    maps: Sequence[FieldMap], arm: Arm, patient: str | None = None
) -> list[FieldMap]:
    """Check maps for a fit and return them in the arm-on-handle convention.

    Raises
    ------
    FitError
        No maps; not a FieldMap; an unknown frame; a unit other than SI; maps of different
        patients (or not of ``patient``); a position the arm cannot reach.
    """
    if maps is None or len(maps) == 0:
        raise FitError("no maps to fit: give at least one postural or stiffness map.")
    out: list[FieldMap] = []
    owners: dict[str, int] = {}
    for k, m in enumerate(maps):
        label = f"map {k}" + (f" ({m.source})" if getattr(m, "source", "") else "")
        if not isinstance(m, FieldMap):
            raise FitError(f"{label}: expected a FieldMap, got {type(m).__name__}.")
        if m.frame not in FRAMES:
            raise FitError(f"{label}: frame {m.frame!r} is not one the fitter knows "
                           f"({', '.join(FRAMES)}); convert it first.")
        for key in UNIT_KEYS:
            if key in m.metadata and _unit(m.metadata[key]) not in SI_VALUE_UNIT[m.kind]:
                raise FitError(
                    f"{label}: inconsistent units: metadata {key!r} says {m.metadata[key]!r}, "
                    f"but {m.kind} values must be in {('N' if m.kind == 'postural' else 'N/m')}; "
                    "convert the map to SI before fitting."
                )
        for key in POSITION_UNIT_KEYS:
            if key in m.metadata and _unit(m.metadata[key]) != "m":
                raise FitError(
                    f"{label}: inconsistent units: metadata {key!r} says {m.metadata[key]!r}, "
                    "but positions must be in m; convert the map to SI before fitting."
                )
        for key in PATIENT_KEYS:
            if key in m.metadata:
                owners.setdefault(str(m.metadata[key]), k)
        mask = arm.reachable(m.positions_m)
        if not np.all(mask):
            i = int(np.argmin(mask))
            x, y = m.positions_m[i]
            raise FitError(
                f"{label}: position index {i} ({x:.4f}, {y:.4f}) m is outside what this arm "
                f"reaches within its range of motion ({int((~mask).sum())} of {m.n} positions);"
                " check the frame, the units and the patient's segment lengths."
            )
        out.append(m.as_arm_on_handle())
    if len(owners) > 1:
        desc = ", ".join(f"map {k} of {p!r}" for p, k in owners.items())
        raise FitError(f"maps of different patients cannot be fitted together: {desc}.")
    if patient is not None and owners and patient not in owners:
        other, k = next(iter(owners.items()))
        raise FitError(f"map {k} belongs to patient {other!r}, not to {patient!r}.")
    return out


class ArmFitter:
    """Fit per-muscle Km, α, β (optionally q_rest) to a patient's measured maps.

    Parameters
    ----------
    algorithm : str
        'mlsl+lbfgs' (default), 'crs2+bobyqa', 'direct+lbfgs' (nlopt global search, then
        local polish) or 'dual_annealing' (scipy; the seed's method, the baseline).
    seed : int
        Makes the fit reproducible.
    fit : sequence of str
        Parameter kinds to fit: any of 'km', 'alpha', 'beta', 'q_rest'.
    bounds : mapping, optional
        Overrides, kind or name -> (low, high) in SI units, e.g. ``{'km': (100, 20000)}``.
    prior_weight : float
        Scale of the weak prior toward unimpaired (see :mod:`fieldbank.fitting.space`).
    max_evals : int, optional
        Evaluation budget of the global stage (nlopt) or of dual annealing.
    progress : callable(n_evals, best_cost), optional
        Called every few dozen evaluations.
    hold_unidentified : bool
        After the fit, hold the parameters the maps do not identify at their unimpaired
        (prior) values and refit the others, unless the maps reject that: a likelihood-ratio
        test, Δχ² of the data above the χ² quantile :data:`HOLD_TEST_LEVEL` with one degree of
        freedom per held parameter. This keeps noise from setting what the data leave open.
    uncertainty : str
        'auto' (Gauss–Newton where it holds, else a parametric bootstrap), 'gauss-newton' or
        'bootstrap' (:mod:`fieldbank.fitting.uncertainty`).
    replicates : int
        Bootstrap replicates (and parameter samples kept with the fit).
    thresholds : Thresholds, optional
        The goodness-of-fit verdict's thresholds (:mod:`fieldbank.fitting.quality`).
    """

    def __init__(
        self,
        algorithm: str = DEFAULT_ALGORITHM,
        seed: int = 0,
        fit: Sequence[str] = ("km", "alpha", "beta"),
        bounds: Mapping[str, tuple[float, float]] | None = None,
        prior_weight: float = DEFAULT_PRIOR_WEIGHT,
        max_evals: int | None = None,
        progress: Progress | None = None,
        hold_unidentified: bool = True,
        uncertainty: str = DEFAULT_UNCERTAINTY,
        replicates: int = DEFAULT_REPLICATES,
        thresholds: Thresholds | None = None,
    ) -> None:
        self.algorithm = algorithm
        self.seed = seed
        self.fit_kinds = tuple(fit)
        self.bounds = dict(bounds) if bounds is not None else None
        self.prior_weight = prior_weight
        self.max_evals = max_evals
        self.progress = progress
        self.hold_unidentified = hold_unidentified
        self.uncertainty = uncertainty
        self.replicates = replicates
        self.thresholds = thresholds

    def options(self) -> dict[str, Any]:
        """The options that decide what a fit gives, as plain JSON values (a stored fit's key
        hashes them; the progress callback is not one)."""
        return {"algorithm": self.algorithm, "seed": int(self.seed),
                "fit": list(self.fit_kinds),
                "bounds": None if self.bounds is None else
                {k: [float(v) for v in b] for k, b in sorted(self.bounds.items())},
                "prior_weight": float(self.prior_weight), "max_evals": self.max_evals,
                "hold_unidentified": bool(self.hold_unidentified),
                "uncertainty": self.uncertainty, "replicates": int(self.replicates),
                "thresholds": None if self.thresholds is None else self.thresholds.to_dict()}

    def __getattr__(self, name: str) -> Any:
        if name in _RESULTS:
            raise FitError(f"ArmFitter has no result {name!r} yet: call fit(maps, base) first.")
        raise AttributeError(name)

    def check_options(self) -> None:
        """Refuse options no fit can run with (FitError naming the option), before any work."""
        if self.algorithm not in ALGORITHMS:
            raise FitError(f"unknown algorithm {self.algorithm!r}; choose one of "
                           f"{', '.join(ALGORITHMS)}.")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) \
                or self.seed < 0:
            raise FitError(f"seed must be a non-negative integer; got {self.seed!r}.")
        if self.max_evals is not None and (not isinstance(self.max_evals, int)
                                           or self.max_evals < 10):
            raise FitError(f"max_evals must be an integer >= 10; got {self.max_evals!r}.")
        unknown = sorted(set(self.fit_kinds) - set(FIT_KINDS))
        if unknown:
            raise FitError(f"cannot fit {', '.join(unknown)}; choose from {', '.join(FIT_KINDS)}.")
        if self.uncertainty not in UNCERTAINTY_METHODS:
            raise FitError(f"unknown uncertainty method {self.uncertainty!r}; choose one of "
                           f"{', '.join(UNCERTAINTY_METHODS)}.")
        if isinstance(self.replicates, bool) or not isinstance(self.replicates, int) \
                or self.replicates < 2:
            raise FitError(f"replicates must be an integer >= 2; got {self.replicates!r}.")

    def fit(self, maps: Sequence[FieldMap], base: ArmParams,
            patient: str | None = None) -> ArmFitter:
        """Fit ``base``'s Km, α, β (and q_rest) to ``maps``; returns self.

        Parameters
        ----------
        maps : sequence of FieldMap
            The patient's measured maps (shoulder frame, SI units; handle-on-arm maps are
            converted).
        base : ArmParams
            The patient's arm: segments, moment arms, rest lengths, and the start values.
        patient : str, optional
            When given, maps whose metadata name another patient are refused.
        """
        self.check_options()
        if not isinstance(base, ArmParams):
            raise FitError(f"base must be ArmParams; got {type(base).__name__}.")
        t0, c0 = time.perf_counter(), time.thread_time()
        arm = Arm.from_params(base)
        used = validate_maps(maps, arm, patient)
        space = ParamSpace.build(base, self.fit_kinds, self.bounds, self.prior_weight)
        problem = FitProblem.from_maps(used, arm, space)
        seed = int(self.seed)
        if self.algorithm == "dual_annealing":
            res = run_dual_annealing(problem, seed, self.max_evals, self.progress)
        else:
            res = run_nlopt(problem, self.algorithm, seed, self.max_evals, self.progress)
        theta = res.theta
        n_evals = res.n_evals
        stop_reason = res.stop_reason
        ident = identify(problem, theta)
        self.held_: list[str] = []
        self.hold_test_: dict[str, Any] | None = None
        if self.hold_unidentified and ident.unidentified:
            held = hold_unidentified(problem, theta, ident.unidentified, self.algorithm, seed)
            n_evals += held.n_evals
            self.hold_test_ = held.test
            if held.accepted:
                theta = held.theta
                self.held_ = list(held.names)
                stop_reason += f"; unidentified held at unimpaired: {held.stop_reason}"
            final = identify(problem, theta)  # uncertainty at the final point
            # what the full fit could not identify stays reported, held or not - unless the
            # maps rejected its hold and identify it at the point they led to
            still = {u.name for u in final.unidentified}
            flagged = tuple(dataclasses.replace(u, reason=u.reason + held.note(u.name))
                            for u in ident.unidentified
                            if u.name in self.held_ or not held.was_released(u.name)
                            or u.name in still)
            ident = dataclasses.replace(final, unidentified=flagged)
        self.attribution_ = attribution(problem, theta, self.held_, seed)
        if self.attribution_:
            ident = dataclasses.replace(ident, unidentified=with_attribution(
                ident.unidentified, self.attribution_))
            n_evals += sum(int(a["n_evals"]) for a in self.attribution_)
        fitted_params = space.to_params(theta, base)
        prior = Prior.for_arm(arm.with_muscles(fitted_params)
                              if fitted_params.q_rest_rad == base.q_rest_rad
                              else Arm.from_params(fitted_params))
        self.prior_ranges_: tuple[GuessRange, ...] = (
            fit_ranges(reduced_problem(problem, theta, self.held_), theta, self.held_, prior)
            if self.held_ else ())
        unc = estimate(problem, theta, self.held_,
                       unidentified=[u.name for u in ident.unidentified],
                       method=self.uncertainty, n_replicates=self.replicates, seed=seed,
                       held_intervals=held_intervals(self.prior_ranges_, prior, seed))
        n_evals += unc.n_evals
        yhat = problem.predict(theta)
        self.time_s_ = time.perf_counter() - t0
        self.cpu_s_ = time.thread_time() - c0  # this thread's CPU over the same span
        self.base_ = base
        self.space_ = space
        self.problem_ = problem
        self.theta_ = theta
        self.params_ = space.to_params(theta, base)
        self.cost_ = float(problem.cost(theta))
        self.chi2_ = float(np.sum(problem.residuals(theta) ** 2))
        self.maps_ = used
        self.residuals_: list[FloatArray] = []
        self.r2_: list[float] = []
        predicted = []
        for m, rows in zip(used, problem.map_rows, strict=True):
            y = problem.y[rows].reshape(m.values.shape)
            fitted = yhat[rows].reshape(m.values.shape)
            predicted.append(fitted)
            self.residuals_.append(y - fitted)
            self.r2_.append(r2_score(y, fitted))
        self.goodness_: GoodnessOfFit = assess(
            used, predicted, ident.effective_parameters, self.thresholds or DEFAULT_THRESHOLDS,
            sds=[problem.sd[rows] for rows in problem.map_rows])
        self.uncertainty_detail_: Uncertainty = unc
        self.uncertainty_ = unc.sd()
        self.intervals_ = unc.intervals()
        self.relative_sd_ = {n: float(ident.relative_sd[k]) for k, n in enumerate(space.names)
                             if space.fitted[k]}
        self.unidentified_: tuple[Unidentified, ...] = ident.unidentified
        self.status_ = status(self.goodness_, len(ident.unidentified))
        self.residual_variance_ = ident.residual_variance
        self.at_bounds_ = [n for k, n in enumerate(space.names) if space.fitted[k] and (
            theta[k] <= space.lower[k] + 1e-9 or theta[k] >= space.upper[k] - 1e-9)]
        self.n_evals_ = n_evals
        self.stop_reason_ = stop_reason
        self.algorithm_ = self.algorithm
        self.seed_ = seed
        samples = draw(FitSamples(unc.names, unc.samples), self.prior_ranges_, prior, seed=seed)
        self.severity_ = _severity(self.params_, [u.name for u in self.unidentified_],
                                   samples)
        self.prior_ = prior
        return self

    # --- using a fit --------------------------------------------------------------------------
    def predict(self, maps: Sequence[FieldMap]) -> list[FieldMap]:
        """The fitted model's maps at the positions and velocities of ``maps``."""
        arm = Arm.from_params(self.params_)
        used = validate_maps(maps, arm)
        space = ParamSpace.build(self.params_, self.fit_kinds, self.bounds, self.prior_weight)
        problem = FitProblem.from_maps(used, arm, space)
        yhat = problem.predict(self.theta_)
        out = []
        for m, rows in zip(used, problem.map_rows, strict=True):
            out.append(FieldMap(kind=m.kind, positions_m=m.positions_m,
                                values=yhat[rows].reshape(m.values.shape),
                                velocity_m_per_s=m.velocity_m_per_s,
                                source="fieldbank fitted model"))
        return out

    def score(self, maps: Sequence[FieldMap]) -> list[float]:
        """R² of the fitted model on each of ``maps`` (e.g. held-out positions)."""
        pred = self.predict(maps)
        return [r2_score(m.as_arm_on_handle().values, p.values)
                for m, p in zip(maps, pred, strict=True)]

    def report(self) -> dict[str, Any]:
        """A JSON-able summary of the fit."""
        space = self.space_
        params = {n: float(self.theta_[k]) for k, n in enumerate(space.names)}
        return {
            "status": self.status_,
            "goodness_of_fit": self.goodness_.to_dict(),
            "algorithm": self.algorithm_,
            "seed": self.seed_,
            "fitted": list(self.fit_kinds),
            "prior_weight": self.prior_weight,
            "cost": self.cost_,
            "chi2": self.chi2_,
            "residual_variance": self.residual_variance_,
            "n_evals": self.n_evals_,
            "time_s": self.time_s_,
            "stop_reason": self.stop_reason_,
            "parameters": params,
            "uncertainty": self.uncertainty_,
            "uncertainty_method": self.uncertainty_detail_.summary(),
            "intervals": self.intervals_,
            "samples": self.uncertainty_detail_.samples_dict(),
            "posterior_to_prior_sd": self.relative_sd_,
            "at_bounds": self.at_bounds_,
            "held_at_unimpaired": self.held_,
            "hold_test": self.hold_test_,
            "prior": prior_dict(self.prior_ranges_, self.prior_),
            "attribution": self.attribution_,
            "unidentified": [u.to_dict() for u in self.unidentified_],
            "maps": [
                {"index": k, "kind": m.kind, "n": m.n, "velocity_m_per_s": list(
                    m.velocity_m_per_s), "source": m.source, "metadata": dict(m.metadata),
                 "r2": self.r2_[k],
                 "rms_residual": float(np.sqrt(np.mean(self.residuals_[k] ** 2))),
                 "chi2_per_value": self.goodness_.maps[k].chi2_per_value,
                 "verdict": self.goodness_.maps[k].verdict}
                for k, m in enumerate(self.maps_)
            ],
            "severity": self.severity_,
            "params": self.params_.to_dict(),
        }


def _severity(params: ArmParams, unidentified: Sequence[str],
              samples: FitSamples | None = None) -> dict[str, Any]:
    """Severity per muscle group, passive and dynamic
    (:func:`fieldbank.evaluate.severity.classify`), as plain values; each grade lists the
    parameters behind it that the maps did not identify and, over the fit's parameter samples
    (held parameters drawn from their prior range), the 95% range of its score and levels -
    the samples graded together, as arrays (:func:`fieldbank.evaluate.gradebatch.scores`)."""
    arm = Arm.from_params(params)
    ref = unimpaired_reference(arm)
    ref_prof = stretch_profiles(ref)
    out = severity_dict(classify(arm, unidentified, ref, reference_profiles=ref_prof))
    if samples is None or samples.values.shape[0] == 0:
        return out
    batch = ArmBatch.from_arrays(arm, samples.values.shape[0], **samples.arrays(params))
    lo_p, hi_p = GRADE_PERCENTILES
    for (g, c), vals in scores(batch, ref, reference_profiles=ref_prof).items():
        grade = out[g][c]
        assert isinstance(grade, dict)
        # the fitted model's own grade belongs to the range (held parameters: its unimpaired
        # end, which the percentiles of the draws may cut off)
        point = float(grade["score"])
        lo, hi = (float(v) for v in np.percentile(vals, [lo_p, hi_p]))
        lo, hi = min(lo, point), max(hi, point)
        grade["score_range"] = [round(lo, 4), round(hi, 4)]
        grade["level_range"] = [_level_of_score(lo, c), _level_of_score(hi, c)]
    return out


def _level_of_score(score: float, component: str) -> str:
    """The level a continuous score (0 unimpaired … 4 severe) is graded."""
    return SCALE.level(ratio_of_score(score, component), component)
