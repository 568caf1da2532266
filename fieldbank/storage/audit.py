"""Reading the audit log, and recording reads of a patient's data.

Every write already appends to ``audit_log`` inside its own transaction
(:meth:`~fieldbank.storage.core.DatabaseCore._audit`); this mixin adds the other half of a
clinic's audit trail: :meth:`AuditTrail.record_read` appends one ``read`` entry when someone
looks at a patient's data (who, when, from where, what), and :meth:`AuditTrail.audit_entries`
reads the log back, filtered by patient, actor and time. Nothing here changes or removes an
entry (the database refuses UPDATE and DELETE on the table).

An entry names its entity by table and id (``plan 7``); which patient it concerns is found
through the rows it names - a patient, its sessions, maps, source files, models, fits, plans,
haptic sessions and their traces and trials - so the filter by patient needs no column the
writes did not fill.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from datetime import datetime
from typing import Any

from sqlalchemy import ColumnElement, and_, false, or_, select
from sqlalchemy.orm import Session

from fieldbank.storage.core import DatabaseCore, now, to_utc
from fieldbank.storage.orm import (
    AuditRow,
    FitRow,
    HapticSessionRow,
    MapRow,
    ModelRow,
    PlanRow,
    SessionRow,
    TraceRow,
)
from fieldbank.storage.records import AuditEntry

#: Longest "what" of a read entry, characters.
MAX_WHAT = 200


def _entry(r: AuditRow) -> AuditEntry:
    return AuditEntry(r.id, to_utc(r.at), r.actor, r.action, r.entity, r.entity_id,
                      json.loads(r.detail_json))


class AuditTrail(DatabaseCore):
    """The audit log of :class:`~fieldbank.storage.Database`: read it, record reads."""

    def record_read(self, patient_code: str, what: str,
                    detail: Mapping[str, Any] | None = None) -> None:
        """Append a ``read`` entry: the actor (and the request context, see
        :meth:`~fieldbank.storage.core.DatabaseCore.acting_as`) looked at ``what`` of the
        patient. An unknown patient is the usual error (nothing is recorded)."""
        with self._write() as s:
            p = self._patient_row(s, patient_code)
            self._audit(s, "read", "patient", p.id,
                        {"patient": p.code, "what": what[:MAX_WHAT], **(detail or {})})

    def _patient_filter(self, s: Session, code: str) -> ColumnElement[bool]:
        """Entries about patient ``code``: its own row and every row that belongs to it."""
        pid = self._patient_row(s, code).id

        def ids(q: Any) -> list[str]:
            return [str(v) for v in s.scalars(q)]

        hs = ids(select(HapticSessionRow.id).where(HapticSessionRow.patient_id == pid))
        owned = {
            "patient": [str(pid)],
            "session": ids(select(SessionRow.id).where(SessionRow.patient_id == pid)),
            "map": ids(select(MapRow.id).where(MapRow.patient_id == pid)),
            "source_file": ids(select(MapRow.source_sha256).where(MapRow.patient_id == pid)
                               .distinct()),
            "model": ids(select(ModelRow.id).where(ModelRow.patient_id == pid)),
            "fit": ids(select(FitRow.id).where(FitRow.patient_id == pid)),
            "plan": ids(select(PlanRow.id).where(PlanRow.patient_id == pid)),
            "haptic_session": hs, "haptic_trials": hs, "haptic_assessments": hs,
            "trace": ids(select(TraceRow.id).where(TraceRow.haptic_session_id.in_(
                [int(h) for h in hs]))) if hs else [],
        }
        clauses = [and_(AuditRow.entity == e, AuditRow.entity_id.in_(v))
                   for e, v in owned.items() if v]
        return or_(*clauses) if clauses else false()

    def audit_entries(self, limit: int | None = None, *, patient: str | None = None,
                      actor: str | None = None, since: datetime | None = None,
                      action: str | None = None) -> list[AuditEntry]:
        """The audit log, newest first: entries about ``patient`` (its code), by ``actor``,
        at or after ``since`` (a timezone-aware time, or naive UTC), of ``action``; ``limit``
        entries at most."""
        q = select(AuditRow).order_by(AuditRow.id.desc())
        with self._read() as s:
            if patient is not None:
                q = q.where(self._patient_filter(s, patient))
            if actor is not None:
                q = q.where(AuditRow.actor == actor)
            if since is not None:
                q = q.where(AuditRow.at >= to_utc(since).replace(tzinfo=None))
            if action is not None:
                q = q.where(AuditRow.action == action)
            if limit is not None:
                q = q.limit(limit)
            return [_entry(r) for r in s.scalars(q)]

    def audit_now(self) -> datetime:
        """The time as the audit log stores it (UTC), timezone-aware."""
        return to_utc(now())
