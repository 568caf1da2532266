"""Lab data out and back: NWB export (checked by nwbinspector), OpenSim .mot/.sto/.osim, and
plain lab CSVs ingested with the flags that supply what they lack.

Round trips say which fields survive, to what precision:

* NWB export → ingest: every map's kind, frame, sign, velocity, source and provenance
  keys exactly; positions, values and sd exactly (float64 both ways); the fitted parameters' value,
  sd and 95 % interval exactly; trace columns exactly (their stored dtype).
* ``.mot``/``.sto``: time and every column to 10 significant digits (the text format), labels
  and units exactly.
* ``.osim``: segment lengths, masses, centres of mass, the range of motion, the rest posture,
  α and Km exactly (17 significant digits); the hand's position against the model's
  kinematics to 1e-9 m; every group's moment arms against the model's constant ones, and its
  change of path length against the change of muscle length, to 1e-9 m; the full parameter
  document exactly.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fieldbank.ingest import ReadOptions
from fieldbank.ingest.csvfmt import read_csv
from fieldbank.model import Arm
from fieldbank.opensimio import arm_osim, read_storage
from fieldbank.params import GROUPS, ArmParams
from fieldbank.storage import Database
from tests.report_helpers import run_cli


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("io") / "demo-out"
    res = run_cli("demo", "--out", str(out), "--haptic-seconds", "0.6")
    assert res.exit_code == 0, res.output
    return out


def _url(demo: Path) -> str:
    return f"sqlite:///{demo / 'home' / 'fieldbank.sqlite3'}"


@pytest.mark.slow
def test_nwb_export_passes_nwbinspector_and_its_maps_come_back(demo: Path,
                                                               tmp_path: Path) -> None:
    from nwbinspector import Importance, inspect_nwbfile
    from pynwb import NWBHDF5IO

    url = _url(demo)
    with Database.open(url) as db:
        patient = db.list_haptic_sessions()[0].patient_code or "SYN-001"
    out = tmp_path / "p.nwb"
    res = run_cli("export", "--db", url, "--patient", patient, "-o", str(out))
    assert res.exit_code == 0, res.output
    found = list(inspect_nwbfile(nwbfile_path=str(out)))
    bad = [m for m in found if m.importance in (Importance.CRITICAL, Importance.ERROR)]
    assert not bad, bad
    # never over an existing file
    again = run_cli("export", "--db", url, "--patient", patient, "-o", str(out))
    assert again.exit_code == 1 and "exists" in again.stderr
    # one subject per file
    res = run_cli("export", "--db", url, "-o", str(tmp_path / "all.nwb"))
    assert res.exit_code == 1 and "--patient" in res.stderr
    with Database.open(url) as db:
        rows = db.list_maps(patient)
        stored = db.get_maps([r.id for r in rows])
        fits = db.list_fits(patient)
        sess = [h for h in db.list_haptic_sessions(patient)]
        traces = {t.name: db.get_trace_array(t.id) for t in db.list_traces(sess[0].id)} \
            if sess else {}
    with NWBHDF5IO(str(out), "r") as io_:
        nwb = io_.read()
        params = nwb.processing["models"]["fitted_parameters"].to_dataframe()
        last = fits[-1]
        mine = params[params.fit_id == last.id].set_index("parameter")
        for name, iv in last.result["intervals"].items():
            for key in ("value", "sd", "low", "high"):
                assert mine.loc[name, key] == float(iv[key]), (name, key)
        if traces:
            h = sess[0].id
            for name, arr in traces.items():
                if name != "t_s":
                    assert np.array_equal(nwb.acquisition[f"haptic_{h}_{name}"].data[:], arr)
    # back in: a new database, the same patient
    url2 = f"sqlite:///{tmp_path / 'back.sqlite3'}"
    with Database.open(url) as db:
        p = db.get_patient(patient)
    Database.open(url2).add_patient(patient, p.body_mass_kg, p.height_m, p.side)
    res = run_cli("ingest", "--db", url2, "--patient", patient, "--session", "back", str(out))
    assert res.exit_code == 0, res.output
    with Database.open(url2) as db:
        back = db.get_maps([r.id for r in db.list_maps(patient)])
    assert len(back) == len(stored)
    for a, b in zip(stored, back, strict=True):
        assert (a.kind, a.frame, a.sign, a.velocity_m_per_s, a.source) == \
            (b.kind, b.frame, b.sign, b.velocity_m_per_s, b.source)
        assert np.array_equal(a.positions_m, b.positions_m)
        assert np.array_equal(a.values, b.values)
        assert (a.sd is None and b.sd is None) or np.array_equal(a.sd, b.sd)
        for k, v in a.metadata.items():
            assert b.metadata[k] == v


@pytest.mark.slow
def test_a_haptic_trace_as_mot_and_sto(demo: Path, tmp_path: Path) -> None:
    url = _url(demo)
    with Database.open(url) as db:
        h = db.list_haptic_sessions()[0]
        traces = {t.name: (db.get_trace_array(t.id), db.trace_attrs(t.id)["unit"])
                  for t in db.list_traces(h.id)}
    for suffix in (".mot", ".sto"):
        out = tmp_path / f"trace{suffix}"
        res = run_cli("export", "--db", url, "--trace", str(h.id), "-o", str(out))
        assert res.exit_code == 0, res.output
        keys, labels, data = read_storage(out.read_text(encoding="utf-8"))
        assert labels[0] == "time" and keys["inDegrees"] == "no"
        assert int(keys["nRows"]) == data.shape[0] == traces["t_s"][0].shape[0]
        assert np.allclose(data[:, 0], traces["t_s"][0], rtol=1e-9, atol=0)
        # arm A's joint angles are the .osim model's coordinates, so the table plays on it
        assert {"shoulder_flexion", "elbow_flexion"} <= set(labels)
        assert "a_q1_rad" not in labels and "<Coordinate name=\"shoulder_flexion\">" in \
            arm_osim(ArmParams.from_anthropometry())
        back = {"shoulder_flexion": "a_q1_rad", "elbow_flexion": "a_q2_rad"}
        for j, name in enumerate(labels[1:], start=1):
            arr, unit = traces[back.get(name, name)]
            assert keys[f"units_{name}"] == unit
            assert np.allclose(data[:, j], arr, rtol=1e-9, atol=1e-12)
    osim = pytest.importorskip("opensim")
    table = osim.TimeSeriesTable(str(tmp_path / "trace.sto"))
    assert table.getNumRows() == traces["t_s"][0].shape[0]
    assert "fx_n" in list(table.getColumnLabels())


def test_a_fitted_arm_as_osim_loads_in_opensim(tmp_path: Path) -> None:
    osim = pytest.importorskip("opensim")     # dev extra; the runtime never needs it
    from fieldbank.opensimio import arm_osim

    params = ArmParams.from_anthropometry(68.0, 1.70).with_group(
        "ef", km_n_per_m=4000.0, alpha_n=420.0, beta=0.7)
    path = tmp_path / "arm.osim"
    path.write_text(arm_osim(params), encoding="utf-8")
    model = osim.Model(str(path))
    state = model.initSystem()
    arm = Arm.from_params(params)
    assert model.getBodySet().getSize() == 2
    upper = model.getBodySet().get("upper_arm")
    assert upper.getMass() == pytest.approx(params.upper_arm_mass_kg, rel=1e-9)
    assert upper.getMassCenter().get(0) == pytest.approx(params.upper_arm_com_m, rel=1e-9)
    coords = model.getCoordinateSet()
    sh, el = coords.get("shoulder_flexion"), coords.get("elbow_flexion")
    assert sh.getRangeMin() == pytest.approx(params.shoulder_range_rad[0], rel=1e-9)
    forces = model.getForceSet()

    def lengths(q: tuple[float, float]) -> list[float]:
        sh.setValue(state, q[0])
        el.setValue(state, q[1])
        model.realizePosition(state)
        return [osim.PathActuator.safeDownCast(forces.get(g)).getGeometryPath().getLength(state)
                for g in GROUPS]

    rest = tuple(float(v) for v in arm.q_rest)
    at_rest = lengths(rest)
    lam_rest = arm.muscle_lengths(np.array([rest]))[0]
    lo = (params.shoulder_range_rad[0], params.elbow_range_rad[0])
    hi = (params.shoulder_range_rad[1], params.elbow_range_rad[1])
    for f1, f2 in ((0.02, 0.02), (0.3, 0.7), (0.5, 0.5), (0.98, 0.98), (0.9, 0.1)):
        q = (lo[0] + f1 * (hi[0] - lo[0]), lo[1] + f2 * (hi[1] - lo[1]))
        now = lengths(q)
        hand = model.getMarkerSet().get("handle").getLocationInGround(state)
        assert [hand.get(0), hand.get(1)] == pytest.approx(list(arm.fk(np.array([q]))[0]),
                                                           abs=1e-9)
        lam = arm.muscle_lengths(np.array([q]))[0]
        for i, g in enumerate(GROUPS):
            assert now[i] - at_rest[i] == pytest.approx(lam[i] - lam_rest[i], abs=1e-9), g
            path = osim.PathActuator.safeDownCast(forces.get(g)).getGeometryPath()
            assert path.computeMomentArm(state, sh) == pytest.approx(-arm.jl[i, 0], abs=1e-9)
            assert path.computeMomentArm(state, el) == pytest.approx(-arm.jl[i, 1], abs=1e-9)
    # the passive springs pull: a posture away from rest accelerates the arm back
    sh.setValue(state, hi[0] - 0.1)
    el.setValue(state, lo[1] + 0.1)
    model.realizeAcceleration(state)
    assert np.abs(np.array([state.getUDot().get(0), state.getUDot().get(1)])).max() > 0.1
    for i, g in enumerate(GROUPS):
        act = osim.PathActuator.safeDownCast(forces.get(g))
        assert act.getOptimalForce() == pytest.approx(params.alpha_n[i], rel=1e-9)
        spring = osim.PathSpring.safeDownCast(forces.get(f"{g}_passive"))
        assert spring.getStiffness() == pytest.approx(params.km_n_per_m[i], rel=1e-9)
        assert spring.getRestingLength() == pytest.approx(at_rest[i], abs=1e-12)
    doc = ArmParams.from_dict(json.loads(model.get_publications()))
    assert doc == params


def test_a_plain_lab_csv_is_ingested_with_flags_and_a_column_mapping(tmp_path: Path) -> None:
    text = "PosX,PosY,ForceX,ForceY\n50,400,1.5,-0.5\n80,420,2.0,-0.25\n"
    opts = ReadOptions.from_flags("postural", "shoulder", "arm-on-handle", "0",
                                  ("x_mm=PosX", "y_mm=PosY", "fx_n=ForceX", "fy_n=ForceY"))
    maps, problems = read_csv("lab.csv", text.encode(), defaults=opts.csv_defaults(),
                              columns=opts.columns)
    assert not problems
    pm = maps[0]
    assert (pm.kind, pm.frame, pm.sign) == ("postural", "shoulder", "arm-on-handle")
    assert np.allclose(pm.positions_m, [[0.05, 0.4], [0.08, 0.42]])
    path = tmp_path / "lab.csv"
    path.write_text(text, encoding="utf-8")
    url = f"sqlite:///{tmp_path / 'db.sqlite3'}"
    Database.open(url).add_patient("LAB", 75.0, 1.75, "right")
    # without the flags the file is refused, naming what is missing
    res = run_cli("ingest", "--db", url, "--patient", "LAB", "--session", "s", str(path))
    assert res.exit_code == 1 and "lab.csv" in res.stderr and "missing 'kind'" in res.stderr
    res = run_cli("ingest", "--db", url, "--patient", "LAB", "--session", "s", str(path),
                  "--kind", "postural", "--frame", "shoulder", "--sign", "arm-on-handle",
                  "--column", "x_mm=PosX", "--column", "y_mm=PosY", "--column",
                  "fx_n=ForceX", "--column", "fy_n=ForceY")
    assert res.exit_code == 0, res.output
    # a flag never overrides what a file says
    said = tmp_path / "said.csv"
    said.write_text("# kind: stiffness\n" + text, encoding="utf-8")
    res = run_cli("ingest", "--db", url, "--patient", "LAB", "--session", "t", str(said),
                  "--kind", "postural", "--frame", "shoulder", "--sign", "arm-on-handle",
                  "--column", "x_mm=PosX", "--column", "y_mm=PosY", "--column",
                  "fx_n=ForceX", "--column", "fy_n=ForceY")
    assert res.exit_code == 1 and "said.csv" in res.stderr and "stiffness" in res.stderr
    # a mapping to a column the file does not have names it
    res = run_cli("ingest", "--db", url, "--patient", "LAB", "--session", "u", str(path),
                  "--kind", "postural", "--frame", "shoulder", "--sign", "arm-on-handle",
                  "--column", "x_mm=HandX")
    assert res.exit_code == 1 and "HandX" in res.stderr
    with Database.open(url) as db:
        assert [r.session_label for r in db.list_maps("LAB")] == ["s"]


def _kinarm_zip(rec: object, shoulder: tuple[float, float], n_files: int) -> bytes:
    """An exam in Dexterit-E's layout (raw/common.c3d + one C3D per trial), written by the c3d
    library: the hand as POINT data in KINARM's coordinates (m), the force sensor as analog
    Right_FS_ForceX/Y with the handle-on-arm sign, TRIAL:TRIAL_NUM in each file."""
    import io
    import zipfile

    import c3d

    def c3d_file(pos: np.ndarray, force: np.ndarray, number: int) -> bytes:
        w = c3d.Writer(point_rate=1000.0, analog_rate=1000.0, point_units="m   ")
        frames = []
        for k in range(len(pos)):
            pts = np.zeros((2, 5), dtype=np.float32)
            pts[0, :2] = pos[k]
            analog = np.zeros((3, 1), dtype=np.float32)          # force x, y, z
            analog[:2, 0] = force[k]
            frames.append((pts, analog))
        w.add_frames(frames)
        w.set_point_labels(["Right_Hand", "Left_Hand"])
        w.set_analog_labels(["Right_FS_ForceX", "Right_FS_ForceY", "Right_FS_ForceZ"])
        w.analog_group.add_str("UNITS", "units", "N N N ", 2, 3)
        g = w.add_group(30, "TRIAL", "trial")
        g.add_array("TRIAL_NUM", "trial number", np.array([number], dtype=np.int16))
        buf = io.BytesIO()
        w.write(buf)
        return buf.getvalue()

    pos = rec.position_m + np.asarray(shoulder)  # type: ignore[attr-defined]
    force = -rec.force_n                          # type: ignore[attr-defined]
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("raw/common.c3d", c3d_file(pos[:10], force[:10], 0))
        for k, idx in enumerate(np.array_split(np.arange(len(pos)), n_files)):
            # stored in reverse name order: the reader must sort by TRIAL_NUM
            z.writestr(f"raw/trial_{n_files - k:02d}.c3d", c3d_file(pos[idx], force[idx], k + 1))
        z.writestr("description.txt", "test exam")
    return out.getvalue()


def test_a_kinarm_exam_zip_is_read_with_its_holds_found(tmp_path: Path) -> None:
    from fieldbank.haptic.measure import run_protocol
    from fieldbank.haptic.patient import resolve_patient
    from fieldbank.maps import model_map_like
    from fieldbank.measure.protocol import ProtocolConfig, plan

    src = resolve_patient("elbow=moderate")
    arm = Arm.from_params(src.params)
    pl = plan(ProtocolConfig(parts=("stiffness",), grid=(2, 1)), arm)
    rec, _ = run_protocol("sim://?patient=elbow=moderate", pl)
    shoulder = (0.05, -0.3)
    path = tmp_path / "exam.zip"
    path.write_bytes(_kinarm_zip(rec, shoulder, 3))
    url = f"sqlite:///{tmp_path / 'db.sqlite3'}"
    Database.open(url).add_patient("KIN", 75.0, 1.75, "right")
    res = run_cli("ingest", "--db", url, "--patient", "KIN", "--session", "s", str(path))
    assert res.exit_code == 1 and "exam.zip" in res.stderr and "--shoulder" in res.stderr
    res = run_cli("ingest", "--db", url, "--patient", "KIN", "--session", "s", str(path),
                  "--shoulder", "0.05,-0.3", "--sign", "handle-on-arm")
    assert res.exit_code == 0, res.output
    with Database.open(url) as db:
        rows = db.list_maps("KIN")
        maps = db.get_maps([r.id for r in rows])
    stiff = next(m for m in maps if m.kind == "stiffness")
    assert stiff.metadata["raw_format"] == "KINARM"
    assert "stillness" in stiff.metadata["trials_found_by"]
    assert stiff.n == 2
    truth = model_map_like(arm, stiff)
    err = (np.linalg.norm(stiff.values - truth.values, axis=(1, 2))
           / np.linalg.norm(truth.values, axis=(1, 2)))
    assert np.all(err < 0.15), err
    post = next(m for m in maps if m.kind == "postural")
    assert np.allclose(post.values, model_map_like(arm, post).values, atol=0.05)
