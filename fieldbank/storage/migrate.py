"""Schema migrations, driven by alembic from code.

The alembic configuration is built here with ``script_location`` pointing at the installed
``fieldbank.migrations`` package (the repository's ``migrations/`` folder), so ``fieldbank db
upgrade`` works from any directory.

Concurrent upgrades are serialised: the upgrade runs inside one transaction that first takes a
lock — ``pg_advisory_xact_lock`` on PostgreSQL, ``BEGIN IMMEDIATE`` (the write lock) on
SQLite — then reads the current revision and migrates only if it is still behind. Two
processes opening a fresh embedded database at once therefore both succeed; one creates the
schema, the other waits and finds it at head. DDL is transactional on both backends, so a
failed upgrade leaves the previous revision in place.

A database whose revision this program does not know was made by a newer fieldbank: every
entry point refuses it with :func:`newer_message` ("created by a newer fieldbank (revision …)")
and changes nothing, instead of calling it behind or letting alembic fail.

Start-up: opening a database that is at head needs no alembic. The revisions this program knows
are read from the revision files' ``revision`` / ``down_revision`` lines
(:mod:`fieldbank.stored.revisions`, checked against alembic's own reading by
tests/test_migrations.py) and the database's revision with one query; alembic itself is
imported only to migrate or to compare the schema, and its INFO lines are kept off the
terminal.
"""

from __future__ import annotations

import io
import logging
from collections.abc import Iterator
from contextlib import contextmanager
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

from sqlalchemy import Connection, Engine, inspect, text
from sqlalchemy import exc as sa_exc

from fieldbank.errors import StorageError
from fieldbank.redact import mask_url
from fieldbank.storage.config import db_failure
from fieldbank.stored.revisions import head_revision, known_revisions, schema_state

if TYPE_CHECKING:  # alembic is heavy: imported where a migration runs (module docstring)
    from alembic.config import Config

#: Arbitrary constant key of the PostgreSQL advisory lock held while migrating.
PG_LOCK_KEY = 0x6669656C64  # "field"


def alembic_config(connection: Connection | None = None,
                   store_root: Path | None = None) -> Config:
    """An alembic Config for the packaged migrations, optionally bound to a connection and
    told the database's array store directory (revision 0002 moves arrays)."""
    from alembic.config import Config

    # alembic announces every step at INFO; a command's output and errors must not carry it
    logging.getLogger("alembic").setLevel(logging.WARNING)
    cfg = Config(stdout=io.StringIO())  # alembic's chatter must not reach our stdout (--json)
    # The migrations ship as the package fieldbank.migrations (the repository's migrations/).
    cfg.set_main_option("script_location", str(resources.files("fieldbank.migrations")))
    if connection is not None:
        cfg.attributes["connection"] = connection
    if store_root is not None:
        cfg.attributes["store_root"] = store_root
    return cfg


@contextmanager
def _errors(engine: Engine, doing: str) -> Iterator[None]:
    """Database failures as StorageError naming the URL without its password."""
    try:
        yield
    except sa_exc.DBAPIError as exc:
        raise StorageError(db_failure(doing, engine.url, exc)) from None


def current_revision(engine: Engine) -> str | None:
    """The database's schema revision (None: not created yet), read with one query."""
    with _errors(engine, "Reading the schema revision of"), engine.connect() as conn:
        return _current(conn)


def _current(conn: Connection) -> str | None:
    if not inspect(conn).has_table("alembic_version"):
        return None
    rows = [r[0] for r in conn.execute(text("SELECT version_num FROM alembic_version"))]
    if len(rows) > 1:
        raise StorageError(f"The database {mask_url(conn.engine.url)} has several schema "
                           f"revisions ({', '.join(sorted(rows))}); fieldbank keeps one.")
    return rows[0] if rows else None


def newer_message(engine: Engine, current: str) -> str:
    """The refusal for a database made by a newer fieldbank."""
    return (f"The database {mask_url(engine.url)} was created by a newer fieldbank (schema "
            f"revision {current}; this fieldbank knows revisions up to {head_revision()}). "
            "Use that newer fieldbank (or a later one) with it; nothing was changed.")


def refuse_newer(engine: Engine, current: str | None) -> None:
    """Raise StorageError when ``current`` is a revision this program does not know."""
    if current is not None and schema_state(current) == "newer":
        raise StorageError(newer_message(engine, current))


def _locked(engine: Engine) -> Connection:
    conn = engine.connect()
    if engine.dialect.name == "sqlite":
        conn = conn.execution_options(fieldbank_begin="IMMEDIATE")
    if engine.dialect.name == "sqlite":
        # batch mode rebuilds a table (copy, drop, rename): dropping it must not trip the
        # foreign keys of the rows that point at it. SQLite's procedure for altering a table:
        # foreign keys off (only possible outside a transaction, so on the driver's connection
        # before BEGIN), then a foreign_key_check before commit (:func:`_check_keys`); they
        # are switched on again when the migration ends (:func:`_migrate`)
        _sqlite_foreign_keys(conn, on=False)
    conn.begin()
    if engine.dialect.name == "postgresql":
        conn.execute(text("SELECT pg_advisory_xact_lock(:k)"), {"k": PG_LOCK_KEY})
    return conn


def upgrade(engine: Engine, revision: str = "head",
            store_root: Path | None = None) -> tuple[str | None, str | None]:
    """Migrate to ``revision`` under the lock; returns (revision before, revision after)."""
    with _errors(engine, "Upgrading"):
        return _migrate(engine, revision, down=False, store_root=store_root)


def downgrade(engine: Engine, revision: str,
              store_root: Path | None = None) -> tuple[str | None, str | None]:
    """Migrate down to ``revision`` ('base' empties the database) under the lock.

    This is the bare step; ``fieldbank db downgrade`` asks for ``--yes`` and makes a backup
    first (:mod:`fieldbank.storage.backup`).
    """
    with _errors(engine, "Downgrading"):
        return _migrate(engine, revision, down=True, store_root=store_root)


def check_target(revision: str) -> None:
    """Refuse a target revision this program does not know, with the known ones."""
    known = known_revisions()
    if revision not in ("head", "base", *known):
        raise StorageError(f"Unknown schema revision {revision!r}; known: base, "
                           f"{', '.join(known)} (head).")


def _migrate(engine: Engine, revision: str, down: bool,
             store_root: Path | None) -> tuple[str | None, str | None]:
    """One migration step in one locked transaction; an upgrade already at the target is a
    no-op (concurrent first uses each find the head the first one reached)."""
    from alembic import command

    check_target(revision)
    conn = _locked(engine)
    try:
        before = _current(conn)
        refuse_newer(engine, before)
        if down:
            command.downgrade(alembic_config(conn, store_root), revision)
        elif before != (head_revision() if revision == "head" else revision):
            command.upgrade(alembic_config(conn, store_root), revision)
        after = _current(conn)
        _check_keys(conn)
        conn.commit()
    except Exception:
        conn.rollback()
        raise
    finally:
        if engine.dialect.name == "sqlite":
            _sqlite_foreign_keys(conn, on=True)
        conn.close()
    return before, after


def _sqlite_foreign_keys(conn: Connection, on: bool) -> None:
    """Switch SQLite's foreign keys on the driver's connection (outside any transaction)."""
    raw = conn.connection.driver_connection
    assert raw is not None  # an open connection
    raw.execute(f"PRAGMA foreign_keys = {'ON' if on else 'OFF'}")


def _check_keys(conn: Connection) -> None:
    """Refuse to commit a SQLite migration that left a row pointing at nothing."""
    if conn.engine.dialect.name != "sqlite":
        return
    bad = conn.execute(text("PRAGMA foreign_key_check")).all()
    if bad:
        tables = sorted({str(r[0]) for r in bad})
        raise StorageError(f"The migration would leave {len(bad)} row(s) of "
                           f"{', '.join(tables)} pointing at nothing; nothing was changed.")


def check_drift(engine: Engine) -> None:
    """Raise StorageError when the ORM models differ from the migrated schema (alembic check)."""
    from alembic import command
    from alembic.util.exc import AutogenerateDiffsDetected

    with engine.connect() as conn:
        try:
            command.check(alembic_config(conn))
        except AutogenerateDiffsDetected as exc:
            raise StorageError(f"The models and the migrations differ: {exc}") from None


def ensure_head(engine: Engine, store_root: Path | None = None) -> None:
    """Bring a database to head if it is behind (first use of the embedded default); refuse
    one made by a newer fieldbank."""
    current = current_revision(engine)
    refuse_newer(engine, current)
    if current != head_revision():
        upgrade(engine, store_root=store_root)
