"""Session bookkeeping: migration 0003 on both backends (existing sessions kept, their A/B/X
answers become trial rows), the patient rule, the session's own times, and ``haptic sessions``,
``status`` and ``serve`` on the command line."""

from __future__ import annotations

import datetime as dt
import json
import re
import threading
import time
from pathlib import Path

import pytest
from click.testing import CliRunner
from sqlalchemy import text

from fieldbank.cli.haptic import haptic
from fieldbank.cli.haptic_control import status_table
from fieldbank.cli.main import cli
from fieldbank.errors import StorageError
from fieldbank.haptic import session
from fieldbank.haptic.client import ControlClient, push_models
from fieldbank.haptic.dbsink import DatabaseTraceSink, trial_rows
from fieldbank.haptic.errors import CommandError
from fieldbank.haptic.probe import probe
from fieldbank.storage import Database, make_engine, migrate
from tests.haptic_util import severe_shoulder, unimpaired

OLD_STATS = {
    "name": "old", "rate_hz": 1000.0, "loop": {}, "faults": [],
    "events": [{"t_s": 1.0, "event": "abx_start", "n_trials": 2, "seed": 5},
               {"t_s": 2.0, "event": "abx_present", "label": "X", "trial": 0}],
    "metadata": {"abx": [{"n_trials": 2, "answered": 2, "correct": 1, "seed": 5,
                          "hide_labels": True, "label_model": {"A": 1, "B": 0},
                          "answers": [{"trial": 0, "answer": "A", "x_is": "A", "correct": True,
                                       "x_model": 1, "t_s": 4.5},
                                      {"trial": 1, "answer": "A", "x_is": "B", "correct": False,
                                       "x_model": 0, "t_s": 9.0}]}]},
}


def test_migration_0003_keeps_sessions_and_their_answers(any_db_url: str) -> None:
    engine = make_engine(any_db_url)
    try:
        migrate.upgrade(engine, "0001")
        now = dt.datetime(2026, 1, 2, 3, 4, 5)
        with engine.begin() as c:
            c.execute(text("INSERT INTO models (id, origin, label, params_json, created_at) "
                           "VALUES (1, 'synthetic', 'm', :p, :t)"),
                      {"p": json.dumps(unimpaired().to_dict()), "t": now})
            for sid, stats in ((1, OLD_STATS), (2, {"name": "no answers"}), (3, "not json")):
                c.execute(text("INSERT INTO haptic_sessions (id, model_a_id, started_at, "
                               "ended_at, robot_url, stats_json) VALUES (:i, 1, :t, :t, "
                               "'sim://', :s)"),
                          {"i": sid, "t": now, "s": stats if isinstance(stats, str)
                           else json.dumps(stats)})
        migrate.upgrade(engine)
        assert migrate.current_revision(engine) == migrate.head_revision()
        migrate.check_drift(engine)
        db = Database(engine, None, "test")  # type: ignore[arg-type]  # no arrays read here
        with engine.connect() as c:  # session 3's unreadable document is left as it was
            assert c.execute(text("SELECT stats_json FROM haptic_sessions WHERE id = 3")
                             ).scalar() == "not json"
        rows = db.list_haptic_trials(1)
        assert [(r.trial, r.answer, r.correct, r.condition) for r in rows] == [
            (0, "A", True, "X=A"), (1, "A", False, "X=B")]
        assert rows[0].started_s == 1.0 and rows[0].response_time_s == pytest.approx(3.5)
        assert rows[1].started_s == 4.5 and rows[1].response_time_s == pytest.approx(4.5)
        assert rows[0].detail["label_model"] == {"A": 1, "B": 0}
        # the backfill is the sink's own reading of the same document
        assert [(r["trial"], r["started_s"]) for r in trial_rows(
            OLD_STATS["events"], OLD_STATS["metadata"])] == [(0, 1.0), (1, 4.5)]  # type: ignore[arg-type]
        assert db.get_haptic_session(1).n_trials == 2 and db.list_haptic_trials(2) == []
        # back down: the sessions and their statistics (with every answer) are still there
        migrate.downgrade(engine, "0001")
        with engine.connect() as c:
            got = c.execute(text("SELECT id, stats_json FROM haptic_sessions ORDER BY id")).all()
        assert [g[0] for g in got] == [1, 2, 3]
        assert json.loads(got[0][1]) == OLD_STATS
        migrate.upgrade(engine)
        assert len(db.list_haptic_trials(1)) == 2
    finally:
        engine.dispose()


@pytest.fixture(params=["sqlite", pytest.param("postgres", marks=pytest.mark.postgres)])
def db(request: pytest.FixtureRequest, tmp_path: Path):  # type: ignore[no-untyped-def]
    url = (request.getfixturevalue("pg_url") if request.param == "postgres"
           else f"sqlite:///{tmp_path / 'fb.sqlite'}")
    d = Database.open(url, upgrade="always", store_root=tmp_path / "a")
    yield d
    d.close()


def test_a_session_belongs_to_its_models_patient_or_says_why(db: Database) -> None:
    db.add_patient("P-1", 70, 1.7, "right")
    db.add_patient("P-2", 80, 1.8, "right")
    m1 = db.add_model(severe_shoulder(), "synthetic", "p1 model", patient_code="P-1").id
    m2 = db.add_model(unimpaired(), "synthetic", "p2 model", patient_code="P-2").id
    free = db.add_model(unimpaired(), "synthetic", "no patient").id
    assert db.session_patient([m1, free]) == "P-1"         # taken from its models
    assert db.session_patient([free, None]) is None
    assert db.session_patient([m1, m1], "P-1") == "P-1"
    with pytest.raises(StorageError, match="model 1 is patient P-1's"):
        db.session_patient([m1, free], "P-2")
    with pytest.raises(StorageError, match="model 2 is patient P-2's"):
        db.session_patient([m1, m2])
    with pytest.raises(StorageError, match="No model with id 999"):
        db.session_patient([999])
    with pytest.raises(StorageError, match="No patient with code"):
        db.session_patient([free], "P-9")
    note = "teaching session: P-2 feels P-1's arm"
    s = db.start_haptic_session(m1, "sim://", m2, "P-2", patient_note=note)
    assert s.patient_code == "P-2" and s.patient_note == note
    with pytest.raises(StorageError, match="renders another patient's model"):
        db.start_haptic_session(m1, "sim://", None, "P-2")


def test_the_record_keeps_the_sessions_own_times(db: Database) -> None:
    trace = probe(severe_shoulder(), "fastpull").trace
    start = dt.datetime(2026, 3, 4, 10, 0, 0, tzinfo=dt.UTC)
    end = start + dt.timedelta(seconds=42)
    trace.metadata.update(started_at=start.isoformat(), ended_at=end.isoformat())
    ref = DatabaseTraceSink(db).write_trace(trace, "timed")
    s = db.get_haptic_session(int(ref.split(":")[1]))
    assert (s.started_at, s.ended_at) == (start, end)
    # the renderer stamps them itself, UTC, around the rendering
    t0 = dt.datetime.now(dt.UTC)
    live = probe(severe_shoulder(), "fastpull").trace
    started = dt.datetime.fromisoformat(live.metadata["started_at"])
    ended = dt.datetime.fromisoformat(live.metadata["ended_at"])
    assert t0 <= started <= ended <= dt.datetime.now(dt.UTC)
    with pytest.raises(StorageError, match="before it started"):
        sid = db.start_haptic_session(s.model_a_id, "sim://", started_at=end).id
        db.end_haptic_session(sid, {}, ended_at=start)


def test_sessions_list_and_show_on_the_command_line(db: Database, tmp_path: Path) -> None:
    db.add_patient("P-7", 70, 1.7, "right")
    m = db.add_model(severe_shoulder(), "synthetic", "shoulder severe", patient_code="P-7")
    url = db.engine.url.render_as_string(hide_password=False)
    trace = probe(severe_shoulder(), "fastpull").trace
    trace.metadata.update(model_ids={"A": m.id, "B": m.id}, abx=OLD_STATS["metadata"]["abx"])  # type: ignore[index]
    trace.events.extend(OLD_STATS["events"])  # type: ignore[arg-type]
    ref = DatabaseTraceSink(db).write_trace(trace, "cli")
    sid = int(ref.split(":")[1])
    run = CliRunner()
    r = run.invoke(haptic, ["sessions", "list", "--db", url, "--json"])
    assert r.exit_code == 0, r.output
    (doc,) = json.loads(r.stdout)
    assert doc["id"] == sid and doc["patient"] == "P-7" and doc["trials"] == 2
    assert doc["model_a"]["label"] == "shoulder severe" and doc["duration_s"] >= 0
    r = run.invoke(haptic, ["sessions", "list", "--db", url])
    assert "P-7" in r.stdout and "started (UTC)" in r.stdout
    r = run.invoke(haptic, ["sessions", "show", str(sid), "--db", url])
    assert r.exit_code == 0, r.output
    assert "A/B/X block 0: 1 of 2 counted answers correct" in r.stdout and "X=B" in r.stdout
    assert f"haptic_session:{sid}" in r.stdout and "patient   P-7" in r.stdout
    r = run.invoke(haptic, ["sessions", "show", str(sid), "--db", url, "--json"])
    assert len(json.loads(r.stdout)["trial_records"]) == 2
    r = run.invoke(cli, ["haptic", "sessions", "show", "999", "--db", url])
    assert r.exit_code == 1 and "No haptic session with id 999" in r.output


def test_serve_refuses_another_patients_models_before_the_robot_moves(db: Database,
                                                                       tmp_path: Path) -> None:
    db.add_patient("P-1", 70, 1.7, "right")
    db.add_patient("P-2", 70, 1.7, "right")
    m = db.add_model(severe_shoulder(), "synthetic", "p1", patient_code="P-1").id
    with pytest.raises(StorageError, match="renders another patient's model"):
        session.serve("sim://?motion=hold", severe_shoulder(), severe_shoulder(),
                      model_ids=(m, m), patient_code="P-2", duration_s=0.05, control=False,
                      db=db)
    assert db.list_haptic_sessions() == []


def test_pushed_model_ids_are_checked_against_the_database(db: Database, tmp_path: Path) -> None:
    db.add_patient("P-1", 70, 1.7, "right")
    db.add_patient("P-2", 70, 1.7, "right")
    own = db.add_model(severe_shoulder(), "synthetic", "p1", patient_code="P-1").id
    other = db.add_model(unimpaired(), "synthetic", "p2", patient_code="P-2").id
    sock = tmp_path / "run" / "h.sock"
    out: dict[str, object] = {}

    def run() -> None:
        out["res"] = session.serve(
            "sim://?mode=realtime&motion=hold&watchdog_ms=1000", severe_shoulder(),
            severe_shoulder(), model_ids=(own, own), duration_s=30.0, socket_path=sock, db=db,
            config=session.RendererConfig(realtime_priority=False), watchdog_ms=1000)

    th = threading.Thread(target=run, daemon=True)
    th.start()
    c = ControlClient(sock)
    deadline = time.time() + 10
    while time.time() < deadline:
        try:
            if c.request("status")["running"]:
                break
        except Exception:  # not up yet
            time.sleep(0.05)
    with pytest.raises(CommandError, match="No model with id 999"):
        push_models(unimpaired(), unimpaired(), sock, model_ids=(999, None))
    with pytest.raises(CommandError, match="model 2 is patient P-2's"):
        push_models(unimpaired(), unimpaired(), sock, model_ids=(own, other))
    assert push_models(severe_shoulder(), unimpaired(), sock,
                       model_ids=(own, None))["pushed"] is True
    table = status_table(c.request("status"))
    assert "renderer" in table and "A · before" in table and "felt now" in table
    c.request("stop")
    th.join(10)
    res = out["res"]
    s = db.get_haptic_session(int(res.database.split(":")[1]))  # type: ignore[attr-defined]
    assert s.patient_code == "P-1"
    pushes = [e for e in s.stats["events"] if e["event"] == "push"]
    assert pushes == [{"t_s": pushes[0]["t_s"], "event": "push",
                       "model_ids": {"A": own, "B": None}}]


def test_status_table_reads_like_a_table() -> None:
    st = {"running": True, "mode": "ARMED", "t_s": 12.5, "ticks": 12500, "gain": 1.0,
          "blend": 1.0, "force_n": [3.0, 4.0], "handle_m": [0.1, 0.45],
          "latched_faults": [], "faults_logged": 0,
          "loop_last_10s": {"period_error_us": {"p50": 3.0, "p99": 40.0, "max": 90.0},
                            "overruns": 0, "tick_total_us": {"p99": 70.0},
                            "realtime_scheduling": False},
          "abx_trial": None, "training": None,
          "models": {"A": {"label": "fitted model", "model_id": 3, "patient": "P-1",
                           "plan": None},
                     "B": {"label": "after botox", "model_id": 7, "patient": "P-1",
                           "plan": "botox ef=200U"}}}
    t = status_table(st)
    lines = t.splitlines()
    assert lines[0].startswith("renderer    running · ARMED · t = 12.50 s")
    assert "A · before  fitted model · model 3 · patient P-1" in t
    assert 'B · after   after botox · model 7 · patient P-1 · plan "botox ef=200U"' in t
    assert "after: after" not in t and "re-arm" not in t
    assert "felt now    B (after); blend 1.00" in t
    assert "force 5.00 N" in t and "p99 40.0 µs" in t
    blinded = status_table({**st, "blend": "hidden", "models": "hidden", "abx_trial": 2})
    assert "hidden (blinded)" in blinded and "trial 3 running" in blinded
    assert "fitted model" not in blinded
    faulted = status_table({**st, "mode": "FAULT", "latched_faults": ["DEVICE"],
                            "faults_now": [{"name": "DEVICE", "t_s": 3.2,
                                            "message": "device watchdog tripped",
                                            "what": "The robot stopped itself.",
                                            "todo": "Re-arm."}],
                            "rearm_refused_because": ["handle speed 3 m/s over the limit"],
                            "paused": True})
    assert re.search(r"\n  DEVICE +The robot stopped itself\. \(device watchdog tripped, "
                     r"t = 3\.20 s\)\. Re-arm\.", faulted)
    assert re.search(r"\nre-arm +would be refused: handle speed 3 m/s over the limit", faulted)
    assert "paused" in faulted
