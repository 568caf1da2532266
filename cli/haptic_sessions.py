"""``fieldbank haptic sessions list|show``: the recorded haptic sessions, from the database."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import click

from fieldbank.cli.options import SESSION_ID, db_option, emit, json_option, open_db
from fieldbank.cli.table import fit_lines, table

if TYPE_CHECKING:  # typing only: the storage and training modules load when a command runs
    from fieldbank.storage import Database, HapticSessionRecord, HapticTrialRecord


@click.group("sessions")
def sessions() -> None:
    """Recorded haptic sessions: when, which models, which patient, the answers."""


def _duration(s: HapticSessionRecord) -> float | None:
    return None if s.ended_at is None else (s.ended_at - s.started_at).total_seconds()


def _model(db: Database, model_id: int | None, plan_id: int | None) -> dict[str, Any] | None:
    if model_id is None:
        return None
    m = db.get_model(model_id)
    plans = [p for p in db.list_plans(m.patient_code)
             if p.result_model_id == m.id and (plan_id is None or p.id == plan_id)]
    return {"id": m.id, "origin": m.origin, "label": m.label, "patient": m.patient_code,
            "plan": plans[-1].label if plans else None,
            "plan_id": plans[-1].id if plans else None}


def _session_doc(db: Database, s: HapticSessionRecord) -> dict[str, Any]:
    from fieldbank.haptic.dbsink import session_plan_id

    plan_id = session_plan_id(s.stats.get("metadata") or {})
    return {"id": s.id, "patient": s.patient_code, "patient_note": s.patient_note,
            "started_at": s.started_at.isoformat(),
            "ended_at": None if s.ended_at is None else s.ended_at.isoformat(),
            "duration_s": _duration(s), "robot": s.robot_url,
            "rate_hz": s.stats.get("rate_hz"), "plan_id": plan_id,
            "model_a": _model(db, s.model_a_id, plan_id),
            "model_b": _model(db, s.model_b_id, plan_id),
            "trials": s.n_trials, "name": s.stats.get("name")}


@sessions.command("list")
@click.option("--patient", help="Only this patient's sessions.")
@db_option
@json_option
def list_cmd(patient: str | None, db_url: str | None, as_json: bool) -> None:
    """List recorded haptic sessions."""
    with open_db(db_url) as db:
        if patient is not None:  # an unknown patient: the one "not found" message
            db.get_patient(patient)
        docs = [_session_doc(db, s) for s in db.list_haptic_sessions(patient)]
    lines = table(("id", "started (UTC)", "length", "patient", "model A", "model B", "trials",
                   "robot"),
                  [(str(d["id"]), d["started_at"][:19].replace("T", " "),
                    "open" if d["duration_s"] is None else f"{d['duration_s']:.1f} s",
                    d["patient"] or "-", str(d["model_a"]["id"] if d["model_a"] else "-"),
                    str(d["model_b"]["id"] if d["model_b"] else "-"), str(d["trials"]),
                    d["robot"]) for d in docs], "><><>>>")
    if not docs:
        lines = ["no haptic sessions recorded" + (f" for patient {patient}" if patient else "")]
    emit(docs, as_json, "\n".join(lines))


#: A group as the results name it (the answer 'both' is the bi-articular group).
_WORDS = {"biarticular": "bi-articular", "both": "bi-articular"}


def _trial_cells(t: HapticTrialRecord) -> tuple[str, ...]:
    right = {True: "right", False: "wrong", None: ""}[t.correct]
    rt = "" if t.response_time_s is None else f"{t.response_time_s:.1f} s"
    window = ("" if t.started_s is None else
              f"t = {t.started_s:.2f}–{(t.answered_s or t.detail.get('ended_s') or 0):.2f} s")
    condition = " ".join(_WORDS.get(w, w) for w in t.condition.split())
    return (str(t.block), str(t.trial + 1), t.phase, condition,
            _WORDS.get(t.answer or "-", t.answer or "-"), right, rt, window)


def _trial_lines(trials: list[HapticTrialRecord]) -> list[str]:
    """The trials as a table, a flagged trial's reason on the line under it."""
    rows = table(("bl", "#", "phase", "condition", "answer", "", "resp.", "trace window"),
                 [_trial_cells(t) for t in trials], ">><<<<><", width=98)
    out = ["  " + rows[0]]
    for t, row in zip(trials, rows[1:], strict=True):  # one line per trial: no cell wraps
        out.append("  " + row)
        if t.flagged:
            out += fit_lines(["      FLAGGED, not counted: "
                              + "; ".join(t.detail.get("flags") or ["fault"])])
    return out


@sessions.command("show")
@click.argument("session_id", type=SESSION_ID)
@db_option
@json_option
def show(session_id: int, db_url: str | None, as_json: bool) -> None:
    """One session: times, models, patient, every trial's answer, the results."""
    from fieldbank.haptic.training import summarise
    from fieldbank.haptic.trainingresults import accuracy_text

    with open_db(db_url) as db:
        s = db.get_haptic_session(session_id)
        doc = _session_doc(db, s)
        trials = db.list_haptic_trials(session_id)
    doc["trial_records"] = [t.to_dict() for t in trials]
    doc["trace"] = f"haptic_session:{s.id}"
    loop = s.stats.get("loop") or {}
    doc["loop"] = {k: loop.get(k) for k in ("period_error_us", "overruns", "realtime_scheduling")}
    doc["faults"] = s.stats.get("faults") or []
    abx = [t for t in trials if t.kind == "abx"]
    training = [t.to_dict() for t in trials if t.kind == "training"]
    if training:
        doc["training_summary"] = summarise(training)
    lines = [f"haptic session {s.id} ({doc['name'] or 'unnamed'})",
             f"  started   {doc['started_at']}",
             f"  ended     {doc['ended_at'] or 'not ended'}"
             + (f" ({doc['duration_s']:.1f} s)" if doc["duration_s"] is not None else ""),
             f"  patient   {s.patient_code or '-'}"
             + (f" (note: {s.patient_note})" if s.patient_note else ""),
             f"  robot     {s.robot_url}"
             + (f" at {doc['rate_hz']:g} Hz" if doc["rate_hz"] else "")]
    for key, name in (("model_a", "model A"), ("model_b", "model B")):
        m = doc[key]
        if m:
            lines.append(f"  {name}   {m['id']}: {m['label']} ({m['origin']}"
                         + (f", patient {m['patient']}" if m["patient"] else "")
                         + (f', plan {m["plan_id"]} "{m["plan"]}"' if m["plan"] else "")
                         + ")")
    pe = (loop.get("period_error_us") or {})
    if pe:
        lines.append(f"  loop      period error p99 {pe.get('p99', 0):.1f} µs, overruns "
                     f"{loop.get('overruns', 0)}; {len(doc['faults'])} fault(s)")
    lines.append(f"  traces    {doc['trace']} (each trial's window below)")
    for kind in sorted({t.kind for t in trials}):  # one table per kind of trial
        lines.append(f"  {kind} trials:")
        lines += _trial_lines([t for t in trials if t.kind == kind])
    if not trials:
        lines.append("  no trials")
    if abx:
        blocks = sorted({t.block for t in abx})
        for b in blocks:
            bt = [t for t in abx if t.block == b]
            counted = [t for t in bt if not t.flagged]
            lines.append(f"  A/B/X block {b}: {sum(bool(t.correct) for t in counted)} of "
                         f"{len(counted)} counted answers correct (A before, B after)"
                         + (f"; {len(bt) - len(counted)} flagged (fault or no force) and "
                            "left out" if len(bt) > len(counted) else ""))
    if training:
        lines += ["  " + line for line in accuracy_text(doc["training_summary"])]
    emit(doc, as_json, "\n".join(lines))
