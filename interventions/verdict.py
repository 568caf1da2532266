"""The verdict's rules in one place: what a later session shows about a plan's prediction
(:class:`Evidence`, gathered by :func:`fieldbank.interventions.validate.check_session`) in,
the session's verdict with its reasons (:class:`Verdict`) out.

In order, the first rule that holds decides (the thresholds are :class:`Rules`; the numbers and
their reasons are stated in :mod:`fieldbank.interventions.realised`):

1. no map of the session could be compared: *inconclusive*;
2. some maps differ from the model before + the predicted change by more than their noise and
   the fit's uncertainty explain:
   a. a change of a parameter the fit held at a guess explains them: *inconclusive* (it may be
      the guess, not the plan);
   b. the fit used no map measured like any of them: *inconclusive* (the model may not describe
      the arm there);
   c. otherwise: *prediction failed*;
3. the maps cannot see the change (it moves them by less than ``min_sensitivity`` sd):
   *inconclusive*, with the measurement that would see it;
4. the change rests on guesses alone (every treated group's change is a parameter the fit did
   not identify): *inconclusive*;
5. the realised fraction's SE is above ``max_se``: *inconclusive*, saying which part is too
   large;
6. else the realised fraction f and its interval f ± z SE decide (:func:`decide`): *prediction
   confirmed*, *more than predicted*, *partial effect*, *prediction failed* or *inconclusive*.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from fieldbank.interventions.realised import (
    CONFIRMED,
    DEFAULT_RULES,
    FAILED,
    INCONCLUSIVE,
    OVER,
    PARTIAL,
    Fraction,
    Rules,
)


@dataclass(frozen=True)
class Evidence:
    """What one later session shows about a plan's prediction.

    ``fraction``: the realised fraction pooled over the session's maps; ``shown``: whether it
    may be reported (seen, not resting on guesses, inside ``limits``, the physical range, and
    precise enough); ``unexplained``: the reasons of the maps the model before + the
    (scaled) predicted change cannot explain; ``untested``: held parameters whose change would
    explain them; ``elsewhere``: those of them measured unlike every map the fit used;
    ``guessed``: treated parameters the fit did not identify (``all_guessed``: every treated
    group's change rests on one, ``all_held``: each was held at the unimpaired value);
    ``advise``: the measurement that would see the change (asked only when the verdict needs
    it).
    """

    compared: bool
    fraction: Fraction
    shown: bool
    limits: tuple[float, float]
    treated: str
    unexplained: tuple[tuple[str, ...], ...] = ()
    untested: tuple[str, ...] = ()
    elsewhere: tuple[int, ...] = ()
    scale: float = 1.0
    guessed: tuple[str, ...] = ()
    all_guessed: bool = False
    all_held: bool = False
    fit_id: int | None = None
    advise: Callable[[], str] = str


@dataclass(frozen=True)
class Verdict:
    """A session's verdict, its reasons in order, whether the realised fraction's interval
    decided it, and the measurement suggested (empty when none is)."""

    verdict: str
    reasons: tuple[str, ...]
    decided: bool = False
    advice: str = ""


def judge(e: Evidence, rules: Rules = DEFAULT_RULES) -> Verdict:
    """The verdict of a session from its evidence (the rules of the module docstring)."""
    f, fit = e.fraction, e.fit_id
    if not e.compared:
        return Verdict(INCONCLUSIVE, ("no map of the session could be compared",))
    misfits = tuple(r for reasons in e.unexplained for r in reasons)
    if e.unexplained and e.untested:
        return Verdict(INCONCLUSIVE, (*misfits, (
            f"these maps differ from the model before + the predicted change by more than "
            f"their noise and the fit's uncertainty, but a change of the "
            f"{' and '.join(e.untested)}, which fit {fit} held at the unimpaired value (a "
            "guess), explains the difference: it may be that guess, not the plan; refit with "
            "maps like these to decide")))
    if e.unexplained and len(e.elsewhere) == len(e.unexplained):
        return Verdict(INCONCLUSIVE, (*misfits, (
            f"these maps differ from the model before + the predicted change by more than "
            f"their noise and the fit's uncertainty, but fit {fit} used no map measured like "
            f"map(s) {', '.join(map(str, e.elsewhere))} (kind, hand velocity and positions): "
            "the model may not describe the arm there, so the difference cannot be laid on "
            "the plan; measure the later maps as the first session's to decide")))
    if e.unexplained:
        sees = f.value is not None and f.sensitivity_sd >= rules.min_sensitivity
        at = f"{e.scale:.2f} × the predicted change" if sees else "the predicted change"
        return Verdict(FAILED, (*misfits, (
            f"the maps changed in a way the plan does not predict: with the model before + "
            f"{at}, {len(e.unexplained)} map(s) still differ by more than their noise and the "
            "fit's uncertainty explain")))
    if f.value is None or f.sensitivity_sd < rules.min_sensitivity:
        advice = e.advise()
        return Verdict(INCONCLUSIVE, (
            f"these maps cannot see a change of the {e.treated}: the predicted change moves "
            f"them by {f.sensitivity_sd:.1f} sd in all (at least {rules.min_sensitivity:g} "
            f"needed); {advice} to decide",), advice=advice)
    if e.all_guessed:
        advice = e.advise()
        how = "held at the unimpaired value" if e.all_held else "not identified"
        return Verdict(INCONCLUSIVE, (
            f"the predicted change rests on a guess: fit {fit} did not identify "
            f"{', '.join(e.guessed)} ({how}), so a realised fraction would measure the guess, "
            f"not the plan; {advice} and refit to decide",), advice=advice)
    se = _num(f.se)
    if se is None or se > rules.max_se:
        parts = f"noise {_f2(f.noise_se)}, fit {_f2(f.fit_part)}" + _misfit(f)
        value = (f"{f.value:.2f} ± {_f2(se)}" if e.shown else
                 f"not known to better than ± {_f2(se)}")
        bigger = (f"the fit before the plan is too uncertain about the {e.treated}"
                  if (f.fit_part or 0.0) > (f.noise_se or 0.0) else
                  "the later maps are too noisy for this change")
        return Verdict(INCONCLUSIVE, (f"the realised fraction is {value} ({parts}): SE above "
                                      f"{rules.max_se:g}, {bigger}",))
    reasons = []
    if e.guessed:
        reasons.append(f"part of the prediction rests on a guess: fit {fit} did not identify "
                       f"{', '.join(e.guessed)}; the realised fraction measures the change of "
                       "the groups it did identify")
    verdict, why = decide(f.value, se, rules)
    if not e.shown:
        lo, hi = e.limits
        why = (f"the measured change along the predicted one is beyond what the plan can "
               f"produce (a fraction outside {lo:.2f} to {hi:.2f})")
    reasons.append(f"realised fraction {_f2(f.value) if e.shown else 'not reported'}"
                   + (f" ± {se:.2f} (noise {_f2(f.noise_se)}, fit {_f2(f.fit_part)}"
                      f"{_misfit(f)})" if e.shown else "") + f": {why}")
    return Verdict(verdict, tuple(reasons), decided=e.shown)


def decide(f: float, se: float, rules: Rules = DEFAULT_RULES) -> tuple[str, str]:
    """Verdict and its reason from a decided realised fraction (SE ≤ ``rules.max_se``)."""
    lo, hi = f - rules.z * se, f + rules.z * se
    top = 1.0 - rules.tolerance
    span = f"{lo:.2f} to {hi:.2f} at {rules.z:g} SE"
    if f > 1.0 + rules.tolerance:
        if lo > 1.0:
            return OVER, (f"the change is stronger than predicted: {f:.2f}, beyond "
                          f"{1 + rules.tolerance:g}, and {span}, above 1")
        return INCONCLUSIVE, (f"the maps leave open whether the change came as predicted or "
                              f"stronger: {f:.2f}, beyond {1 + rules.tolerance:g}, but {span} "
                              "reaches 1")
    if hi < top:
        if hi < 0:
            return FAILED, f"the maps changed the opposite way to the prediction: {span}"
        if lo <= 0:
            return FAILED, (f"no change distinguishable from none where the prediction "
                            f"expected one: {span}, below {top:g} and reaching 0")
        return PARTIAL, (f"part of the predicted change came: {span}, clearly above 0 and "
                         f"below {top:g}")
    if lo >= rules.confirm_floor:
        return CONFIRMED, (f"the change came as predicted: {span}, at least "
                           f"{rules.confirm_floor:g} and reaching {top:g}")
    return INCONCLUSIVE, (f"the maps leave open whether all or only part of the change came: "
                          f"{span}, reaching both below {rules.confirm_floor:g} and "
                          f"{top:g}")


def _num(v: float | None) -> float | None:
    return None if v is None or not math.isfinite(v) else float(v)


def _misfit(f: Fraction) -> str:
    return f"; × {f.misfit:.2f} for misfit" if f.misfit >= 1.005 else ""


def _f2(v: float | None) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{v:.2f}"
