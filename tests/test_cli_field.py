"""``fieldbank field``: outputs that parse back, plots that exist, clean errors."""

from __future__ import annotations

import io
import json

import numpy as np
from click.testing import CliRunner

from fieldbank.cli.main import cli
from fieldbank.evaluate.severity import synthesize
from fieldbank.model import Arm


def _run(*args: str):
    return CliRunner().invoke(cli, list(args))


def _csv_rows(text: str) -> tuple[dict[str, str], list[str], np.ndarray]:
    meta, body = {}, []
    for line in text.splitlines():
        if line.startswith("# "):
            k, v = line[2:].split(":", 1)
            meta[k.strip()] = v.strip()
        else:
            body.append(line)
    header = body[0].split(",")
    data = np.loadtxt(io.StringIO("\n".join(body[1:])), delimiter=",", ndmin=2)
    return meta, header, data


def test_postural_csv_matches_the_model():
    res = _run("field", "postural", "--severity", "elbow=severe", "--grid", "6")
    assert res.exit_code == 0, res.output
    meta, header, data = _csv_rows(res.stdout)
    assert meta["kind"] == "postural" and meta["frame"] == "shoulder"
    assert meta["sign"] == "arm-on-handle" and meta["velocity_m_per_s"] == "0"
    assert "ef passive severe; ef dynamic severe; ee passive severe" in meta["source"]
    assert header == ["x_m", "y_m", "fx_n", "fy_n"]
    arm = Arm.from_params(synthesize({"elbow": "severe"}))
    np.testing.assert_allclose(data[:, 2:], arm.endpoint_force(data[:, :2]), rtol=1e-6,
                               atol=1e-8)


def test_stiffness_json_at_positions_and_velocity():
    res = _run("field", "stiffness", "--at", "0.05,0.45;0.1,0.5", "--velocity", "0,-1.5",
               "--severity", "elbow=severe", "--json")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    arm = Arm.from_params(synthesize({"elbow": "severe"}))
    _, k, b = arm.field([[0.05, 0.45], [0.1, 0.5]], [0.0, -1.5])
    np.testing.assert_allclose(doc["values"], k, rtol=1e-12)
    np.testing.assert_allclose(doc["damping_n_s_per_m"], b, rtol=1e-12)
    assert doc["velocity_m_per_s"] == [0.0, -1.5]
    assert doc["severity"]["ef"]["passive"]["level"] == "severe"
    assert doc["severity"]["ee"]["dynamic"]["level"] == "severe"
    assert doc["severity"]["sf"]["dynamic"]["level"] == "unimpaired"
    assert len(doc["ellipse"]["major_n_per_m"]) == 2


def test_plots_are_written(tmp_path):
    png = tmp_path / "f.png"
    svg = tmp_path / "k.svg"
    assert _run("field", "postural", "--grid", "8", "--out", str(png)).exit_code == 0
    assert _run("field", "stiffness", "--grid", "8", "--out", str(svg)).exit_code == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 5000
    text = svg.read_text(encoding="utf-8")
    assert "<svg" in text[:400]
    # the report's conventions: a key in units, the markers named, every ellipse drawn
    assert "diameter = " in text and " N/m" in text
    assert "rest hand position" in text and "shoulder" in text
    assert text.count("<ellipse") >= 20
    pdf = tmp_path / "f.pdf"
    assert _run("field", "postural", "--grid", "8", "--out", str(pdf)).exit_code == 0
    assert pdf.read_bytes()[:5] == b"%PDF-"


def test_params_file_round_trip(tmp_path):
    p = synthesize({"shoulder": "mild"})
    f = tmp_path / "arm.json"
    f.write_text(p.to_json())
    a = _run("field", "postural", "--params", str(f), "--at", "0.1,0.4")
    b = _run("field", "postural", "--severity", "shoulder=mild", "--at", "0.1,0.4")
    assert a.exit_code == 0 and a.stdout.splitlines()[-1] == b.stdout.splitlines()[-1]


def test_errors_exit_nonzero_with_the_reason(tmp_path):
    res = _run("field", "postural", "--at", "2,2")
    assert res.exit_code == 1 and "this arm reaches" in res.output
    res = _run("field", "postural", "--severity", "elbow=awful")
    assert res.exit_code == 1 and "Unknown severity level 'awful'" in res.output
    bad = ArmParamsJSON = tmp_path / "bad.json"
    doc = synthesize({}).to_dict()
    doc["beta"] = [0.1, 0.1, 2.0, 0.1, 0.1, 0.1]
    ArmParamsJSON.write_text(json.dumps(doc))
    res = _run("field", "postural", "--params", str(bad))
    assert res.exit_code == 1
    assert "'beta[2] (ef)' parameter must be a finite number in [0, 1]; got 2.0" in res.output
    res = _run("field", "postural", "--at", "0.1,0.4", "--out", str(tmp_path / "x.gif"),
               "--format", "png")
    assert res.exit_code == 0  # explicit format wins over the suffix
    res = _run("field", "postural", "--velocity", "0,1")
    assert res.exit_code == 1 and "static" in res.output
