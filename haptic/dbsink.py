"""Traces into the field database: a :class:`haptic.recording.TraceSink` over
:class:`fieldbank.storage.Database`.

A session becomes one ``haptic_session`` row (models A and B, robot URL, the wall-clock times
the session itself started and ended, and as its statistics the loop figures, faults, events,
A/B/X and training results and metadata), one trace per column — time and every per-tick
column of :data:`haptic.recording.COLUMNS`, each an array in the HDF5 array store with its
unit, checksummed by the storage layer — and one ``haptic_trials`` row per A/B/X or training
trial (:func:`trial_rows`). The session's models are the ones the clinician chose - those it
started with, or the last pair pushed - never a training protocol's arms; stored models are
referred to by id (with the plan, for a what-if pair), and only models rendered without a
database id (from a file or a severity) are stored first (origin 'synthetic', labelled as
haptic-session models).

The sink is typed against :class:`HapticStore`, the part of the ``Database`` API it uses, so the
storage layer (SQLAlchemy) is loaded by whoever opens a database, not by this module.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numpy.typing import ArrayLike

from fieldbank.errors import StorageError
from fieldbank.haptic.recording import COLUMNS, NCOL, Trace, public_metadata
from fieldbank.params import ArmParams

if TYPE_CHECKING:  # typing only: the records come with whatever database is passed in
    from fieldbank.storage.records import (
        HapticSessionRecord,
        HapticTrialRecord,
        StoredModel,
        TraceRecord,
    )

SESSION_PREFIX = "haptic_session:"


class HapticStore(Protocol):
    """The methods of :class:`fieldbank.storage.Database` that haptic sessions use."""

    def add_model(self, params: ArmParams, origin: str, label: str,
                  patient_code: str | None = None, parent_id: int | None = None) -> StoredModel:
        ...

    def get_model(self, model_id: int) -> StoredModel: ...

    def session_patient(self, model_ids: Sequence[int | None], patient_code: str | None = None,
                        patient_note: str | None = None) -> str | None: ...

    def start_haptic_session(self, model_a_id: int, robot_url: str,
                             model_b_id: int | None = None,
                             patient_code: str | None = None, *,
                             started_at: _dt.datetime | None = None,
                             patient_note: str | None = None) -> HapticSessionRecord: ...

    def end_haptic_session(self, haptic_session_id: int, stats: Mapping[str, Any],
                           ended_at: _dt.datetime | None = None) -> HapticSessionRecord: ...

    def add_haptic_trials(self, haptic_session_id: int,
                          trials: Sequence[Mapping[str, Any]]) -> int: ...

    def list_haptic_trials(self, haptic_session_id: int | None = None,
                           kind: str | None = None) -> list[HapticTrialRecord]: ...

    def get_haptic_session(self, haptic_session_id: int) -> HapticSessionRecord: ...

    def add_trace(self, haptic_session_id: int, name: str, array: ArrayLike, unit: str,
                  provenance: Mapping[str, Any] | None = None) -> TraceRecord: ...

    def list_traces(self, haptic_session_id: int) -> list[TraceRecord]: ...

    def get_trace_array(self, trace_id: int) -> np.ndarray: ...


class DatabaseTraceSink:
    """Records traces in ``db`` (a :class:`fieldbank.storage.Database`).

    Parameters
    ----------
    db : HapticStore
    patient_code : str, optional
        The patient the sessions belong to (default: their models' patient).
    patient_note : str, optional
        Why the sessions' patient is not their models' patient (required then).
    """

    def __init__(self, db: HapticStore, patient_code: str | None = None,
                 patient_note: str | None = None) -> None:
        self.db = db
        self.patient_code = patient_code
        self.patient_note = patient_note

    def _model_id(self, trace: Trace, key: str, name: str) -> int:
        ids = trace.metadata.get("model_ids") or {}
        if ids.get(key) is not None:
            return int(ids[key])
        params = ArmParams.from_dict(trace.models[key], where=f"trace {name} model {key}")
        stored = self.db.add_model(params, "synthetic", f"haptic session {name}: model {key}",
                                   patient_code=self.patient_code)
        return int(stored.id)

    def write_trace(self, trace: Trace, name: str) -> str:
        a_id = self._model_id(trace, "A", name)
        b_id = self._model_id(trace, "B", name)
        metadata = public_metadata(trace.metadata)
        robot = str(metadata.get("robot", "unknown"))
        sess = self.db.start_haptic_session(
            a_id, robot, model_b_id=b_id, patient_code=self.patient_code,
            started_at=_when(trace.metadata.get("started_at")), patient_note=self.patient_note)
        prov = {"trace_name": name, "rate_hz": trace.rate_hz, "frame": "robot",
                "sign": "force on the handle"}
        self.db.add_trace(sess.id, "t_s", np.asarray(trace.t_s, dtype=np.float64), "s", prov)
        for i, (col, unit) in enumerate(COLUMNS):
            self.db.add_trace(sess.id, col, np.ascontiguousarray(trace.data[:, i]), unit, prov)
        trials = trial_rows(trace.events, trace.metadata)
        if trials:
            self.db.add_haptic_trials(sess.id, trials)
        self.db.end_haptic_session(sess.id, {
            "name": name, "rate_hz": trace.rate_hz, "loop": trace.stats,
            "faults": trace.faults, "events": trace.events, "metadata": metadata,
        }, ended_at=_when(trace.metadata.get("ended_at")))
        return f"{SESSION_PREFIX}{sess.id}"


def session_plan_id(metadata: Mapping[str, Any]) -> int | None:
    """The stored plan of the session's models (model B's, else A's), or None: the session
    record keeps it in its statistics document, with the models' descriptions."""
    info = metadata.get("model_info") or {}
    for k in ("B", "A"):
        pid = (info.get(k) or {}).get("plan_id")
        if isinstance(pid, int) and not isinstance(pid, bool):
            return pid
    return None


def _when(text: object) -> _dt.datetime | None:
    """An ISO 8601 time from a trace's metadata (None when absent or unreadable)."""
    if not isinstance(text, str):
        return None
    try:
        return _dt.datetime.fromisoformat(text)
    except ValueError:
        return None


def trial_rows(events: Sequence[Mapping[str, Any]],
               metadata: Mapping[str, Any]) -> list[dict[str, Any]]:
    """One row per A/B/X and training trial of a session, for ``haptic_trials``.

    A/B/X blocks come first (``block`` 0, 1, …; a trial starts when the previous answer was
    given, the first when its block started), then the training sessions, each a block. Times
    are session times, s: the trial's window in the session's traces.
    """
    rows: list[dict[str, Any]] = []
    starts = [float(e["t_s"]) for e in events if e.get("event") == "abx_start"]
    block = 0
    for res in metadata.get("abx") or []:
        prev = starts[block] if block < len(starts) else None
        for a in res.get("answers") or []:
            answered = float(a["t_s"])
            rows.append({
                "kind": "abx", "block": block, "trial": int(a["trial"]), "phase": "abx",
                "condition": f"X={a['x_is']}" + (f" ({a['x_was']})" if a.get("x_was") else ""),
                "answer": a["answer"], "correct": a["correct"],
                "started_s": prev, "answered_s": answered,
                "response_time_s": None if prev is None else answered - prev,
                "x_model": a.get("x_model"), "x_was": a.get("x_was"),
                "label_model": res.get("label_model"), "seed": res.get("seed"),
                "flagged": bool(a.get("flagged")), "flags": a.get("flags") or [],
                "peak_force_n": a.get("peak_force_n"),
            })
            prev = answered
        block += 1
    for res in metadata.get("training") or []:
        proto = res.get("protocol") or {}
        for t in res.get("trials") or []:
            rows.append({
                "kind": "training", "block": block, "trial": int(t["trial"]),
                "phase": t["phase"], "condition": t["condition"], "answer": t.get("answer"),
                "correct": t.get("correct"), "started_s": t.get("started_s"),
                "answered_s": t.get("answered_s"), "response_time_s": t.get("response_time_s"),
                "group": t.get("group"), "severity": t.get("severity"),
                "instruction": t.get("instruction"), "legend_shown": t.get("legend_shown"),
                "ended_s": t.get("ended_s"), "duration_s": t.get("duration_s"),
                "protocol_seed": proto.get("seed"), "protocol": res.get("protocol_name"),
                "abandoned": res.get("abandoned", False),
                "flagged": bool(t.get("flagged")), "flags": t.get("flags") or [],
                "peak_force_n": t.get("peak_force_n"),
            })
        block += 1
    return rows


def read_trace_db(db: HapticStore, haptic_session_id: int) -> Trace:
    """Rebuild a :class:`Trace` from a recorded haptic session; StorageError if incomplete."""
    sess = db.get_haptic_session(haptic_session_id)
    arrays = {t.name: t for t in db.list_traces(haptic_session_id)}
    missing = [c for c in ["t_s"] + [n for n, _ in COLUMNS] if c not in arrays]
    if missing:
        raise StorageError(f"haptic session {haptic_session_id} lacks trace(s) "
                           f"{', '.join(missing)}")
    t = np.asarray(db.get_trace_array(arrays["t_s"].id), dtype=np.float64)
    data = np.empty((t.shape[0], NCOL), dtype=np.float32)
    for i, (col, _unit) in enumerate(COLUMNS):
        data[:, i] = db.get_trace_array(arrays[col].id)
    st = sess.stats
    models = {"A": db.get_model(sess.model_a_id).params.to_dict()}
    models["B"] = (db.get_model(sess.model_b_id).params.to_dict() if sess.model_b_id is not None
                   else models["A"])
    meta = dict(st.get("metadata", {}))
    meta.setdefault("model_ids", {"A": sess.model_a_id, "B": sess.model_b_id})
    return Trace(t_s=t, data=data, rate_hz=float(st.get("rate_hz", 1000.0)), models=models,
                 events=list(st.get("events", [])), faults=list(st.get("faults", [])),
                 stats=dict(st.get("loop", {})), metadata=meta)
