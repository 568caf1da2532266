"""The seed's training protocol: the plan, the state machine, the results, and a simulated trainee
running a whole (reduced) protocol faster than real time into the database."""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from fieldbank.errors import ParameterError
from fieldbank.evaluate import probing
from fieldbank.evaluate.severity import classify
from fieldbank.haptic import commands as C
from fieldbank.haptic.activities.training import Training
from fieldbank.haptic.clock import RealClock
from fieldbank.haptic.commandbase import RendererCommand
from fieldbank.haptic.dbsink import DatabaseTraceSink
from fieldbank.haptic.errors import CommandError
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.probe import sim_url
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.trainee import DirectionRule, DirectionTrainee, simulate
from fieldbank.haptic.training import (
    TrainingProtocol,
    TrainingSession,
    probe_paths,
    summarise,
)
from fieldbank.haptic.trainingresults import results_html
from fieldbank.model import Arm
from fieldbank.params import JOINT_GROUPS, ArmParams
from fieldbank.probepath import ProbePath


def test_the_seed_protocol_has_the_papers_counts_and_order() -> None:
    p = TrainingProtocol.seed_protocol()
    plan = p.plan()
    fam = [t for t in plan if t.phase == "familiarisation"]
    ass = [t for t in plan if t.phase == "assessment"]
    assert (len(fam), len(ass), len(plan)) == (32, 108, 140)  # 8 × 4 and 3 × 4 × 9
    assert all(t.duration_s == 30.0 for t in fam) and all(t.duration_s == 15.0 for t in ass)
    assert [t.condition for t in fam[:4]] == ["unimpaired", "shoulder severe", "elbow severe",
                                              "biarticular severe"]
    cells = Counter((t.group, t.severity) for t in ass)
    assert len(cells) == 12 and set(cells.values()) == {9}
    # random order, seeded: the same seed gives the same order, another seed another
    assert [t.condition for t in ass] == [t.condition for t in p.plan()[32:]]
    other = TrainingProtocol(seed=1).plan()[32:]
    assert [t.condition for t in ass] != [t.condition for t in other]
    # no run of the same group through the whole assessment (it is shuffled)
    assert len({t.group for t in ass[:12]}) == 3
    # the arms rendered are the severity scale's: the level reads back from the model
    base = p.base()
    for t in ass[:6]:
        grades = classify(Arm.from_params(t.params(base)))
        for muscles in JOINT_GROUPS[str(t.group)]:
            assert grades[muscles].passive.level == t.severity
            assert grades[muscles].dynamic.level == t.severity


@pytest.mark.parametrize("kw,message", [
    ({"instruction": "guided"}, "instruction"),
    ({"assessment_repetitions": 51}, "assessment_repetitions"),
    ({"familiarisation_rounds": -1}, "familiarisation_rounds"),
    ({"familiarisation_rounds": 2.5}, "integer"),
    ({"assessment_s": 0.1}, "assessment_s"),
    ({"groups": ("wrist",)}, "Unknown joint group"),
    ({"severities": ("severe", "severe")}, "each once"),
    ({"severities": ("unimpaired",)}, "severities"),
    ({"probes": ("zigzag",)}, "unknown probing motion"),
    ({"familiarisation_rounds": 0, "assessment_repetitions": 0}, "at least one trial"),
])
def test_protocol_bounds_name_the_field(kw: dict[str, object], message: str) -> None:
    with pytest.raises(ParameterError, match=message):
        TrainingProtocol(**kw)  # type: ignore[arg-type]


def test_protocol_json_round_trip_refuses_unknown_keys() -> None:
    p = TrainingProtocol(instruction="instructed", familiarisation_rounds=1,
                         severities=("mild", "severe"),
                         extra_probes=(ProbePath("designed", "a stroke", (0.0, 0.5),
                                                 ((0.1, 0.5), (0.1, 0.4)), (0.0, 0.1)),))
    assert TrainingProtocol.from_dict(p.to_dict()) == p
    # a protocol written with the earlier form of a probe (shoulder frame) still reads
    old = {**p.to_dict(), "extra_probes": [{"name": "designed", "times_s": [0.0, 0.5],
                                            "positions_m": [[0.1, 0.4], [0.1, 0.3]]}]}
    assert TrainingProtocol.from_dict(old).extra_probes == (
        ProbePath("designed", "", (0.0, 0.5), ((0.1, 0.4), (0.1, 0.3))),)
    with pytest.raises(ParameterError, match="unknown training parameter"):
        TrainingProtocol.from_dict({"speed": 3})


def test_probe_paths_are_the_seed_probes_and_accept_designed_ones() -> None:
    arm = Arm.from_params(ArmParams.from_anthropometry())
    pull = probing.pull(arm).path()
    assert pull.points_m[0] == pytest.approx(tuple(arm.rest_position()))
    # the pull goes 15 cm toward the body (−y) in 0.3 s (fieldbank.evaluate.probing)
    x, y, vx, vy = pull.at(pull.duration_s)
    assert (vx, vy) == (0.0, 0.0)  # held at the end
    assert (x, y) == pytest.approx((arm.rest_position()[0], arm.rest_position()[1] - 0.15))
    assert pull.duration_s == pytest.approx(0.3)
    # linear between samples, velocity the slope, held at the ends
    mid = pull.at(0.15)
    assert mid[1] == pytest.approx(arm.rest_position()[1] - 0.075, abs=2e-3)
    assert mid[3] < -0.5 and pull.at(-1.0)[2:] == (0.0, 0.0)
    # a designed probe drawn for a robot whose shoulder sits at (0.05, 0.1) is drawn and
    # followed relative to the shoulder
    designed = ProbePath("designed: diagonal", "a diagonal stroke", (0.0, 0.4),
                         ((0.13, 0.65), (0.05, 0.55)), (0.05, 0.1))
    tr = TrainingSession(TrainingProtocol(instruction="instructed", familiarisation_rounds=1,
                                          extra_probes=(designed,)))
    paths = probe_paths(arm, tr.protocol.probes, tr.protocol.extra_probes)
    assert np.array(paths[2].points_m) == pytest.approx(np.array([[0.08, 0.55], [0.0, 0.45]]))
    assert paths[2].shoulder_offset_m == (0.0, 0.0)
    tr.begin(0, 0.0, paths)
    shown = tr.state(0.0)["paths"]
    assert [p["name"] for p in shown] == ["pull", "semi-ellipse", "designed: diagonal"]
    assert all(2 <= len(p["points_m"]) <= 40 for p in shown)
    assert shown[2]["points_m"][0] == pytest.approx([0.08, 0.55])
    with pytest.raises(ParameterError, match="times must not decrease"):
        ProbePath("bad", "", (0.0, 1.0, 0.5), ((0, 0), (0, 0), (0, 0)))


def test_the_session_state_machine_blinds_and_records() -> None:
    tr = TrainingSession(TrainingProtocol(familiarisation_rounds=1, assessment_repetitions=1,
                                          severities=("severe",)))
    assert len(tr.trials) == 4 + 3
    tr.begin(0, 0.0)
    assert not tr.blinded and tr.state(1.0)["legend"] == "Unimpaired arm"
    with pytest.raises(CommandError, match="no assessment trial"):
        tr.answer("elbow", 1.0)
    with pytest.raises(CommandError, match="not the next one"):
        tr.begin(3, 1.0)
    for i in range(1, 5):
        tr.begin(i, 10.0 * i)
    assert tr.blinded and tr.awaiting_answer
    st = tr.state(41.0)
    assert st["legend"] is None and "group" not in st and st["phase"] == "assessment"
    with pytest.raises(CommandError, match="answer trial 5 first"):
        tr.begin(5, 45.0)
    with pytest.raises(CommandError, match="shoulder, elbow or both"):
        tr.answer("wrist", 45.0)
    rec = tr.answer("Both", 46.5)
    assert rec["response_time_s"] == pytest.approx(6.5)
    assert rec["correct"] == (tr.trials[4].group == "biarticular")
    assert [r["phase"] for r in tr.records[:4]] == ["familiarisation"] * 4
    assert tr.records[3]["ended_s"] == 40.0  # closed when the next trial began
    for i in (5, 6):
        tr.begin(i, 50.0 + i)
        tr.answer(str(tr.trials[i].expected_answer), 52.0 + i)
    assert tr.done and not tr.blinded
    assert tr.result()["summary"]["accuracy"]["n"] == 3


def test_summary_counts_a_hand_made_set_of_answers() -> None:
    def rec(group: str, sev: str, answer: str) -> dict[str, object]:
        right = {"shoulder": "shoulder", "elbow": "elbow", "biarticular": "both"}[group]
        return {"phase": "assessment", "group": group, "severity": sev, "answer": answer,
                "correct": answer == right, "instruction": "instructed",
                "response_time_s": 2.0}

    records = [rec("shoulder", "severe", "shoulder"), rec("shoulder", "mild", "both"),
               rec("elbow", "severe", "elbow"), rec("elbow", "mild", "elbow"),
               rec("biarticular", "severe", "elbow"), rec("biarticular", "mild", "both"),
               {"phase": "familiarisation", "group": None, "answer": None}]
    s = summarise(records)
    assert s["confusion"]["counts"] == [[1, 0, 1], [0, 2, 0], [0, 1, 1]]
    assert s["accuracy"] == {"n": 6, "correct": 4, "accuracy": pytest.approx(4 / 6)}
    assert s["by_severity"]["severe"]["accuracy"] == pytest.approx(2 / 3)
    assert s["by_severity"]["mild"]["accuracy"] == pytest.approx(2 / 3)
    assert s["by_severity"]["moderate"] == {"n": 0, "correct": 0, "accuracy": None}
    html = results_html(s, "Session 3")
    assert "<section" in html and "4 of 6 assessment answers correct" in html
    assert html.count("<tr>") == 1 + 3 + 1 + 4  # matrix header + rows, severity header + rows


def test_training_through_the_renderer_commands() -> None:
    p = ArmParams.from_anthropometry()
    link = RobotLink.open(sim_url(p, "hold"))
    link.handshake(1000, 20)
    rd = Renderer(link, p, p, RendererConfig(state_wait_s=0.05, realtime_priority=False))
    rd.start()

    def run(cmd: RendererCommand) -> dict[str, object]:
        req = rd.submit(cmd)
        while not req.done.is_set():
            rd.tick()
        return req.wait()

    try:
        proto = TrainingProtocol(familiarisation_rounds=1, assessment_repetitions=1,
                                 severities=("severe",), seed=4)
        run(C.TrainStart(proto))
        with pytest.raises(CommandError, match="already running"):
            run(C.TrainStart(proto))
        with pytest.raises(CommandError, match="A/B/X block cannot start"):
            run(C.AbxStart(2))
        st = run(C.TrainNext())
        assert st["trial"] == 1 and st["legend"] == "Unimpaired arm"
        for _ in range(1000):
            rd.tick()
        for _ in range(4):
            st = run(C.TrainNext())
            for _ in range(700):  # the push fade: out, swap, in
                rd.tick()
        assert st["phase"] == "assessment" and rd.activities.blinded
        tr = rd.activities.running
        assert isinstance(tr, Training)
        trial = tr.session.current
        assert trial is not None
        assert rd.pair.params[0] == trial.params(proto.base()) == rd.pair.params[1]  # its arm
        assert rd.info()["models"] == "hidden" and rd.info()["params"] is None
        assert rd.status()["blend"] == "hidden"
        with pytest.raises(CommandError, match="push refused"):
            run(C.Push(p, p))
        run(C.TrainAnswer("shoulder"))
        run(C.TrainStop())
        assert tr.done and tr.session.abandoned and rd.activities.running is None
    finally:
        trace = rd.finish()
        link.close()
    res = trace.metadata["training"][0]
    assert res["abandoned"] and len(res["trials"]) == 5
    assert [e["event"] for e in trace.events].count("train_trial") == 5


def test_a_simulated_trainee_runs_a_reduced_protocol_to_a_stored_confusion_matrix(
        any_db_url: str, tmp_path: Path) -> None:
    from fieldbank.storage import Database

    proto = TrainingProtocol.short(instruction="instructed", seed=11)

    def no_waiting(*_args: object) -> None:
        raise AssertionError("the simulation waited on the wall clock")

    # faster than real time by construction: the loop runs on a virtual clock and never
    # sleeps to a tick's deadline (no wall-clock bound, which a loaded machine would break)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(RealClock, "sleep_until", no_waiting)
        res = simulate(proto)
    assert res.simulated_s > 30.0  # the short protocol: a minute of trials, simulated
    summary = res.summary
    assert summary["accuracy"]["n"] == 12
    assert sum(map(sum, summary["confusion"]["counts"])) == 12
    assert not res.trace.faults
    # the trainee followed the drawn probes: the handle went down the pull (−y) by ~15 cm
    y = res.trace.column("y_m")
    assert float(np.ptp(y)) > 0.10
    with Database.open(any_db_url, upgrade="always", store_root=tmp_path / "a") as db:
        ref = DatabaseTraceSink(db).write_trace(res.trace, "train-sim")
        sid = int(ref.split(":")[1])
        stored = db.list_haptic_trials(sid)
        sess = db.get_haptic_session(sid)
    assert len(stored) == 16 and sess.n_trials == 16
    assert {t.kind for t in stored} == {"training"}
    # the confusion matrix from the stored rows is the one the session computed
    again = summarise([t.to_dict() for t in stored])
    assert again["confusion"] == summary["confusion"]
    assert again["by_severity"] == summary["by_severity"]
    first = stored[4]  # the first assessment trial: its window, answer and response time
    assert first.phase == "assessment" and first.answer in ("shoulder", "elbow", "both")
    assert first.response_time_s == pytest.approx(first.answered_s - first.started_s)
    assert sess.ended_at is not None and sess.ended_at >= sess.started_at


@pytest.mark.slow
def test_following_the_probes_beats_free_exploration() -> None:
    """The seed's finding (Fig. 4b), reproduced by the simulated trainee: instructed probing
    identifies the impaired group better than free exploration."""
    acc = {}
    for instruction in ("instructed", "non-instructed"):
        proto = TrainingProtocol(instruction=instruction, familiarisation_rounds=1,
                                 assessment_repetitions=1, seed=3)
        acc[instruction] = simulate(proto).summary["accuracy"]["accuracy"]
    assert acc["instructed"] > acc["non-instructed"] + 0.2, acc
    assert acc["instructed"] > 0.5  # well above chance (1/3)


def test_the_trainee_rule_is_the_nearest_template() -> None:
    t = DirectionTrainee(DirectionRule())
    t.learn("shoulder", [0.0, math.pi / 2])
    t.learn("elbow", [math.pi, math.pi / 2])
    t.learn("biarticular", [math.pi, -math.pi / 2])
    t.learn(None, [1.0, 1.0])  # the unimpaired arm names no group
    assert t.answer([0.2, 1.4]) == "shoulder"
    assert t.answer([3.0, 1.7]) == "elbow"
    assert t.answer([-3.0, -1.4]) == "both"  # wraps around ±π
    noisy = DirectionTrainee(DirectionRule(direction_noise_deg=90.0, seed=1))
    noisy.learn("shoulder", [0.0])
    noisy.learn("elbow", [math.pi])
    answers = {noisy.answer([0.0]) for _ in range(40)}
    assert answers == {"shoulder", "elbow"}  # the stated error makes it err sometimes
