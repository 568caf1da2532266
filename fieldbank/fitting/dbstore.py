"""The :class:`~fieldbank.fitting.records.FitStore` on the field database.

An adapter over :class:`fieldbank.storage.Database`, using its ``get_patient``,
``list_maps``, ``get_maps``, ``fit_by_key``, ``add_fitted_model`` (model and fit in one
transaction), ``list_models``, ``get_model``, ``model_lineage`` and ``list_fits``. The fitted
model is stored with origin 'fitted' and the fit (report, algorithm, seed, evaluations, time,
cost, map ids) refers to it.
"""

from __future__ import annotations

from collections.abc import Sequence

from fieldbank.fitting.records import FitSubmission, ModelDetail, PatientMap, SavedFit
from fieldbank.params import ArmParams
from fieldbank.storage import Database, StoredModel


class DatabaseFitStore:
    """FitStore over a :class:`fieldbank.storage.Database`."""

    def __init__(self, db: Database) -> None:
        self.db = db

    def patient_params(self, patient: str) -> ArmParams:
        return self.db.get_patient(patient).arm_params()

    def maps_for(self, patient: str, session: str | None = None) -> Sequence[PatientMap]:
        self.db.get_patient(patient)  # unknown patient -> the storage layer's clear error
        if session is not None:
            self.db.get_session(patient, session)  # unknown session -> its sessions listed
        stored = list(self.db.list_maps(patient_code=patient, session_label=session))
        if not stored:
            return []
        arrays = self.db.get_maps([s.id for s in stored])
        return [PatientMap(s.id, s.patient_code, s.session_label, m)
                for s, m in zip(stored, arrays, strict=True)]

    def map_ids(self, patient: str, session: str | None = None) -> Sequence[int | str]:
        """The ids of the maps :meth:`maps_for` would read (their arrays left unread)."""
        return [m.id for m in self.db.list_maps(patient_code=patient, session_label=session)]

    def fit_with_key(self, fit_key: str) -> SavedFit | None:
        """The fit stored under ``fit_key`` (:func:`~fieldbank.fitting.records.fit_key`) and
        its model, not created now; None when there is none."""
        found = self.db.fit_by_key(fit_key)
        return None if found is None else SavedFit(found.id, found.model_id, created=False)

    def add_fit(self, record: FitSubmission) -> SavedFit:
        label = (f"fit of {len(record.map_ids)} maps"
                 + (f", session {record.session}" if record.session else "")
                 + f" ({record.algorithm}, seed {record.seed})")
        report = dict(record.report)
        args = (record.params, label, record.patient, record.algorithm, record.seed,
                int(report["n_evals"]), float(report["time_s"]), float(report["cost"]), report,
                [int(m) for m in record.map_ids])
        if record.fit_key is None:
            model, fit = self.db.add_fitted_model(*args, model_version=record.model_version,
                                                  session_label=record.session)
            return SavedFit(fit.id, model.id)
        model, fit, created = self.db.add_fitted_model_once(
            *args, fit_key=record.fit_key, model_version=record.model_version,
            session_label=record.session)
        return SavedFit(fit.id, model.id, created)

    def list_models(self, patient: str | None = None) -> Sequence[StoredModel]:
        if patient is not None:
            self.db.get_patient(patient)  # an unknown patient: the one "not found" message
        return self.db.list_models(patient_code=patient)

    def get_model(self, model_id: int | str) -> ModelDetail:
        m = self.db.get_model(int(model_id))
        fits = [f for f in self.db.list_fits(m.patient_code) if f.model_id == m.id] \
            if m.patient_code else []
        return ModelDetail(m, tuple(self.db.model_lineage(m.id)[1:]),
                           dict(fits[-1].result) if fits else None)


def open_fit_store(db_url: str | None) -> DatabaseFitStore:
    """Open the field database (``db_url`` or the default) as a FitStore; a database that does
    not exist is refused (:class:`~fieldbank.errors.DatabaseMissing`), never created."""
    return DatabaseFitStore(Database.open(db_url, create=False))
