"""``fieldbank probe design|classify|paths|trials``: outputs that parse back, files and plots
that exist, stored models as candidates, clean errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fieldbank.cli.main import COMMANDS, cli
from fieldbank.evaluate.design import equilibrium, severity_candidates
from fieldbank.evaluate.observation import Observation, with_force_noise
from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic.probe import probe_path
from fieldbank.haptic.recording import write_trace_h5
from fieldbank.params import GROUPS, ArmParams
from fieldbank.probepath import ProbePath
from fieldbank.storage import Database
from tests.haptic_util import mild_shoulder_trace


def _run(*args: str):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(cli, list(args))


def test_the_registered_help_line_is_the_commands_own() -> None:
    lazy = COMMANDS["probe"]
    assert lazy.help == lazy.load().get_short_help_str(limit=10_000)


def test_design_writes_json_probes_and_a_plot(tmp_path: Path) -> None:
    out, png = tmp_path / "probes.json", tmp_path / "probes.png"
    r = _run("probe", "design", "--json", "--out", str(out), "--plot", str(png),
             "--shoulder-offset", "0.05,0.1")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["candidates"] == ["shoulder severe", "elbow severe", "biarticular severe"]
    assert 1 <= doc["summary"]["probes"] <= 2 and doc["summary"]["separates_all_by_feel"]
    assert doc["seed_probes"]["summary"]["probes"] == 2
    assert doc["search_s"] > 0 and doc["limits"]["force_limit_n"] == 40.0
    drawn = json.loads(out.read_text(encoding="utf-8"))
    assert drawn["format"] == "fieldbank-probes"
    first = drawn["probes"][0]
    assert first["frame"] == "robot" and first["shoulder_offset_m"] == [0.05, 0.1]
    # the polyline starts at the arm's rest hand position, shifted into the robot frame
    eq = equilibrium(severity_candidates())
    assert first["points_m"][0] == pytest.approx([eq[0] + 0.05, eq[1] + 0.1], abs=1e-6)
    assert first["times_s"][0] == 0.0 and first["times_s"][-1] > 0.1
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_design_text_reads_both_sets_in_clinic_words() -> None:
    r = _run("probe", "design", "--criterion", "orientation")
    assert r.exit_code == 0, r.output
    assert "designed (orientation, strokes" in r.stdout
    assert "the seed's pull and semi-ellipse, measured the same way" in r.stdout
    assert "toward" in r.stdout and "N toward" in r.stdout


def test_candidates_from_files_and_stored_models(tmp_path: Path) -> None:
    a, b = tmp_path / "stiff-elbow.json", tmp_path / "stiff-shoulder.json"
    a.write_text(synthesize({"elbow": "moderate"}).to_json(), encoding="utf-8")
    b.write_text(synthesize({"shoulder": "moderate"}).to_json(), encoding="utf-8")
    url = f"sqlite:///{tmp_path / 'db.sqlite3'}"
    with Database.open(url) as db:
        db.add_patient("P-1", 70.0, 1.7, "right")
        m, _fit = db.add_fitted_model(
            synthesize({"biarticular": "mild"}), "fitted", "P-1", "mlsl+lbfgs", 0, 10, 0.1, 1.0,
            {"unidentified": [{"name": "beta[4]", "reason": "β of bf not identifiable: all "
                               "stiffness maps are static"}]}, [])
    r = _run("probe", "design", "--candidate-params", str(a), "--candidate-params", str(b),
             "--candidate-model", str(m.id), "--db", url, "--max-probes", "1")
    assert r.exit_code == 0, r.output
    assert "stiff-elbow" in r.stdout and f"model {m.id}" in r.stdout
    assert f"note: model {m.id}: rests on a guess: β of bf not identifiable" in r.stdout


@pytest.fixture(scope="module")
def trace_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return mild_shoulder_trace(tmp_path_factory.mktemp("traces") / "probe.h5")


def test_classify_a_trace_file_with_a_plot(trace_file: Path, tmp_path: Path) -> None:
    """A mild shoulder probed once is most probably a mild shoulder, not yet for certain; the
    next probe the classifier suggests, performed on the same arm, settles it.

    On the per-group scale the mild shoulder and the mild elbow feel alike on this stroke: it
    extends the shoulder by ≈ 13° and flexes the elbow by ≈ 26°, stretching the shoulder
    flexors by 0.04 m × 0.23 rad ≈ 9 mm and the elbow extensors by 0.025 m × 0.45 rad ≈ 11 mm;
    Km 2,344 N/m against 600 N/m in one or the other gives ≈ 3.4 N at the hand for both, ≈ 25°
    apart, |ΔF| ≈ 1.5 N at the end. Over the 0.4 s stroke (minimum jerk, ∫s² = 0.39) and the
    0.2 s after it, at σ = 2 N and τ = 50 ms: D ≈ (8 × 0.39 + 4) × 1.5² / 8 ≈ 2 nats, odds
    ≈ 7 : 1 - so a probability near 0.9, short of the 0.99 at which the classifier stops.
    """
    png = tmp_path / "classified.png"
    r = _run("probe", "classify", str(trace_file), "--levels", "mild,severe", "--json",
             "--plot", str(png))
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["best"]["candidate"] == "shoulder mild"
    assert 0.7 < doc["best"]["probability"] < 0.99
    assert doc["group_posterior"]["shoulder"] == pytest.approx(doc["best"]["probability"],
                                                               abs=1e-3)
    assert doc["candidates"][1]["candidate"] == "elbow mild"  # the runner-up
    assert 1.0 < doc["log10_likelihood_ratio"] * 2.302585 < 4.0  # ≈ 2 nats
    assert "still in play" in doc["next_reason"]
    drawing = doc["next_probe"]["probes"][0]["drawing"]
    assert drawing["frame"] == "robot"
    assert png.stat().st_size > 10_000
    text = _run("probe", "classify", str(trace_file), "--levels", "mild,severe")
    assert "most probable: shoulder mild" in text.stdout and "next probe: stroke" in text.stdout
    # the suggested probe, performed on the same arm, and both recordings together
    res = probe_path(synthesize({"shoulder": "mild"}), ProbePath.from_dict(drawing), seed=1)
    second = tmp_path / "next.h5"
    write_trace_h5(res.trace, second)
    r = _run("probe", "classify", str(trace_file), str(second), "--levels", "mild,severe",
             "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["best"]["candidate"] == "shoulder mild" and doc["best"]["probability"] > 0.99
    assert doc["group_posterior"]["shoulder"] > 0.99
    assert doc["next_probe"] is None and doc["next_reason"].startswith("none needed")


def test_classify_an_exported_csv_in_the_robot_frame(trace_file: Path, tmp_path: Path) -> None:
    csv = tmp_path / "probe.csv"
    r = _run("haptic", "replay", str(trace_file), "--csv", str(csv))
    assert r.exit_code == 0, r.output
    r = _run("probe", "classify", str(csv), "--levels", "all", "--json", "--no-next")
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["best"]["group"] == "shoulder"


def test_classify_errors_say_what_and_where(tmp_path: Path) -> None:
    r = _run("probe", "classify", str(tmp_path / "missing.h5"))
    assert r.exit_code != 0 and "no trace file" in r.output
    for ref in ("haptic_session:abc", "haptic_session:0", "haptic_session:99999999999"):
        r = _run("probe", "classify", ref, "--db", f"sqlite:///{tmp_path / 'none.db'}")
        assert r.exit_code == 1 and f"{ref!r} names no haptic session" in r.output, r.output
    assert not (tmp_path / "none.db").exists()  # refused before a database is opened
    bad = tmp_path / "bad.csv"
    bad.write_text("# frame: shoulder\n# sign: arm-on-handle\nt_s,x_m,y_m,fx_n,fy_n\n"
                   "0,0.1,0.5,0,0\n0.001,0.1,nan?,0,0\n", encoding="utf-8")
    r = _run("probe", "classify", str(bad))
    assert r.exit_code == 1 and "row 5" in r.output


def test_paths_reports_both_paradigms() -> None:
    """Both paradigms' sets, in JSON and in words, and whether they separate every pair - for
    three candidates, exactly when every pair is ≥ 1 JND apart on one of the paths (two paths
    cover what any choice of paths covers). On the per-group scale the fixed paths leave the
    severe elbow and bi-articular arms within a JND of orientation (tests/test_probe_design.py),
    and the read-out says so."""
    r = _run("probe", "paths", "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert [p["name"] for p in doc["probes"]] == ["pull", "semi-ellipse", "circle 4 cm",
                                                  "circle 6 cm", "circle 8 cm"]
    text = _run("probe", "paths").stdout
    for what, key, measure in (("min-max", "minmax_set", "minmax_jnd"),
                               ("orientation", "orientation_set", "orientation_jnd")):
        chosen = doc[key]
        assert len(chosen["paths"]) <= 2
        assert chosen["separates_all"] == all(p[measure] >= 1.0 for p in doc["pairs"])
        words = "separates every pair" if chosen["separates_all"] else \
            "does not separate every pair"
        assert f"{what} paradigm: {', '.join(chosen['paths']) or 'no path'} {words}" in text
    pair = next(p for p in doc["pairs"] if p["pair"] == ["elbow severe", "biarticular severe"])
    assert pair["orientation_jnd"] < 1.0 and not doc["orientation_set"]["separates_all"]
    feats = doc["probes"][0]["features"]
    assert {f["candidate"] for f in feats} == {"shoulder severe", "elbow severe",
                                               "biarticular severe"}


def test_bad_options_are_clean_errors() -> None:
    r = _run("probe", "design", "--workspace", "1,2")
    assert r.exit_code == 2 and "XMIN,XMAX,YMIN,YMAX" in r.output
    r = _run("probe", "design", "--levels", "extreme")
    assert r.exit_code == 1 and "Unknown severity level 'extreme'" in r.output
    r = _run("probe", "design", "--groups", "elbow", "--levels", "mild,severe",
             "--target", "group")
    assert r.exit_code == 1 and "nothing to tell apart" in r.output
    r = _run("probe", "design", "--force-sd-n", "-1")
    assert r.exit_code == 1 and "'force_sd_n' noise parameter" in r.output


@pytest.mark.slow
def test_trials_prints_confusion_matrices() -> None:
    r = _run("probe", "trials", "--groups", "shoulder,elbow", "--levels", "severe", "--reps",
             "1", "--draws", "2", "--max-probes", "1", "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    sets = doc["trials"]["sets"]
    assert set(sets) == {"designed", "seed"}
    assert sum(map(sum, sets["seed"]["confusion"])) == 2 * 2



def _stretch_csvs(params: ArmParams, folder: Path, seed: int) -> list[str]:
    """The stretch of every group performed on the arm ``params``, 2 N of sensor noise, one
    CSV a stretch as a recording would be exported."""
    from fieldbank.evaluate.design import NoiseModel
    from fieldbank.evaluate.design.coverage import stretch_set
    from fieldbank.evaluate.replay import replay_forces
    from fieldbank.model import Arm

    rng = np.random.default_rng(seed)
    noise = NoiseModel(force_sd_n=2.0)
    true = Arm.from_params(params)
    out = []
    for m in stretch_set(Arm.from_params(params.with_unimpaired_muscles())):
        dt = float(m.times_s[1] - m.times_s[0])
        start = (float(m.positions_m[0, 0]), float(m.positions_m[0, 1]))
        f = replay_forces([true], m.positions_m, m.velocities_m_per_s, dt, start)[0]
        obs = with_force_noise(Observation.from_arrays(m.name, m.times_s, m.positions_m, f,
                                                       m.velocities_m_per_s), noise, rng)
        path = folder / f"{m.name.replace(' ', '_')}.csv"
        rows = np.column_stack([obs.times_s, obs.positions_m, obs.force_n,
                                m.velocities_m_per_s])
        path.write_text("# frame: shoulder\n# sign: arm-on-handle\n"
                        "t_s,x_m,y_m,fx_n,fy_n,vx_m_per_s,vy_m_per_s\n"
                        + "\n".join(",".join(f"{v:.6g}" for v in r) for r in rows) + "\n")
        out.append(str(path))
    return out


@pytest.mark.slow
def test_classify_open_says_per_group_how_it_is_impaired_and_when_no_state_explains(
        tmp_path: Path) -> None:
    """Severe elbow-flexor spasticity on a body of the clinic's own, probed with the stretch of
    every group: the elbow flexors are named impaired, most probably by spasticity, the other
    groups not; three severe groups at once are none of the candidates."""
    body = ["--mass", "82", "--height", "1.84", "--side", "left"]
    base = ArmParams.from_anthropometry(82.0, 1.84, "left")
    ef = tmp_path / "ef"
    ef.mkdir()
    files = _stretch_csvs(synthesize({"ef:dynamic": "severe"}, base), ef, seed=5)
    r = _run("probe", "classify", *files, "--open", *body, "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["answer"] == "ef" and doc["probability"] > 0.3, doc
    g = doc["groups"]["ef"]
    assert g["impaired"] > 0.6 and g["impaired"] == max(v["impaired"] for v in
                                                        doc["groups"].values()), doc["groups"]
    kinds = {k: g[k] for k in ("stiffness", "spasticity", "spasticity and stiffness",
                               "contracture")}
    assert max(kinds, key=kinds.__getitem__) == "spasticity" and g["contracture"] < 0.1, g
    assert sum(kinds.values()) == pytest.approx(g["impaired"], abs=1e-5)
    assert all(doc["groups"][o]["impaired"] < 0.2 for o in ("sf", "se", "ee")), doc["groups"]
    assert doc["explains_recording"] and doc["none_of_the_candidates"] < 0.5
    # what is stated: one claim a group, or partner groups the recording cannot tell apart
    said = {tuple(st["groups"]): st for st in doc["statements"]}
    assert sorted(g for gs in said for g in gs) == sorted(GROUPS), said
    ef = next(st for gs, st in said.items() if "ef" in gs)
    assert ef["impaired"] and ef["probability"] >= g["impaired"] - 1e-6, said
    for gs, st in said.items():
        assert 0.5 <= st["probability"] <= 1.0
        if len(gs) == 1:
            p = doc["groups"][gs[0]]["impaired"]
            assert st["probability"] == pytest.approx(max(p, 1 - p), abs=1e-5)
    assert not any(st["impaired"] for gs, st in said.items() if gs and set(gs) <= {"sf", "se"})
    text = _run("probe", "classify", *files, "--open", *body)
    assert text.exit_code == 0, text.output
    assert "most probable set of groups: impaired: ef" in text.stdout
    assert "elbow flexors (ef)" in text.stdout
    assert "none of the candidates: p = " in text.stdout
    assert text.stdout.startswith("stated (per group")
    # one "p = …" line a statement, before the table (long ones wrapped)
    head = text.stdout.split("most probable set of groups")[0]
    assert head.count("\n  p = ") == len(said), text.stdout
    said_ef = f"p = {ef['probability']:.2f} {ef['says']}"
    assert " ".join(said_ef.split()) in " ".join(head.split()), text.stdout
    three = tmp_path / "three"
    three.mkdir()
    files = _stretch_csvs(synthesize({"sf": "severe", "ee": "severe", "bf": "severe"}, base),
                          three, seed=6)
    r = _run("probe", "classify", *files, "--open", *body, "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["answer"] == "none of the candidates" and doc["probability"] > 0.9, doc
    assert not doc["explains_recording"]
    assert doc["statements"][0]["groups"] == [] and doc["statements"][0]["says"] == (
        "none of the candidates explains this recording")
    assert doc["statements"][0]["probability"] == pytest.approx(doc["probability"])
    # the candidate lists of the joint-group classifier do not apply to the open set
    r = _run("probe", "classify", *files, "--open", "--levels", "severe")
    assert r.exit_code != 0 and "--levels do not apply" in r.output
