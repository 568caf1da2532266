"""``fieldbank fit --all`` and ``fieldbank jobs`` on the local engine (this process and a
process pool), on SQLite and PostgreSQL: every session fitted once, a refit found not repeated,
a failure named by patient and session with the rest done, fits keyed so that racing writers
store one."""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any

from click.testing import CliRunner, Result

from fieldbank.cli.main import cli
from fieldbank.engine import Task
from fieldbank.fitting.batch import fit_session
from fieldbank.storage import Database
from tests.cohort_helpers import store_sessions

#: Fast fits: the batch machinery is under test, not the fitter.
FAST = ["--max-evals", "60", "--replicates", "4"]
FAST_OPTIONS: dict[str, Any] = {"seed": 0, "max_evals": 60, "replicates": 4}


def _run(*args: str) -> Result:
    return CliRunner().invoke(cli, list(args), catch_exceptions=False)


def _fit_counts(db: Database) -> dict[tuple[str, str | None], int]:
    out: dict[tuple[str, str | None], int] = {}
    for f in db.list_fits():
        out[(f.patient_code, f.session_label)] = out.get((f.patient_code, f.session_label),
                                                         0) + 1
    return out


def test_fit_all_fits_each_session_once_and_finds_them_again(any_db_url: str) -> None:
    with Database.open(any_db_url, upgrade="always") as db:
        pairs = store_sessions(db, 2)
    res = _run("fit", "--all", "--jobs", "2", "--db", any_db_url, "--json", *FAST)
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["counts"]["done"] == len(pairs) and doc["left"] == 0
    assert [(t["patient"], t["session"]) for t in doc["tasks"]] == pairs
    assert all(0 < t["result"]["fit_cpu_s"] <= t["result"]["fit_s"] + 1e-3 for t in doc["tasks"])
    with Database.open(any_db_url) as db:
        assert _fit_counts(db) == dict.fromkeys(pairs, 1)
        fits = db.list_fits()
        assert all(f.model_version == 1 and f.fit_key for f in fits)
        assert len({f.fit_key for f in fits}) == len(pairs)
    # the same maps, options and model version: found, nothing repeated or stored
    res = _run("fit", "--all", "--db", any_db_url, *FAST)
    assert res.exit_code == 0, res.output
    assert "0 fitted, 4 found fitted already, 0 failed" in res.stderr
    # other options are another fit: only the named patient's sessions, fitted again
    res = _run("fit", "--all", "--patient", pairs[0][0], "--seed", "1", "--db", any_db_url,
               *FAST)
    assert res.exit_code == 0 and "2 fitted, 0 found" in res.stderr
    with Database.open(any_db_url) as db:
        counts = _fit_counts(db)
        assert counts[pairs[0]] == 2 and counts[pairs[2]] == 1
    res = _run("jobs", "--db", any_db_url, "--json")
    runs = json.loads(res.stdout)
    assert [r["counts"]["done"] for r in runs] == [2, 0, 4]
    assert [r["counts"]["skipped"] for r in runs] == [0, 4, 0]
    res = _run("jobs", str(runs[-1]["id"]), "--db", any_db_url)
    assert res.exit_code == 0 and f"{pairs[0][0]}/{pairs[0][1]}" in res.stdout
    assert "4 done, 0 skipped, 0 failed, 0 left" in res.stdout


def test_a_failing_session_is_named_and_the_rest_are_done(sqlite_url: str) -> None:
    with Database.open(sqlite_url) as db:
        store_sessions(db, 1)
        # maps measured on a tall arm, filed under a short patient: out of reach
        store_sessions(db, 1, sessions=("pre",), prefix="TALL")
        db.add_patient("SHORT-1", 40.0, 1.2, "right")
        maps = db.get_maps([m.id for m in db.list_maps("TALL-0000")])
        from tests.cohort_helpers import ingest_maps

        ingest_maps(db, "SHORT-1", "visit-1", maps)
    res = _run("fit", "--all", "--db", sqlite_url, *FAST)
    assert res.exit_code == 1
    assert "3 fitted, 0 found fitted already, 1 failed" in res.stderr
    assert "failed: patient SHORT-1, session visit-1:" in res.stderr
    assert "outside what this arm reaches" in res.stderr
    res = _run("jobs", "--db", sqlite_url, "--json")
    run = json.loads(res.stdout)[0]
    assert run["counts"] == {"pending": 0, "running": 0, "done": 3, "skipped": 0, "failed": 1}
    res = _run("jobs", str(run["id"]), "--state", "failed", "--db", sqlite_url, "--json")
    (task,) = json.loads(res.stdout)["tasks"]
    assert task["patient"] == "SHORT-1" and task["session"] == "visit-1"
    assert task["attempts"] == 1 and "SHORT-1" in task["error"]


def test_older_than_refits_fits_of_older_versions_only(sqlite_url: str) -> None:
    with Database.open(sqlite_url) as db:
        pairs = store_sessions(db, 2)
    assert _run("fit", "--all", "--db", sqlite_url, *FAST).exit_code == 0
    res = CliRunner().invoke(cli, ["fit", "--all", "--older-than", "1", "--db", sqlite_url])
    assert res.exit_code == 1 and "nothing to refit" in res.output
    res = CliRunner().invoke(cli, ["fit", "--all", "--older-than", "2", "--db", sqlite_url])
    assert res.exit_code == 1 and "give a version from 1 to 1" in res.output
    with Database.open(sqlite_url) as db:
        # a fit stored before versions and keys were kept
        first = db.list_fits()[0]
        db.raw_sql(f"UPDATE fits SET model_version = NULL, fit_key = NULL WHERE id = {first.id}")
    res = _run("fit", "--all", "--older-than", "1", "--db", sqlite_url, "--json", *FAST)
    assert res.exit_code == 0, res.output
    tasks = json.loads(res.stdout)["tasks"]
    assert [(t["patient"], t["session"], t["state"]) for t in tasks] == [
        (first.patient_code, first.session_label, "done")]
    with Database.open(sqlite_url) as db:
        assert _fit_counts(db)[(first.patient_code, first.session_label)] == 2
        assert sum(_fit_counts(db).values()) == len(pairs) + 1


def test_a_task_run_twice_stores_one_fit(any_db_url: str) -> None:
    """A worker died after committing its fit, before saying so: the task runs again and
    finds the fit instead of storing another."""
    with Database.open(any_db_url, upgrade="always") as db:
        (pair, *_) = store_sessions(db, 1, sessions=("pre",))
        task = Task(f"{pair[0]}/{pair[1]}", pair[0], pair[1])
        first = fit_session(db, task, FAST_OPTIONS)
        again = fit_session(db, task, FAST_OPTIONS)
        assert first.state == "done" and again.state == "skipped"
        assert again.result["fit_id"] == first.result["fit_id"]
        # the fit's own time, kept for the run's figures: one thread's CPU within its wall
        assert 0 < first.result["fit_cpu_s"] <= first.result["fit_s"] + 1e-3
        assert "fit_cpu_s" not in again.result
        assert len(db.list_fits()) == 1
        assert len(db.list_models(origin="fitted")) == 1


def test_racing_writers_with_one_key_store_one_fit(any_db_url: str) -> None:
    with Database.open(any_db_url, upgrade="always") as db:
        store_sessions(db, 1, sessions=("pre",))
        fit = None
        task = Task("x", "COH-0000", "pre")
        fit_session(db, task, FAST_OPTIONS)
        fit = db.list_fits()[0]
        model = db.get_model(fit.model_id)
        db.raw_sql(f"UPDATE fits SET fit_key = NULL WHERE id = {fit.id}")
    results: list[Any] = []
    barrier = threading.Barrier(4)

    def store() -> None:
        with Database.open(any_db_url) as own:
            barrier.wait()
            results.append(own.add_fitted_model_once(
                model.params, "race", fit.patient_code, fit.algorithm, fit.seed, fit.n_evals,
                fit.time_s, fit.cost, fit.result, list(fit.map_ids), fit_key="k" * 64,
                model_version=1, session_label="pre"))

    threads = [threading.Thread(target=store) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(created for _, _, created in results) == [False, False, False, True]
    assert len({f.id for _, f, _ in results}) == 1
    with Database.open(any_db_url) as db:
        assert len([f for f in db.list_fits() if f.fit_key == "k" * 64]) == 1
        # the losers' models rolled back with their fits
        assert len(db.list_models(origin="fitted")) == 2


def test_fit_command_line_refuses_mixed_options(sqlite_url: str, tmp_path: Path) -> None:
    res = CliRunner().invoke(cli, ["fit", "P-1", "--all", "--db", sqlite_url])
    assert res.exit_code == 2 and "it takes no PATIENT" in res.output
    res = CliRunner().invoke(cli, ["fit", "P-1", "--patient", "P-2", "--db", sqlite_url])
    assert res.exit_code == 2 and "go with --all" in res.output
    res = CliRunner().invoke(cli, ["fit", "--db", sqlite_url])
    assert res.exit_code == 2 and "give a PATIENT" in res.output
    res = CliRunner().invoke(cli, ["fit", "--all", "--scheduler", "nowhere", "--db",
                                   sqlite_url])
    assert res.exit_code == 1 and "must be a Dask scheduler address" in res.output
    assert CliRunner().invoke(cli, ["db", "upgrade", "--db", sqlite_url]).exit_code == 0
    res = CliRunner().invoke(cli, ["jobs", "99", "--db", sqlite_url])
    assert res.exit_code == 1 and "No job run with id 99" in res.output
