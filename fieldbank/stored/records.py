"""The records the list commands read: patients, maps, models as listed, plans, batch runs
and their jobs - returned alike by :class:`fieldbank.storage.Database` and by the light listing
(:mod:`fieldbank.stored.listing`), never ORM rows. The database's other records are in
:mod:`fieldbank.storage.records`.

Timestamps are timezone-aware UTC datetimes; JSON documents come back as dicts.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import date, datetime
from typing import Any, Protocol

from fieldbank.params import ArmParams

#: Kinds of batch work, and the states of one task of a run (the keys of
#: :attr:`JobRunRecord.counts`, in this order).
JOB_KINDS = ("fit", "report", "validate")
JOB_STATES = ("pending", "running", "done", "skipped", "failed")


@dataclass(frozen=True)
class PatientInfo:
    """A patient: a pseudonymous code and the anthropometry the arm model needs."""

    id: int
    code: str
    body_mass_kg: float
    height_m: float
    side: str
    notes: str
    created_at: datetime

    def arm_params(self) -> ArmParams:
        """Unimpaired parameters of this patient's arm (used to check reachability)."""
        return ArmParams.from_anthropometry(self.body_mass_kg, self.height_m, self.side)


@dataclass(frozen=True)
class StoredMap:
    """What the database holds about a map besides its arrays (load those with get_map)."""

    id: int
    patient_code: str
    session_label: str
    session_date: date | None
    kind: str
    frame: str
    sign: str
    velocity_m_per_s: tuple[float, float]
    n_points: int
    value_unit: str
    source_text: str
    source_file: str
    source_sha256: str
    index_in_file: int
    ingested_at: datetime
    ingested_by: str


class ListedModel(Protocol):
    """What a listing of models shows of each: a :class:`ModelEntry` or a
    :class:`fieldbank.storage.records.StoredModel`."""

    @property
    def id(self) -> int: ...
    @property
    def patient_code(self) -> str | None: ...
    @property
    def parent_id(self) -> int | None: ...
    @property
    def origin(self) -> str: ...
    @property
    def label(self) -> str: ...
    @property
    def created_at(self) -> datetime: ...
    @property
    def plan_id(self) -> int | None: ...
    @property
    def plans_from(self) -> Sequence[int]: ...


@dataclass(frozen=True)
class ModelEntry:
    """A stored model as a listing shows it: everything of
    :class:`~fieldbank.storage.records.StoredModel` but its parameters (``models list`` reads
    no parameter set)."""

    id: int
    patient_code: str | None
    parent_id: int | None
    origin: str
    label: str
    created_at: datetime
    plan_id: int | None = None
    plans_from: tuple[int, ...] = ()


def model_summary(m: ListedModel) -> dict[str, Any]:
    """The JSON document of one model in ``fieldbank models list`` (and of the lineage in
    ``models show``)."""
    return {"id": m.id, "patient": m.patient_code, "origin": m.origin, "label": m.label,
            "parent_id": m.parent_id, "created_at": m.created_at, "plan_id": m.plan_id,
            "plans_from": list(m.plans_from)}


@dataclass(frozen=True)
class PlanRecord:
    """An intervention plan applied to a base model, giving a result model."""

    id: int
    patient_code: str | None
    base_model_id: int
    result_model_id: int
    label: str
    spec: dict[str, Any]
    created_at: datetime

    @property
    def given_on(self) -> date | None:
        """The day the plan was carried out (its document's ``given_on``); None for a plan
        only explored."""
        given = self.spec.get("given_on")
        return date.fromisoformat(given) if isinstance(given, str) else None


@dataclass(frozen=True)
class JobRunRecord:
    """A batch command run over workers, with how many of its jobs are in each state."""

    id: int
    kind: str
    token: str
    engine: str
    args: dict[str, Any]
    actor: str
    started_at: datetime
    finished_at: datetime | None
    counts: dict[str, int]

    @property
    def left(self) -> int:
        """Jobs not finished: pending, or started and not (yet) done."""
        return self.counts.get("pending", 0) + self.counts.get("running", 0)


@dataclass(frozen=True)
class JobRecord:
    """One job of a run: its state, how often it was started, where and when it ran."""

    id: int
    run_id: int
    key: str
    patient_code: str | None
    session_label: str | None
    state: str
    attempts: int
    worker: str | None
    started_at: datetime | None
    finished_at: datetime | None
    error: str | None
    result: dict[str, Any] | None
