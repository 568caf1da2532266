"""Batch work on a real Dask ``LocalCluster`` (two worker processes) against the real
PostgreSQL server: a cohort refit in which a worker is killed mid-task loses nothing and
duplicates nothing; a report computed on the cluster is the same bytes as from one process;
plans checked on the cluster give the same checks."""

from __future__ import annotations

import filecmp
import logging
import os
import signal
import threading
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from fieldbank.fitting.batch import fit_all
from fieldbank.storage import Database
from tests.cohort_helpers import store_sessions

pytestmark = [pytest.mark.postgres, pytest.mark.slow]


@pytest.fixture(scope="module")
def cluster() -> Iterator[Any]:
    from distributed import LocalCluster

    # FIELDBANK_DB empty: the workers use the database URL each task brings
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address="127.0.0.1:0", silence_logs=logging.ERROR,
                      env={"FIELDBANK_DB": ""}) as c:
        yield c


def _kill_a_worker_mid_task(db: Database, cluster: Any, deadline: float) -> tuple[str, str]:
    """Wait for a fit job running its first attempt, kill its worker's process (SIGKILL: no
    goodbye to the scheduler); returns (job key, killed worker address)."""
    while time.monotonic() < deadline:
        runs = db.list_runs(kind="fit")
        if runs:
            for j in db.list_jobs(runs[0].id, ["running"]):
                if j.attempts != 1 or not j.worker:
                    continue
                address = j.worker.split()[0]
                for nanny in cluster.workers.values():
                    if nanny.worker_address == address:
                        os.kill(nanny.process.process.pid, signal.SIGKILL)
                        return j.key, address
        time.sleep(0.01)
    raise AssertionError("no fit job was seen running")


def test_cohort_refit_with_a_worker_killed_mid_task_loses_and_duplicates_nothing(
        cluster: Any, pg_url: str) -> None:
    with Database.open(pg_url, upgrade="always") as db:
        pairs = store_sessions(db, 3)
    out: dict[str, Any] = {}

    def refit() -> None:
        with Database.open(pg_url) as own:
            out["result"] = fit_all(own, {"seed": 0, "replicates": 4},
                                    scheduler=cluster.scheduler_address)

    worker = threading.Thread(target=refit)
    worker.start()
    with Database.open(pg_url) as db:
        key, killed = _kill_a_worker_mid_task(db, cluster, time.monotonic() + 120)
        worker.join(timeout=240)
        assert not worker.is_alive()
        res = out["result"]
        assert res.failed == ()
        # every session fitted exactly once, and no model without its fit
        counts: dict[tuple[str, str | None], int] = {}
        for f in db.list_fits():
            counts[(f.patient_code, f.session_label)] = counts.get(
                (f.patient_code, f.session_label), 0) + 1
        assert counts == dict.fromkeys(pairs, 1)
        assert len(db.list_models(origin="fitted")) == len(pairs)
        run = db.get_run(res.run.id)
        assert run.left == 0 and run.counts["done"] + run.counts["skipped"] == len(pairs)
        # the killed task ran again, on the other worker, and ended done
        (job,) = [j for j in db.list_jobs(run.id) if j.key == key]
        assert job.attempts >= 2 and job.state in ("done", "skipped")
        assert job.worker is not None and not job.worker.startswith(killed + " ")
    # the dashboard groups the tasks under their kind
    assert "fieldbank-fit" in cluster.scheduler.task_prefixes


def test_report_from_the_cluster_is_the_same_bytes_as_from_one_process(
        cluster: Any, pg_url: str, tmp_path: Path) -> None:
    from fieldbank.cli.demo import populate
    from fieldbank.interventions.report import Selection, build_report
    from fieldbank.interventions.validate import validate_plans
    from fieldbank.interventions.validate_batch import validate_on_cluster

    with Database.open(pg_url, upgrade="always") as db:
        populate(db, tmp_path / "samples", patients=("SYN-001", "SYN-003"))
        one = build_report(db, Selection(), tmp_path / "one", jobs=1)
        said: list[str] = []
        many = build_report(db, Selection(), tmp_path / "cluster",
                            scheduler=cluster.scheduler_address, say=said.append)
        assert many.jobs_used == 0 and one.n_cases == many.n_cases == 4
        for f in ("report.html", "metrics.csv", "metrics.json"):
            assert filecmp.cmp(one.out_dir / f, many.out_dir / f, shallow=False), f
        run = db.list_runs(kind="report")[0]
        assert run.counts["done"] == 4 and run.left == 0
        assert db.job_payloads(run.id) == {}  # read back, then cleared
        # the same checks against later maps (SYN-003's prediction failed)
        remote, lost = validate_on_cluster(db, cluster.scheduler_address)
        local = validate_plans(db)
        assert lost == () and remote.verdict == local.verdict == "prediction failed"
        assert remote.to_dict() == local.to_dict()
    assert "dashboard: http://127.0.0.1:" in said[0]
    with urllib.request.urlopen(cluster.dashboard_link, timeout=30) as page:
        assert page.status == 200
