"""URL resolution, SQLite durability settings, password masking."""

from __future__ import annotations

from pathlib import Path

import pytest
from sqlalchemy import text

from fieldbank.config import DEFAULT_DB_FILE
from fieldbank.redact import mask_url
from fieldbank.storage import Database, make_engine, resolve_url


def test_url_resolution_order(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("FIELDBANK_HOME", str(tmp_path / "h"))
    assert resolve_url().database == str(tmp_path / "h" / DEFAULT_DB_FILE)
    monkeypatch.setenv("FIELDBANK_DB", "sqlite:///env.sqlite3")
    assert resolve_url().database == "env.sqlite3"
    assert resolve_url("sqlite:///explicit.sqlite3").database == "explicit.sqlite3"


def test_default_home_is_platform_dir(monkeypatch: pytest.MonkeyPatch) -> None:
    import platformdirs

    monkeypatch.delenv("FIELDBANK_HOME")
    assert resolve_url().database == str(
        Path(platformdirs.user_data_dir("fieldbank", appauthor=False)) / DEFAULT_DB_FILE)


def test_sqlite_pragmas(sqlite_url: str) -> None:
    e = make_engine(sqlite_url)
    with e.connect() as c:
        assert c.execute(text("PRAGMA journal_mode")).scalar() == "wal"
        assert c.execute(text("PRAGMA synchronous")).scalar() == 2  # FULL
        assert c.execute(text("PRAGMA foreign_keys")).scalar() == 1
        assert c.execute(text("PRAGMA busy_timeout")).scalar() >= 10_000
    e.dispose()


def test_password_is_masked() -> None:
    url = "postgresql+psycopg://alice:Sup3r-Secret@db.example:5432/fieldbank"
    masked = mask_url(url)
    assert "Sup3r-Secret" not in masked and "alice" in masked and "***" in masked
    assert "Sup3r-Secret" not in mask_url(resolve_url(url))


def test_bad_url_message_has_no_password() -> None:
    from fieldbank.errors import StorageError

    with pytest.raises(StorageError) as info:
        Database.open("notaurl://x:Secret9@")
    assert "Secret9" not in str(info.value)


def test_server_database_must_be_upgraded_first(monkeypatch: pytest.MonkeyPatch) -> None:
    # A database that is not SQLite is never migrated implicitly; unreachable -> clear error.
    from fieldbank.errors import StorageError

    with pytest.raises(StorageError) as info:
        Database.open("postgresql+psycopg://u:Pw12345@127.0.0.1:1/none")
    assert "Pw12345" not in str(info.value) and "***" in str(info.value)
