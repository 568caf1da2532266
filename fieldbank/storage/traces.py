"""Haptic sessions and their recorded traces.

A haptic session records which models a robot rendered (A, and B for a comparison), when, on
which robot (URL stored masked, :func:`fieldbank.redact.mask_url`) and the session's statistics.
Its traces are large arrays (:mod:`fieldbank.storage.arrays`: with unit and provenance beside
the data; equal arrays share one copy), and every read verifies the array against its SHA-256.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

from numpy.typing import ArrayLike, NDArray
from sqlalchemy import select
from sqlalchemy.orm import Session

from fieldbank.errors import StorageError
from fieldbank.redact import mask_url
from fieldbank.storage.arrays import array_ref
from fieldbank.storage.core import DatabaseCore, now, to_utc, to_utc_opt
from fieldbank.storage.orm import ArrayRow, HapticSessionRow, ModelRow, PatientRow, TraceRow
from fieldbank.storage.records import HapticSessionRecord, TraceRecord


class Traces(DatabaseCore):
    """Haptic sessions and traces of :class:`~fieldbank.storage.Database`."""

    def _haptic(self, s: Session, r: HapticSessionRow) -> HapticSessionRecord:
        return HapticSessionRecord(r.id, self._code_of(s, r.patient_id), r.model_a_id,
                                   r.model_b_id, to_utc(r.started_at), to_utc_opt(r.ended_at),
                                   r.robot_url, json.loads(r.stats_json))

    def start_haptic_session(self, model_a_id: int, robot_url: str,
                             model_b_id: int | None = None,
                             patient_code: str | None = None) -> HapticSessionRecord:
        """Open a haptic session record; the robot URL is stored masked (no password)."""
        safe_url = mask_url(robot_url)
        with self._write() as s:
            pid = self._optional_patient_id(s, patient_code)
            for mid in (model_a_id, model_b_id):
                if mid is not None and s.get(ModelRow, mid) is None:
                    raise StorageError(f"No model with id {mid}.")
            row = HapticSessionRow(patient_id=pid, model_a_id=model_a_id, model_b_id=model_b_id,
                                   started_at=now(), ended_at=None, robot_url=safe_url,
                                   stats_json="{}")
            s.add(row)
            s.flush()
            self._audit(s, "start", "haptic_session", row.id, {"robot": safe_url})
            return self._haptic(s, row)

    def end_haptic_session(self, haptic_session_id: int,
                           stats: Mapping[str, Any]) -> HapticSessionRecord:
        """Close a haptic session with its statistics (a JSON document); once only."""
        with self._write() as s:
            row = s.get(HapticSessionRow, haptic_session_id)
            if row is None:
                raise StorageError(f"No haptic session with id {haptic_session_id}.")
            if row.ended_at is not None:
                raise StorageError(f"Haptic session {haptic_session_id} has already ended.")
            row.ended_at = now()
            row.stats_json = json.dumps(dict(stats), sort_keys=True, default=str)
            self._audit(s, "end", "haptic_session", row.id, {})
            return self._haptic(s, row)

    def get_haptic_session(self, haptic_session_id: int) -> HapticSessionRecord:
        with self._read() as s:
            r = s.get(HapticSessionRow, haptic_session_id)
            if r is None:
                raise StorageError(f"No haptic session with id {haptic_session_id}.")
            return self._haptic(s, r)

    def list_haptic_sessions(self, patient_code: str | None = None) -> list[HapticSessionRecord]:
        q = (select(HapticSessionRow)
             .outerjoin(PatientRow, HapticSessionRow.patient_id == PatientRow.id)
             .order_by(HapticSessionRow.id))
        if patient_code is not None:
            q = q.where(PatientRow.code == patient_code)
        with self._read() as s:
            return [self._haptic(s, r) for r in s.scalars(q)]

    def add_trace(self, haptic_session_id: int, name: str, array: ArrayLike, unit: str,
                  provenance: Mapping[str, Any] | None = None) -> TraceRecord:
        """Write an array to the HDF5 store, then record it as a trace of the session.

        Parameters
        ----------
        array : array_like
            Any numeric array, stored with its dtype and shape.
        unit : str
            Unit of the values ('N', 'm', 'rad', ...); required.
        provenance : mapping, optional
            JSON document stored beside the array (rate, robot, software, ...).
        """
        pending = self.arrays.prepare(array, unit, {"haptic_session": haptic_session_id,
                                                    "trace": name, "stored_by": self.actor,
                                                    **dict(provenance or {})})
        ref = pending.ref
        with self._write() as s:
            if s.get(HapticSessionRow, haptic_session_id) is None:
                raise StorageError(f"No haptic session with id {haptic_session_id}.")
            self.arrays.record(s, pending, now())
            row = TraceRow(haptic_session_id=haptic_session_id, name=name,
                           array_sha256=ref.sha256, created_at=now())
            s.add(row)
            s.flush()
            self._audit(s, "add", "trace", row.id, {"array": ref.sha256, "unit": unit})
            return TraceRecord(row.id, haptic_session_id, name, ref, to_utc(row.created_at))

    def list_traces(self, haptic_session_id: int) -> list[TraceRecord]:
        q = (select(TraceRow, ArrayRow).join(ArrayRow, TraceRow.array_sha256 == ArrayRow.sha256)
             .where(TraceRow.haptic_session_id == haptic_session_id).order_by(TraceRow.id))
        with self._read() as s:
            return [TraceRecord(t.id, t.haptic_session_id, t.name, array_ref(a),
                                to_utc(t.created_at)) for t, a in s.execute(q)]

    def get_trace_array(self, trace_id: int) -> NDArray[Any]:
        """The trace's array, verified against its SHA-256 (dtype and shape as stored)."""
        with self._read() as s:
            t = s.get(TraceRow, trace_id)
            if t is None:
                raise StorageError(f"No trace with id {trace_id}.")
            return self.arrays.get(s, t.array_sha256)

    def trace_attrs(self, trace_id: int) -> dict[str, Any]:
        """Unit, SHA-256 and provenance stored beside a trace's array."""
        with self._read() as s:
            t = s.get(TraceRow, trace_id)
            if t is None:
                raise StorageError(f"No trace with id {trace_id}.")
            return self.arrays.attrs(s, t.array_sha256)
