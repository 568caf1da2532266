"""The supervised assessment without a browser (the station's desk reading a link's tap), what
a remote session stores (SQLite and PostgreSQL), the sites' refusals, and the simulated
trainee's severity judgement."""

from __future__ import annotations

import json
import math
import subprocess
from pathlib import Path

import pytest
from click.testing import CliRunner

from fieldbank.cli.main import cli
from fieldbank.errors import StorageError
from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic.errors import AssessError
from fieldbank.haptic.remote.channel import Impairment
from fieldbank.haptic.remote.clinician_site import AssessOptions, assessment_rows
from fieldbank.haptic.remote.config import SiteConfig
from fieldbank.haptic.remote.desk import Desk
from fieldbank.haptic.remote.linklog import CLINICIAN_COLUMNS
from fieldbank.haptic.remote.simulate import Pair, Stretch, clinician_robot, stretch_script
from fieldbank.haptic.remote.tap import TapWriter
from fieldbank.haptic.remote.wire import new_key, write_key
from fieldbank.haptic.trainee import SEVERITY_SHARE, DirectionRule, DirectionTrainee
from fieldbank.params import ArmParams
from fieldbank.storage import Database
from tests.haptic_util import rest_hand
from tests.test_remote_sites import _cli, _free_udp_port


def test_the_desk_cuts_probes_from_the_link_and_names_the_elbow(tmp_path: Path) -> None:
    """Both sites in one process at 100 ms and 5 % loss; the desk reads the clinician's tap as
    the station does: two probes, each classified from the patient's side as received; the
    elbow named; the posterior after each probe and the answer go to the assessment log."""
    p = synthesize({"elbow": "severe"})
    hand = rest_hand(p)
    r = math.hypot(*hand)
    script = stretch_script(hand, (hand[0] / r, hand[1] / r),
                            stretches=(Stretch(0.05, 2.5), Stretch(0.05, 0.3)))
    cfg = SiteConfig(lockstep=True, impairment=Impairment(0.1, loss=0.05))
    pair = Pair(p, cfg, clinician_robot(hand, cfg.rate_hz, script.path))
    log = tmp_path / "a.jsonl"
    with TapWriter(tuple(c for c, _ in CLINICIAN_COLUMNS)) as tap:
        pair.port.tap = tap
        desk = Desk({"tap_path": str(tap.path), "assessment_path": str(log),
                     "columns": [c for c, _ in CLINICIAN_COLUMNS], "rate_hz": cfg.rate_hz,
                     "drawing": p.with_unimpaired_muscles().to_dict(),
                     "assess": AssessOptions().to_dict()})
        ended = []
        for k in range(round((script.path.duration_s + 1.0) * cfg.rate_hz)):
            pair.tick()
            if k % 100 == 0:
                ended += desk.poll()
        ended += desk.poll()
        pair.finish()
        # the slow stretch, then its return and the fast stretch: one probe, or two when the
        # hand rested long enough between them (1 s of rest against the 0.4 s the cut needs)
        assert [q.index for q in ended] in ([1, 2], [1, 2, 3])
        assert ended[0].ended_s < script.phase("return 1")[1] + 1.0
        assert ended[-1].started_s < script.phase("stretch 2")[0] + 0.3 < ended[-1].ended_s
        cl = desk.classify(design_next=False)
        assert cl is not None
        msg = desk.posterior_message(cl)
        assert msg["group"] == "elbow" and msg["group_probability"] >= 0.9
        assert 95 <= desk.link["one_way_ms"] <= 105 and 0.02 < desk.link["loss"] < 0.09
        desk.answer("elbow", "severe", "firm catch")
        with pytest.raises(AssessError, match="severity"):
            desk.answer("elbow", "extreme", "")
        with pytest.raises(AssessError, match=r"muscle group is one of .*'knee'"):
            desk.answer("knee", None, "")
        with pytest.raises(AssessError, match="at most 2000 characters; this one has 2001"):
            desk.answer(None, None, "x" * 2001)
        desk.set_prior(["shoulder", "biarticular"], ["severe"], unimpaired=False)
        cl2 = desk.classify(design_next=False)
        assert cl2 is not None and cl2.group_posterior.get("elbow", 0.0) == 0.0
        with pytest.raises(AssessError, match="every candidate"):
            desk.set_prior([], [], unimpaired=False)
        desk.close()
    records = [json.loads(line) for line in log.read_text().splitlines()]
    assert [r["kind"] for r in records] == ["posterior", "answer", "prior"]
    rows = assessment_rows(records)
    assert rows[0]["probe"] == ended[-1].index and rows[0]["answer_level"] == "severe"


def test_posteriors_revised_by_the_prior_and_answers_pair_with_their_probe() -> None:
    recs = [{"kind": "posterior", "probe": 1, "group": "elbow", "posterior": {"a": 1.0}},
            {"kind": "posterior", "probe": 2, "group": "elbow", "posterior": {"a": 1.0}},
            {"kind": "answer", "group": "elbow", "level": "mild", "note": "", "t_s": 9.0},
            {"kind": "posterior", "probe": 2, "group": "shoulder", "posterior": {"b": 1.0}},
            {"kind": "answer", "group": "elbow", "level": "moderate", "note": "x", "t_s": 11.0}]
    rows = assessment_rows(recs)
    assert [r["probe"] for r in rows] == [1, 2]
    assert rows[0]["answer_group"] is None
    assert rows[1]["group"] == "elbow" and rows[1]["revisions"][0]["group"] == "shoulder"
    assert rows[1]["answer_level"] == "moderate" and rows[1]["answered_s"] == 11.0


@pytest.mark.parametrize("backend", ["sqlite", pytest.param("postgres",
                                                            marks=pytest.mark.postgres)])
def test_remote_links_and_assessments_round_trip(backend: str, request: pytest.FixtureRequest,
                                                 tmp_path: Path) -> None:
    url = (f"sqlite:///{tmp_path / 'f.db'}" if backend == "sqlite"
           else request.getfixturevalue("pg_url"))
    with Database.open(url, upgrade="always", store_root=tmp_path / "arrays") as db:
        m = db.add_model(ArmParams.from_anthropometry(), "synthetic", "drawing")
        sid = db.start_haptic_session(m.id, "sim://?" + "x" * 400).id   # long URLs fit too
        assert "characters" in db.get_haptic_session(sid).robot_url
        assert db.get_remote_link(sid) is None
        lid = db.add_remote_link(sid, "clinician", "10.0.0.7:47400", "0123456789abcdef",
                                 {"rate_hz": 1000, "impairment": {"delay_s": 0.1}},
                                 {"link": {"rtt_ms": 202.0}})
        rec = db.get_remote_link(sid)
        assert rec is not None and rec.id == lid and rec.settings["impairment"]["delay_s"] == 0.1
        with pytest.raises(StorageError):
            db.add_remote_link(sid, "clinician", "x", "y", {}, {})        # one per session
        rows = [{"probe": 1, "posterior": {"elbow severe": 0.97, "unimpaired": 0.03},
                 "verdict": "elbow", "group": "elbow", "group_probability": 0.97,
                 "level": "severe", "level_probability": 0.97, "explains": True,
                 "started_s": 1.0, "ended_s": 3.0, "prior": {"elbow severe": 0.5},
                 "next_probe": {"name": "next probe", "points_m": [[0, 0.3], [0, 0.4]]},
                 "answer_group": "elbow", "answer_level": "severe", "answer_note": "ok",
                 "answered_s": 4.0}]
        assert db.add_assessments(sid, rows) == 1
        [a] = db.list_assessments(sid)
        assert (a.group, a.level, a.answer_level, a.answered_s) == ("elbow", "severe",
                                                                    "severe", 4.0)
        assert a.posterior["elbow severe"] == 0.97 and a.detail["next_probe"]["name"]
        bad = [{"probe": 2, "posterior": {"x": 1.5}, "verdict": "?"}]
        with pytest.raises(StorageError, match="probability"):
            db.add_assessments(sid, bad)
        assert len(db.list_assessments(sid)) == 1                        # nothing half-written


@pytest.mark.slow
def test_a_patient_site_answers_nobody_without_the_key_and_refuses_a_mismatched_clinician(
        tmp_path: Path) -> None:
    """Three clinicians: one with another key (no answer at all: it gives up), one at another
    rate (told why), then one that fits; the patient's site serves only that one."""
    key = write_key(tmp_path / "k", new_key())
    other = write_key(tmp_path / "other", new_key())
    port = _free_udp_port()
    patient = subprocess.Popen(
        _cli("patient", "--robot", "sim://?mode=lockstep&patient=elbow%3Dsevere", "--bind",
             f"127.0.0.1:{port}", "--key", str(key), "--lockstep", "--log-dir",
             str(tmp_path), "--json"), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True)
    try:
        base = ["--robot", "sim://?mode=lockstep", "--peer", f"127.0.0.1:{port}",
                "--lockstep", "--no-db", "--trace-dir", str(tmp_path)]
        stranger = subprocess.run(_cli("clinician", *base, "--key", str(other), "--wait-s",
                                       "3"), capture_output=True, text=True, timeout=120)
        assert stranger.returncode == 1 and "no answer from the patient's site" in \
            stranger.stderr
        wrong_rate = subprocess.run(_cli("clinician", *base, "--key", str(key), "--rate-hz",
                                         "500", "--wait-s", "20"),
                                    capture_output=True, text=True, timeout=120)
        assert wrong_rate.returncode == 1 and "refused the session" in wrong_rate.stderr
        assert "rate 500" in wrong_rate.stderr
        good = subprocess.run(_cli("clinician", *base, "--key", str(key), "--duration-s", "1",
                                   "--wait-s", "20"), capture_output=True, text=True,
                              timeout=180)
        assert good.returncode == 0, good.stderr
        out, _ = patient.communicate(timeout=60)
    finally:
        if patient.poll() is None:
            patient.kill()
            patient.wait()
    summary = json.loads(out)
    assert summary["link"]["refused"].get("aead", 0) >= 1       # the stranger's HELLOs
    assert summary["ticks"] > 900


def test_key_and_address_errors_are_clear(tmp_path: Path) -> None:
    runner = CliRunner()
    res = runner.invoke(cli, ["haptic", "remote", "key", "--out", str(tmp_path / "k")])
    assert res.exit_code == 0 and (tmp_path / "k").stat().st_mode & 0o777 == 0o600
    res = runner.invoke(cli, ["haptic", "remote", "key", "--out", str(tmp_path / "k")])
    assert res.exit_code == 1 and "exists" in res.output
    res = runner.invoke(cli, ["haptic", "remote", "clinician", "--robot", "sim://",
                              "--peer", "nowhere", "--key", str(tmp_path / "k")])
    assert res.exit_code == 2 and "HOST:PORT" in res.output
    res = runner.invoke(cli, ["haptic", "remote", "patient", "--robot", "/dev/ttyUSB9",
                              "--key", str(tmp_path / "k")])
    assert res.exit_code == 2 and "--shoulder" in res.output
    # a rate the clinician's renderer cannot run is refused where it is typed
    res = runner.invoke(cli, ["haptic", "remote", "clinician", "--robot", "sim://",
                              "--peer", "127.0.0.1:9", "--key", str(tmp_path / "k"),
                              "--rate-hz", "250"])
    assert res.exit_code == 2 and "250 is not in the range 500<=x<=4000" in res.output


def test_the_trainee_judges_severity_by_the_share_of_the_severe_arms_extra_force() -> None:
    t = DirectionTrainee(DirectionRule())
    t.learn_size("elbow", 5.0)
    assert t.severity("elbow", 5.0 * SEVERITY_SHARE["mild"]) == "mild"
    assert t.severity("elbow", 5.0 * 0.9) == "severe"
    assert t.severity("elbow", 0.1) == "very mild"
    assert t.severity("both", 1.0) is None                   # never felt in familiarisation
    noisy = DirectionTrainee(DirectionRule(magnitude_noise=0.5, seed=1))
    noisy.learn_size("elbow", 5.0)
    said = {noisy.severity("elbow", 5.0 * SEVERITY_SHARE["moderate"]) for _ in range(40)}
    assert len(said) > 1                                     # the blur is felt

