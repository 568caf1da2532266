"""Is a prediction right? Stored plans checked against the maps measured after them (BRIEF §14).

For each stored plan that was carried out - its document records ``given_on``, the day
(``fieldbank whatif --save --given-on DATE``; the demo stores the sample patients' plans so) -
and each later session of its patient with maps (dated after that day, and not a session the
model before was fitted to):

1. **the predicted after-model**: the plan applied to the model before, re-timed to the
   session - botulinum steps are seen (session date - given_on) weeks after the injection
   (:meth:`~fieldbank.interventions.plan.Plan.at_week`), so an injection measured at 8 weeks
   is not judged by its 5-week prediction; other steps do not change with time;
2. **per measured map**: the predicted after-model's values at the map's positions (and
   velocity) against the measured ones - R², RMS error in N or N/m, χ²/n against the map's sd
   widened by the fit's spread of the prediction, the verdict of
   :mod:`fieldbank.fitting.quality`; how far the predicted change moves the map (sd); a map
   stored twice (one measurement from two files) is counted once;
3. **the change**: the realised fraction f of the predicted change (measured ÷ predicted, 1 as
   predicted, 0 none), its SE from the later maps' noise and the fit's parameter samples
   together, and whether the maps can see the change at all
   (:mod:`fieldbank.interventions.realised`, which states the verdict's rules and numbers);
4. **the verdict** of the session: *prediction confirmed*, *partial effect*, *prediction
   failed* or *inconclusive* (:class:`~fieldbank.interventions.realised.Rules`). A plan
   fails when any of its sessions fails, is partial when one shows a partial effect and none
   fails, is confirmed when a session confirms it and none contradicts it.

Plans without a date were only explored: they are listed as not checked, with the reason, as
are plans whose patient has no later maps. :func:`validate_plans` reads the database
(:func:`read_plan_inputs` per plan, then :func:`check_plan`); :func:`check_session` is the pure
computation, which reports also run (:mod:`fieldbank.interventions.report`). Every step is
deterministic: the same inputs give the same bytes in any process. Leaving one map out of a
fit: :mod:`fieldbank.fitting.crossval`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import date
from typing import Any

import numpy as np

from fieldbank.errors import FieldbankError
from fieldbank.fitting.quality import DEFAULT_THRESHOLDS, MapFit, Thresholds
from fieldbank.interventions.catalogue import Botulinum
from fieldbank.interventions.errors import InterventionError
from fieldbank.interventions.plan import Plan
from fieldbank.interventions.realised import (
    CONFIRMED,
    CONTRADICTED,
    DEFAULT_RULES,
    FAILED,
    INCONCLUSIVE,
    MAX_REPORTED_SE,
    NOT_CHECKED,
    OVER,
    PARTIAL,
    Fraction,
    MapChange,
    Rules,
    fraction_of,
    guesses_explain,
    map_changes,
    physical_range,
    positions_of,
    treated,
)
from fieldbank.interventions.spread import NO_FIT, FitSpread, first_session_se
from fieldbank.interventions.suggest import suggestion
from fieldbank.interventions.verdict import Evidence, judge
from fieldbank.interventions.whatifchoices import CHANGE_TOLERANCE, MAX_CHANGE_SE
from fieldbank.maps import FieldMap
from fieldbank.modelsource import fit_behind
from fieldbank.params import ArmParams
from fieldbank.storage import Database
from fieldbank.stored.records import PlanRecord

__all__ = [
    "LaterSession", "MapCheck", "PlanInputs",
    "PlanValidation", "SessionCheck", "ValidationReport", "check_plan", "check_session",
    "given_on", "predicted_after", "read_plan_inputs", "validate_plans",
]


@dataclass(frozen=True, eq=False)
class LaterSession:
    """A session measured after a plan was given: label, date and its maps (id, map)."""

    label: str
    session_date: date
    maps: tuple[tuple[int, FieldMap], ...]


def _num(v: float | None) -> float | None:
    return None if v is None or not math.isfinite(v) else float(v)


@dataclass(frozen=True)
class MapCheck:
    """One later map against the prediction (see the module docstring).

    ``realised_fraction`` and ``realised_se`` are None where this map alone cannot see the
    predicted change, the prediction rests on a guess, or the fraction lies outside the plan's
    physical range; ``sensitivity_sd`` is how far the predicted change moves the map, in sd.
    """

    map_id: int
    kind: str
    velocity_m_per_s: tuple[float, float]
    unit: str
    prediction: MapFit
    no_change: MapFit
    predicted_change_rms: float
    measured_change_rms: float
    realised_fraction: float | None
    realised_se: float | None
    sensitivity_sd: float = 0.0
    duplicate_of: int | None = None

    def to_dict(self) -> dict[str, Any]:
        p = self.prediction
        return {"map_id": self.map_id, "kind": self.kind,
                "velocity_m_per_s": list(self.velocity_m_per_s), "unit": self.unit,
                "n_values": p.n_values, "r2": p.r2, "rms_error": p.rms_residual,
                "chi2_per_value": p.chi2_per_value, "chi2_limit": p.chi2_limit,
                "verdict": p.verdict, "reasons": list(p.reasons),
                "no_change_chi2_per_value": self.no_change.chi2_per_value,
                "predicted_change_rms": self.predicted_change_rms,
                "measured_change_rms": self.measured_change_rms,
                "sensitivity_sd": self.sensitivity_sd,
                "realised_fraction": self.realised_fraction, "realised_se": self.realised_se,
                "duplicate_of": self.duplicate_of}


@dataclass(frozen=True)
class SessionCheck:
    """A plan's prediction against one later session.

    ``realised_fraction``/``realised_se``: pooled over the session's maps, None when not
    reported (module docstring of :mod:`~fieldbank.interventions.realised`);
    ``noise_se``/``fit_se``: the two parts of the SE; ``sensitivity_sd``: how far the predicted
    change moves the maps (sd); ``interval``: f ± z SE; ``guessed``: parameters the change
    rests on that the fit did not identify; ``suggestion``: the measurement that would decide
    when these maps cannot; ``fit_uncertainty``: what the fit part rests on.
    """

    session: str
    session_date: str
    weeks_after: float
    retimed: bool
    maps: tuple[MapCheck, ...]
    realised_fraction: float | None
    realised_se: float | None
    verdict: str
    reasons: tuple[str, ...]
    noise_se: float | None = None
    fit_se: float | None = None
    sensitivity_sd: float = 0.0
    interval: tuple[float, float] | None = None
    physical_range: tuple[float, float] = (-1.0, 3.0)
    treated: tuple[str, ...] = ()
    guessed: tuple[str, ...] = ()
    suggestion: str = ""
    fit_uncertainty: str = ""
    rules: Rules = field(default=DEFAULT_RULES)
    #: The verdict was read from the realised fraction's interval (the rules of
    #: :func:`~fieldbank.interventions.verdict.decide`).
    decided: bool = False

    def to_dict(self) -> dict[str, Any]:
        return {"session": self.session, "date": self.session_date,
                "weeks_after": self.weeks_after, "retimed": self.retimed,
                "verdict": self.verdict, "reasons": list(self.reasons),
                "realised_fraction": self.realised_fraction, "realised_se": self.realised_se,
                "noise_se": self.noise_se, "fit_se": self.fit_se,
                "interval": list(self.interval) if self.interval is not None else None,
                "sensitivity_sd": self.sensitivity_sd,
                "physical_range": list(self.physical_range), "treated": list(self.treated),
                "guessed": list(self.guessed), "suggestion": self.suggestion or None,
                "fit_uncertainty": self.fit_uncertainty, "decided": self.decided,
                "maps": [m.to_dict() for m in self.maps]}

    @property
    def worst_chi2_per_value(self) -> float:
        return max((m.prediction.chi2_per_value for m in self.maps if m.duplicate_of is None),
                   default=math.nan)

    @property
    def lowest_r2(self) -> float:
        return min((m.prediction.r2 for m in self.maps if m.duplicate_of is None),
                   default=math.nan)


def plan_verdict(verdicts: Sequence[str]) -> str:
    """A plan's verdict from its sessions': failed before partial before confirmed (by one
    session, contradicted by none) before inconclusive; not checked without sessions."""
    found = set(verdicts)
    for v in (FAILED, OVER, PARTIAL, CONFIRMED):
        if v in found:
            return v
    return INCONCLUSIVE if found else NOT_CHECKED


@dataclass(frozen=True)
class PlanValidation:
    """One stored plan: its sessions checked, or why it was not checked."""

    plan_id: int
    patient: str | None
    label: str
    given_on: str | None
    before_model_id: int
    fit_id: int | None
    sessions: tuple[SessionCheck, ...] = ()
    not_checked: str | None = None

    @property
    def verdict(self) -> str:
        if self.not_checked is not None or not self.sessions:
            return NOT_CHECKED
        return plan_verdict([s.verdict for s in self.sessions])

    def to_dict(self) -> dict[str, Any]:
        return {"plan_id": self.plan_id, "patient": self.patient, "label": self.label,
                "given_on": self.given_on, "before_model_id": self.before_model_id,
                "fit_id": self.fit_id, "verdict": self.verdict,
                "not_checked": self.not_checked,
                "sessions": [s.to_dict() for s in self.sessions]}


@dataclass(frozen=True)
class ValidationReport:
    """Every plan considered, and the one overall verdict."""

    plans: tuple[PlanValidation, ...]
    tolerance: float = CHANGE_TOLERANCE
    max_se: float = MAX_CHANGE_SE

    @property
    def rules(self) -> Rules:
        return dataclasses.replace(DEFAULT_RULES, tolerance=self.tolerance, max_se=self.max_se)

    @property
    def failed(self) -> tuple[PlanValidation, ...]:
        return tuple(p for p in self.plans if p.verdict == FAILED)

    @property
    def contradicted(self) -> tuple[PlanValidation, ...]:
        """Plans whose prediction the later maps contradict (failed or partial): exit 1."""
        return tuple(p for p in self.plans if p.verdict in CONTRADICTED)

    @property
    def counts(self) -> dict[str, int]:
        out = dict.fromkeys((CONFIRMED, OVER, PARTIAL, FAILED, INCONCLUSIVE, NOT_CHECKED), 0)
        for p in self.plans:
            out[p.verdict] += 1
        return out

    @property
    def verdict(self) -> str:
        """Failed when a plan failed; else partial when one came out partial; else confirmed
        when every checked plan was; not checked when none was; else inconclusive."""
        verdicts = {p.verdict for p in self.plans}
        for v in CONTRADICTED:
            if v in verdicts:
                return v
        checked = verdicts - {NOT_CHECKED}
        if not checked:
            return NOT_CHECKED
        return CONFIRMED if checked == {CONFIRMED} else INCONCLUSIVE

    def to_dict(self) -> dict[str, Any]:
        return {"verdict": self.verdict, "counts": self.counts,
                "contradicted": [p.plan_id for p in self.contradicted],
                "change_tolerance": self.tolerance, "max_change_se": self.max_se,
                "rules": self.rules.to_dict(), "rules_text": self.rules.lines(),
                "thresholds": DEFAULT_THRESHOLDS.to_dict(),
                "plans": [p.to_dict() for p in self.plans]}


def given_on(spec: dict[str, Any]) -> date | None:
    """The day a stored plan was carried out (its document's ``given_on``), if recorded."""
    raw = spec.get("given_on")
    if not raw:
        return None
    try:
        return date.fromisoformat(str(raw))
    except ValueError:
        return None


def predicted_after(before: ArmParams, plan: Plan | None, stored_after: ArmParams,
                    weeks: float) -> tuple[ArmParams, bool]:
    """The after-model at ``weeks`` after the plan was given, and whether it was re-timed."""
    if plan is None or not any(isinstance(s, Botulinum) for s in plan.steps):
        return stored_after, False
    return plan.at_week(max(weeks, 0.0)).apply(before), True


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(a**2))) if a.size else 0.0


def _reportable(f: Fraction, rules: Rules, guessed: Sequence[str],
                limits: tuple[float, float]) -> bool:
    return (f.value is not None and f.sensitivity_sd >= rules.min_sensitivity and not guessed
            and limits[0] <= f.value <= limits[1] and f.se is not None
            and f.se <= max(MAX_REPORTED_SE, rules.max_se))


def _map_check(c: MapChange, rules: Rules, thresholds: Thresholds, guessed: Sequence[str],
               limits: tuple[float, float]) -> MapCheck:
    label = f"map {c.map_id}"
    pred = c.check(1.0, thresholds, label)
    nochange = c.check(0.0, thresholds, label)
    f = fraction_of([dataclasses.replace(c, duplicate_of=None)])
    shown = _reportable(f, rules, guessed, limits)
    m = c.measured
    return MapCheck(c.map_id, m.kind, m.velocity_m_per_s, pred.unit, pred, nochange,
                    _rms(c.after - c.before), _rms(c.y - c.before),
                    f.value if shown else None, _num(f.se) if shown else None,
                    f.sensitivity_sd, c.duplicate_of)


def check_session(before: ArmParams, plan: Plan | None, stored_after: ArmParams, given: date,
                  later: LaterSession, *, tolerance: float = CHANGE_TOLERANCE,
                  max_se: float = MAX_CHANGE_SE,
                  thresholds: Thresholds = DEFAULT_THRESHOLDS,
                  spread: FitSpread = NO_FIT) -> SessionCheck:
    """A plan's prediction against the maps of one later session (module docstring).

    ``spread``: the fit's samples of the model before (:class:`FitSpread`); without them the
    SE counts the later maps' noise only, and the session says so.
    """
    rules = dataclasses.replace(DEFAULT_RULES, tolerance=tolerance, max_se=max_se)
    weeks = (later.session_date - given).days / 7.0
    after, retimed = predicted_after(before, plan, stored_after, weeks)
    note = spread.note
    pairs: list[tuple[ArmParams, ArmParams]] = []
    if spread.samples and plan is not None:
        timed = plan.at_week(max(weeks, 0.0)) if retimed else plan
        pairs = [(p, timed.apply(p)) for p in spread.samples]
    elif spread.samples:
        note = "the plan document could not be read: the SE counts the later maps' noise only"
    changes, reasons = map_changes(before, after, later.maps, pairs)
    what = treated(before, after)
    floor = first_session_se(spread, before, after)
    treated_names = [n for t in what for n in t.names]
    guessed = tuple(n for n in treated_names
                    if n in spread.unidentified and n not in spread.varied)
    # the prediction rests on guesses alone when every treated group's change is guessed
    all_guessed = bool(what) and all(any(n in guessed for n in t.names) for t in what)
    limits = physical_range(before, after)
    f = dataclasses.replace(fraction_of(changes), first_se=floor)
    blocked = guessed if all_guessed else ()
    shown = _reportable(f, rules, blocked, limits)
    checks = tuple(_map_check(c, rules, thresholds, blocked, limits) for c in changes)
    words = " and ".join(t.words for t in what) or "model"
    # the maps against the model before + f × the predicted change: what f cannot explain
    seen = f.value is not None and f.sensitivity_sd >= rules.min_sensitivity
    scale = (min(max(f.value, max(limits[0], 0.0)), limits[1])
             if seen and f.value is not None else 1.0)
    poor = [(c, c.check(scale, thresholds, f"map {c.map_id}")) for c in changes
            if c.duplicate_of is None]
    unexplained = [u for _, u in poor if u.verdict == "poor"]
    untested = (guesses_explain(changes, before, spread.held, scale, thresholds)
                if unexplained else ())
    # a misfit where the model before was never fitted may be the model's, not a change
    elsewhere = [c.map_id for c, u in poor if u.verdict == "poor" and not spread.covers(c.measured)]
    se = _num(f.se)
    interval = None
    if shown:
        assert f.value is not None and se is not None
        interval = (f.value - rules.z * se, f.value + rules.z * se)
    evidence = Evidence(
        compared=bool(changes), fraction=f, shown=shown, limits=limits, treated=words,
        unexplained=tuple(tuple(u.reasons) for u in unexplained), untested=tuple(untested),
        elsewhere=tuple(elsewhere), scale=scale, guessed=guessed, all_guessed=all_guessed,
        all_held=all(n in spread.held for n in guessed), fit_id=spread.fit_id,
        advise=lambda: suggestion(before, after, positions_of(changes), what))
    v = judge(evidence, rules)
    return SessionCheck(
        session=later.label, session_date=later.session_date.isoformat(), weeks_after=weeks,
        retimed=retimed, maps=checks, realised_fraction=f.value if shown else None,
        realised_se=se if shown else None, verdict=v.verdict, reasons=(*reasons, *v.reasons),
        noise_se=_num(f.noise_se) if seen else None, fit_se=_num(f.fit_part) if seen else None,
        sensitivity_sd=f.sensitivity_sd, interval=interval, physical_range=limits,
        treated=tuple(t.words for t in what), guessed=guessed, suggestion=v.advice,
        fit_uncertainty=note, rules=rules, decided=v.decided)


@dataclass(frozen=True, eq=False)
class PlanInputs:
    """What checking one stored plan needs, read from the database (picklable)."""

    record: PlanRecord
    plan: Plan | None
    before: ArmParams
    after: ArmParams
    given_on: date | None
    fit_id: int | None
    later: tuple[LaterSession, ...]
    not_checked: str | None
    #: The fit's samples of the model before, and what it did not identify.
    spread: FitSpread = NO_FIT


def _fit_maps(db: Database, map_ids: Sequence[int]) -> tuple[FieldMap, ...]:
    """The maps a fit used; none when one of them is gone."""
    try:
        return tuple(db.get_maps(list(map_ids)))
    except FieldbankError:
        return ()


def read_plan_inputs(db: Database, record: PlanRecord) -> PlanInputs:
    """The plan, its two models, the fit behind it and the later sessions with their maps."""
    doc = record.spec.get("plan", record.spec)
    try:
        plan: Plan | None = Plan.from_dict(doc, where=f"plan {record.id}")
    except InterventionError:
        plan = None
    before = db.get_model(record.base_model_id).params
    after = db.get_model(record.result_model_id).params
    found = fit_behind(db, record.base_model_id)
    fit = found[0] if found else None
    spread = NO_FIT if found is None else FitSpread.from_report(
        found[0].id, found[0].result, before, found[1] == record.base_model_id, found[1],
        _fit_maps(db, found[0].map_ids))
    day = given_on(record.spec)
    if record.patient_code is None:
        return PlanInputs(record, plan, before, after, day, None, (),
                          "the plan belongs to no patient")
    if day is None:
        return PlanInputs(record, plan, before, after, None, fit.id if fit else None, (),
                          "not recorded as given (a what-if only explored); store a plan that "
                          "was carried out with 'fieldbank whatif ... --save --given-on DATE'")
    fitted_sessions: set[str] = set()
    if fit is not None:
        fitted_sessions = {m.session_label for m in db.list_maps(record.patient_code)
                           if m.id in set(fit.map_ids)}
    later = []
    for s in db.list_sessions(record.patient_code):
        if s.n_maps == 0 or s.session_date is None or s.session_date <= day \
                or s.label in fitted_sessions:
            continue
        stored = db.list_maps(record.patient_code, s.label)
        maps = db.get_maps([m.id for m in stored])
        later.append(LaterSession(s.label, s.session_date,
                                  tuple((m.id, fm) for m, fm in zip(stored, maps, strict=True))))
    why = None if later else (f"patient {record.patient_code} has no maps dated after "
                              f"{day.isoformat()}, the day the plan was given")
    return PlanInputs(record, plan, before, after, day, fit.id if fit else None, tuple(later),
                      why, spread)


def check_plan(inputs: PlanInputs, *, tolerance: float = CHANGE_TOLERANCE,
               max_se: float = MAX_CHANGE_SE) -> PlanValidation:
    """Every later session of one plan (:func:`check_session`)."""
    r = inputs.record
    day = inputs.given_on
    head = PlanValidation(r.id, r.patient_code, r.label, day.isoformat() if day else None,
                          r.base_model_id, inputs.fit_id)
    if inputs.not_checked is not None or day is None:
        return dataclasses.replace(head, not_checked=inputs.not_checked or "no date")
    sessions = tuple(check_session(inputs.before, inputs.plan, inputs.after, day, s,
                                   tolerance=tolerance, max_se=max_se, spread=inputs.spread)
                     for s in inputs.later)
    return dataclasses.replace(head, sessions=sessions)


def check_rule_numbers(tolerance: float, max_se: float) -> None:
    """InterventionError unless the verdict's tolerance and maximal SE are in (0, 10)."""
    if not 0 < tolerance < 10 or not 0 < max_se < 10:
        raise InterventionError(f"validate: tolerance and maximal SE must be in (0, 10); got "
                                f"{tolerance!r} and {max_se!r}.")


def plans_to_check(db: Database, patients: Sequence[str] = (),
                   plan_ids: Sequence[int] = ()) -> list[PlanRecord]:
    """The stored plans a check considers: ``plan_ids`` if given, else every plan of
    ``patients``, else every plan; in that order.

    Raises
    ------
    InterventionError
        Nothing to consider: no stored plans (for these patients).
    """
    for code in patients:
        db.get_patient(code)  # an unknown patient: the storage layer's clear error
    if plan_ids:
        records = [db.get_plan(int(i)) for i in plan_ids]
    elif patients:
        records = [p for code in patients for p in db.list_plans(code)]
    else:
        records = db.list_plans()
    if not records:
        who = f"patients {', '.join(patients)}" if patients else "the database"
        raise InterventionError(f"validate: {who} has no stored plans; store one with "
                                "'fieldbank whatif PATIENT --botox ef=150U --save --given-on "
                                "DATE'.")
    return records


def validate_plans(db: Database, patients: Sequence[str] = (), plan_ids: Sequence[int] = (),
                   *, tolerance: float = CHANGE_TOLERANCE,
                   max_se: float = MAX_CHANGE_SE) -> ValidationReport:
    """Check stored plans (all, a patient's, or the given ids) against later maps.

    Raises
    ------
    InterventionError
        Nothing to consider: no stored plans (for these patients).
    """
    check_rule_numbers(tolerance, max_se)
    records = plans_to_check(db, patients, plan_ids)
    checks = tuple(check_plan(read_plan_inputs(db, r), tolerance=tolerance, max_se=max_se)
                   for r in records)
    return ValidationReport(checks, tolerance, max_se)
