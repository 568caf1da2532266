"""Measuring on the simulated robot with a virtual patient: measure → maps → database → fit.

The virtual patient is a severe-elbow arm (``sim://?patient=elbow=severe``); the raw recording
is written by pynwb and ingested through the same path as a lab's NWB file; the C3D file is
written by the ``c3d`` library itself and ingested to maps.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fieldbank import storage
from fieldbank.cli.fit import fit
from fieldbank.cli.ingest import ingest
from fieldbank.cli.main import cli
from fieldbank.haptic.measure import run_protocol
from fieldbank.haptic.patient import resolve_patient
from fieldbank.maps import model_map_like
from fieldbank.measure.c3draw import read_c3d_recording, write_c3d
from fieldbank.measure.estimate import estimate
from fieldbank.measure.protocol import ProtocolConfig, plan
from fieldbank.model import Arm


def _db(tmp_path: Path, code: str) -> str:
    url = f"sqlite:///{tmp_path / 'fieldbank.sqlite3'}"
    storage.Database.open(url).add_patient(code, 75.0, 1.75, "right")
    return url


@pytest.mark.slow
def test_severe_elbow_measured_on_the_robot_is_fitted_severe(tmp_path: Path) -> None:
    url = _db(tmp_path, "SEV")
    raw = tmp_path / "sev.nwb"
    runner = CliRunner()
    res = runner.invoke(cli, ["haptic", "measure", "--db", url, "--robot",
                                 "sim://?patient=elbow=severe", "--patient", "SEV",
                                 "--session", "pre", "--grid", "3x3", "--raw", str(raw),
                                 "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert out["stored"] == 1 and raw.exists()
    assert out["robot_time_s"] > 60
    with storage.Database.open(url) as db:
        maps = db.list_maps("SEV")
        kinds = {(m.kind, m.velocity_m_per_s != (0.0, 0.0)) for m in db.get_maps(
            [r.id for r in maps])}
        full = db.get_maps([r.id for r in maps])
    assert ("postural", False) in kinds and ("stiffness", False) in kinds
    assert ("stiffness", True) in kinds          # the stretch part: a moving map
    meta = full[0].metadata
    assert meta["raw_format"] == "NWB" and "trials_dropped" in meta
    assert json.loads(meta["protocol"])["grid"] == [3, 3]
    assert json.loads(meta["channels"])["fx"].startswith("acquisition/hand_force")
    # a second measurement never overwrites the raw file
    again = runner.invoke(cli, ["haptic", "measure", "--db", url, "--robot",
                                   "sim://?patient=elbow=severe", "--patient", "SEV",
                                   "--session", "pre", "--grid", "1x1", "--protocol",
                                   "postural", "--raw", str(raw)])
    assert again.exit_code != 0 and "exists" in again.output
    res = runner.invoke(fit, ["SEV", "--db", url, "--json"])
    assert res.exit_code == 0, res.output
    sev = json.loads(res.stdout)["severity"]
    for g in ("ef", "ee"):
        assert sev[g]["passive"]["level"] == "severe", sev[g]
    for g in ("sf", "se"):
        assert sev[g]["passive"]["level"] == "unimpaired", sev[g]
    # … what-if on the fitted arm, and feel it: before and after on the (simulated) robot
    res = runner.invoke(cli, ["whatif", "SEV", "--db", url, "--botox", "ef=200U", "--save",
                              "--weeks", "5", "--json"])
    assert res.exit_code == 0, res.output
    saved = json.loads(res.stdout)["saved"]
    res = runner.invoke(cli, ["haptic", "serve", "--db", url, "--robot",
                              "sim://?motion=pull", "--before-id",
                              str(saved["base_model_id"]), "--after-id",
                              str(saved["result_model_id"]), "--duration-s", "0.3",
                              "--trace-dir", str(tmp_path)])
    assert res.exit_code == 0, res.output
    with storage.Database.open(url) as db:
        sessions = db.list_haptic_sessions("SEV")
        assert len(sessions) == 1 and sessions[0].model_a_id == saved["base_model_id"]


def test_stiffness_and_postural_accuracy_at_default_noise() -> None:
    """MIHB estimate against the virtual patient's own model (a smaller grid than the
    benchmark): K within 10 % (Frobenius) at ≥ 90 % of postures, postural forces within 2 sd
    for most components."""
    src = resolve_patient("elbow=moderate")
    arm = Arm.from_params(src.params)
    pl = plan(ProtocolConfig(parts=("stiffness",), grid=(3, 3)), arm)
    rec, _ = run_protocol("sim://?patient=elbow=moderate&seed=3", pl)
    est = estimate(rec, arm, pl.postures_m)
    post, stiff = est.maps
    truth = model_map_like(arm, stiff)
    err = (np.linalg.norm(stiff.values - truth.values, axis=(1, 2))
           / np.linalg.norm(truth.values, axis=(1, 2)))
    assert np.mean(err < 0.10) >= 0.85, err   # the 25-posture benchmark asks 90 %
    z = (post.values - model_map_like(arm, post).values) / post.sd
    assert np.mean(np.abs(z) < 2) >= 0.8, z
    assert est.n_directions == {p: 8 for p in range(9)}


def test_a_c3d_file_written_by_the_c3d_library_is_ingested_to_maps(tmp_path: Path) -> None:
    src = resolve_patient("shoulder=moderate")
    arm = Arm.from_params(src.params)
    pl = plan(ProtocolConfig(parts=("stiffness",), grid=(2, 2)), arm)
    rec, _ = run_protocol("sim://?patient=shoulder=moderate", pl)
    data = write_c3d(rec, pl.postures_m)       # the c3d library's own writer
    back, postures, _ = read_c3d_recording("m.c3d", data)
    assert len(back.trials) == len(rec.trials)
    assert postures is not None and np.allclose(postures, pl.postures_m, atol=1e-6)
    assert np.allclose(back.force_n, rec.force_n[:back.n], atol=1e-5)
    path = tmp_path / "lab.c3d"
    path.write_bytes(data)
    url = _db(tmp_path, "C3D")
    res = CliRunner().invoke(ingest, ["--db", url, "--patient", "C3D", "--session", "s",
                                      str(path), "--json"])
    assert res.exit_code == 0, res.output
    with storage.Database.open(url) as db:
        rows = db.list_maps("C3D")
        assert sorted(r.kind for r in rows) == ["postural", "stiffness"]
        m = db.get_maps([r.id for r in rows if r.kind == "stiffness"])[0]
    assert m.metadata["raw_format"] == "C3D"
    assert "ForceX (N)" in json.loads(m.metadata["channels"])["fx"]
    truth = model_map_like(arm, m)
    err = (np.linalg.norm(m.values - truth.values, axis=(1, 2))
           / np.linalg.norm(truth.values, axis=(1, 2)))
    assert np.all(err < 0.15), err


def test_bad_raw_files_name_the_file_channel_and_reason(tmp_path: Path) -> None:
    src = resolve_patient("elbow=mild")
    arm = Arm.from_params(src.params)
    pl = plan(ProtocolConfig(parts=("postural",), grid=(1, 1)), arm)
    rec, _ = run_protocol("sim://?patient=elbow=mild", pl)
    data = write_c3d(rec, pl.postures_m)
    url = _db(tmp_path, "BAD")
    good = tmp_path / "ok.c3d"
    good.write_bytes(data)
    runner = CliRunner()
    res = runner.invoke(cli, ["ingest", "--db", url, "--patient", "BAD", "--session", "s",
                              str(good),
                                 "--column", "fx=NoSuchChannel"])
    assert res.exit_code != 0
    assert "ok.c3d" in res.output and "NoSuchChannel" in res.output
    broken = tmp_path / "broken.c3d"
    broken.write_bytes(data[: len(data) // 3])
    res = runner.invoke(cli, ["ingest", "--db", url, "--patient", "BAD", "--session", "s",
                              str(broken)])
    assert res.exit_code != 0 and "broken.c3d" in res.output
    with storage.Database.open(url) as db:
        assert db.list_maps("BAD") == []        # nothing half-written


def test_raw_nwb_recording_passes_nwbinspector(tmp_path: Path) -> None:
    from nwbinspector import Importance, inspect_nwbfile

    from fieldbank.measure.nwbraw import RecordingInfo, read_recording, write_recording

    src = resolve_patient("elbow=mild")
    arm = Arm.from_params(src.params)
    pl = plan(ProtocolConfig(parts=("postural",), grid=(2, 1)), arm)
    rec, cmd = run_protocol("sim://?patient=elbow=mild", pl)
    data = write_recording(rec, RecordingInfo("P1", "s1"), cmd, pl.postures_m)
    path = tmp_path / "raw.nwb"
    path.write_bytes(data)
    found = list(inspect_nwbfile(nwbfile_path=str(path)))
    bad = [m for m in found if m.importance in (Importance.CRITICAL, Importance.ERROR)]
    assert not bad, bad
    back, postures, prov = read_recording("raw.nwb", data)
    assert prov["patient"] == "P1"
    assert np.array_equal(back.force_n, rec.force_n) and len(back.trials) == len(rec.trials)
    assert postures is not None and np.allclose(postures, pl.postures_m)


def test_a_fault_ends_the_measurement_with_every_sample_kept() -> None:
    """The measurement's checks are the renderer's (haptic.monitor): the handle led out of the
    safety workspace on the way to the second posture trips WORKSPACE on the first state read
    outside it, and the samples taken so far come with the error."""
    from fieldbank.haptic.measure import MeasureConfig, MeasurementAborted
    from fieldbank.haptic.safety import SafetyConfig

    arm = Arm.from_params(resolve_patient("elbow=mild").params)
    pl = plan(ProtocolConfig(parts=("postural",), grid=(2, 1), centre_m=(0.0, 0.50),
                             spacing_m=0.04), arm)
    assert pl.postures_m[0][0] < 0.0 < pl.postures_m[1][0]  # x −0.02 m, then +0.02 m
    box = (-0.6, 0.01, 0.05, 0.8)  # the start and the first posture inside, the second not
    cfg = MeasureConfig(safety=SafetyConfig(passivity=False, workspace_m=box))
    with pytest.raises(MeasurementAborted, match="WORKSPACE") as info:
        run_protocol("sim://?patient=elbow=mild", pl, cfg)
    err = info.value
    assert err.recording is not None and err.commanded is not None
    n = len(err.recording.t_s)
    assert len(err.commanded) == n and err.recording.t_s[-1] > 1.25  # into the move
    # the last sample is the first outside the box
    x = err.recording.position_m[:, 0]
    assert x[-1] > 0.01 and np.all(x[:-1] <= 0.01) and np.any(err.commanded != 0.0)
