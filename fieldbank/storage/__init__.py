"""The field database: schema, engine configuration, migrations and the :class:`Database` API.

See :mod:`fieldbank.storage.database` for the API, :mod:`fieldbank.storage.config` for where
the database lives, and ``docs/storage.md`` for the schema and durability guarantees.
"""

from fieldbank.storage.config import data_home, make_engine, mask_url, resolve_url
from fieldbank.storage.database import Database
from fieldbank.storage.records import (
    AuditEntry,
    CheckReport,
    FitRecord,
    HapticSessionRecord,
    IncomingFile,
    IngestOutcome,
    PatientInfo,
    PlanRecord,
    SessionInfo,
    SourceFileInfo,
    StoredMap,
    StoredModel,
    TraceRecord,
)

__all__ = [
    "AuditEntry",
    "CheckReport",
    "Database",
    "FitRecord",
    "HapticSessionRecord",
    "IncomingFile",
    "IngestOutcome",
    "PatientInfo",
    "PlanRecord",
    "SessionInfo",
    "SourceFileInfo",
    "StoredMap",
    "StoredModel",
    "TraceRecord",
    "data_home",
    "make_engine",
    "mask_url",
    "resolve_url",
]
