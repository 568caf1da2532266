"""The what-if says when it guesses, and refuses a poor fit unless the user insists.

Everything runs the real flow on SQLite: synthetic maps written as lab files, ingested, fitted
by ``fieldbank fit``, then ``fieldbank whatif`` / ``report`` on the stored model.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from fieldbank.fitting.synthetic import impaired_params, synthetic_patient
from fieldbank.maps import FieldMap
from fieldbank.params import ArmParams
from tests.report_helpers import run_cli

BASE = ArmParams.from_anthropometry()


def _store_patient(url: str, tmp_path: Path, code: str, maps: list[FieldMap]) -> None:
    files = []
    for k, m in enumerate(maps):
        f = tmp_path / f"{code}-{k}.csv"
        f.write_text(m.to_csv(), encoding="utf-8")
        files.append(str(f))
    assert run_cli("patient", "add", code, "--mass-kg", "75", "--height-m", "1.75",
                   "--side", "right", "--db", url).exit_code == 0
    res = run_cli("ingest", *files, "--patient", code, "--session", "s1", "--date",
                  "2024-03-01", "--db", url)
    assert res.exit_code == 0, res.output
    res = run_cli("fit", code, "--db", url, "--replicates", "8", "--json")
    assert res.exit_code == 0, res.output


@pytest.fixture(scope="module")
def postural_only(tmp_path_factory: pytest.TempPathFactory) -> str:
    """A patient with a severe elbow measured by a postural map only (no moving map)."""
    tmp = tmp_path_factory.mktemp("postural")
    url = f"sqlite:///{tmp / 'db' / 'fb.sqlite3'}"
    pat = synthetic_patient(impaired_params("elbow", "severe", BASE), seed=8, moving=False,
                            patient="POST-1")
    _store_patient(url, tmp, "POST-1", [pat.maps[0]])
    return url


def test_postural_only_fit_warns_about_the_unidentified_reflex(postural_only: str) -> None:
    url = postural_only
    text = run_cli("whatif", "POST-1", "--db", url, "--botox", "ef=150U",
                   "--interval-samples", "6")
    assert text.exit_code == 0, text.output
    out = text.stdout
    flat = " ".join(out.split())  # wrapped lines as one
    assert "WARNING: step 1 (botulinum" in flat
    assert "stretch reflex (α, β) of ef" in flat and "rests on a guess" in flat
    # in the summary's three lines already, not dozens of lines down
    assert "WARNING: step 1 (botulinum" in " ".join(out.splitlines()[:12])
    rests = flat[flat.index("not identified by the maps"):]
    assert "alpha_ef" in rests and "(held at the unimpaired value)" in rests
    assert "warning(s) in the output" in text.stderr

    doc = json.loads(run_cli("whatif", "POST-1", "--db", url, "--botox", "ef=150U", "--json",
                             "--interval-samples", "6").stdout)
    assert doc["fit"]["status"] == "under-determined"
    assert doc["fit"]["accepted_poor_fit"] is False
    unid = {u["name"]: u for u in doc["unidentified"]}
    assert unid["alpha_ef"]["held_at_unimpaired"] and unid["beta_ef"]["held_at_unimpaired"]
    assert "static" in unid["beta_ef"]["reason"]
    ef_warnings = [w for w in doc["warnings"] if "of ef" in w]
    assert len(ef_warnings) == 1 and "alpha_ef = 100" in ef_warnings[0]
    # the intervals carry the fit's samples through the plan, the held reflex drawn from its
    # prior range: the point prediction keeps the held (unimpaired, lowest) value, so it lies
    # at the bottom of the interval, which the guessed reflex widens upward; the interval of
    # what the maps identified (held values kept) brackets the point
    iv = doc["intervals"]
    assert iv["samples"] == 6 and iv["level"] == 0.95
    peak = iv["metrics"]["elbow extension peak torque"]
    lo, hi = peak["before_interval"]
    assert peak["rests_on_guess"] and lo < hi and lo >= peak["before"] * 0.95
    klo, khi = peak["without_guesses"]["before_interval"]
    assert klo <= peak["before"] * 1.05 and khi >= peak["before"] * 0.95
    assert hi - lo > 5 * (khi - klo)
    assert "drawn from their prior range" in iv["note"]


def test_a_step_on_identified_parameters_is_not_warned_about(postural_only: str) -> None:
    """Casting changes the passive stiffness (Km), which the postural map identifies."""
    doc = json.loads(run_cli("whatif", "POST-1", "--db", postural_only, "--cast", "ef",
                             "--json", "--interval-samples", "0").stdout)
    assert doc["warnings"] == []
    assert doc["unidentified"]  # the guesses are still listed: the prediction depends on them
    assert doc["intervals"]["metrics"] == {}


@pytest.fixture(scope="module")
def poor(tmp_path_factory: pytest.TempPathFactory) -> str:
    """A patient whose postural map points away from rest: no arm model can produce it."""
    tmp = tmp_path_factory.mktemp("poor")
    url = f"sqlite:///{tmp / 'db' / 'fb.sqlite3'}"
    pat = synthetic_patient(impaired_params("elbow", "severe", BASE), seed=9, moving=False,
                            patient="BAD-1")
    m = pat.maps[0]
    flipped = FieldMap(kind=m.kind, positions_m=m.positions_m, values=-m.values, sd=m.sd,
                       velocity_m_per_s=m.velocity_m_per_s, metadata=dict(m.metadata))
    _store_patient(url, tmp, "BAD-1", [flipped, *pat.maps[1:]])
    return url


def test_a_poor_fit_is_refused_for_whatif_unless_insisted(poor: str, tmp_path: Path) -> None:
    url = poor
    shown = run_cli("models", "show", "1", "--db", url)
    assert "status: poor" in shown.stdout and "R² " in shown.stdout
    report = json.loads(run_cli("models", "show", "1", "--db", url, "--json").stdout)["fit"]
    assert report["status"] == "poor"
    assert report["goodness_of_fit"]["maps"][0]["r2"] < 0

    refused = run_cli("whatif", "BAD-1", "--db", url, "--botox", "ef=150U", "--save")
    assert refused.exit_code == 1
    assert "poor fit" in refused.stderr and "--accept-poor-fit" in refused.stderr
    out = tmp_path / "out"
    refused = run_cli("whatif", "BAD-1", "--db", url, "--botox", "ef=150U", "--out", str(out))
    assert refused.exit_code == 1 and not out.exists()  # nothing half-written

    ok = run_cli("whatif", "BAD-1", "--db", url, "--botox", "ef=150U", "--save", "--json",
                 "--accept-poor-fit", "--interval-samples", "4")
    assert ok.exit_code == 0, ok.output
    doc = json.loads(ok.stdout)
    assert doc["fit"]["status"] == "poor" and doc["fit"]["accepted_poor_fit"] is True
    assert doc["warnings"][0].startswith("poor fit accepted by the user (--accept-poor-fit)")
    text = run_cli("whatif", "BAD-1", "--db", url, "--botox", "ef=150U", "--accept-poor-fit",
                   "--interval-samples", "0")
    assert "status poor (accepted by the user)" in text.stdout

    from fieldbank.storage import Database

    with Database.open(url) as db:
        plan = db.get_plan(doc["saved"]["plan_id"])
        assert plan.spec["accepted_poor_fit"].startswith("poor fit accepted")

    # reports refuse the case too, unless told; then the CSV says so
    rep = run_cli("report", "--db", url, "--out", str(tmp_path / "rep"), "--jobs", "1")
    assert rep.exit_code == 1 and "poor fit" in rep.stderr
    rep = run_cli("report", "--db", url, "--out", str(tmp_path / "rep"), "--jobs", "1",
                  "--accept-poor-fit")
    assert rep.exit_code == 0, rep.output
    rows = list(csv.DictReader((tmp_path / "rep" / "metrics.csv").open(encoding="utf-8")))
    assert rows[0]["fit_status"] == "poor (accepted)"
    assert "poor fit accepted" in rows[0]["warnings"]


def test_intervals_show_a_drop_where_the_fit_identified_the_reflex(tmp_path: Path) -> None:
    """Moving maps identify the elbow flexors' reflex: 150 U into ef lowers the elbow
    extension reflex torque in every sample, and the interval is not a point."""
    url = f"sqlite:///{tmp_path / 'db' / 'fb.sqlite3'}"
    pat = synthetic_patient(impaired_params("elbow", "severe", BASE), seed=1, n_stiffness=12,
                            patient="MOV-1")
    _store_patient(url, tmp_path, "MOV-1", list(pat.maps))
    doc = json.loads(run_cli("whatif", "MOV-1", "--db", url, "--botox", "ef=150U", "--json",
                             "--interval-samples", "8").stdout)
    assert not [w for w in doc["warnings"] if "of ef" in w]
    reflex = doc["intervals"]["metrics"]["elbow extension reflex torque"]
    lo, hi = reflex["change_interval"]
    assert hi < 0 and lo < hi
    assert lo <= reflex["change"] <= hi or np.isclose(reflex["change"], lo, rtol=0.05) \
        or np.isclose(reflex["change"], hi, rtol=0.05)


def test_the_whatif_says_the_maps_cannot_tell_a_normal_reflex_from_a_severe_one(
        postural_only: str) -> None:
    """A postural map never moves the arm: every reflex is held. The what-if says, in words,
    that the maps cannot tell a normal reflex from a severe one, and which stretch would."""
    res = run_cli("whatif", "POST-1", "--db", postural_only, "--botox", "ef=150U",
                  "--interval-samples", "6")
    assert res.exit_code == 0, res.output
    flat = " ".join(res.stdout.split())
    said = "cannot tell a normal stretch reflex from a severe one in the"
    assert said in flat and "elbow flexors (ef)" in flat[flat.index(said):]
    assert "ef: a fast stretch of the elbow into extension" in flat
    # the bi-articular groups are tested with the shoulder placed to lengthen them
    assert "be: a fast stretch of the elbow into flexion with the shoulder flexed" in flat
    doc = json.loads(run_cli("whatif", "POST-1", "--db", postural_only, "--botox", "ef=150U",
                             "--json", "--interval-samples", "6").stdout)
    unseen = doc["unseen_reflexes"]
    assert len(unseen) == 7 and said in unseen[0]  # the sentence, then one test per group
