"""Shared test fixtures.

PostgreSQL: tests marked ``postgres`` use the server at ``FIELDBANK_TEST_PG_URL`` (start one
with ``eval "$(scripts/pg-test-server)"``). Without that URL they are skipped, unless
``FIELDBANK_REQUIRE_PG=1`` (CI), where a missing server is an error.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

PG_ENV = "FIELDBANK_TEST_PG_URL"


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if os.environ.get(PG_ENV):
        return
    if os.environ.get("FIELDBANK_REQUIRE_PG") == "1":
        for item in items:
            if "postgres" in item.keywords:
                item.add_marker(pytest.mark.usefixtures("_require_pg"))
        return
    skip = pytest.mark.skip(reason=f"{PG_ENV} is not set (no PostgreSQL server)")
    for item in items:
        if "postgres" in item.keywords:
            item.add_marker(skip)


@pytest.fixture
def _require_pg() -> None:
    pytest.fail(f"FIELDBANK_REQUIRE_PG=1 but {PG_ENV} is not set: PostgreSQL tests must run.")


@pytest.fixture
def pg_url() -> Iterator[str]:
    """URL of a fresh, empty PostgreSQL database on the test server, dropped afterwards."""
    base = os.environ.get(PG_ENV)
    if not base:
        pytest.fail(f"{PG_ENV} is not set")
    from sqlalchemy import create_engine, text
    from sqlalchemy.engine import make_url

    name = f"fbtest_{uuid.uuid4().hex[:12]}"
    admin = create_engine(base, isolation_level="AUTOCOMMIT")
    with admin.connect() as c:
        c.execute(text(f'CREATE DATABASE "{name}"'))
    try:
        yield make_url(base).set(database=name).render_as_string(hide_password=False)
    finally:
        with admin.connect() as c:
            c.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        admin.dispose()


@pytest.fixture
def sqlite_url(tmp_path: Path) -> str:
    return f"sqlite:///{tmp_path / 'db' / 'fieldbank.sqlite3'}"


@pytest.fixture(params=["sqlite", pytest.param("postgres", marks=pytest.mark.postgres)])
def any_db_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """A fresh database URL on each backend (SQLite file; PostgreSQL when available)."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'db' / 'fieldbank.sqlite3'}"
    return str(request.getfixturevalue("pg_url"))


@pytest.fixture(scope="session")
def sample_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The synthetic sample files, written once per test run."""
    from fieldbank.sampledata import write_samples

    root = tmp_path_factory.mktemp("samples")
    write_samples(root)
    return root


@pytest.fixture(autouse=True)
def _isolated_home(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """No test reads or writes the user's real data directory or database."""
    monkeypatch.setenv("FIELDBANK_HOME", str(tmp_path / "fieldbank-home"))
    monkeypatch.delenv("FIELDBANK_DB", raising=False)
    monkeypatch.delenv("FIELDBANK_ARRAYS", raising=False)
