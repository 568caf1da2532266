"""Models, fits and plans: where each stored arm model came from.

A model is a set of :class:`~fieldbank.params.ArmParams` with an origin ('synthetic', 'fitted'
or 'intervention') and a parent: a model after an intervention has its base as parent, so
:meth:`Lineage.model_lineage` walks back to the fitted or synthetic model it started from. A
fit records how a fitted model was obtained (algorithm, seed, evaluations, time, cost, report
and the maps used); a plan records which intervention turned a base model into a result model.

The use cases that create two rows store them in one transaction - :meth:`add_fitted_model`
(model and fit) and :meth:`add_plan_result` (result model, plan and, if needed, its base) -
so a crash never leaves a fitted model without its fit or a plan without its result.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from datetime import date
from typing import Any

from sqlalchemy import or_, select
from sqlalchemy.orm import Session

from fieldbank.errors import ParameterError, StorageError
from fieldbank.params import ArmParams
from fieldbank.storage.core import DatabaseCore, chunks, now, to_utc
from fieldbank.storage.orm import (
    FitRow,
    MapRow,
    ModelRow,
    PatientRow,
    PlanRow,
    SessionRow,
    fit_maps,
)
from fieldbank.storage.records import FitRecord, StoredModel
from fieldbank.stored.records import PlanRecord

ORIGINS = ("synthetic", "fitted", "intervention")


def _model(r: ModelRow, code: str | None) -> StoredModel:
    return StoredModel(r.id, code, r.parent_id, r.origin, r.label,
                       ArmParams.from_json(r.params_json, where=f"model {r.id}"),
                       to_utc(r.created_at))


def _plan_record(r: PlanRow, code: str | None) -> PlanRecord:
    return PlanRecord(r.id, code, r.base_model_id, r.result_model_id, r.label,
                      json.loads(r.spec_json), to_utc(r.created_at))


class Lineage(DatabaseCore):
    """Models, fits and plans of :class:`~fieldbank.storage.Database`."""

    # --- models -----------------------------------------------------------------------------
    def add_model(self, params: ArmParams, origin: str, label: str,
                  patient_code: str | None = None, parent_id: int | None = None) -> StoredModel:
        """Store arm parameters; ``origin`` is 'synthetic', 'fitted' or 'intervention'."""
        with self._write() as s:
            return self._add_model(s, params, origin, label, patient_code, parent_id)

    def _add_model(self, s: Session, params: ArmParams, origin: str, label: str,
                   patient_code: str | None, parent_id: int | None) -> StoredModel:
        if origin not in ORIGINS:
            raise ParameterError(f"origin must be one of {', '.join(ORIGINS)}; got {origin!r}.")
        pid = self._optional_patient_id(s, patient_code)
        if parent_id is not None and s.get(ModelRow, parent_id) is None:
            raise self._no_row(s, ModelRow, "model", parent_id, " (the parent)")
        row = ModelRow(patient_id=pid, parent_id=parent_id, origin=origin, label=label,
                       params_json=params.to_json(), created_at=now())
        s.add(row)
        s.flush()
        self._audit(s, "add", "model", row.id,
                    {"origin": origin, "label": label, "parent": parent_id})
        return _model(row, patient_code)

    def get_model(self, model_id: int) -> StoredModel:
        with self._read() as s:
            r = s.get(ModelRow, model_id)
            if r is None:
                raise self._no_row(s, ModelRow, "model", model_id)
            return _with_plans(_model(r, self._code_of(s, r.patient_id)),
                               _plan_links(s, [r.id]))

    def list_models(self, patient_code: str | None = None,
                    origin: str | None = None) -> list[StoredModel]:
        q = (select(ModelRow, PatientRow.code)
             .outerjoin(PatientRow, ModelRow.patient_id == PatientRow.id).order_by(ModelRow.id))
        if patient_code is not None:
            q = q.where(PatientRow.code == patient_code)
        if origin is not None:
            q = q.where(ModelRow.origin == origin)
        with self._read() as s:
            rows = [_model(r, code) for r, code in s.execute(q)]
            links = _plan_links(s, [m.id for m in rows])
        return [_with_plans(m, links) for m in rows]

    def get_models(self, model_ids: Sequence[int]) -> dict[int, StoredModel]:
        """The stored models among ``model_ids``, by id (an id not stored is left out): what
        :meth:`get_model` returns for each, in two queries for them all."""
        wanted = sorted({int(m) for m in model_ids})
        if not wanted:
            return {}
        q = (select(ModelRow, PatientRow.code)
             .outerjoin(PatientRow, ModelRow.patient_id == PatientRow.id)
             .where(ModelRow.id.in_(wanted)))
        with self._read() as s:
            rows = [_model(r, code) for r, code in s.execute(q)]
            links = _plan_links(s, [m.id for m in rows])
        return {m.id: _with_plans(m, links) for m in rows}

    def model_lineage(self, model_id: int) -> list[StoredModel]:
        """The model and its ancestors, newest first."""
        return walk_lineage(model_id, self.get_model)

    # --- fits -------------------------------------------------------------------------------
    def add_fit(self, patient_code: str, model_id: int, algorithm: str, seed: int | None,
                n_evals: int, time_s: float, cost: float, result: Mapping[str, Any],
                map_ids: Sequence[int]) -> FitRecord:
        """Record a fit: the fitted model (stored before, origin 'fitted') and the maps used.

        ``result`` is the fit report, a JSON document; ``time_s`` in s.
        """
        with self._write() as s:
            return self._add_fit(s, patient_code, model_id, algorithm, seed, n_evals, time_s,
                                 cost, result, map_ids)

    def add_fitted_model(self, params: ArmParams, label: str, patient_code: str,
                         algorithm: str, seed: int | None, n_evals: int, time_s: float,
                         cost: float, result: Mapping[str, Any],
                         map_ids: Sequence[int], *, fit_key: str | None = None,
                         model_version: int | None = None,
                         session_label: str | None = None) -> tuple[StoredModel, FitRecord]:
        """Store a fitted model and its fit record in one transaction: both or neither.

        ``fit_key`` (unique), ``model_version`` and ``session_label`` record what the fit was
        made from (:meth:`add_fitted_model_once` stores a keyed fit at most once).
        """
        with self._write() as s:
            model = self._add_model(s, params, "fitted", label, patient_code, None)
            fit = self._add_fit(s, patient_code, model.id, algorithm, seed, n_evals, time_s,
                                cost, result, map_ids, fit_key, model_version, session_label)
            return model, fit

    def add_fitted_model_once(self, params: ArmParams, label: str, patient_code: str,
                              algorithm: str, seed: int | None, n_evals: int, time_s: float,
                              cost: float, result: Mapping[str, Any], map_ids: Sequence[int],
                              *, fit_key: str, model_version: int | None = None,
                              session_label: str | None = None
                              ) -> tuple[StoredModel, FitRecord, bool]:
        """:meth:`add_fitted_model` unless a fit with ``fit_key`` is stored already: then
        nothing is stored and that fit and its model come back. The last item says whether
        this call stored them.

        Two writers racing with one key (a batch task run twice, after its first worker died
        having committed) cannot both store: the key is unique, the loser's transaction rolls
        back whole (model included) and it returns the winner's fit.
        """
        found = self.fit_by_key(fit_key)
        if found is None:
            try:
                model, fit = self.add_fitted_model(
                    params, label, patient_code, algorithm, seed, n_evals, time_s, cost,
                    result, map_ids, fit_key=fit_key, model_version=model_version,
                    session_label=session_label)
                return model, fit, True
            except StorageError:
                found = self.fit_by_key(fit_key)
                if found is None:
                    raise
        return self.get_model(found.model_id), found, False

    def fit_by_key(self, fit_key: str) -> FitRecord | None:
        """The fit stored with ``fit_key``, or None."""
        with self._read() as s:
            r = s.scalar(select(FitRow).where(FitRow.fit_key == fit_key))
            return None if r is None else self._fit(s, r)

    def _add_fit(self, s: Session, patient_code: str, model_id: int, algorithm: str,
                 seed: int | None, n_evals: int, time_s: float, cost: float,
                 result: Mapping[str, Any], map_ids: Sequence[int],
                 fit_key: str | None = None, model_version: int | None = None,
                 session_label: str | None = None) -> FitRecord:
        p = self._patient_row(s, patient_code)
        session_id = (None if session_label is None else
                      self._session_row(s, p, session_label, None, create=False).id)
        if s.get(ModelRow, model_id) is None:
            raise self._no_row(s, ModelRow, "model", model_id)
        found = set(s.scalars(select(MapRow.id).where(MapRow.id.in_(list(map_ids)),
                                                      MapRow.patient_id == p.id)))
        missing = [m for m in map_ids if m not in found]
        if missing:
            raise StorageError(f"Maps {missing} are not maps of patient {patient_code!r}.")
        row = FitRow(patient_id=p.id, model_id=model_id, algorithm=algorithm, seed=seed,
                     n_evals=int(n_evals), time_s=float(time_s), cost=float(cost),
                     result_json=json.dumps(dict(result), sort_keys=True),
                     created_at=now(), fit_key=fit_key, model_version=model_version,
                     session_id=session_id)
        s.add(row)
        s.flush()
        ids = tuple(dict.fromkeys(int(m) for m in map_ids))
        if ids:
            s.execute(fit_maps.insert(), [{"fit_id": row.id, "map_id": m} for m in ids])
        self._audit(s, "add", "fit", row.id, {"model": model_id, "maps": list(ids),
                                              "key": fit_key, "model_version": model_version})
        return FitRecord(row.id, p.code, model_id, algorithm, seed, row.n_evals,
                         row.time_s, row.cost, json.loads(row.result_json), ids,
                         to_utc(row.created_at), fit_key, model_version, session_label)

    def _fit(self, s: Session, r: FitRow) -> FitRecord:
        return self._fits(s, [(r, str(self._code_of(s, r.patient_id)))])[0]

    def _fits(self, s: Session, rows: Sequence[tuple[FitRow, str]]) -> list[FitRecord]:
        """Fit records of (row, patient code) pairs: their maps and session labels read in
        one query each for all of them."""
        if not rows:
            return []
        ids = [r.id for r, _ in rows]
        maps: dict[int, list[int]] = {i: [] for i in ids}
        for part in chunks(ids):
            for fid, mid in s.execute(select(fit_maps.c.fit_id, fit_maps.c.map_id)
                                      .where(fit_maps.c.fit_id.in_(part))
                                      .order_by(fit_maps.c.fit_id, fit_maps.c.map_id)):
                maps[fid].append(mid)
        labels: dict[int, str] = {}
        for part in chunks(sorted({r.session_id for r, _ in rows if r.session_id is not None})):
            labels.update((i, label) for i, label in s.execute(
                select(SessionRow.id, SessionRow.label).where(SessionRow.id.in_(part))))
        return [FitRecord(r.id, code, r.model_id, r.algorithm, r.seed, r.n_evals, r.time_s,
                          r.cost, json.loads(r.result_json), tuple(maps[r.id]),
                          to_utc(r.created_at), r.fit_key, r.model_version,
                          None if r.session_id is None else labels.get(r.session_id))
                for r, code in rows]

    def get_fit(self, fit_id: int) -> FitRecord:
        with self._read() as s:
            r = s.get(FitRow, fit_id)
            if r is None:
                raise self._no_row(s, FitRow, "fit", fit_id)
            return self._fit(s, r)

    def list_fits(self, patient_code: str | None = None) -> list[FitRecord]:
        return self._list_fits(None if patient_code is None else [patient_code])

    def fits_of(self, patient_codes: Sequence[str]) -> dict[str, list[FitRecord]]:
        """:meth:`list_fits` of each of ``patient_codes`` (each a list, empty for a patient
        without fits), in three queries per thousand patients."""
        out: dict[str, list[FitRecord]] = {c: [] for c in patient_codes}
        for part in chunks(sorted(out)):
            for f in self._list_fits(part):
                out[f.patient_code].append(f)
        return out

    def _list_fits(self, codes: Sequence[str] | None) -> list[FitRecord]:
        q = (select(FitRow, PatientRow.code).join(PatientRow, FitRow.patient_id == PatientRow.id)
             .order_by(FitRow.id))
        if codes is not None:
            q = q.where(PatientRow.code.in_(codes))
        with self._read() as s:
            return self._fits(s, [(r, code) for r, code in s.execute(q)])

    # --- plans ------------------------------------------------------------------------------
    def add_plan(self, base_model_id: int, result_model_id: int, spec: Mapping[str, Any],
                 label: str = "", patient_code: str | None = None) -> PlanRecord:
        """Record a plan (``spec``: its JSON document) turning one stored model into another."""
        with self._write() as s:
            return self._add_plan(s, base_model_id, result_model_id, spec, label, patient_code)

    def add_plan_result(self, after: ArmParams, spec: Mapping[str, Any], label: str,
                        patient_code: str | None = None, base_model_id: int | None = None,
                        before: ArmParams | None = None,
                        before_label: str = "") -> tuple[int, StoredModel, PlanRecord]:
        """Store a plan with its result model in one transaction: all or nothing.

        The base is a stored model (``base_model_id``) or, when it is not stored yet, the
        ``before`` parameters, stored first as a synthetic model. Returns (base model id,
        the after model (origin 'intervention', parent = base), the plan record).
        """
        if (base_model_id is None) == (before is None):
            raise ParameterError("Give exactly one of base_model_id and before.")
        with self._write() as s:
            if base_model_id is None:
                assert before is not None
                base_model_id = self._add_model(s, before, "synthetic", before_label,
                                                patient_code, None).id
            child = self._add_model(s, after, "intervention", label, patient_code,
                                    base_model_id)
            plan = self._add_plan(s, base_model_id, child.id, spec, label, patient_code)
            return base_model_id, child, plan

    def _add_plan(self, s: Session, base_model_id: int, result_model_id: int,
                  spec: Mapping[str, Any], label: str, patient_code: str | None) -> PlanRecord:
        pid = self._optional_patient_id(s, patient_code)
        for mid in (base_model_id, result_model_id):
            if s.get(ModelRow, mid) is None:
                raise self._no_row(s, ModelRow, "model", mid)
        row = PlanRow(patient_id=pid, base_model_id=base_model_id,
                      result_model_id=result_model_id, label=label,
                      spec_json=json.dumps(dict(spec), sort_keys=True), created_at=now())
        s.add(row)
        s.flush()
        self._audit(s, "add", "plan", row.id,
                    {"base": base_model_id, "result": result_model_id})
        return PlanRecord(row.id, patient_code, base_model_id, result_model_id, label,
                          json.loads(row.spec_json), to_utc(row.created_at))

    def _plan(self, s: Session, r: PlanRow) -> PlanRecord:
        return _plan_record(r, self._code_of(s, r.patient_id))

    def get_plan(self, plan_id: int) -> PlanRecord:
        with self._read() as s:
            r = s.get(PlanRow, plan_id)
            if r is None:
                raise self._no_row(s, PlanRow, "plan", plan_id)
            return self._plan(s, r)

    def get_plans(self, plan_ids: Sequence[int]) -> list[PlanRecord]:
        """The plans ``plan_ids`` in that order, in one query (:meth:`get_plan`'s error for
        the first one not stored)."""
        ids = [int(i) for i in plan_ids]
        q = (select(PlanRow, PatientRow.code)
             .outerjoin(PatientRow, PlanRow.patient_id == PatientRow.id)
             .where(PlanRow.id.in_(set(ids))))
        with self._read() as s:
            found = {r.id: _plan_record(r, code) for r, code in s.execute(q)}
            for i in ids:
                if i not in found:
                    raise self._no_row(s, PlanRow, "plan", i)
        return [found[i] for i in ids]

    def set_plan_given(self, plan_id: int, given_on: date) -> PlanRecord:
        """Record in plan ``plan_id``'s document the day it was carried out (``given_on``),
        audited. A different day already recorded is refused: a stored record is added to,
        never silently changed."""
        with self._write() as s:
            r = s.get(PlanRow, plan_id)
            if r is None:
                raise self._no_row(s, PlanRow, "plan", plan_id)
            spec = json.loads(r.spec_json)
            had = spec.get("given_on")
            if had not in (None, given_on.isoformat()):
                raise StorageError(f"Plan {plan_id} is already recorded as given on {had}.")
            spec["given_on"] = given_on.isoformat()
            r.spec_json = json.dumps(spec, sort_keys=True)
            self._audit(s, "give", "plan", plan_id, {"given_on": given_on.isoformat()})
            s.flush()
            return self._plan(s, r)

    def list_plans(self, patient_code: str | None = None) -> list[PlanRecord]:
        q = (select(PlanRow, PatientRow.code)
             .outerjoin(PatientRow, PlanRow.patient_id == PatientRow.id).order_by(PlanRow.id))
        if patient_code is not None:
            q = q.where(PatientRow.code == patient_code)
        with self._read() as s:
            return [_plan_record(r, code) for r, code in s.execute(q)]


#: Up to this many models, :func:`_plan_links` asks for their plans by id; beyond, it reads
#: every plan once.
_LINKS_BY_ID = 200


def _plan_links(s: Session, model_ids: Sequence[int]) -> dict[int, tuple[int | None, list[int]]]:
    """model id -> (the plan that made it, the plans applied to it), in one query."""
    out: dict[int, tuple[int | None, list[int]]] = {m: (None, []) for m in model_ids}
    if not model_ids:
        return out
    wanted = set(model_ids)
    q = select(PlanRow.id, PlanRow.base_model_id, PlanRow.result_model_id).order_by(PlanRow.id)
    if len(wanted) <= _LINKS_BY_ID:  # a few models: their plans only, not every plan
        q = q.where(or_(PlanRow.base_model_id.in_(wanted), PlanRow.result_model_id.in_(wanted)))
    for pid, base, result in s.execute(q):
        if result in wanted:
            out[result] = (pid, out[result][1])
        if base in wanted:
            out[base][1].append(pid)
    return out


def _with_plans(m: StoredModel, links: Mapping[int, tuple[int | None, list[int]]]) -> StoredModel:
    made_by, applied = links.get(m.id, (None, []))
    return replace(m, plan_id=made_by, plans_from=tuple(applied))


def walk_lineage(model_id: int, get_model: Callable[[int], StoredModel]) -> list[StoredModel]:
    """The model ``model_id`` and its ancestors, newest first, each read with ``get_model``
    (the database's, or a reader holding models read ahead); a parent met twice ends the walk."""
    out: list[StoredModel] = []
    seen: set[int] = set()
    current: int | None = model_id
    while current is not None and current not in seen:
        seen.add(current)
        m = get_model(current)
        out.append(m)
        current = m.parent_id
    return out
