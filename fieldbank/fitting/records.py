"""Fitting a stored patient: the seam between the fitter and the database.

The fitter needs four things from storage, gathered in the :class:`FitStore` protocol so that
the storage layer (or a test double) can provide them:

* ``patient_params(patient)`` - the patient's base :class:`ArmParams` (segments from mass and
  height, and the start values); unknown patient -> a FieldbankError naming it;
* ``maps_for(patient, session)`` - the patient's measured maps as :class:`PatientMap`
  (all sessions when ``session`` is None; an unknown session -> a FieldbankError);
* ``add_fit(record)`` - store the fit and the fitted model **in one transaction** and return
  their ids (:class:`SavedFit`); the record carries the lineage (patient, session, map ids)
  and its :func:`fit_key`: a store that keeps keys returns an identical fit stored before
  instead of storing a second one (``SavedFit.created`` False);
* ``list_models(patient)`` - the stored models as
  :class:`~fieldbank.storage.records.StoredModel` records, for ``fieldbank models list``;
* ``get_model(model_id)`` - a :class:`ModelDetail`: the model, its ancestors (newest first)
  and the stored fit report that produced it, for ``fieldbank models show``.

:func:`fit_patient` runs one fit for a stored patient and stores it.
:meth:`ModelDetail.to_json_dict` gives the JSON document of ``models show``
(:func:`fieldbank.stored.records.model_summary`, that of each model in ``models list``).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

from fieldbank.errors import FitError
from fieldbank.fitchoices import MODEL_VERSION
from fieldbank.fitting.fitter import ArmFitter
from fieldbank.maps import FieldMap
from fieldbank.params import ArmParams
from fieldbank.storage.records import StoredModel
from fieldbank.stored.records import model_summary


@dataclass(frozen=True)
class PatientMap:
    """A measured map as stored: its id, owner and session."""

    map_id: int | str
    patient: str
    session: str | None
    map: FieldMap


@dataclass(frozen=True)
class FitSubmission:
    """Everything stored for one fit and its fitted model.

    ``report`` is :meth:`ArmFitter.report` (parameters, cost, R² and residual RMS per map,
    uncertainty, unidentified parameters with reasons, algorithm, seed, evaluations, time,
    severity); ``params`` the fitted model; ``map_ids`` the maps used, in fit order.
    """

    patient: str
    session: str | None
    map_ids: tuple[int | str, ...]
    base_params: ArmParams
    params: ArmParams
    report: Mapping[str, Any]
    algorithm: str
    seed: int
    status: str
    severity: Mapping[str, Any] | None = field(default=None)
    #: :func:`fit_key` of what the fit was made from; a store keeps one fit per key.
    fit_key: str | None = None
    model_version: int = MODEL_VERSION


@dataclass(frozen=True)
class SavedFit:
    """The stored fit and model; ``created`` False: an identical fit (same key) was stored
    already, and these are its ids (nothing new was stored)."""

    fit_id: int | str
    model_id: int | str
    created: bool = True


def fit_key(patient: str, session: str | None, map_ids: Sequence[int | str],
            base: ArmParams, options: Mapping[str, Any]) -> str:
    """SHA-256 of what a fit is made from: the patient and the session asked for, the maps
    (stored maps never change, so their ids stand for their contents), the patient's base
    parameters, the fitter's options (:meth:`ArmFitter.options`) and
    :data:`fieldbank.fitchoices.MODEL_VERSION`. The same key means the same fit would result."""
    doc = {"patient": patient, "session": session, "maps": sorted(str(m) for m in map_ids),
           "base": base.to_dict(), "options": dict(options), "model_version": MODEL_VERSION}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode("utf-8")).hexdigest()


@dataclass(frozen=True)
class ModelDetail:
    """A stored model with where it came from.

    Attributes
    ----------
    model : StoredModel
        The model and its parameters.
    lineage : tuple of StoredModel
        Its ancestors, newest first (the model itself not included).
    fit : mapping or None
        The stored report of the fit that produced it (:meth:`ArmFitter.report`, a JSON
        document), or None when it was not fitted.
    """

    model: StoredModel
    lineage: tuple[StoredModel, ...] = ()
    fit: Mapping[str, Any] | None = None

    def to_json_dict(self) -> dict[str, Any]:
        """The JSON document of ``fieldbank models show``."""
        return {**model_summary(self.model), "params": self.model.params,
                "lineage": [model_summary(a) for a in self.lineage],
                "fit": None if self.fit is None else dict(self.fit)}


class FitStore(Protocol):
    """What :func:`fit_patient` and the ``fit``/``models`` commands need from storage."""

    def patient_params(self, patient: str) -> ArmParams: ...

    def maps_for(self, patient: str, session: str | None = None) -> Sequence[PatientMap]: ...

    def map_ids(self, patient: str, session: str | None = None) -> Sequence[int | str]: ...

    def fit_with_key(self, fit_key: str) -> SavedFit | None: ...

    def add_fit(self, record: FitSubmission) -> SavedFit: ...

    def list_models(self, patient: str | None = None) -> Sequence[StoredModel]: ...

    def get_model(self, model_id: int | str) -> ModelDetail: ...


@dataclass(frozen=True)
class FitOutcome:
    saved: SavedFit
    fitter: ArmFitter
    record: FitSubmission


def fit_patient(
    store: FitStore,
    patient: str,
    session: str | None,
    fitter: ArmFitter,
    progress: Callable[[str], None] | None = None,
) -> FitOutcome:
    """Fit ``patient``'s stored maps (one session or all) and store the fit and the model.

    Raises
    ------
    FitError
        The patient has no maps (in that session), or a returned map belongs to another
        patient; and everything :meth:`ArmFitter.fit` refuses. Nothing is stored then.
    """
    base = store.patient_params(patient)
    stored = list(store.maps_for(patient, session))
    where = f"patient {patient!r}" + (f", session {session!r}" if session else "")
    if not stored:
        raise FitError(f"no maps to fit: {where} has no measured maps.")
    strangers = [s for s in stored if s.patient != patient]
    if strangers:
        s = strangers[0]
        raise FitError(f"map {s.map_id} belongs to patient {s.patient!r}, not to {patient!r}; "
                       "refusing to fit maps of another patient.")
    if progress:
        progress(f"fitting {len(stored)} maps of {where} with {fitter.algorithm} "
                 f"(seed {fitter.seed})")
    maps: list[FieldMap] = []
    for s in stored:
        meta = dict(s.map.metadata)
        meta.setdefault("map_id", str(s.map_id))
        maps.append(replace(s.map, metadata=meta))
    key = fit_key(patient, session, [s.map_id for s in stored], base, fitter.options())
    fitter.fit(maps, base, patient=None)
    report = fitter.report()
    report["patient"] = patient
    report["session"] = session
    report["map_ids"] = [s.map_id for s in stored]
    record = FitSubmission(
        patient=patient,
        session=session,
        map_ids=tuple(s.map_id for s in stored),
        base_params=base,
        params=fitter.params_,
        report=report,
        algorithm=fitter.algorithm_,
        seed=fitter.seed_,
        status=fitter.status_,
        severity=fitter.severity_,
        fit_key=key,
    )
    saved = store.add_fit(record)
    return FitOutcome(saved, fitter, record)
