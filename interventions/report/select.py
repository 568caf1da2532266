"""Which stored plans a report covers.

A case is one stored plan (``plans`` table): its base model is "before", its result model
"after". A case's sessions are those of the measured maps its base model was fitted to (the
first fitted model in the base model's lineage, through its fit record); its date is the latest
of those session dates, else the day the plan was stored (UTC). A :class:`Selection` keeps the
cases that match every filter given:

* ``patients`` - patient codes;             * ``plan_ids`` - plan ids;
* ``sessions`` - any of the case's session labels is one of these;
* ``since`` / ``until`` - the case's date lies in [since, until];
* ``kinds`` - the plan has a step of one of these intervention kinds.

:func:`select_cases` reads everything a case needs into a picklable :class:`CaseSpec` - the
two parameter sets and the plan, already read; the report of the fit behind the model before;
and, for a plan recorded as given, the maps measured after it
(:func:`fieldbank.interventions.validate.read_plan_inputs`) - so the computation can run in
other processes without the database.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import date
from typing import Any, cast

from fieldbank.interventions.errors import InterventionError, SelectionError
from fieldbank.interventions.guesses import IntervalSet
from fieldbank.interventions.plan import Plan
from fieldbank.interventions.validate import PlanInputs, read_plan_inputs
from fieldbank.params import ArmParams
from fieldbank.storage import Database, FitRecord, StoredModel
from fieldbank.stored.records import PatientInfo, StoredMap


@dataclass(frozen=True)
class Selection:
    """Filters over stored plans; an empty filter matches everything."""

    patients: tuple[str, ...] = ()
    plan_ids: tuple[int, ...] = ()
    sessions: tuple[str, ...] = ()
    since: date | None = None
    until: date | None = None
    kinds: tuple[str, ...] = ()

    def describe(self) -> str:
        parts = []
        if self.patients:
            parts.append("patients " + ", ".join(self.patients))
        if self.plan_ids:
            parts.append("plans " + ", ".join(str(i) for i in self.plan_ids))
        if self.sessions:
            parts.append("sessions " + ", ".join(self.sessions))
        if self.since:
            parts.append(f"since {self.since.isoformat()}")
        if self.until:
            parts.append(f"until {self.until.isoformat()}")
        if self.kinds:
            parts.append("kinds " + ", ".join(self.kinds))
        return "; ".join(parts) if parts else "every stored plan"

    def to_dict(self) -> dict[str, Any]:
        return {"patients": list(self.patients), "plan_ids": list(self.plan_ids),
                "sessions": list(self.sessions),
                "since": self.since.isoformat() if self.since else None,
                "until": self.until.isoformat() if self.until else None,
                "kinds": list(self.kinds)}


@dataclass(frozen=True)
class CaseSpec:
    """Everything one case needs, read from the database (picklable, no database handle).

    ``plan`` is the stored plan document read back (None when it cannot be read: the case is
    then reported without its steps and time course); ``plan_doc`` the document as stored.
    """

    plan_id: int
    patient_code: str | None
    patient: dict[str, Any]
    plan_label: str
    plan_doc: dict[str, Any]
    plan: Plan | None
    kinds: tuple[str, ...]
    base_model_id: int
    base_origin: str
    base_label: str
    before: ArmParams
    result_model_id: int
    after: ArmParams
    sessions: tuple[tuple[str, str | None], ...]
    case_date: str
    fit_id: int | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    #: The stored report of fit ``fit_id`` and the fitted model it produced.
    fit_report: dict[str, Any] | None = None
    fitted_model_id: int | None = None
    #: What checking the plan against later maps needs (None: not read).
    checks: PlanInputs | None = None
    #: A poor fit behind the model before was accepted by the user.
    accept_poor_fit: bool = False
    #: The case's prediction intervals as kept with its fit (None: to be computed).
    intervals: IntervalSet | None = None

    @property
    def title(self) -> str:
        who = self.patient_code or "no patient"
        return f"{who} — plan {self.plan_id}: {self.plan_label or ', '.join(self.kinds)}"


def plan_kinds(spec: Mapping[str, Any]) -> tuple[str, ...]:
    """Step kinds of a stored plan record's spec (the lineage document of ``whatif --save``)."""
    doc = spec.get("plan", spec)
    steps = doc.get("steps", []) if isinstance(doc, dict) else doc
    if not isinstance(steps, list):
        return ()
    return tuple(sorted({str(s.get("kind")) for s in steps if isinstance(s, dict)}))


def read_plan(spec: Mapping[str, Any], plan_id: int) -> Plan | None:
    """The stored plan record's plan, or None if it cannot be read back."""
    doc = spec.get("plan", spec)
    try:
        return Plan.from_dict(doc, where=f"plan {plan_id}")
    except InterventionError:
        return None


class _ReadOnce:
    """The records one selection reads from ``db``, each read once: a case's models, its
    patient's fits and maps are asked for by the selection and again by
    :func:`~fieldbank.interventions.validate.read_plan_inputs` (stored records do not change;
    a selection is a moment's view). Everything else goes to the database."""

    def __init__(self, db: Database) -> None:
        self._db = db
        self._seen: dict[tuple[Any, ...], Any] = {}

    def __getattr__(self, name: str) -> Any:
        return getattr(self._db, name)

    def _once(self, key: tuple[Any, ...], read: Any) -> Any:
        if key not in self._seen:
            self._seen[key] = read()
        return self._seen[key]

    def get_model(self, model_id: int) -> StoredModel:
        return self._once(("model", model_id),
                          lambda: self._db.get_model(model_id))

    def model_lineage(self, model_id: int) -> list[StoredModel]:
        return self._once(("lineage", model_id),
                          lambda: self._db.model_lineage(model_id))

    def list_fits(self, patient_code: str) -> list[FitRecord]:
        return self._once(("fits", patient_code),
                          lambda: self._db.list_fits(patient_code))

    def list_maps(self, patient_code: str, session_label: str | None = None) -> list[StoredMap]:
        return self._once(("maps", patient_code, session_label),
                          lambda: self._db.list_maps(patient_code, session_label))


def _fitted_ancestor(db: Database, model_id: int) -> StoredModel | None:
    for m in db.model_lineage(model_id):
        if m.origin == "fitted":
            return m
    return None


def select_cases(db: Database, selection: Selection, checks: bool = True) -> list[CaseSpec]:
    """The cases matching ``selection``, ordered by patient code then plan id; ``checks``:
    with what checking each plan against later maps needs (a command whose cases a cluster's
    workers compute leaves it to them: they read it themselves).

    Raises
    ------
    SelectionError
        Nothing matches (the message says which filter and what is stored), or a named patient
        or plan has no data to report (no plans; no fitted model).
    """
    db = cast(Database, _ReadOnce(db))
    for named in selection.patients:
        db.get_patient(named)  # an unknown patient: the storage layer's clear error
    plans = []
    if selection.plan_ids:
        plans = [db.get_plan(int(i)) for i in selection.plan_ids]
    elif selection.patients:
        for named in selection.patients:
            found = db.list_plans(named)
            if not found:
                models = db.list_models(named)
                fitted = [m for m in models if m.origin == "fitted"]
                what = ("no stored plans" if fitted else
                        "no fitted model and no stored plans")
                raise SelectionError(
                    f"Patient {named!r} has {what} in {db.url_masked}: "
                    + ("" if fitted else f"fit one with 'fieldbank fit {named}', then ")
                    + f"store a plan with 'fieldbank whatif {named} --botox ef=200U --save'.")
            plans.extend(found)
    else:
        plans = db.list_plans()
    if not plans:
        raise SelectionError(f"No stored plans in {db.url_masked}: store one with "
                             "'fieldbank whatif PATIENT --botox ef=200U --save'.")
    fits_by_model: dict[int, FitRecord] = {}
    maps_by_id: dict[int, StoredMap] = {}
    patients: dict[str, PatientInfo] = {}
    cases = []
    for plan in plans:
        code = plan.patient_code
        if selection.patients and code not in selection.patients:
            continue
        if code is not None and code not in patients:
            patients[code] = db.get_patient(code)
            for f in db.list_fits(code):
                fits_by_model[f.model_id] = f
            for stored_map in db.list_maps(code):
                maps_by_id[stored_map.id] = stored_map
        kinds = plan_kinds(plan.spec)
        if selection.kinds and not set(kinds) & set(selection.kinds):
            continue
        base = db.get_model(plan.base_model_id)
        result = db.get_model(plan.result_model_id)
        ancestor = _fitted_ancestor(db, base.id)
        fit = fits_by_model.get(ancestor.id) if ancestor is not None else None
        sessions: dict[str, str | None] = {}
        if fit is not None:
            for mid in fit.map_ids:
                m = maps_by_id.get(mid)
                if m is not None:
                    sessions[m.session_label] = (m.session_date.isoformat()
                                                 if m.session_date else None)
        dates = sorted(d for d in sessions.values() if d)
        case_date = dates[-1] if dates else plan.created_at.date().isoformat()
        if selection.sessions and not set(sessions) & set(selection.sessions):
            continue
        if selection.since and case_date < selection.since.isoformat():
            continue
        if selection.until and case_date > selection.until.isoformat():
            continue
        p = patients.get(code) if code else None
        cases.append(CaseSpec(
            plan_id=plan.id, patient_code=code,
            patient=({"code": p.code, "body_mass_kg": p.body_mass_kg, "height_m": p.height_m,
                      "side": p.side} if p else {}),
            plan_label=plan.label, plan_doc=dict(plan.spec),
            plan=read_plan(plan.spec, plan.id), kinds=kinds,
            base_model_id=base.id, base_origin=base.origin, base_label=base.label,
            before=base.params, result_model_id=result.id, after=result.params,
            sessions=tuple(sorted(sessions.items())), case_date=case_date,
            fit_id=fit.id if fit is not None else None,
            fit_report=dict(fit.result) if fit is not None else None,
            fitted_model_id=ancestor.id if ancestor is not None and fit is not None else None,
            checks=read_plan_inputs(db, plan) if checks else None))
    if not cases:
        raise SelectionError(
            f"No stored plan matches the selection ({selection.describe()}) in "
            f"{db.url_masked}; {len(plans)} plan(s) were considered.")
    cases.sort(key=lambda c: (c.patient_code or "", c.plan_id))
    return cases
