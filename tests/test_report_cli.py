"""``fieldbank report``: determinism, selection, and clear refusals."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any

import pytest

from tests.report_helpers import build_batch, run_cli

FILES = ("report.html", "metrics.csv", "metrics.json")


@pytest.fixture(scope="module")
def batch(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    return build_batch(tmp_path_factory.mktemp("report-batch"))


def _rows(out: Path) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO((out / "metrics.csv").read_text(encoding="utf-8"))))


def test_stored_batch_reports_byte_identically(batch: dict[str, Any], tmp_path: Path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    r1 = run_cli("report", "--db", batch["url"], "--out", str(a), "--jobs", "1", "--json",
                 "--no-date")
    r2 = run_cli("report", "--db", batch["url"], "--out", str(b), "--jobs", "2", "--json",
                 "--no-date")
    assert r1.exit_code == 0, r1.output
    assert r2.exit_code == 0, r2.output
    assert json.loads(r1.stdout)["jobs"] == 1
    assert json.loads(r2.stdout)["jobs"] == 2  # the second run really used two processes
    for name in FILES:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    rows = _rows(a)
    plan_ids = sorted(i for ids in batch["plans"].values() for i in ids)
    assert sorted(int(r["plan_id"]) for r in rows) == plan_ids
    assert [r["patient"] for r in rows] == sorted(r["patient"] for r in rows)
    doc = json.loads((a / "metrics.json").read_text(encoding="utf-8"))
    assert doc["schema"] == "fieldbank.report"
    assert "generated" not in doc["inputs"]
    assert len(doc["cases"]) == len(plan_ids)
    html = (a / "report.html").read_text(encoding="utf-8")
    n_fig = html.count('<svg xmlns="http://www.w3.org/2000/svg"')
    # botulinum: stretches, moving field, grades, probes, time course (the static field
    # unchanged: a sentence); lengthening: stretches, moving and static field, stiffness,
    # grades, probes; a plan checked against later maps: the check; a batch: the cohort
    # figure and, with checked plans, the cohort's check
    n_bot = sum("botulinum" in r["kinds"] for r in rows)
    n_checked = sum(bool(r["validation_sessions"]) for r in rows)
    assert n_checked >= 1
    # probing motions the plan does not change are a sentence, not two identical curves:
    # only where both probes' peaks are equal before and after
    quiet = [r for r in rows if r["pull_peak_before_n"] == r["pull_peak_after_n"]
             and r["semi_ellipse_peak_before_n"] == r["semi_ellipse_peak_after_n"]]
    n_quiet = html.count("these motions do not engage what the plan changes")
    assert n_quiet <= len(quiet)
    assert n_fig == 5 * n_bot + 6 * (len(rows) - n_bot) + n_checked + 2 - n_quiet
    assert html.count('<figure data-figure="validation">') == n_checked
    assert html.count('<figure data-figure="cohort-validation">') == 1
    # the unchanged static field of each botulinum case, and the unchanged probes, in words
    assert html.count('class="nochange"') == n_bot + n_quiet
    # self-contained: no address but the SVG namespace
    assert "https://" not in html
    assert html.replace("http://www.w3.org/2000/svg", "").count("http://") == 0


def test_metrics_match_the_intervention(batch: dict[str, Any], tmp_path: Path) -> None:
    assert run_cli("report", "--db", batch["url"], "--out", str(tmp_path)).exit_code == 0
    for r in _rows(tmp_path):
        if r["kinds"] == "botulinum":
            # botulinum acts on reflexes: the static field and potential do not change
            assert abs(float(r["static_diff_rms_n"])) < 1e-9
            assert abs(float(r["potential_rms_change_j"])) < 1e-9
            assert float(r["moving_diff_rms_n"]) > 0
        else:
            assert r["kinds"] == "lengthening"
            assert float(r["static_diff_rms_n"]) > 1e-3
            assert float(r["potential_rms_change_j"]) > 0
    doc = json.loads((tmp_path / "metrics.json").read_text(encoding="utf-8"))
    for case in doc["cases"]:
        assert (case["timecourse"] is not None) == ("botulinum" in case["kinds"])
        assert case["sessions"] == [{"label": "pre-BoNT", "date": "2024-01-10"}]


@pytest.mark.parametrize(("args", "expect"), [
    (("--kind", "lengthening"), {"lengthening"}),
    (("--kind", "botulinum", "--patient", "SYN-002"), {"botulinum"}),
    (("--session", "pre-BoNT", "--until", "2024-01-31"), {"botulinum", "lengthening"}),
])
def test_selection_filters(batch: dict[str, Any], tmp_path: Path, args: tuple[str, ...],
                           expect: set[str]) -> None:
    res = run_cli("report", "--db", batch["url"], "--out", str(tmp_path), "--jobs", "1", *args)
    assert res.exit_code == 0, res.output
    rows = _rows(tmp_path)
    assert rows and {r["kinds"] for r in rows} == expect
    if "--patient" in args:
        assert {r["patient"] for r in rows} == {"SYN-002"}


def test_one_plan(batch: dict[str, Any], tmp_path: Path) -> None:
    plan_id = batch["plans"]["SYN-002"][1]
    res = run_cli("report", "--db", batch["url"], "--out", str(tmp_path), "--plan", str(plan_id))
    assert res.exit_code == 0, res.output
    assert [int(r["plan_id"]) for r in _rows(tmp_path)] == [plan_id]
    assert f"plan {plan_id}" in (tmp_path / "report.html").read_text(encoding="utf-8")


def test_the_date_of_writing_is_left_out_only_when_asked(batch: dict[str, Any],
                                                         tmp_path: Path) -> None:
    plan = str(batch["plans"]["SYN-001"][0])
    res = run_cli("report", "--db", batch["url"], "--out", str(tmp_path / "a"), "--plan", plan)
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "a" / "metrics.json").read_text(encoding="utf-8"))
    assert doc["inputs"]["generated"][:4].isdigit()
    assert "<th>written</th>" in (tmp_path / "a" / "report.html").read_text(encoding="utf-8")
    res = run_cli("report", "--db", batch["url"], "--out", str(tmp_path / "b"), "--plan", plan,
                  "--no-date")
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "b" / "metrics.json").read_text(encoding="utf-8"))
    assert "generated" not in doc["inputs"]
    assert "written" not in (tmp_path / "b" / "report.html").read_text(encoding="utf-8")


@pytest.mark.parametrize(("args", "message"), [
    (("--session", "post-BoNT"), "No stored plan matches the selection (sessions post-BoNT)"),
    (("--since", "2025-01-01"), "No stored plan matches the selection (since 2025-01-01)"),
    (("--patient", "NOBODY"), "NOBODY"),
    (("--plan", "999"), "No plan with id 999"),
])
def test_empty_selection_is_a_clear_error(batch: dict[str, Any], tmp_path: Path,
                                          args: tuple[str, ...], message: str) -> None:
    out = tmp_path / "out"
    res = run_cli("report", "--db", batch["url"], "--out", str(out), *args)
    assert res.exit_code == 1
    assert message in res.stderr
    assert not out.exists()  # nothing written


def test_bad_kind_and_dates_are_usage_errors(batch: dict[str, Any], tmp_path: Path) -> None:
    res = run_cli("report", "--db", batch["url"], "--out", str(tmp_path), "--kind", "surgery")
    assert res.exit_code == 2 and "'surgery' is not an intervention kind" in res.stderr
    res = run_cli("report", "--db", batch["url"], "--out", str(tmp_path), "--since",
                  "2024-03-01", "--until", "2024-01-01")
    assert res.exit_code == 2 and "--since is after --until" in res.stderr


def test_missing_data_names_what_is_missing(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'empty.sqlite3'}"
    out = tmp_path / "out"
    res = run_cli("report", "--db", url, "--out", str(out))
    assert res.exit_code == 1 and "No database at" in res.stderr  # never created by surprise
    assert not (tmp_path / "empty.sqlite3").exists()
    assert run_cli("db", "upgrade", "--db", url).exit_code == 0
    res = run_cli("report", "--db", url, "--out", str(out))
    assert res.exit_code == 1
    assert "No stored plans in" in res.stderr and "--save" in res.stderr
    assert run_cli("patient", "add", "P-1", "--db", url, "--mass-kg", "70", "--height-m",
                   "1.7", "--side", "left").exit_code == 0
    res = run_cli("report", "--db", url, "--out", str(out), "--patient", "P-1")
    assert res.exit_code == 1
    assert "Patient 'P-1' has no fitted model and no stored plans" in res.stderr
    assert "fieldbank fit P-1" in res.stderr
    assert not out.exists()


def test_a_full_disk_leaves_nothing_behind_and_the_rerun_is_not_refused(
        batch: dict[str, Any], tmp_path: Path) -> None:
    """The report's process may not write files beyond a size limit (RLIMIT_FSIZE: each
    write past it fails with EFBIG, as on a full disk) - large enough for metrics.csv, too
    small for metrics.json and report.html."""
    import os
    import resource
    import signal
    import subprocess
    import sys

    first = tmp_path / "first"  # also keeps the intervals, so the limited run writes no data
    assert run_cli("report", "--db", batch["url"], "--out", str(first), "--jobs", "1",
                   "--no-date").exit_code == 0
    sizes = {f: (first / f).stat().st_size for f in FILES}
    # SQLite's shared-memory index of the database needs 32 KiB of file
    limit = max(sizes["metrics.csv"] + 1, 64 << 10)
    assert limit < sizes["report.html"] and limit < sizes["metrics.json"]

    def limited() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a failed write, not a killed process
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    out = tmp_path / "reports" / "all"
    cmd = [sys.executable, "-m", "fieldbank.cli", "report", "--db", batch["url"], "--out",
           str(out), "--jobs", "1", "--no-date"]
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, preexec_fn=limited,
                       timeout=600)
    assert r.returncode == 1, r.stderr
    assert "No space left to write" in r.stderr and "Traceback" not in r.stderr
    assert not out.exists()
    assert list(out.parent.iterdir()) == []  # no temporary directory left either
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600)
    assert r.returncode == 0, r.stderr
    for f in FILES:
        assert (out / f).read_bytes() == (first / f).read_bytes(), f
