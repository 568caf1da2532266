"""KINARM ``.kinarm`` exams (binary channels), built in the documented layout from seeded
recordings of the simulated robot, read back into maps; an exoskeleton without a force sensor
inspected and refused in words."""

from __future__ import annotations

import numpy as np
import pytest

from fieldbank.ingest.batch import detect_format, read_file
from fieldbank.ingest.inspect import inspect_file
from fieldbank.ingest.options import ReadOptions
from fieldbank.measure.kinarmbin import (
    channel_bytes,
    events_bytes,
    parse_channel,
    parse_events,
    read_exam,
    write_kinarm_binary,
)
from fieldbank.model import Arm

SHOULDER = (0.05, -0.3)
INFO = {"model": "SUBJ01", "protocol": "Postural holds", "dex_ver": "3.9.2",
        "robot_arm": "right", "robotver": "KINARM_EP_Rev2"}


@pytest.fixture(scope="module")
def measured() -> tuple[object, Arm]:
    from fieldbank.haptic.measure import run_protocol
    from fieldbank.haptic.patient import resolve_patient
    from fieldbank.measure.protocol import ProtocolConfig, plan

    src = resolve_patient("elbow=moderate")
    arm = Arm.from_params(src.params)
    pl = plan(ProtocolConfig(parts=("stiffness",), grid=(2, 1)), arm)
    rec, _ = run_protocol("sim://?patient=elbow=moderate", pl)
    return rec, arm


def _exam(rec: object, force: bool = True, n_trials: int = 3) -> bytes:
    pos = rec.position_m + np.asarray(SHOULDER)  # type: ignore[attr-defined]
    f = -rec.force_n                              # type: ignore[attr-defined]
    trials, events = [], []
    for idx in np.array_split(np.arange(len(pos)), n_trials):
        ch: dict[str, np.ndarray] = {"Right_Hand": pos[idx],
                                     "Right_L1Ang": np.linspace(0.5, 0.6, len(idx)),
                                     "Right_L2Ang": np.linspace(1.5, 1.6, len(idx))}
        if force:
            ch["Right_FS_ForceX"] = f[idx, 0]
            ch["Right_FS_ForceY"] = f[idx, 1]
        trials.append(ch)
        events.append([("TRIAL_START", 0.0), ("HOLD_DONE", float(len(idx)) / 1000.0)])
    info = dict(INFO) if force else {**INFO, "robotver": "KINARM_Exo_Classic"}
    return write_kinarm_binary(trials, info, events, {"Right_Hand": "m", "Right_L1Ang": "rad"})


def test_channel_and_event_files_read_back_exactly() -> None:
    rng = np.random.default_rng(7)
    xy = rng.normal(size=(50, 2)).astype("<f4")
    ch = parse_channel(channel_bytes("Right_Hand", xy, "m"), 2, "x")
    assert ch.name == "Right_Hand" and ch.strings == ["m"] and np.array_equal(ch.samples, xy)
    one = parse_channel(channel_bytes("Right_L1Ang", xy[:, 0]), 1, "x")
    assert one.strings == [] and np.array_equal(one.samples, xy[:, 0])
    ev = [("TARGET1_ONSET", 0.001), ("IN_TARGET2", 2.94)]
    for twice in (False, True):
        got = parse_events(events_bytes(ev, twice), "x")
        assert [e for e, _ in got] == [e for e, _ in ev]
        assert np.allclose([t for _, t in got], [t for _, t in ev])
    with pytest.raises(Exception, match="no sample count matches"):
        parse_channel(channel_bytes("Right_Hand", xy, "m")[:-3], 2, "bad.kinarm:raw/x")


def test_a_kinarm_exam_is_read_into_maps(measured: tuple[object, Arm]) -> None:
    from fieldbank.maps import model_map_like

    rec, arm = measured
    data = _exam(rec)
    assert detect_format(data) == "kinarm"
    exam = read_exam("exam.kinarm", data)
    assert len(exam.trials) == 3 and exam.robot == "KINARM_EP_Rev2"
    assert exam.trials[1].events[1][0] == "HOLD_DONE"
    inc, probs = read_file("exam.kinarm", data, arm, "P01")
    assert inc is None and "--shoulder" in " ".join(p.reason for p in probs)
    opts = ReadOptions.from_flags(sign="handle-on-arm", shoulder_m=SHOULDER)
    inc, probs = read_file("exam.kinarm", data, arm, "P01", options=opts)
    assert inc is not None, probs
    stiff = next(m for m in inc.maps if m.kind == "stiffness")
    assert stiff.metadata["raw_format"] == "KINARM"
    assert stiff.metadata["kinarm_robot"] == "KINARM_EP_Rev2"
    truth = model_map_like(arm, stiff)
    err = (np.linalg.norm(stiff.values - truth.values, axis=(1, 2))
           / np.linalg.norm(truth.values, axis=(1, 2)))
    assert stiff.n == 2 and np.all(err < 0.15), err


def test_an_exoskeleton_without_a_force_sensor_is_inspected_and_refused_in_words(
        measured: tuple[object, Arm], tmp_path: object) -> None:
    rec, _ = measured
    path = tmp_path / "exo.kinarm"  # type: ignore[operator]
    path.write_bytes(_exam(rec, force=False))
    ins = inspect_file(path)
    assert ins.readable and ins.data["kinarm"]["robot"] == "KINARM_Exo_Classic"
    assert len(ins.data["kinarm"]["trials"]) == 3
    refusal = " ".join(ins.data["ingest"]["refused"])
    assert "no hand force: this robot has no force sensor" in refusal
    assert "KINARM_Exo_Classic" in refusal and "--column fx=NAME" in refusal
