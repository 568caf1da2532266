"""Shared test configuration.

PostgreSQL tests (marker ``postgres``) use the server at ``FIELDBANK_TEST_PG_URL``. Without it
they are skipped on a developer machine; with ``FIELDBANK_REQUIRE_PG=1`` (set by scripts/test,
which starts a real server) a missing URL is an error, so CI never skips them silently.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile(
    "fieldbank", deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True
)
settings.load_profile("fieldbank")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if os.environ.get("FIELDBANK_TEST_PG_URL"):
        return
    required = os.environ.get("FIELDBANK_REQUIRE_PG") == "1"
    for item in items:
        if "postgres" in item.keywords:
            if required:
                raise pytest.UsageError(
                    "FIELDBANK_REQUIRE_PG=1 but FIELDBANK_TEST_PG_URL is unset: "
                    "start a server with scripts/pg-test-server."
                )
            item.add_marker(pytest.mark.skip(reason="FIELDBANK_TEST_PG_URL not set"))


@pytest.fixture
def pg_url() -> Iterator[str]:
    """URL of a fresh, empty PostgreSQL database on the test server, dropped afterwards."""
    base = os.environ.get("FIELDBANK_TEST_PG_URL")
    if not base:
        pytest.fail("FIELDBANK_TEST_PG_URL is not set")
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
    from fieldbank.interventions.samples import write_samples

    root = tmp_path_factory.mktemp("samples")
    write_samples(root)
    return root


@pytest.fixture(autouse=True)
def _isolated_home(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """No test reads or writes the user's real data directory or database."""
    monkeypatch.setenv("FIELDBANK_HOME", str(tmp_path / "fieldbank-home"))
    monkeypatch.delenv("FIELDBANK_DB", raising=False)
    monkeypatch.delenv("FIELDBANK_ARRAYS", raising=False)


@pytest.fixture
def clean_work(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """No fieldbank variable (but the test server's and the isolated home), no configuration
    file found; the current directory an empty one of its own, returned."""
    for k in list(os.environ):
        if k.startswith("FIELDBANK_") and k not in ("FIELDBANK_TEST_PG_URL", "FIELDBANK_HOME"):
            monkeypatch.delenv(k)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg-config"))
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    return work
