"""``db check`` finds damaged references and checksums, and reports orphans as harmless."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from fieldbank.maps import postural_map
from fieldbank.model import Arm
from fieldbank.storage import Database, IncomingFile
from fieldbank.storage.orm import MapRow, SourceFileRow


@pytest.fixture
def db(tmp_path: Path):
    d = Database.open(f"sqlite:///{tmp_path / 'c.sqlite3'}", store_root=tmp_path / "arrays")
    p = d.add_patient("CH-1", 75, 1.75, "right")
    m = postural_map(Arm.from_params(p.arm_params()), [[0.05, 0.4], [0.1, 0.35]])
    data = m.to_csv().encode()
    d.ingest_files("CH-1", "s", [IncomingFile("a.csv", hashlib.sha256(data).hexdigest(), "csv",
                                              data, (m,))])
    yield d
    d.close()


def _tamper(db: Database, stmt) -> None:
    # Damage the database behind the API, as a faulty disk or a manual edit would.
    with db.engine.begin() as c:
        c.execute(stmt)


def test_clean_database_checks_ok(db: Database) -> None:
    r = db.check()
    assert r.ok and r.orphans == () and r.counts["maps"] == 1


def test_check_reads_only_the_engine_and_the_arrays(db: Database) -> None:
    from fieldbank.storage.check import check

    class Bare:  # not a Database: check needs nothing else
        engine = db.engine
        arrays = db.arrays

    assert check(Bare()) == db.check()


def test_changed_source_bytes_are_detected(db: Database) -> None:
    from sqlalchemy import update

    _tamper(db, update(SourceFileRow).values(content=b"changed"))
    r = db.check()
    assert not r.ok and any("does not match its SHA-256" in p for p in r.problems)


def test_truncated_map_blob_is_detected(db: Database) -> None:
    from sqlalchemy import update

    _tamper(db, update(MapRow).values(values=b"\0" * 8))
    r = db.check()
    assert any("values holds 8 bytes" in p for p in r.problems)


def test_missing_trace_array_and_orphans(db: Database, tmp_path: Path) -> None:
    m = db.add_model(db.get_patient("CH-1").arm_params(), "synthetic", "m")
    hs = db.start_haptic_session(m.id, "loop://")
    t = db.add_trace(hs.id, "force", np.ones((100, 2)), "N")
    orphan = db.store.put(np.arange(5.0), "m")
    r = db.check()
    assert r.ok and len(r.orphans) == 1 and orphan.sha256[:2] in r.orphans[0]
    db.store.path(t.array.sha256).unlink()
    r = db.check()
    assert not r.ok and any("missing from the store" in p for p in r.problems)


def test_cli_check_exit_code(db: Database, monkeypatch: pytest.MonkeyPatch) -> None:
    from click.testing import CliRunner
    from sqlalchemy import update

    from fieldbank.cli.main import cli

    url = db.engine.url.render_as_string(hide_password=False)
    monkeypatch.setenv("FIELDBANK_ARRAYS", str(db.store.root))
    ok = CliRunner().invoke(cli, ["db", "check", "--db", url, "--json"])
    assert ok.exit_code == 0
    assert json.loads(ok.stdout)["ok"] is True  # stdout is pure JSON
    _tamper(db, update(SourceFileRow).values(content=b"x"))
    bad = CliRunner().invoke(cli, ["db", "check", "--db", url])
    assert bad.exit_code == 1 and "problem:" in bad.output


def test_map_patient_must_match_session_patient(db: Database) -> None:
    from sqlalchemy import update

    other = db.add_patient("CH-2", 70, 1.7, "left")
    _tamper(db, update(MapRow).values(patient_id=other.id))
    r = db.check()
    assert any("differs from its session's patient" in p for p in r.problems)
