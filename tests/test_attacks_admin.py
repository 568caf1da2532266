"""Attacks on administration: a full disk, a read-only database, a database from a newer
release, destructive downgrades, orphaned store files, and a server database seen from two
workstations.

A full disk and a read-only file system are real: a small tmpfs, mounted (and remounted
read-only) inside a private mount namespace (``unshare``), so nothing outside the test sees it.
"""

from __future__ import annotations

import json
import os
import shutil
import sqlite3
import subprocess
import sys
import threading
from datetime import datetime
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import text

from fieldbank.errors import StorageError
from fieldbank.ingest import ingest_paths, read_file
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.storage import Database, IncomingFile, migrate
from fieldbank.storage.mapstore import INLINE_MAX_BYTES

ROOT = Path(__file__).resolve().parents[1]
HEAD = "# kind: postural\n# frame: shoulder\n# sign: arm-on-handle\n# source: lab {n}\n"
ARM = Arm.from_params(ArmParams.from_anthropometry(75, 1.75, "right"))


def _large_csv(path: Path, n: int = 0, size: int = INLINE_MAX_BYTES + 4096) -> Path:
    """A valid map file larger than INLINE_MAX_BYTES (so it goes to the array store)."""
    body = "x_m,y_m,fx_n,fy_n\n0.05,0.40,1.5,-0.5\n0.10,0.35,0.5,0.2\n"
    pad = "# padding\n" * (size // 10)
    path.write_text(HEAD.format(n=n) + pad + body)
    return path


def _cli(*args: str, home: Path | None = None, env: dict[str, str] | None = None,
         timeout: float = 120) -> subprocess.CompletedProcess[str]:
    e = {**os.environ, "PYTHONPATH": str(ROOT), **(env or {})}
    if home is not None:
        e["FIELDBANK_HOME"] = str(home)
    return subprocess.run([sys.executable, "-m", "fieldbank.cli", *args], cwd=ROOT, env=e,
                          text=True, capture_output=True, timeout=timeout)


def _private_mount(script: str, timeout: float = 180) -> subprocess.CompletedProcess[str]:
    """Run a shell script in a private mount namespace (root: ``unshare -m``; otherwise a user
    namespace, ``unshare -rm``)."""
    unshare = shutil.which("unshare")
    assert unshare is not None, "util-linux's unshare is needed for the mount tests"
    flags = ["-m", "--propagation", "private"] if os.geteuid() == 0 else ["-rm"]
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PY": sys.executable}
    return subprocess.run([unshare, *flags, "sh", "-c", script], cwd=ROOT, env=env, text=True,
                          capture_output=True, timeout=timeout)


# --- a full disk --------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("where,size", [("array store", "3m"), ("database file", "400k")])
def test_full_disk_is_a_clean_error_and_nothing_is_half_written(where: str, size: str,
                                                                  tmp_path: Path) -> None:
    big = _large_csv(tmp_path / "big.csv", size=4 << 20) if where == "array store" else (
        _large_csv(tmp_path / "mid.csv", size=900_000))
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    r = _private_mount(f"""
        mount -t tmpfs -o size={size} tmpfs {mnt} || exit 99
        export FIELDBANK_HOME={mnt}
        "$PY" -m fieldbank.cli patient add F-1 --mass-kg 75 --height-m 1.75 --side right || exit 98
        "$PY" -m fieldbank.cli ingest {big} --patient F-1 --session s
        echo "ingest-rc=$?"
        "$PY" -m fieldbank.cli db check --json > {tmp_path}/check.json
        echo "check-rc=$?"
        "$PY" -m fieldbank.cli maps list --json > {tmp_path}/maps.json
        ls -R {mnt} > {tmp_path}/files.txt
    """)
    assert "ingest-rc=1" in r.stdout, r.stdout + r.stderr
    assert "Traceback" not in r.stderr and "Segmentation" not in r.stderr
    assert ("No space left" in r.stderr if where == "array store"
            else "database or disk is full" in r.stderr), r.stderr
    assert "check-rc=0" in r.stdout, r.stdout + r.stderr
    check = json.loads((tmp_path / "check.json").read_text())
    assert check["ok"] and check["orphans"] == [] and check["counts"]["maps"] == 0
    assert json.loads((tmp_path / "maps.json").read_text()) == []
    assert ".tmp" not in (tmp_path / "files.txt").read_text()


# --- a read-only database -----------------------------------------------------------------
@pytest.mark.slow
def test_read_only_database_can_be_read_and_refuses_writes(tmp_path: Path,
                                                           sample_dir: Path) -> None:
    home = tmp_path / "src"
    db = Database.open(f"sqlite:///{home / 'fieldbank.sqlite3'}")
    db.add_patient("SYN-001", 72, 1.74, "right")
    ingest_paths(db, sorted((sample_dir / "SYN-001" / "pre-BoNT").iterdir()), "SYN-001", "pre")
    ingest_paths(db, [_large_csv(tmp_path / "big.csv")], "SYN-001", "big")
    db.close()
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    out = tmp_path / "out"
    out.mkdir()
    r = _private_mount(f"""
        mount -t tmpfs -o size=50m tmpfs {mnt} || exit 99
        cp -a {home}/. {mnt}/
        mount -o remount,ro {mnt} || exit 97
        export FIELDBANK_HOME={mnt}
        "$PY" -m fieldbank.cli maps list --json > {out}/maps.json; echo "maps-rc=$?"
        "$PY" -m fieldbank.cli db check --json > {out}/check.json; echo "check-rc=$?"
        "$PY" -m fieldbank.cli export --patient SYN-001 -o {out}/all.h5; echo "export-rc=$?"
        "$PY" -m fieldbank.cli patient add R-2 --mass-kg 70 --height-m 1.7 --side right
        echo "add-rc=$?"
        "$PY" -m fieldbank.cli db gc; echo "gc-rc=$?"
    """)
    for step in ("maps", "check", "export"):
        assert f"{step}-rc=0" in r.stdout, r.stdout + r.stderr
    assert "add-rc=1" in r.stdout and "gc-rc=1" in r.stdout
    assert "is read-only" in r.stderr and "Traceback" not in r.stderr
    assert len(json.loads((out / "maps.json").read_text())) == 4
    assert json.loads((out / "check.json").read_text())["ok"]
    inc, problems = read_file("all.h5", (out / "all.h5").read_bytes(), None)
    assert problems == [] and len(inc.maps) == 4


# --- a database from a newer release ------------------------------------------------------
def test_database_from_a_newer_release_is_refused_everywhere(tmp_path: Path) -> None:
    home = tmp_path / "home"
    assert _cli("patient", "add", "N-1", "--mass-kg", "70", "--height-m", "1.7", "--side",
                "right", home=home).returncode == 0
    path = home / "fieldbank.sqlite3"
    c = sqlite3.connect(path)
    c.execute("UPDATE alembic_version SET version_num = '0099'")
    c.commit()
    c.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    c.close()
    before = path.read_bytes()
    for args in (("patient", "list"), ("maps", "list"), ("db", "current"), ("db", "check"),
                 ("db", "upgrade"), ("db", "downgrade", "0001", "--yes"), ("db", "gc"),
                 ("ingest", str(tmp_path / "x.csv"), "--patient", "N-1", "--session", "s")):
        r = _cli(*args, home=home)
        assert r.returncode == 1, (args, r.stdout, r.stderr)
        assert "created by a newer fieldbank" in r.stdout + r.stderr, (args, r.stderr)
        assert "revision 0099" in r.stdout + r.stderr and "Traceback" not in r.stderr, args
    assert path.read_bytes() == before


# --- destructive downgrades ---------------------------------------------------------------
def test_downgrade_needs_yes_and_keeps_a_backup_on_sqlite(tmp_path: Path) -> None:
    home = tmp_path / "home"
    assert _cli("patient", "add", "D-1", "--mass-kg", "70", "--height-m", "1.7", "--side",
                "right", home=home).returncode == 0
    r = _cli("db", "downgrade", "base", home=home)
    assert r.returncode == 1 and "every table and all its data, the audit log included" \
        in r.stderr and "--yes" in r.stderr
    assert _cli("patient", "list", home=home).stdout.startswith("D-1")
    r = _cli("db", "downgrade", "base", "--yes", "--backup-dir", str(tmp_path / "bk"),
             home=home)
    assert r.returncode == 0, r.stderr
    backups = list((tmp_path / "bk").iterdir())
    assert len(backups) == 1 and "backup: " + str(backups[0]) in r.stderr
    with sqlite3.connect(backups[0]) as c:
        assert c.execute("SELECT code FROM patients").fetchall() == [("D-1",)]
        assert c.execute("SELECT count(*) FROM audit_log").fetchone()[0] >= 1
    with sqlite3.connect(home / "fieldbank.sqlite3") as c:
        tables = {n for (n,) in c.execute("SELECT name FROM sqlite_master WHERE type='table'")}
    assert "patients" not in tables and "audit_log" not in tables
    # the backup is the database: put it back and it opens at its revision
    shutil.copy(backups[0], home / "fieldbank.sqlite3")
    assert _cli("patient", "list", home=home).stdout.startswith("D-1")


@pytest.mark.postgres
def test_downgrade_on_postgresql_backs_up_with_pg_dump_or_refuses(pg_url: str,
                                                                  tmp_path: Path) -> None:
    db = Database.open(pg_url, upgrade="always", store_root=tmp_path / "arrays")
    db.add_patient("D-2", 70, 1.7, "left")
    db.close()
    bk = tmp_path / "bk"
    # no pg_dump on the PATH: refused, with what to do, nothing changed
    r = _cli("db", "downgrade", "0001", "--yes", "--db", pg_url, "--backup-dir", str(bk),
             env={"PATH": str(tmp_path / "empty")})
    assert r.returncode == 1 and "pg_dump was not found" in r.stderr and "--no-backup" in \
        r.stderr
    head = migrate.head_revision()
    assert _cli("db", "current", "--db", pg_url, "--json").stdout.count(f'"{head}"') == 2
    if shutil.which("pg_dump") is None:
        pytest.fail("pg_dump is needed for this test (Debian's postgresql-client)")
    r = _cli("db", "downgrade", "0001", "--yes", "--db", pg_url, "--backup-dir", str(bk))
    assert r.returncode == 0, r.stderr
    dumps = list(bk.iterdir())
    assert len(dumps) == 1 and dumps[0].stat().st_size > 0
    listing = subprocess.run(["pg_restore", "--list", str(dumps[0])], capture_output=True,
                             text=True, timeout=60)
    assert listing.returncode == 0 and "audit_log" in listing.stdout
    assert json.loads(_cli("db", "current", "--db", pg_url, "--json").stdout)["current"] == \
        "0001"


# --- orphans: db gc, and never what a writer is about to use -------------------------------
def _incoming(path: Path) -> IncomingFile:
    inc, problems = read_file(path.name, path.read_bytes(), ARM)
    assert inc is not None, problems
    return inc


def test_gc_removes_orphans(tmp_path: Path) -> None:
    db = Database.open(f"sqlite:///{tmp_path / 'g.sqlite3'}", store_root=tmp_path / "arrays")
    db.add_patient("G-1", 75, 1.75, "right")
    kept = db.ingest_files("G-1", "s", [_incoming(_large_csv(tmp_path / "a.csv", 1))])
    orphan = db.store.put(np.arange(5.0), "m")  # a writer that died before its transaction
    stray = db.store.path(orphan.sha256).parent / ".deadbeef.0.tmp"
    stray.write_bytes(b"partial")  # a writer killed mid-write
    with db._write() as s:  # an array recorded that nothing uses
        db.arrays.record(s, db.arrays.prepare(np.arange(3.0), "m"), datetime(2024, 1, 1))
    before = db.check()
    assert before.ok and len(before.orphans) == 3
    report = db.gc()  # the unused row goes, then its file and the orphan, then the stray
    assert len(report.rows) == 1 and len(report.files) == 2 and len(report.temporaries) == 1
    after = db.check()
    assert after.ok and after.orphans == ()
    assert db.source_bytes(kept[0].sha256) == (tmp_path / "a.csv").read_bytes()
    assert [e.action for e in db.audit_entries(2)] == ["gc", "gc"]
    db.close()


def test_gc_never_removes_what_a_writer_is_about_to_reference(tmp_path: Path) -> None:
    import fcntl

    db = Database.open(f"sqlite:///{tmp_path / 'w.sqlite3'}", store_root=tmp_path / "arrays")
    db.add_patient("G-2", 75, 1.75, "right")
    inc = _incoming(_large_csv(tmp_path / "b.csv", 2))
    # a writer has written its store file and not yet begun its transaction ...
    pending = db.arrays.prepare(np.frombuffer(inc.content, np.uint8), "bytes")
    assert db.store.has(pending.ref.sha256)
    # ... and another is still writing a temporary file (it holds the lock)
    live = db.store.root / "ab" / ".abcdef.live.tmp"
    live.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(live, os.O_CREAT | os.O_RDWR)
    fcntl.flock(fd, fcntl.LOCK_EX)
    report = db.gc()  # the unreferenced file goes: nothing refers to it yet
    assert not db.store.has(pending.ref.sha256) and len(report.files) == 1
    assert live.exists() and any("a writer is using it" in x for x in report.in_use)
    os.close(fd)
    # the writer's transaction finds its file gone and writes it again before committing
    with db._write() as s:
        db.arrays.record(s, pending, datetime(2024, 1, 1))
    assert db.store.has(pending.ref.sha256) and db.check().problems == ()
    db.close()


@pytest.mark.slow
def test_gc_while_ingests_run_loses_nothing(any_db_url: str, tmp_path: Path) -> None:
    db = Database.open(any_db_url, upgrade="always", store_root=tmp_path / "arrays")
    db.add_patient("G-3", 75, 1.75, "right")
    files = [_large_csv(tmp_path / f"c{i}.csv", i, size=INLINE_MAX_BYTES + 1000 * i)
             for i in range(12)]
    errors: list[BaseException] = []
    done = threading.Event()

    def writer() -> None:
        mine = Database.open(any_db_url, store_root=tmp_path / "arrays")
        try:
            for i, f in enumerate(files):
                mine.ingest_files("G-3", f"s{i}", [_incoming(f)])
        except BaseException as exc:
            errors.append(exc)
        finally:
            mine.close()
            done.set()

    def collector() -> None:
        mine = Database.open(any_db_url, store_root=tmp_path / "arrays")
        try:
            while not done.is_set():
                mine.gc()
        except BaseException as exc:
            errors.append(exc)
        finally:
            mine.close()

    threads = [threading.Thread(target=writer), threading.Thread(target=collector)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(300)
    assert not errors, errors
    report = db.check()
    assert report.ok and report.orphans == (), (report.problems, report.orphans)
    for f in files:
        sha = _incoming(f).sha256
        assert db.source_bytes(sha) == f.read_bytes()
    db.close()


# --- a server database from two workstations ----------------------------------------------
@pytest.mark.postgres
def test_server_database_is_the_same_from_every_workstation(pg_url: str,
                                                            tmp_path: Path) -> None:
    a = Database.open(pg_url, upgrade="always", store_root=tmp_path / "ws-a" / "arrays")
    a.add_patient("W-1", 75, 1.75, "right")
    big = _large_csv(tmp_path / "big.csv", 7)
    rep = ingest_paths(a, [big], "W-1", "s")
    m = a.add_model(ArmParams.from_anthropometry(), "synthetic", "m")
    hs = a.start_haptic_session(m.id, "sim://")
    trace = a.add_trace(hs.id, "force", np.ones((5000, 2)), "N")
    assert not (tmp_path / "ws-a" / "arrays").exists()  # nothing in a workstation directory
    b = Database.open(pg_url, store_root=tmp_path / "ws-b" / "arrays")  # another workstation
    assert b.source_bytes(rep.outcomes[0].sha256) == big.read_bytes()
    np.testing.assert_array_equal(b.get_trace_array(trace.id), np.ones((5000, 2)))
    report = b.check()
    assert report.ok and report.orphans == (), (report.problems, report.orphans)
    r = _cli("db", "check", "--db", pg_url, "--json",
             env={"FIELDBANK_ARRAYS": str(tmp_path / "ws-c")})
    assert r.returncode == 0 and json.loads(r.stdout)["ok"], r.stdout + r.stderr
    a.close()
    b.close()


def _at_0001_with_a_file_array(url: str, root: Path) -> tuple[str, bytes]:
    """A database at revision 0001 holding one large source file in ``root`` (as 0001 did)."""
    from fieldbank.arraystore import ArrayStore

    engine = Database.open(url, upgrade="never").engine
    migrate.upgrade(engine, "0001")
    data = _large_csv(root.parent / "legacy.csv", 9).read_bytes()
    import hashlib

    sha = hashlib.sha256(data).hexdigest()
    ref = ArrayStore(root).put(np.frombuffer(data, np.uint8), "bytes")
    with engine.begin() as c:
        c.execute(text("INSERT INTO arrays (sha256, relpath, nbytes, shape_json, dtype, unit, "
                       "created_at) VALUES (:k, :p, :n, :s, '|u1', 'bytes', '2024-01-01')"),
                  {"k": ref.sha256, "p": ref.relpath, "n": ref.nbytes,
                   "s": json.dumps(list(ref.shape))})
        c.execute(text("INSERT INTO source_files (sha256, file_name, file_format, nbytes, "
                       "array_sha256, ingested_at, ingested_by) VALUES (:s, 'legacy.csv', "
                       "'csv', :n, :k, '2024-01-01', 'test')"),
                  {"s": sha, "n": len(data), "k": ref.sha256})
    engine.dispose()
    return sha, data


def test_revision_0002_keeps_existing_arrays_on_sqlite(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'm.sqlite3'}"
    root = tmp_path / "m.sqlite3.arrays"
    sha, data = _at_0001_with_a_file_array(url, root)
    db = Database.open(url)  # a SQLite file is brought to head on first use
    assert migrate.current_revision(db.engine) == migrate.head_revision()
    assert db.source_bytes(sha) == data and db.check().ok
    db.close()


@pytest.mark.postgres
def test_revision_0002_moves_arrays_into_a_server_database_and_back(pg_url: str,
                                                                    tmp_path: Path) -> None:
    ws_a = tmp_path / "ws-a"
    sha, data = _at_0001_with_a_file_array(pg_url, ws_a)
    engine = Database.open(pg_url, upgrade="never").engine
    migrate.upgrade(engine, store_root=ws_a)  # the upgrade runs on the workstation with it
    engine.dispose()
    b = Database.open(pg_url, store_root=tmp_path / "ws-b")  # another workstation reads it
    assert b.source_bytes(sha) == data
    assert b.check().ok
    with b.engine.connect() as c:
        assert c.execute(text("SELECT location FROM arrays")).scalar() == "database"
    # downgrade: the arrays are written out to this workstation's store, nothing is lost
    ws_c = tmp_path / "ws-c"
    migrate.downgrade(b.engine, "0001", store_root=ws_c)
    b.close()
    from fieldbank.arraystore import ArrayStore

    with Database.open(pg_url, upgrade="never").engine.connect() as c:
        key = c.execute(text("SELECT array_sha256 FROM source_files")).scalar()
    assert ArrayStore(ws_c).get(str(key)).tobytes() == data


def test_an_unreachable_workstation_file_is_named_not_a_traceback(tmp_path: Path) -> None:
    # on SQLite the store is the database's own: a missing file is damage, said plainly
    db = Database.open(f"sqlite:///{tmp_path / 'u.sqlite3'}", store_root=tmp_path / "arrays")
    db.add_patient("U-1", 75, 1.75, "right")
    out = db.ingest_files("U-1", "s", [_incoming(_large_csv(tmp_path / "u.csv"))])
    for p in db.store.keys():
        db.store.path(p).unlink()
    with pytest.raises(StorageError, match="missing from the store"):
        db.source_bytes(out[0].sha256)
    assert any("missing from the store" in p for p in db.check().problems)
    db.close()
