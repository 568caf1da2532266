"""Honest faults and the session's own models, on the in-process simulated robot (lockstep, a
virtual clock): a fault pauses training and A/B/X (no answer is taken while it lasts), the trial
whose window held it is stored flagged and left out of accuracy, push and switch answer with
the renderer's true state, and a session started with the patient's models 1 and 5 is stored
with 1 and 5 after a training protocol rendered its own arms."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from click.testing import CliRunner

from fieldbank.cli.main import cli
from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic.activities.abx import AbxBlock
from fieldbank.haptic.activities.training import Training
from fieldbank.haptic.clock import VirtualClock
from fieldbank.haptic.commands import Push
from fieldbank.haptic.dbsink import DatabaseTraceSink
from fieldbank.haptic.errors import CommandError
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.modelinfo import ModelInfo, to_wire
from fieldbank.haptic.probe import sim_url
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.training import TrainingProtocol
from fieldbank.params import ArmParams
from fieldbank.storage import Database

#: Two assessment trials, no familiarisation: the shortest protocol with answers.
PROTOCOL = TrainingProtocol(familiarisation_rounds=0, assessment_repetitions=1,
                            groups=("elbow",), severities=("severe", "mild"), name="two")


@pytest.fixture(params=["sqlite", pytest.param("postgres", marks=pytest.mark.postgres)])
def db(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Database]:
    url = (request.getfixturevalue("pg_url") if request.param == "postgres"
           else f"sqlite:///{tmp_path / 'fb.sqlite'}")
    d = Database.open(url, upgrade="always", store_root=tmp_path / "a")
    yield d
    d.close()


def _renderer(before: ArmParams, after: ArmParams,
              ids: tuple[int | None, int | None] = (None, None)) -> Renderer:
    link = RobotLink.open(sim_url(before, "circle"))
    link.handshake(1000, 20)
    rd = Renderer(link, before, after, RendererConfig(state_wait_s=0.05), clock=VirtualClock())
    if any(i is not None for i in ids):  # as haptic.session.serve tells it
        rd.metadata["model_ids"] = {"A": ids[0], "B": ids[1]}
        rd.metadata["model_info"] = to_wire({
            "A": ModelInfo("fitted model", ids[0], "P-1"),
            "B": ModelInfo("what-if result", ids[1], "P-1", "botulinum ef 200 U", None)})
    return rd


def _do(rd: Renderer, cmd: object, **args: object) -> dict[str, object]:
    """Submit a command and tick once (the loop applies it at the tick's start)."""
    req = rd.submit(cmd, **args)  # type: ignore[arg-type]
    rd.tick()
    return req.wait()


def _ticks(rd: Renderer, n: int) -> None:
    for _ in range(n):
        rd.tick()


def _inject_nan(rd: Renderer) -> None:
    device = rd.port.port.device  # type: ignore[attr-defined]  # the sim:// port's device
    device.nan_frames = 2


def test_a_fault_pauses_training_and_flags_its_trial(db: Database) -> None:
    db.add_patient("P-1", 75, 1.75, "right")
    before = synthesize({"elbow": "severe"})
    after = ArmParams.from_anthropometry()
    ids = [db.add_model(p, "synthetic", f"m{k}", patient_code="P-1").id
           for k, p in enumerate((before, after, after, after, after))]
    a_id, b_id = ids[0], ids[4]  # models 1 and 5 of the patient
    assert (a_id, b_id) == (1, 5)
    rd = _renderer(before, after, (a_id, b_id))
    rd.start(expected_ticks=20000)
    _do(rd, "switch", target="B")
    _ticks(rd, 600)
    assert rd.pair.blend.value == 1.0
    _do(rd, "train_start", protocol=PROTOCOL)
    assert _do(rd, "train_next")["protocol"] == "two"
    _ticks(rd, 800)
    # a fault mid-trial: force zero, the protocol waits, nothing is answered
    _inject_nan(rd)
    _ticks(rd, 5)
    assert rd.safety.mode.name == "FAULT" and rd.fx == rd.fy == 0.0
    st = rd.status()
    assert st["paused"] is True and st["faults_now"][0]["name"] == "NAN"
    assert "invalid handle position" in st["faults_now"][0]["what"]
    assert "re-arm" in st["faults_now"][0]["todo"]
    assert st["rearm_refused_because"] == []  # the handle is fine: a re-arm would be taken
    for cmd, args in (("train_answer", {"answer": "elbow"}), ("train_next", {}),
                      ("switch", {"target": "A"})):
        with pytest.raises(CommandError, match=r"paused by a fault \(NAN"):
            _do(rd, cmd, **args)
    tr = rd.activities.running
    assert isinstance(tr, Training) and not tr.session.records  # no answer counted
    # re-armed: the protocol goes on; the trial that held the fault is kept, flagged
    _do(rd, "arm")
    _ticks(rd, 400)
    ans = _do(rd, "train_answer", answer="elbow")
    assert ans["flagged"] is True and "fault during the trial (NAN)" in ans["flags"][0]
    _do(rd, "train_next")
    _ticks(rd, 800)
    done = _do(rd, "train_answer", answer="elbow")
    assert done["done"] and done["flagged"] is False
    summary = done["result"]["summary"]
    assert summary["accuracy"]["n"] == 1 and summary["flagged"] == 1
    assert summary["flagged_trials"] == [1]
    # the patient's pair, its blend and its description are back
    _ticks(rd, 800)
    assert rd.pair.params == (before, after) and rd.pair.blend.value == 1.0
    assert rd.status()["felt"] == "B (after)"
    assert rd.metadata["model_ids"] == {"A": 1, "B": 5}
    trace = rd.finish()
    rd.port.close()
    ref = DatabaseTraceSink(db, "P-1").write_trace(trace, "honest")
    sid = int(ref.split(":")[1])
    sess = db.get_haptic_session(sid)
    assert (sess.model_a_id, sess.model_b_id) == (1, 5)  # the clinician's models, no copies
    assert [m.id for m in db.list_models("P-1")] == [1, 2, 3, 4, 5]
    trials = db.list_haptic_trials(sid)
    assert [(t.trial, t.flagged) for t in trials] == [(0, True), (1, False)]
    assert trials[0].detail["flags"][0].startswith("fault during the trial")
    assert trials[0].detail["protocol"] == "two"
    url = db.engine.url.render_as_string(hide_password=False)
    out = CliRunner().invoke(cli, ["haptic", "sessions", "show", str(sid), "--db", url])
    assert out.exit_code == 0, out.output
    assert "FLAGGED, not counted: fault during the trial (NAN)" in out.output
    # the reason on its own line under the trial's row, not run onto its trace window
    shown = out.output.splitlines()
    at = next(i for i, ln in enumerate(shown) if "FLAGGED" in ln)
    assert shown[at].lstrip().startswith("FLAGGED, not counted: fault during the trial (NAN)")
    assert shown[at - 1].split()[1] == "1"  # trial 1 (of its block)
    assert shown[at - 1].rstrip().endswith(" s")
    assert max(len(ln) for ln in shown) <= 100
    assert "assessment: 1 of 1 correct" in out.output and "1 answered trial (1) flagged" \
        in out.output
    assert "model A   1: m0" in out.output and "model B   5: m4" in out.output


def test_a_fault_pauses_abx_and_push_and_switch_tell_the_truth() -> None:
    before = synthesize({"shoulder": "severe"})
    after = ArmParams.from_anthropometry()
    rd = _renderer(before, after)
    rd.start(expected_ticks=20000)
    pushed = _do(rd, Push(after, before))
    assert pushed["pushed"] and pushed["mode"] == "ARMED" and pushed["swapping"] is True
    _ticks(rd, 800)
    _do(rd, "abx_start", n_trials=2, seed=1)
    _do(rd, "abx_present", label="X")
    _ticks(rd, 600)
    _inject_nan(rd)
    _ticks(rd, 3)
    with pytest.raises(CommandError, match="A/B/X answer refused: paused by a fault"):
        _do(rd, "abx_answer", answer="A")
    with pytest.raises(CommandError, match="push refused: paused by a fault"):
        _do(rd, Push(before, after))
    abx = rd.activities.running
    assert isinstance(abx, AbxBlock) and abx.session.answers == []
    _do(rd, "arm")
    _ticks(rd, 400)
    first = _do(rd, "abx_answer", answer="A")
    assert first["flagged"] is True
    _do(rd, "abx_present", label="X")
    _ticks(rd, 600)
    last = _do(rd, "abx_answer", answer="B")
    res = last["result"]
    assert (res["answered"], res["counted"], res["flagged"]) == (2, 1, 1)
    assert res["label_model"] == {"A": 0, "B": 1}
    assert [a["x_was"] for a in res["answers"]] == [
        "before" if a["x_is"] == "A" else "after" for a in res["answers"]]
    # disarmed, a switch is taken and says that nothing is felt
    _do(rd, "disarm")
    _ticks(rd, 2)
    sw = _do(rd, "switch", target="A")
    assert sw["mode"] == "DISARMED" and sw["rearm_refused_because"] == []
    rd.finish()
    rd.port.close()


def test_a_trial_with_no_force_is_flagged() -> None:
    p = ArmParams.from_anthropometry()
    rd = _renderer(p, p)
    rd.start(expected_ticks=20000)
    _do(rd, "train_start", protocol=PROTOCOL)
    _do(rd, "train_next")
    _ticks(rd, 300)
    _do(rd, "disarm")
    _ticks(rd, 300)
    with pytest.raises(CommandError, match="disarmed"):
        _do(rd, "train_answer", answer="both")
    _do(rd, "arm")
    _ticks(rd, 300)
    ans = _do(rd, "train_answer", answer="both")
    assert ans["flagged"] and ans["flags"] == ["no force for 0.30 s (robot not armed)"]
    rd.finish()
    rd.port.close()


def test_rearm_says_every_reason_it_refuses() -> None:
    p = ArmParams.from_anthropometry()
    rd = _renderer(p, p)
    rd.start(expected_ticks=2000)
    _ticks(rd, 10)
    device = rd.port.port.device  # type: ignore[attr-defined]
    device.x = 5.0  # the handle far outside the workspace, moving fast
    device.vx = 9.0
    _ticks(rd, 2)
    assert rd.safety.mode.name == "FAULT"
    problems = rd.status()["rearm_refused_because"]
    assert any("outside the workspace" in p for p in problems), problems
    with pytest.raises(CommandError, match="cannot arm: handle at"):
        _do(rd, "arm")
    rd.finish()
    rd.port.close()


@pytest.mark.parametrize("backend", ["sqlite", pytest.param("postgres",
                                                            marks=pytest.mark.postgres)])
def test_migration_0007_keeps_stored_trials_unflagged(backend: str, tmp_path: Path,
                                                      request: pytest.FixtureRequest) -> None:
    """Trials stored before windows were judged read back unflagged, every field as it was;
    down again, the rows are still there."""
    import datetime as dt

    from sqlalchemy import text

    from fieldbank.storage import make_engine, migrate

    url = (request.getfixturevalue("pg_url") if backend == "postgres"
           else f"sqlite:///{tmp_path / 'old.sqlite'}")
    engine = make_engine(url)
    try:
        migrate.upgrade(engine, "0003")
        now = dt.datetime(2026, 1, 2, 3, 4, 5)
        with engine.begin() as c:
            c.execute(text("INSERT INTO models (id, origin, label, params_json, created_at) "
                           "VALUES (1, 'synthetic', 'm', :p, :t)"),
                      {"p": '{"x": 1}', "t": now})
            c.execute(text("INSERT INTO haptic_sessions (id, model_a_id, started_at, "
                           "ended_at, robot_url, stats_json) VALUES (1, 1, :t, :t, 'sim://', "
                           "'{}')"), {"t": now})
            c.execute(text("INSERT INTO haptic_trials (haptic_session_id, kind, block, trial, "
                           "phase, condition, answer, correct, detail_json) VALUES (1, "
                           "'training', 0, 0, 'assessment', 'elbow mild', 'elbow', :ok, "
                           "'{}')"), {"ok": True})
        migrate.upgrade(engine)
        migrate.check_drift(engine)
        db = Database(engine, None, "test")  # type: ignore[arg-type]  # no arrays read here
        (t,) = db.list_haptic_trials(1)
        assert (t.answer, t.correct, t.flagged, t.condition) == ("elbow", True, False,
                                                                 "elbow mild")
        migrate.downgrade(engine, "0003")
        with engine.connect() as c:
            assert c.execute(text("SELECT count(*) FROM haptic_trials")).scalar() == 1
    finally:
        engine.dispose()
