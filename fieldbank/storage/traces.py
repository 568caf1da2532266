"""Haptic sessions, their recorded traces and their trials.

A haptic session records which models a robot rendered (A, and B for a comparison), when the
session itself started and ended, on which robot (URL stored masked,
:func:`fieldbank.redact.mask_url`), the patient it belongs to, and the session's statistics.
Its traces are large arrays (:mod:`fieldbank.storage.arrays`: with unit and provenance beside
the data; equal arrays share one copy), and every read verifies the array against its SHA-256.
Its trials (A/B/X and training) are rows: condition, answer, whether it was right, response
time, and the trial's time window in the traces.

A session's patient is its models' patient. A session filed under another patient than a model
it renders - or rendering two patients' models - needs a stated reason (``patient_note``);
without one it is refused (:meth:`Traces.session_patient`, used before rendering and at every
push, and again when the session is written). With no patient named, a session takes its
models' patient.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from typing import Any

from numpy.typing import ArrayLike, NDArray
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from fieldbank.errors import StorageError
from fieldbank.redact import mask_url
from fieldbank.storage.arrays import array_ref
from fieldbank.storage.core import DatabaseCore, now, to_utc, to_utc_opt
from fieldbank.storage.orm import (
    ArrayRow,
    HapticSessionRow,
    HapticTrialRow,
    ModelRow,
    PatientRow,
    TraceRow,
)
from fieldbank.storage.records import HapticSessionRecord, HapticTrialRecord, TraceRecord

#: Longest stated reason for a session filed under another patient than its models'.
MAX_PATIENT_NOTE_CHARS = 500
#: Longest robot URL its column holds (String(255)); a longer one - a simulated robot following
#: a long scripted path - is shortened there, and kept whole in the session's statistics
#: (``metadata.robot``, written by the trace sink).
MAX_ROBOT_URL_CHARS = 255


def _column_url(url: str) -> str:
    if len(url) <= MAX_ROBOT_URL_CHARS:
        return url
    return f"{url[:190]}… ({len(url)} characters; whole in the session's metadata)"
_TRIAL_FIELDS = ("kind", "block", "trial", "phase", "condition", "answer", "correct",
                 "started_s", "answered_s", "response_time_s", "flagged")


class Traces(DatabaseCore):
    """Haptic sessions and traces of :class:`~fieldbank.storage.Database`."""

    def _haptic(self, s: Session, r: HapticSessionRow) -> HapticSessionRecord:
        n = s.scalar(select(func.count()).select_from(HapticTrialRow)
                     .where(HapticTrialRow.haptic_session_id == r.id)) or 0
        return HapticSessionRecord(r.id, self._code_of(s, r.patient_id), r.model_a_id,
                                   r.model_b_id, to_utc(r.started_at), to_utc_opt(r.ended_at),
                                   r.robot_url, json.loads(r.stats_json), r.patient_note,
                                   int(n))

    def _session_patient(self, s: Session, model_ids: Sequence[int | None],
                         patient_code: str | None, patient_note: str | None) -> str | None:
        if patient_note is not None and (not patient_note.strip()
                                         or len(patient_note) > MAX_PATIENT_NOTE_CHARS):
            raise StorageError(f"The reason for a session's patient must be 1 to "
                               f"{MAX_PATIENT_NOTE_CHARS} characters.")
        owners: dict[int, str | None] = {}
        for mid in model_ids:
            if mid is None:
                continue
            row = s.get(ModelRow, mid)
            if row is None:
                raise self._no_row(s, ModelRow, "model", mid)
            owners[mid] = self._code_of(s, row.patient_id)
        if patient_code is not None:
            self._patient_row(s, patient_code)  # a clear error for an unknown patient
        named = {c for c in owners.values() if c is not None}
        if patient_code is None and len(named) == 1:
            patient_code = next(iter(named))
        other = {m: c for m, c in owners.items() if c is not None and c != patient_code}
        if other and not patient_note:
            whose = ", ".join(f"model {m} is patient {c}'s" for m, c in sorted(other.items()))
            raise StorageError(
                f"A haptic session filed under {patient_code or 'no patient'!s} renders another "
                f"patient's model ({whose}); render that patient's own models, file the session "
                f"under that patient, or state why (--patient-note).")
        return patient_code

    def session_patient(self, model_ids: Sequence[int | None], patient_code: str | None = None,
                        patient_note: str | None = None) -> str | None:
        """The patient a session rendering ``model_ids`` is filed under (the rule in the module
        docstring); StorageError names the models of another patient when no reason is given.
        """
        with self._read() as s:
            return self._session_patient(s, model_ids, patient_code, patient_note)

    def start_haptic_session(self, model_a_id: int, robot_url: str,
                             model_b_id: int | None = None,
                             patient_code: str | None = None, *,
                             started_at: datetime | None = None,
                             patient_note: str | None = None) -> HapticSessionRecord:
        """Open a haptic session record; the robot URL is stored masked (no password).

        Parameters
        ----------
        started_at : datetime, optional
            When the session itself started (default: now); a naive time is taken as UTC.
        patient_note : str, optional
            Why the session's patient is not its models' patient (required then).
        """
        safe_url = _column_url(mask_url(robot_url))
        with self._write() as s:
            code = self._session_patient(s, (model_a_id, model_b_id), patient_code,
                                         patient_note)
            pid = self._optional_patient_id(s, code)
            row = HapticSessionRow(patient_id=pid, model_a_id=model_a_id, model_b_id=model_b_id,
                                   started_at=_stored_time(started_at), ended_at=None,
                                   robot_url=safe_url, stats_json="{}",
                                   patient_note=patient_note)
            s.add(row)
            s.flush()
            self._audit(s, "start", "haptic_session", row.id, {"robot": safe_url})
            return self._haptic(s, row)

    def end_haptic_session(self, haptic_session_id: int, stats: Mapping[str, Any],
                           ended_at: datetime | None = None) -> HapticSessionRecord:
        """Close a haptic session with its statistics (a JSON document); once only.

        ``ended_at``: when the session itself ended (default: now).
        """
        with self._write() as s:
            row = s.get(HapticSessionRow, haptic_session_id)
            if row is None:
                raise self._no_row(s, HapticSessionRow, "haptic session", haptic_session_id)
            if row.ended_at is not None:
                raise StorageError(f"Haptic session {haptic_session_id} has already ended.")
            end = _stored_time(ended_at)
            if end < row.started_at:
                raise StorageError(f"Haptic session {haptic_session_id} cannot end "
                                   f"({end:%Y-%m-%d %H:%M:%S}) before it started "
                                   f"({row.started_at:%Y-%m-%d %H:%M:%S}).")
            row.ended_at = end
            row.stats_json = json.dumps(dict(stats), sort_keys=True, default=str)
            self._audit(s, "end", "haptic_session", row.id, {})
            return self._haptic(s, row)

    def get_haptic_session(self, haptic_session_id: int) -> HapticSessionRecord:
        with self._read() as s:
            r = s.get(HapticSessionRow, haptic_session_id)
            if r is None:
                raise self._no_row(s, HapticSessionRow, "haptic session", haptic_session_id)
            return self._haptic(s, r)

    def list_haptic_sessions(self, patient_code: str | None = None) -> list[HapticSessionRecord]:
        q = (select(HapticSessionRow)
             .outerjoin(PatientRow, HapticSessionRow.patient_id == PatientRow.id)
             .order_by(HapticSessionRow.id))
        if patient_code is not None:
            q = q.where(PatientRow.code == patient_code)
        with self._read() as s:
            return [self._haptic(s, r) for r in s.scalars(q)]

    def add_haptic_trials(self, haptic_session_id: int,
                          trials: Sequence[Mapping[str, Any]]) -> int:
        """Record a session's trials in one transaction; the number recorded.

        Each trial is a mapping with ``kind`` ('abx' | 'training'), ``block``, ``trial``,
        ``phase``, ``condition``, and optionally ``answer``, ``correct``, ``started_s``,
        ``answered_s``, ``response_time_s``, ``flagged`` (its window held a fault or no force);
        any other key is kept as its detail.
        """
        with self._write() as s:
            if s.get(HapticSessionRow, haptic_session_id) is None:
                raise self._no_row(s, HapticSessionRow, "haptic session", haptic_session_id)
            for i, t in enumerate(trials):
                missing = [k for k in ("kind", "block", "trial", "phase", "condition")
                           if t.get(k) is None]
                if missing:
                    raise StorageError(f"Haptic trial {i} of session {haptic_session_id} "
                                       f"lacks {', '.join(missing)}.")
                detail = {k: v for k, v in t.items() if k not in _TRIAL_FIELDS}
                s.add(HapticTrialRow(
                    haptic_session_id=haptic_session_id, kind=str(t["kind"]),
                    block=int(t["block"]), trial=int(t["trial"]), phase=str(t["phase"]),
                    condition=str(t["condition"]), answer=t.get("answer"),
                    correct=t.get("correct"), started_s=t.get("started_s"),
                    answered_s=t.get("answered_s"), response_time_s=t.get("response_time_s"),
                    flagged=bool(t.get("flagged")),
                    detail_json=json.dumps(detail, sort_keys=True, default=str)))
            s.flush()
            self._audit(s, "add", "haptic_trials", haptic_session_id, {"n": len(trials)})
            return len(trials)

    def list_haptic_trials(self, haptic_session_id: int | None = None,
                           kind: str | None = None) -> list[HapticTrialRecord]:
        """Trials of one session (or of all), in session, block and trial order."""
        q = select(HapticTrialRow).order_by(HapticTrialRow.haptic_session_id,
                                            HapticTrialRow.block, HapticTrialRow.trial)
        if haptic_session_id is not None:
            q = q.where(HapticTrialRow.haptic_session_id == haptic_session_id)
        if kind is not None:
            q = q.where(HapticTrialRow.kind == kind)
        with self._read() as s:
            return [HapticTrialRecord(r.id, r.haptic_session_id, r.kind, r.block, r.trial,
                                      r.phase, r.condition, r.answer, r.correct, r.started_s,
                                      r.answered_s, r.response_time_s, json.loads(r.detail_json),
                                      bool(r.flagged))
                    for r in s.scalars(q)]

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
                raise self._no_row(s, HapticSessionRow, "haptic session", haptic_session_id)
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
                raise self._no_row(s, TraceRow, "trace", trace_id)
            return self.arrays.get(s, t.array_sha256)

    def trace_attrs(self, trace_id: int) -> dict[str, Any]:
        """Unit, SHA-256 and provenance stored beside a trace's array."""
        with self._read() as s:
            t = s.get(TraceRow, trace_id)
            if t is None:
                raise self._no_row(s, TraceRow, "trace", trace_id)
            return self.arrays.attrs(s, t.array_sha256)


def _stored_time(t: datetime | None) -> datetime:
    """A time as stored (UTC without a zone); now when None; a naive time is UTC already."""
    if t is None:
        return now()
    return t if t.tzinfo is None else t.astimezone(UTC).replace(tzinfo=None)
