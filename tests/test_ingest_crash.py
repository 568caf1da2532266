"""A real ``kill -9`` in the middle of a batch (SQLite and PostgreSQL), and two ingest processes
at once on SQLite.

The ingests run in ``tests/slow_ingest.py``, a program that calls the library with a progress
callback which marks each file written inside the open transaction and slows the write phase.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from fieldbank.maps import postural_map
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.storage import Database
from fieldbank.storage.mapstore import INLINE_MAX_BYTES

ROOT = Path(__file__).resolve().parents[1]
SLOW_INGEST = Path(__file__).resolve().with_name("slow_ingest.py")


def _files(d: Path, n: int, seed: int, n_large: int = 0) -> list[Path]:
    arm = Arm.from_params(ArmParams.from_anthropometry(75, 1.75, "right"))
    rng = np.random.default_rng(seed)
    d.mkdir(parents=True, exist_ok=True)
    out = []
    for i in range(n):
        pos = np.array([[0.0, 0.40], [0.08, 0.36], [-0.06, 0.44]]) + rng.uniform(-0.01, 0.01,
                                                                                  (3, 2))
        text = postural_map(arm, pos, source=f"crash test {seed}/{i}").to_csv()
        if i < n_large:  # large files go to the array store before the transaction
            text += "# padding\n" * (INLINE_MAX_BYTES // 10 + 100)
        p = d / f"m{seed}-{i:03d}.csv"
        p.write_text(text)
        out.append(p)
    return out


def _env(url: str, arrays: Path) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT), "FIELDBANK_DB": url,
            "FIELDBANK_ARRAYS": str(arrays)}


def _slow_ingest(url: str, arrays: Path, files: list[Path], patient: str, session: str,
                 sleep_s: float, mark: Path | None = None) -> list[str]:
    """The command line of the slow ingest program (see tests/slow_ingest.py)."""
    return [sys.executable, str(SLOW_INGEST), "--db", url, "--arrays", str(arrays),
            "--patient", patient, "--session", session, "--sleep-s", str(sleep_s),
            *(["--mark", str(mark)] if mark is not None else []), *map(str, files)]


@pytest.mark.slow
def test_kill_9_mid_batch_leaves_database_and_store_consistent(any_db_url: str,
                                                               tmp_path: Path) -> None:
    url = any_db_url
    arrays = tmp_path / "arrays"
    db = Database.open(url, upgrade="always", store_root=arrays)
    db.add_patient("K-1", 75, 1.75, "right")
    files = _files(tmp_path / "in", 30, seed=1, n_large=2)
    mark = tmp_path / "mark.txt"
    proc = subprocess.Popen(
        _slow_ingest(url, arrays, files, "K-1", "s1", sleep_s=0.05, mark=mark),
        cwd=ROOT, env=_env(url, arrays), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if mark.exists() and len(mark.read_text().splitlines()) >= 10:
            break
        assert proc.poll() is None, proc.stderr.read() if proc.stderr else ""
        time.sleep(0.01)
    else:
        proc.kill()
        pytest.fail("ingest never reached the middle of the batch")
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(10)
    assert proc.returncode == -signal.SIGKILL
    written = len(mark.read_text().splitlines())
    assert 10 <= written < len(files)  # killed in the middle of the batch
    # the batch is absent; the check is clean apart from explained orphans: the two large files
    # a SQLite database wrote to its store before the transaction (a server database writes
    # them inside it, so the rollback takes them too)
    db2 = Database.open(url, store_root=arrays)
    assert db2.list_maps() == [] and db2.list_sessions() == []
    report = db2.check()
    assert report.ok, report.problems
    assert len(report.orphans) == (2 if url.startswith("sqlite") else 0)
    assert all("not referenced by the database" in o for o in report.orphans)
    # re-running the batch (with the command line) stores it whole and adopts the orphaned
    # store files
    r = subprocess.run([sys.executable, "-m", "fieldbank.cli", "ingest", *map(str, files),
                        "--patient", "K-1", "--session", "s1"], cwd=ROOT, env=_env(url, arrays),
                       text=True, capture_output=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert len(db2.list_maps()) == len(files)
    final = db2.check()
    assert final.ok and final.orphans == ()
    db2.close()
    db.close()


@pytest.mark.slow
def test_two_ingest_processes_at_once_on_sqlite(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'conc.sqlite3'}"
    arrays = tmp_path / "arrays"
    db = Database.open(url, store_root=arrays)
    db.add_patient("C-1", 75, 1.75, "right")
    db.add_patient("C-2", 75, 1.75, "right")
    batches = [_files(tmp_path / "a", 20, seed=2), _files(tmp_path / "b", 20, seed=3)]
    procs = [
        subprocess.Popen(_slow_ingest(url, arrays, fs, code, "s", sleep_s=0.02),
                         cwd=ROOT, env=_env(url, arrays),
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        for code, fs in (("C-1", batches[0]), ("C-2", batches[1]))
    ]
    for p in procs:
        _, err = p.communicate(timeout=120)
        assert p.returncode == 0, err.decode()
    assert len(db.list_maps("C-1")) == 20 and len(db.list_maps("C-2")) == 20
    assert db.check().ok
    db.close()


@pytest.mark.postgres
def test_concurrent_ingest_of_the_same_files_on_postgresql(pg_url: str, tmp_path: Path) -> None:
    import threading

    from fieldbank.ingest import ingest_paths

    db = Database.open(pg_url, upgrade="always", store_root=tmp_path / "arrays")
    db.add_patient("PG-1", 75, 1.75, "right")
    files = _files(tmp_path / "in", 10, seed=4)
    reports = []
    errors: list[BaseException] = []

    def run() -> None:
        mine = Database.open(pg_url, store_root=tmp_path / "arrays")
        try:
            reports.append(ingest_paths(mine, files, "PG-1", "s"))
        except BaseException as exc:  # reported by the assertion below
            errors.append(exc)
        finally:
            mine.close()

    threads = [threading.Thread(target=run) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    assert not errors
    assert sorted(r.n_stored for r in reports) == [0, 0, 10]
    assert len(db.list_maps("PG-1")) == 10 and db.check().ok
    db.close()
