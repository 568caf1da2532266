"""Sessions into the field database and back, and the serve command end to end."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fieldbank.cli.haptic import haptic
from fieldbank.haptic.probe import probe
from fieldbank.haptic.recording import COLUMNS
from fieldbank.haptic.replay import rerun
from tests.haptic_util import severe_shoulder


def test_serve_on_the_simulated_robot_writes_a_trace(tmp_path: Path) -> None:
    r = CliRunner().invoke(haptic, [
        "serve", "--robot", "sim://?mode=realtime&motion=fastpull", "--duration-s", "0.6",
        "--before-severity", "shoulder=severe", "--after-severity", "shoulder=mild",
        "--trace-dir", str(tmp_path / "traces"), "--socket", str(tmp_path / "run" / "h.sock"),
        "--no-db", "--json"])
    assert r.exit_code == 0, r.output
    s = json.loads(r.stdout)
    assert s["ticks"] == 600 and len(s["sha256"]) == 64
    assert s["stats"]["rate_hz"] == 1000 and "period_error_us" in s["stats"]
    assert not (tmp_path / "run" / "h.sock").exists()  # the socket is removed at the end
    r2 = CliRunner().invoke(haptic, ["replay", s["trace"], "--rerun", "--json"])
    assert r2.exit_code == 0, r2.output
    assert json.loads(r2.stdout)["rerun"]["max_deviation_n"] < 1e-4


def test_replay_refuses_a_missing_trace() -> None:
    r = CliRunner().invoke(haptic, ["replay", "/nonexistent/t.h5"])
    assert r.exit_code == 2 and "no trace file" in r.output


# --- with the field database ----------------------------------------------------------------
@pytest.fixture(params=["sqlite", pytest.param("postgres", marks=pytest.mark.postgres)])
def db(request: pytest.FixtureRequest, tmp_path: Path):  # type: ignore[no-untyped-def]
    """The field database on each backend (PostgreSQL through the shared ``pg_url`` fixture)."""
    import fieldbank.storage as storage
    if request.param == "postgres":
        url = request.getfixturevalue("pg_url")
    else:
        url = f"sqlite:///{tmp_path / 'fb.sqlite'}"
    d = storage.Database.open(url, upgrade="always", store_root=tmp_path / "a")
    yield d
    d.close()


def test_database_sink_round_trip(db) -> None:  # type: ignore[no-untyped-def]
    from fieldbank.haptic.dbsink import DatabaseTraceSink, read_trace_db

    trace = probe(severe_shoulder(), "fastpull").trace
    ref = DatabaseTraceSink(db).write_trace(trace, "s1")
    sid = int(ref.split(":")[1])
    back = read_trace_db(db, sid)
    assert np.array_equal(back.t_s, trace.t_s)
    assert np.array_equal(back.data, trace.data)
    assert back.models["A"] == severe_shoulder().to_dict()
    assert back.faults == trace.faults
    assert rerun(back)["max_deviation_n"] < 1e-4
    traces = db.list_traces(sid)
    assert {t.name for t in traces} == {"t_s"} | {c for c, _ in COLUMNS}
    units = {t.name: t.array.unit for t in traces}
    assert units["fx_n"] == "N" and units["t_s"] == "s"
    sess = db.get_haptic_session(sid)
    assert sess.ended_at is not None and sess.stats["rate_hz"] == 1000.0
    report = db.check()
    assert report.ok and not report.orphans, report


def test_serve_records_the_session_in_the_database(db, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    m = db.add_model(severe_shoulder(), "synthetic", "severe shoulder")
    url = db.engine.url.render_as_string(hide_password=False)
    r = CliRunner().invoke(haptic, [
        "serve", "--robot", "sim://?mode=realtime&motion=hold", "--duration-s", "0.3",
        "--before-id", str(m.id), "--db", url, "--trace-dir", str(tmp_path / "t"),
        "--socket", str(tmp_path / "h.sock"), "--json"])
    assert r.exit_code == 0, r.output
    ref = json.loads(r.stdout)["database"]
    sid = int(ref.split(":")[1])
    sess = db.get_haptic_session(sid)
    assert sess.model_a_id == m.id and sess.model_b_id == m.id
