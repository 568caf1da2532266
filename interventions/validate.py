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
   velocity) against the measured ones - R², RMS error in N or N/m, χ²/n against the map's sd,
   and the verdict of :mod:`fieldbank.fitting.quality` (the same rule a fit must pass);
3. **the change**: measured (the later maps - the model before) against predicted (the model
   after - the model before) at the same points: the RMS of each, and the realised fraction
   f = Σ w·Δm·Δp / Σ w·Δp² (w = 1/sd²: a weighted regression of the measured on the predicted
   change through the origin; 1 when the change came as predicted, 0 when nothing changed)
   with its standard error 1/√(Σ w·Δp²), per map and pooled over the session;
4. **the verdict** of the session: *prediction failed* when a map is poor against the
   prediction, or the change is measurable (SE ≤ :data:`MAX_CHANGE_SE`) and f lies outside
   1 ± :data:`CHANGE_TOLERANCE`; *prediction confirmed* when every map is good and the change
   is measurable and within the tolerance; *inconclusive* when the maps fit but the predicted
   change is too small against the noise to tell. A plan fails when any of its sessions fails.

Plans without a date were only explored: they are listed as not checked, with the reason, as
are plans whose patient has no later maps. :func:`validate_plans` reads the database;
:func:`check_session` is the pure computation, which reports also run
(:mod:`fieldbank.interventions.report`). Leaving one map out of a fit:
:mod:`fieldbank.fitting.crossval`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import date
from typing import Any

import numpy as np

from fieldbank.errors import FieldbankError
from fieldbank.fitting.problem import map_sd
from fieldbank.fitting.quality import DEFAULT_THRESHOLDS, MapFit, Thresholds, map_fit
from fieldbank.interventions.catalogue import Botulinum
from fieldbank.interventions.errors import InterventionError
from fieldbank.interventions.plan import Plan
from fieldbank.maps import FieldMap, model_map_like
from fieldbank.model import Arm
from fieldbank.modelsource import fit_behind
from fieldbank.params import ArmParams
from fieldbank.storage import Database, PlanRecord

#: A measured change within this fraction of the predicted one counts as predicted.
CHANGE_TOLERANCE = 0.5
#: The realised fraction is measurable when its standard error is at most this.
MAX_CHANGE_SE = 0.25

CONFIRMED = "prediction confirmed"
FAILED = "prediction failed"
INCONCLUSIVE = "inconclusive"
NOT_CHECKED = "not checked"


@dataclass(frozen=True, eq=False)
class LaterSession:
    """A session measured after a plan was given: label, date and its maps (id, map)."""

    label: str
    session_date: date
    maps: tuple[tuple[int, FieldMap], ...]


@dataclass(frozen=True)
class MapCheck:
    """One later map against the prediction (see the module docstring)."""

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
                "realised_fraction": self.realised_fraction, "realised_se": self.realised_se}


@dataclass(frozen=True)
class SessionCheck:
    """A plan's prediction against one later session."""

    session: str
    session_date: str
    weeks_after: float
    retimed: bool
    maps: tuple[MapCheck, ...]
    realised_fraction: float | None
    realised_se: float | None
    verdict: str
    reasons: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return {"session": self.session, "date": self.session_date,
                "weeks_after": self.weeks_after, "retimed": self.retimed,
                "verdict": self.verdict, "reasons": list(self.reasons),
                "realised_fraction": self.realised_fraction, "realised_se": self.realised_se,
                "maps": [m.to_dict() for m in self.maps]}

    @property
    def worst_chi2_per_value(self) -> float:
        return max((m.prediction.chi2_per_value for m in self.maps), default=math.nan)

    @property
    def lowest_r2(self) -> float:
        return min((m.prediction.r2 for m in self.maps), default=math.nan)


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
        verdicts = {s.verdict for s in self.sessions}
        if FAILED in verdicts:
            return FAILED
        return CONFIRMED if verdicts == {CONFIRMED} else INCONCLUSIVE

    def to_dict(self) -> dict[str, Any]:
        return {"plan_id": self.plan_id, "patient": self.patient, "label": self.label,
                "given_on": self.given_on, "before_model_id": self.before_model_id,
                "fit_id": self.fit_id, "verdict": self.verdict,
                "not_checked": self.not_checked,
                "sessions": [s.to_dict() for s in self.sessions]}


@dataclass(frozen=True)
class ValidationReport:
    """Every plan considered, and the overall verdict."""

    plans: tuple[PlanValidation, ...]
    tolerance: float = CHANGE_TOLERANCE
    max_se: float = MAX_CHANGE_SE

    @property
    def failed(self) -> tuple[PlanValidation, ...]:
        return tuple(p for p in self.plans if p.verdict == FAILED)

    @property
    def verdict(self) -> str:
        checked = [p for p in self.plans if p.verdict != NOT_CHECKED]
        if self.failed:
            return FAILED
        if not checked:
            return NOT_CHECKED
        return CONFIRMED if all(p.verdict == CONFIRMED for p in checked) else INCONCLUSIVE

    def to_dict(self) -> dict[str, Any]:
        return {"verdict": self.verdict, "change_tolerance": self.tolerance,
                "max_change_se": self.max_se,
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


def _fraction(dm: np.ndarray, dp: np.ndarray, w: np.ndarray) -> tuple[float | None, float | None]:
    den = float(np.sum(w * dp * dp))
    if den <= 0:
        return None, None
    return float(np.sum(w * dm * dp)) / den, 1.0 / math.sqrt(den)


def check_session(before: ArmParams, plan: Plan | None, stored_after: ArmParams, given: date,
                  later: LaterSession, *, tolerance: float = CHANGE_TOLERANCE,
                  max_se: float = MAX_CHANGE_SE,
                  thresholds: Thresholds = DEFAULT_THRESHOLDS) -> SessionCheck:
    """A plan's prediction against the maps of one later session (module docstring)."""
    weeks = (later.session_date - given).days / 7.0
    after, retimed = predicted_after(before, plan, stored_after, weeks)
    arm_b, arm_a = Arm.from_params(before), Arm.from_params(after)
    checks: list[MapCheck] = []
    reasons: list[str] = []
    sums = [0.0, 0.0]  # Σ w Δm Δp, Σ w Δp²
    for map_id, raw in later.maps:
        m = raw.as_arm_on_handle()
        label = f"map {map_id}"
        try:
            yb = model_map_like(arm_b, m).values
            ya = model_map_like(arm_a, m).values
        except FieldbankError as exc:
            reasons.append(f"{label}: not compared: {exc}")
            continue
        sd = map_sd(m)
        n = m.n
        pred = map_fit(0, m, ya, sd, thresholds, label=label)
        nochange = map_fit(0, m, yb, sd, thresholds, label=label)
        dp = (ya - yb).reshape(n, -1)
        dm = (m.values - yb).reshape(n, -1)
        w = 1.0 / sd**2
        f, se = _fraction(dm, dp, w)
        sums[0] += float(np.sum(w * dm * dp))
        sums[1] += float(np.sum(w * dp * dp))
        checks.append(MapCheck(
            int(map_id), m.kind, m.velocity_m_per_s, pred.unit, pred, nochange,
            float(np.sqrt(np.mean(dp**2))), float(np.sqrt(np.mean(dm**2))), f, se))
        reasons += list(pred.reasons)
    f_all = sums[0] / sums[1] if sums[1] > 0 else None
    se_all = 1.0 / math.sqrt(sums[1]) if sums[1] > 0 else None
    poor = [c for c in checks if c.prediction.verdict == "poor"]
    measurable = se_all is not None and se_all <= max_se
    change_off = measurable and f_all is not None and abs(f_all - 1.0) > tolerance
    if change_off:
        assert f_all is not None and se_all is not None
        word = "weaker" if f_all < 1 else "stronger"
        reasons.append(f"the measured change is {100 * f_all:.0f}% ± {100 * se_all:.0f}% of the "
                       f"predicted change ({word} than predicted; tolerance ±"
                       f"{100 * tolerance:.0f}%)")
    if not checks:
        verdict = INCONCLUSIVE
        reasons.append("no map of the session could be compared")
    elif poor or change_off:
        verdict = FAILED
    elif measurable:
        verdict = CONFIRMED
    else:
        verdict = INCONCLUSIVE
        reasons.append("the predicted change is too small against the maps' noise to check "
                       + ("(the plan predicts no change of these maps)" if f_all is None else
                          f"(realised fraction {f_all:.2f} ± {se_all:.2f})"))
    return SessionCheck(later.label, later.session_date.isoformat(), weeks, retimed,
                        tuple(checks), f_all, se_all, verdict, tuple(reasons))


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
                      why)


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
                                   tolerance=tolerance, max_se=max_se) for s in inputs.later)
    return dataclasses.replace(head, sessions=sessions)


def validate_plans(db: Database, patients: Sequence[str] = (), plan_ids: Sequence[int] = (),
                   *, tolerance: float = CHANGE_TOLERANCE,
                   max_se: float = MAX_CHANGE_SE) -> ValidationReport:
    """Check stored plans (all, a patient's, or the given ids) against later maps.

    Raises
    ------
    InterventionError
        Nothing to consider: no stored plans (for these patients).
    """
    if not 0 < tolerance < 10 or not 0 < max_se < 10:
        raise InterventionError(f"validate: tolerance and maximal SE must be in (0, 10); got "
                                f"{tolerance!r} and {max_se!r}.")
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
    checks = tuple(check_plan(read_plan_inputs(db, r), tolerance=tolerance, max_se=max_se)
                   for r in records)
    return ValidationReport(checks, tolerance, max_se)
