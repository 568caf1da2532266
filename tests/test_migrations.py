"""Migrations: empty to head, no drift from the models, downgrade/upgrade, concurrency."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from sqlalchemy import inspect

from fieldbank.storage import Database, make_engine, migrate
from fieldbank.storage.orm import Base
from fieldbank.stored import revisions

ROOT = Path(__file__).resolve().parents[1]


def _tables(url: str) -> set[str]:
    e = make_engine(url)
    try:
        return set(inspect(e).get_table_names()) - {"alembic_version"}
    finally:
        e.dispose()


def test_empty_to_head_without_drift(any_db_url: str) -> None:
    engine = make_engine(any_db_url)
    try:
        assert migrate.current_revision(engine) is None
        before, after = migrate.upgrade(engine)
        assert before is None and after == migrate.head_revision()
        assert _tables(any_db_url) == set(Base.metadata.tables)
        migrate.check_drift(engine)  # alembic check: models == migrations
        # upgrading again is a no-op
        assert migrate.upgrade(engine) == (after, after)
    finally:
        engine.dispose()


def test_drift_is_detected(any_db_url: str) -> None:
    from sqlalchemy import Column, Integer, Table

    engine = make_engine(any_db_url)
    extra = Table("not_migrated", Base.metadata, Column("id", Integer, primary_key=True))
    try:
        migrate.upgrade(engine)
        with pytest.raises(Exception, match="differ"):
            migrate.check_drift(engine)
    finally:
        Base.metadata.remove(extra)
        engine.dispose()


def test_downgrade_upgrade_cycle(any_db_url: str, tmp_path: Path) -> None:
    db = Database.open(any_db_url, upgrade="always", store_root=tmp_path / "a")
    db.add_patient("CYC-1", 70, 1.7, "right")
    db.raw_sql("SELECT 1")
    _, after = migrate.downgrade(db.engine, "base")
    assert after is None and _tables(any_db_url) == set()
    migrate.upgrade(db.engine)
    assert _tables(any_db_url) == set(Base.metadata.tables)
    migrate.check_drift(db.engine)
    # the schema works again, triggers included
    db.add_patient("CYC-1", 70, 1.7, "right")
    with pytest.raises(Exception, match="append-only"):
        db.raw_sql("DELETE FROM audit_log")
    db.close()


def test_embedded_default_is_created_at_head_on_first_use(tmp_path: Path) -> None:
    db = Database.open()  # FIELDBANK_HOME points into tmp_path (conftest)
    try:
        assert db.engine.url.database == str(
            Path(os.environ["FIELDBANK_HOME"]) / "fieldbank.sqlite3")
        assert migrate.current_revision(db.engine) == migrate.head_revision()
    finally:
        db.close()


def test_concurrent_first_use_of_embedded_database(tmp_path: Path) -> None:
    env = {**os.environ, "FIELDBANK_HOME": str(tmp_path / "shared-home"),
           "PYTHONPATH": str(ROOT)}
    procs = [subprocess.Popen([sys.executable, "-m", "fieldbank.cli", "db", "upgrade"],
                              env=env, cwd=ROOT, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE) for _ in range(4)]
    results = [p.communicate(timeout=120) for p in procs]
    for p, (_out, err) in zip(procs, results, strict=True):
        assert p.returncode == 0, err.decode()
    e = make_engine(f"sqlite:///{tmp_path / 'shared-home' / 'fieldbank.sqlite3'}")
    assert migrate.current_revision(e) == migrate.head_revision()
    e.dispose()


@pytest.mark.postgres
def test_concurrent_upgrades_on_postgresql(pg_url: str) -> None:
    errors: list[BaseException] = []
    results: list[tuple[str | None, str | None]] = []

    def run() -> None:
        engine = make_engine(pg_url)
        try:
            results.append(migrate.upgrade(engine))
        except BaseException as exc:
            errors.append(exc)
        finally:
            engine.dispose()

    threads = [threading.Thread(target=run) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    assert not errors
    head = migrate.head_revision()
    assert sorted(results, key=str) == sorted([(None, head)] + [(head, head)] * 3, key=str)


def _cli(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "fieldbank.cli", *args], cwd=ROOT, text=True,
                          capture_output=True, timeout=120,
                          env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})})


def test_cli_db_commands_on_sqlite(sqlite_url: str) -> None:
    r = _cli("db", "current", "--db", sqlite_url, "--json")
    assert r.returncode == 1 and "No database at" in r.stderr  # not created by a look
    r = _cli("db", "upgrade", "--db", sqlite_url)
    assert r.returncode == 0, r.stderr
    r = _cli("db", "current", "--db", sqlite_url, "--json")
    assert '"up_to_date": true' in r.stdout
    r = _cli("db", "check", "--db", sqlite_url)
    assert r.returncode == 0 and "OK" in r.stderr


@pytest.mark.postgres
def test_cli_never_prints_password(pg_url: str) -> None:
    from sqlalchemy.engine import make_url

    secret = "s3cr3t-Pa55"
    url = make_url(pg_url).set(password=secret).render_as_string(hide_password=False)
    for args in (("db", "upgrade"), ("db", "current", "--json"), ("db", "check", "--json"),
                 ("patient", "list")):
        r = _cli(*args, "--db", url)
        assert r.returncode == 0, r.stderr
        assert secret not in r.stdout + r.stderr
    assert "***" in _cli("db", "current", "--db", url).stdout
    # unreachable server: the error names the URL without its password
    bad = make_url(url).set(port=1).render_as_string(hide_password=False)
    r = _cli("patient", "list", "--db", bad, env={"FIELDBANK_DB": bad})
    assert r.returncode != 0
    assert secret not in r.stdout + r.stderr


def test_the_light_reading_of_the_revisions_is_alembic_s() -> None:
    """Opening a database reads the revisions without alembic (start-up time); what it reads
    must be what alembic itself reads: the same chain, head and titles."""
    from alembic.script import ScriptDirectory

    script = ScriptDirectory.from_config(migrate.alembic_config())
    walked = [r.revision for r in reversed(list(script.walk_revisions()))]
    assert revisions.known_revisions() == walked
    assert migrate.head_revision() == script.get_current_head()
    for rev in walked:
        doc = (script.get_revision(rev).doc or "").strip()
        assert revisions.revision_title(rev) == (doc.splitlines()[0].rstrip(".") if doc else rev)


def test_a_downgrade_that_rebuilds_a_table_keeps_the_rows_that_point_at_it(
        tmp_path: Path) -> None:
    """Dropping a column rebuilds ``haptic_sessions`` on SQLite; the traces that point at it
    used to make the downgrade fail ('FOREIGN KEY constraint failed')."""
    import numpy as np

    from fieldbank.params import ArmParams
    from fieldbank.storage import Database

    url = f"sqlite:///{tmp_path / 'fb.sqlite3'}"
    with Database.open(url, store_root=tmp_path / "arrays") as db:
        m = db.add_model(ArmParams.from_anthropometry(), "synthetic", "m")
        hs = db.start_haptic_session(m.id, "sim://")
        db.add_trace(hs.id, "t", np.zeros((10, 3)), "mixed", {})
        engine = db.engine
        head = migrate.head_revision()
        assert migrate.downgrade(engine, "0002", tmp_path / "arrays") == (head, "0002")
        with engine.connect() as conn:
            assert conn.exec_driver_sql("PRAGMA foreign_key_check").all() == []
            assert conn.exec_driver_sql("SELECT count(*) FROM traces").scalar() == 1
            assert conn.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1  # on again
        assert migrate.upgrade(engine, store_root=tmp_path / "arrays") == ("0002", head)
        assert db.check().ok
