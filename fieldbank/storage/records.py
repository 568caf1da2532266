"""Frozen records that :class:`fieldbank.storage.Database` returns (never ORM rows).

Timestamps are timezone-aware UTC datetimes; JSON documents come back as dicts. The records
the list commands read (patients, maps, models as listed, plans, batch runs and their jobs) are
in :mod:`fieldbank.stored.records`, which the light listing returns without loading this
package.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import date, datetime
from typing import Any

from fieldbank.arraystore import ArrayRef
from fieldbank.maps import FieldMap
from fieldbank.params import ArmParams


@dataclass(frozen=True)
class SessionInfo:
    """A visit of a patient, e.g. label 'pre-BoNT' on a date."""

    id: int
    patient_code: str
    label: str
    session_date: date | None
    created_at: datetime
    n_maps: int = 0


@dataclass(frozen=True)
class SourceFileInfo:
    """A raw file as ingested, kept unchanged."""

    sha256: str
    file_name: str
    file_format: str
    nbytes: int
    ingested_at: datetime
    ingested_by: str
    in_array_store: bool


@dataclass(frozen=True)
class StoredModel:
    """A set of arm parameters with its origin and lineage."""

    id: int
    patient_code: str | None
    parent_id: int | None
    origin: str
    label: str
    params: ArmParams
    created_at: datetime
    #: the stored plan that made this model (origin 'intervention'), and the plans applied to it
    plan_id: int | None = None
    plans_from: tuple[int, ...] = ()


@dataclass(frozen=True)
class FitRecord:
    """A fit of a model to maps, with what is needed to reproduce it."""

    id: int
    patient_code: str
    model_id: int
    algorithm: str
    seed: int | None
    n_evals: int
    time_s: float
    cost: float
    result: dict[str, Any]
    map_ids: tuple[int, ...]
    created_at: datetime
    #: What the fit was made from, hashed (None: stored before fits kept keys).
    fit_key: str | None = None
    #: The model version it was made under (None: not recorded).
    model_version: int | None = None
    #: The session whose maps it fitted (None: every session of the patient).
    session_label: str | None = None


@dataclass(frozen=True)
class HapticSessionRecord:
    """A haptic rendering session on a robot (URL stored without password)."""

    id: int
    patient_code: str | None
    model_a_id: int
    model_b_id: int | None
    started_at: datetime
    ended_at: datetime | None
    robot_url: str
    stats: dict[str, Any]
    patient_note: str | None = None
    n_trials: int = 0


@dataclass(frozen=True)
class HapticTrialRecord:
    """One A/B/X or training trial of a haptic session, with the answer given.

    ``started_s``/``answered_s`` are session times, s: with the session's id they are the
    trial's reference into its traces.
    """

    id: int
    haptic_session_id: int
    kind: str
    block: int
    trial: int
    phase: str
    condition: str
    answer: str | None
    correct: bool | None
    started_s: float | None
    answered_s: float | None
    response_time_s: float | None
    detail: dict[str, Any]
    flagged: bool = False

    def to_dict(self) -> dict[str, Any]:
        return {**self.detail, "id": self.id, "haptic_session_id": self.haptic_session_id,
                "kind": self.kind, "block": self.block, "trial": self.trial,
                "phase": self.phase, "condition": self.condition, "answer": self.answer,
                "correct": self.correct, "started_s": self.started_s,
                "answered_s": self.answered_s, "response_time_s": self.response_time_s,
                "flagged": self.flagged}


@dataclass(frozen=True)
class RemoteLinkRecord:
    """The link of a remote haptic session (the key itself is never stored)."""

    id: int
    haptic_session_id: int
    role: str
    peer: str
    key_fingerprint: str
    settings: dict[str, Any]
    summary: dict[str, Any]
    created_at: datetime


@dataclass(frozen=True)
class AssessmentRecord:
    """The posterior over the candidates after one probe, and the clinician's answer.

    ``posterior`` maps each candidate ("elbow severe", "unimpaired") to its probability;
    ``detail`` keeps the group and level posteriors, the next probe drawn and the link's state
    when the probe ended. Times are session times, s.
    """

    id: int
    haptic_session_id: int
    probe: int
    started_s: float | None
    ended_s: float | None
    prior: dict[str, float]
    posterior: dict[str, float]
    group: str | None
    group_probability: float | None
    level: str | None
    level_probability: float | None
    explains: bool | None
    verdict: str
    detail: dict[str, Any]
    answer_group: str | None
    answer_level: str | None
    answer_note: str | None
    answered_s: float | None

    def to_dict(self) -> dict[str, Any]:
        return {"id": self.id, "haptic_session_id": self.haptic_session_id,
                "probe": self.probe, "started_s": self.started_s, "ended_s": self.ended_s,
                "prior": self.prior, "posterior": self.posterior, "group": self.group,
                "group_probability": self.group_probability, "level": self.level,
                "level_probability": self.level_probability, "explains": self.explains,
                "verdict": self.verdict, **self.detail,
                "answer": {"group": self.answer_group, "level": self.answer_level,
                           "note": self.answer_note, "answered_s": self.answered_s}}


@dataclass(frozen=True)
class TraceRecord:
    """A recorded trace of a haptic session; its array is in the array store."""

    id: int
    haptic_session_id: int
    name: str
    array: ArrayRef
    created_at: datetime


@dataclass(frozen=True)
class AuditEntry:
    id: int
    at: datetime
    actor: str
    action: str
    entity: str
    entity_id: str
    detail: dict[str, Any]


@dataclass(frozen=True)
class UserRecord:
    """An account of the workspace. ``password_hash`` is the Argon2id PHC string (never the
    password); ``disabled_at`` set: the account can no longer log in or use its tokens."""

    id: int
    name: str
    role: str
    password_hash: str = field(repr=False)
    created_at: datetime
    disabled_at: datetime | None = None


@dataclass(frozen=True)
class ApiTokenRecord:
    """A bearer token of an account (only its SHA-256 is stored)."""

    id: int
    user: str
    label: str
    created_at: datetime
    revoked_at: datetime | None = None


@dataclass(frozen=True)
class CheckReport:
    """Result of :meth:`Database.check`: problems are errors; orphans are harmless leftovers."""

    problems: tuple[str, ...]
    orphans: tuple[str, ...]
    counts: dict[str, int] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return not self.problems


@dataclass(frozen=True, eq=False)
class IncomingFile:
    """A validated file ready to be stored: its raw bytes and the maps read from it."""

    file_name: str
    sha256: str
    file_format: str
    content: bytes
    maps: tuple[FieldMap, ...]
    #: Per map, the (label, date) of the session it belongs to when the file says so (an NWB
    #: export of several sessions), else None: the batch's session. Empty: all the batch's.
    map_sessions: tuple[tuple[str, date | None] | None, ...] = ()


@dataclass(frozen=True)
class IngestOutcome:
    """What happened to one file of a batch: 'stored', 'duplicate' or (dry run) 'would-store'."""

    file_name: str
    sha256: str
    status: str
    map_ids: tuple[int, ...]
    n_maps: int
