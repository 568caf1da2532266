"""What a fit holds at unimpaired values, and what it says it could not tell apart.

A parameter the maps do not identify is held at its unimpaired value when the maps allow it
(:func:`hold_unidentified`: a χ² test of the hold, then per-unit release tests); a stretch
reflex the maps may place in either of two groups is tested by moving it to the partner group
(:func:`attribution`); every held parameter keeps the range the severity scale's prior gives it
(:func:`held_intervals`), so that a prediction resting on it is an interval, not a number.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from fieldbank.evaluate.severity import classify
from fieldbank.evaluate.tone import GRADED_STRETCH
from fieldbank.fitchoices import ALGORITHMS, DEFAULT_ALGORITHM
from fieldbank.fitting.identify import Unidentified
from fieldbank.fitting.prior import GuessRange, Prior, draw, units
from fieldbank.fitting.problem import FitProblem
from fieldbank.fitting.search import HOLD_EVALS, run_nlopt
from fieldbank.fitting.uncertainty import FitSamples, reduced_problem, refit_local
from fieldbank.model import Arm, FloatArray

#: Significance level of the test that may keep unidentified parameters at unimpaired values.
HOLD_TEST_LEVEL = 0.95
#: Family-wise level of the per-unit release tests (a group's Km, its reflex, a rest angle):
#: each unit is released when the maps reject its hold at 1 - (1 - level) / units tested
#: (Bonferroni), so holding a dozen units releases none by chance in 95% of fits.
RELEASE_TEST_LEVEL = 0.95
#: Groups whose stretch reflexes show in the same stretches (a flexor or an extensor group of
#: one joint and the bi-articular group of the same direction): the maps may not tell them
#: apart, and a fit must not attribute the reflex to one of them without saying so.
REFLEX_PARTNERS: tuple[tuple[str, str], ...] = (("ef", "bf"), ("sf", "bf"), ("ee", "be"),
                                                ("se", "be"))
#: Level of the attribution test: the reflex is moved to the partner group and refitted; the
#: maps tell the two apart when that costs more than this χ² quantile (2 degrees of freedom).
ATTRIBUTION_TEST_LEVEL = 0.95

@dataclasses.dataclass(frozen=True)
class Hold:
    accepted: bool
    theta: FloatArray
    names: tuple[str, ...]
    n_evals: int
    stop_reason: str
    test: dict[str, Any]

    def was_released(self, name: str) -> bool:
        return any(name in r["names"] for r in self.test["released"])

    def note(self, name: str) -> str:
        t = self.test
        for r in t["released"]:
            if name in r["names"]:
                return (f"; the maps reject holding {', '.join(r['names'])} at the unimpaired "
                        f"value (Δχ² {r['delta_chi2']:.3g} > {r['threshold']:.3g}), so it is "
                        "fitted, not held")
        if name not in t["held"]:
            return ""
        if self.accepted:
            return (f"; held at the unimpaired value (the maps do not reject it: Δχ² "
                    f"{t['delta_chi2']:.3g} <= {t['threshold']:.3g})")
        return (f"; the maps reject holding the unidentified parameters at unimpaired values "
                f"(Δχ² {t['delta_chi2']:.3g} > {t['threshold']:.3g}), so the fitted value is "
                "kept")


def chi2_of(problem: FitProblem, theta: FloatArray) -> float:
    r = problem.residuals(theta)
    return float(r @ r)


def hold_units(names: Sequence[str]) -> list[tuple[str, ...]]:
    """The units a hold is tested by: a group's Km, its reflex (α and β), its slack length,
    each rest angle."""
    out = list(units(names).values())
    out += [(n,) for n in names if n.startswith(("q_rest_", "slack_"))]
    return out


def hold_unidentified(problem: FitProblem, theta: FloatArray,
                       unidentified: Sequence[Unidentified], algorithm: str, seed: int) -> Hold:
    """Hold what the maps do not identify at the unimpaired (prior) values, unless the maps
    reject it.

    1. Refit with every unidentified parameter at its prior mean.
    2. Release tests per unit (:func:`hold_units`), by forward selection: each unit still
       held is freed alone and refitted from the current point (a local search with a coarse
       scan of every reflex gain, which a reflex that never fires at the held point needs),
       the rest held; the unit the maps improve most on is released when that improvement
       exceeds the χ² quantile of :data:`RELEASE_TEST_LEVEL`, Bonferroni-corrected over the
       units tested in the round; then the others are tested again against that fit (a
       group's missing reflex can make a neighbour's look needed, until it is released). A
       reflex the full search missed (stuck where it never fires, so "not identified") is
       found here, not held at unimpaired.
    3. The joint likelihood-ratio test of what stays held against the full fit
       (:data:`HOLD_TEST_LEVEL`, one degree of freedom per held parameter) decides whether
       the hold stands.
    """
    from scipy.stats import chi2  # heavy: loaded when a fit runs, not with the module

    space = problem.space
    names = tuple(u.name for u in unidentified)
    idx = [space.names.index(n) for n in names]
    base = theta.copy()
    base[idx] = space.prior_mean[idx]
    reduced = reduced_problem(problem, base, names)
    name = algorithm if algorithm in ALGORITHMS and algorithm != "dual_annealing" \
        else DEFAULT_ALGORITHM
    res = run_nlopt(reduced, name, seed, HOLD_EVALS)
    n_evals = reduced.n_evals
    theta_h = res.theta
    remaining = hold_units(names)
    tested: list[dict[str, Any]] = []
    released: list[dict[str, Any]] = []
    theta_f = theta_h
    held_now = list(names)
    # forward selection: release the unit the maps reject most, then test the others again
    # against that fit (a group's missing reflex can make another group's look needed)
    while remaining:
        unit_level = 1.0 - (1.0 - RELEASE_TEST_LEVEL) / len(remaining)
        best: tuple[float, int, FloatArray] | None = None
        chi_now = chi2_of(problem, theta_f)
        for k, unit in enumerate(remaining):
            red = reduced_problem(problem, theta_f, [n for n in held_now if n not in unit])
            th, ne = refit_local(red, red.y, theta_f, seed)
            n_evals += ne
            delta = chi_now - chi2_of(problem, th)
            limit = float(chi2.ppf(unit_level, len(unit)))
            tested.append({"names": list(unit), "delta_chi2": delta, "threshold": limit,
                           "level": unit_level, "round": len(released) + 1})
            if delta > limit and (best is None or delta > best[0]):
                best = (delta, k, th)
        if best is None:
            break
        unit = remaining.pop(best[1])
        released.append(next(t for t in reversed(tested) if t["names"] == list(unit)))
        held_now = [n for n in held_now if n not in unit]
        theta_f = best[2]
    final = tuple(held_now)
    chi_full = chi2_of(problem, theta)
    delta = chi2_of(problem, theta_f) - chi_full
    threshold = float(chi2.ppf(HOLD_TEST_LEVEL, max(1, len(final))))
    accepted = delta <= threshold
    test = {"held": list(final), "delta_chi2": delta, "threshold": threshold,
            "level": HOLD_TEST_LEVEL, "accepted": accepted, "released": released,
            "tested": tested}
    return Hold(accepted, theta_f if accepted else theta, final if accepted else (),
                 n_evals, res.stop_reason, test)


def attribution(problem: FitProblem, theta: FloatArray, held: Sequence[str],
                 seed: int) -> list[dict[str, Any]]:
    """Whether the maps tell a fitted stretch reflex from that of its partner group
    (:data:`REFLEX_PARTNERS`: the bi-articular reflex and an elbow or shoulder group's show in
    the same stretches).

    For each partner pair where one group's reflex is fitted above unimpaired (its dynamic
    grade not unimpaired) and the other's is not, the reflex is moved: the impaired group's α
    and β held at the unimpaired values, the partner's freed and refitted (a local search with
    a coarse scan of every reflex gain). When that costs the maps no more than the χ²
    quantile of :data:`ATTRIBUTION_TEST_LEVEL`, the maps do not tell the two apart: both
    groups' reflex parameters are reported as not identified, with the test. When the moved
    reflex fits better by more than that, the fit is reported as having attributed it to the
    wrong group (the same flag, with the better fit's Δχ²).
    """
    from scipy.stats import chi2  # heavy: loaded when a fit runs, not with the module

    space = problem.space
    params = space.to_params(theta, problem.arm.params)
    grades = classify(problem.arm.with_muscles(params)
                      if params.q_rest_rad == problem.arm.params.q_rest_rad
                      else Arm.from_params(params))
    fitted = set(n for k, n in enumerate(space.names) if space.fitted[k])
    out: list[dict[str, Any]] = []
    limit = float(chi2.ppf(ATTRIBUTION_TEST_LEVEL, 2))
    chi0 = chi2_of(problem, theta)
    for a, b in REFLEX_PARTNERS:
        for g, h in ((a, b), (b, a)):
            if grades[g].dynamic.level == "unimpaired" or \
                    grades[h].dynamic.level != "unimpaired":
                continue
            mine = (f"alpha_{g}", f"beta_{g}")
            theirs = (f"alpha_{h}", f"beta_{h}")
            if not all(n in fitted for n in mine + theirs):
                continue
            t = theta.copy()
            for n in mine:
                k = space.names.index(n)
                t[k] = space.prior_mean[k]
            keep = [n for n in held if n not in theirs] + list(mine)
            red = reduced_problem(problem, t, keep)
            th, ne = refit_local(red, red.y, t, seed)
            delta = chi2_of(problem, th) - chi0
            if delta <= limit:
                out.append({"group": g, "partner": h, "delta_chi2": delta, "threshold": limit,
                            "stretch": " ".join(GRADED_STRETCH[g]), "n_evals": ne,
                            "names": list(mine + theirs)})
    return out


def with_attribution(flagged: Sequence[Unidentified],
                      attribution: Sequence[Mapping[str, Any]]) -> tuple[Unidentified, ...]:
    """``flagged`` with the reflex parameters of every pair the maps do not tell apart."""
    out = {u.name: u for u in flagged}
    for a in attribution:
        g, h = a["group"], a["partner"]
        better = a["delta_chi2"] < 0
        why = (f"the maps do not tell the stretch reflex of {g} from that of {h}: putting it on "
               f"{h} instead " + (f"fits better (Δχ² {a['delta_chi2']:.3g})" if better else
                                  f"costs only Δχ² {a['delta_chi2']:.3g} <= "
                                  f"{a['threshold']:.3g}")
               + f"; the fit's {g} reflex may be {h}'s")
        for n in a["names"]:
            old = out.get(n)
            out[n] = Unidentified(n, why if old is None else old.reason + "; " + why,
                                  old.posterior_to_prior_sd if old is not None else 1.0)
    return tuple(out.values())


def held_intervals(ranges: Sequence[GuessRange], prior: Prior, seed: int
                    ) -> dict[str, tuple[float, float, float]]:
    """(sd, low, high) of every held parameter over its prior range (draws of the range)."""
    if not ranges:
        return {}
    drawn = draw(FitSamples((), np.zeros((1, 0))), ranges, prior, 400, seed=seed)
    out = {}
    for r in ranges:
        iv = prior.interval(r)
        for n in r.names:
            col = drawn.values[:, drawn.names.index(n)]
            out[n] = (float(col.std(ddof=1)), *iv[n])
    return out
