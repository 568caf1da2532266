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

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import date
from typing import Any, cast

from fieldbank.interventions.errors import InterventionError, SelectionError
from fieldbank.interventions.guesses import IntervalSet
from fieldbank.interventions.plan import Plan
from fieldbank.interventions.validate import PlanInputs, given_on, read_plan_inputs
from fieldbank.maps import FieldMap
from fieldbank.modelsource import fit_behind
from fieldbank.params import ArmParams
from fieldbank.storage import Database, FitRecord, SessionInfo, StoredModel
from fieldbank.storage.lineage import walk_lineage
from fieldbank.stored.records import PatientInfo, PlanRecord, StoredMap


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


#: Plans whose records one round of set-based reads covers (a cohort is read in such chunks).
CHUNK_PLANS = 200


class _CohortReads:
    """The records a selection reads, read set-based: for a chunk of plans, their patients,
    fits, map listings and models (with the ancestors of the models before) in one query per
    table (:meth:`read_records`), then for the cases kept the sessions and the maps the plan
    checks need (:meth:`read_checks`). It answers the :class:`~fieldbank.storage.Database`
    methods the selection and :func:`~fieldbank.interventions.validate.read_plan_inputs` ask
    (stored records do not change; a selection is a moment's view) with what those return;
    anything it has not read, and everything else, goes to the database."""

    def __init__(self, db: Database) -> None:
        self._db = db
        self._patients: dict[str, PatientInfo] = {}
        self._fits: dict[str, list[FitRecord]] = {}
        self._maps: dict[str, list[StoredMap]] = {}
        self._models: dict[int, StoredModel] = {}
        self._sessions: dict[str, list[SessionInfo]] = {}
        self._arrays: dict[int, FieldMap] = {}

    def __getattr__(self, name: str) -> Any:
        return getattr(self._db, name)

    def read_records(self, plans: Sequence[PlanRecord]) -> None:
        """Patients, fits, map listings and models of ``plans``."""
        codes = sorted({p.patient_code for p in plans if p.patient_code is not None}
                       - set(self._patients))
        if codes:
            self._patients.update(self._db.patients_by_code(codes))
            self._fits.update(self._db.fits_of(codes))
            for code in codes:
                self._maps[code] = []
            for m in self._db.maps_of(codes):
                self._maps[m.patient_code].append(m)
        wanted = {i for p in plans for i in (p.base_model_id, p.result_model_id)}
        while missing := sorted(wanted - set(self._models)):  # a generation per query
            got = self._db.get_models(missing)
            self._models.update(got)
            wanted = {m.parent_id for m in got.values() if m.parent_id is not None}

    def read_checks(self, plans: Sequence[PlanRecord]) -> None:
        """The sessions of ``plans``' patients and the maps their checks read: the maps of
        the fit behind each model before, and those of the sessions after the day a plan was
        given."""
        codes = sorted({p.patient_code for p in plans if p.patient_code is not None}
                       - set(self._sessions))
        for code in codes:
            self._sessions[code] = []
        for x in self._db.sessions_of(codes) if codes else ():
            self._sessions[x.patient_code].append(x)
        ids: set[int] = set()
        for p in plans:
            found = fit_behind(cast(Database, self), p.base_model_id)
            if found is not None:
                ids.update(found[0].map_ids)
            day = given_on(p.spec)
            if p.patient_code is None or day is None:
                continue
            later = {x.label for x in self._sessions.get(p.patient_code, ())
                     if x.session_date is not None and x.session_date > day}
            ids.update(m.id for m in self._maps.get(p.patient_code, ())
                       if m.session_label in later)
        ids -= set(self._arrays)
        if ids:
            self._arrays.update(self._db.maps_by_id(sorted(ids)))

    # --- the Database methods answered from what was read ----------------------------------
    def get_patient(self, code: str) -> PatientInfo:
        found = self._patients.get(code)
        return found if found is not None else self._db.get_patient(code)

    def get_model(self, model_id: int) -> StoredModel:
        found = self._models.get(model_id)
        return found if found is not None else self._db.get_model(model_id)

    def model_lineage(self, model_id: int) -> list[StoredModel]:
        """As :meth:`Database.model_lineage` (the model and its ancestors, newest first)."""
        return walk_lineage(model_id, self.get_model)

    def list_fits(self, patient_code: str | None = None) -> list[FitRecord]:
        found = self._fits.get(patient_code) if patient_code is not None else None
        return list(found) if found is not None else self._db.list_fits(patient_code)

    def list_maps(self, patient_code: str | None = None, session_label: str | None = None,
                  **filters: Any) -> list[StoredMap]:
        found = self._maps.get(patient_code) if patient_code is not None else None
        if found is None or filters:
            return self._db.list_maps(patient_code, session_label, **filters)
        return [m for m in found if session_label is None or m.session_label == session_label]

    def list_sessions(self, patient_code: str | None = None) -> list[SessionInfo]:
        found = self._sessions.get(patient_code) if patient_code is not None else None
        return list(found) if found is not None else self._db.list_sessions(patient_code)

    def get_maps(self, map_ids: Sequence[int]) -> list[FieldMap]:
        if all(i in self._arrays for i in map_ids):
            return [self._arrays[i] for i in map_ids]
        return self._db.get_maps(map_ids)  # one not read, or gone: the database says


def _fitted_ancestor(db: Database, model_id: int) -> StoredModel | None:
    for m in db.model_lineage(model_id):
        if m.origin == "fitted":
            return m
    return None


def _case(db: Database, plan: PlanRecord, selection: Selection) -> CaseSpec | None:
    """The case of ``plan`` without its checks, or None when ``selection`` leaves it out."""
    code = plan.patient_code
    kinds = plan_kinds(plan.spec)
    if selection.kinds and not set(kinds) & set(selection.kinds):
        return None
    base = db.get_model(plan.base_model_id)
    result = db.get_model(plan.result_model_id)
    ancestor = _fitted_ancestor(db, base.id)
    owner = ancestor.patient_code if ancestor is not None else None
    fits_by_model = {f.model_id: f for f in db.list_fits(owner)} if owner is not None else {}
    fit = fits_by_model.get(ancestor.id) if ancestor is not None else None
    sessions: dict[str, str | None] = {}
    if fit is not None:
        maps_by_id = {m.id: m for m in db.list_maps(fit.patient_code)}
        for mid in fit.map_ids:
            m = maps_by_id.get(mid)
            if m is not None:
                sessions[m.session_label] = (m.session_date.isoformat()
                                             if m.session_date else None)
    dates = sorted(d for d in sessions.values() if d)
    case_date = dates[-1] if dates else plan.created_at.date().isoformat()
    if selection.sessions and not set(sessions) & set(selection.sessions):
        return None
    if selection.since and case_date < selection.since.isoformat():
        return None
    if selection.until and case_date > selection.until.isoformat():
        return None
    p = db.get_patient(code) if code else None
    return CaseSpec(
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
        fitted_model_id=ancestor.id if ancestor is not None and fit is not None else None)


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
    reads = _CohortReads(db)
    db = cast(Database, reads)
    for named in selection.patients:
        db.get_patient(named)  # an unknown patient: the storage layer's clear error
    plans = []
    if selection.plan_ids:
        plans = db.get_plans([int(i) for i in selection.plan_ids])
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
    cases = []
    for k in range(0, len(plans), CHUNK_PLANS):
        part = [p for p in plans[k:k + CHUNK_PLANS]
                if not selection.patients or p.patient_code in selection.patients]
        reads.read_records(part)
        kept = [(p, spec) for p in part if (spec := _case(db, p, selection)) is not None]
        if checks:
            reads.read_checks([p for p, _ in kept])
        cases += [dataclasses.replace(spec, checks=read_plan_inputs(db, p)) if checks
                  else spec for p, spec in kept]
    if not cases:
        raise SelectionError(
            f"No stored plan matches the selection ({selection.describe()}) in "
            f"{db.url_masked}; {len(plans)} plan(s) were considered.")
    cases.sort(key=lambda c: (c.patient_code or "", c.plan_id))
    return cases
