"""Where the database lives and how an engine is made.

URL resolution, first match wins:

1. an explicit URL (the CLI's ``--db``);
2. the environment variable ``FIELDBANK_DB``;
3. the embedded default: a SQLite file ``fieldbank.sqlite3`` in the data directory, which is
   ``FIELDBANK_HOME`` when set, else the platform's user data directory (platformdirs).

SQLite connections are opened with WAL journaling, ``synchronous=FULL`` (a committed ingest
survives power loss), foreign keys on and a busy timeout so that several processes can write
one file in turn. The driver's own transaction handling is switched off so that fieldbank emits
``BEGIN`` itself: write transactions use ``BEGIN IMMEDIATE`` (execution option
``fieldbank_begin``), which takes the write lock up front and waits for it instead of failing
when two processes upgrade a read lock at once.

A password in a URL is never printed or logged: use :func:`mask_url` for every message.
"""

from __future__ import annotations

import os
import sqlite3
from pathlib import Path

from sqlalchemy import Connection, Engine, create_engine, event
from sqlalchemy.engine import URL, make_url
from sqlalchemy.exc import ArgumentError
from sqlalchemy.pool import ConnectionPoolEntry

from fieldbank.errors import StorageError
from fieldbank.home import data_home

ENV_DB = "FIELDBANK_DB"
DEFAULT_DB_FILE = "fieldbank.sqlite3"
#: How long a SQLite connection waits for another writer before giving up, ms.
SQLITE_BUSY_TIMEOUT_MS = 60_000


def resolve_url(explicit: str | None = None) -> URL:
    """The database URL: ``explicit`` > ``FIELDBANK_DB`` > SQLite file in :func:`data_home`."""
    text = explicit or os.environ.get(ENV_DB)
    if not text:
        home = data_home()
        return URL.create("sqlite", database=str(home / DEFAULT_DB_FILE))
    try:
        return make_url(text)
    except ArgumentError:
        raise StorageError(
            "Not a database URL (expected e.g. sqlite:///path/file.sqlite3 or "
            "postgresql+psycopg://user@host/db)."
        ) from None


def mask_url(url: URL | str) -> str:
    """The URL as text with any password replaced by ``***``."""
    if isinstance(url, str):
        try:
            url = make_url(url)
        except ArgumentError:
            return "<unparseable URL>"
    return url.render_as_string(hide_password=True)


def is_sqlite(url: URL) -> bool:
    return url.get_backend_name() == "sqlite"


def sqlite_path(url: URL) -> Path | None:
    """The file of a SQLite URL, or None for an in-memory database."""
    if not is_sqlite(url) or url.database in (None, "", ":memory:"):
        return None
    return Path(url.database)


def _sqlite_connect(dbapi_connection: sqlite3.Connection, _record: ConnectionPoolEntry) -> None:
    # fieldbank issues BEGIN itself (see _sqlite_begin); the driver must not.
    dbapi_connection.isolation_level = None
    cur = dbapi_connection.cursor()
    cur.execute(f"PRAGMA busy_timeout = {SQLITE_BUSY_TIMEOUT_MS}")
    cur.execute("PRAGMA journal_mode = WAL")
    cur.execute("PRAGMA synchronous = FULL")
    cur.execute("PRAGMA foreign_keys = ON")
    cur.close()


def _sqlite_begin(conn: Connection) -> None:
    mode = conn.get_execution_options().get("fieldbank_begin", "DEFERRED")
    if mode not in ("DEFERRED", "IMMEDIATE", "EXCLUSIVE"):
        raise StorageError(f"Unknown SQLite transaction mode {mode!r}.")
    conn.exec_driver_sql(f"BEGIN {mode}")


def make_engine(url: URL | str | None = None) -> Engine:
    """An engine for ``url`` (resolved with :func:`resolve_url` when None or text)."""
    u = url if isinstance(url, URL) else resolve_url(url)
    if is_sqlite(u):
        path = sqlite_path(u)
        if path is not None:
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise StorageError(
                    f"Cannot create the data directory {path.parent} ({exc.strerror})."
                ) from None
    try:
        engine = create_engine(u)
    except (ArgumentError, ImportError) as exc:
        raise StorageError(f"Cannot open database {mask_url(u)}: {exc}") from None
    if is_sqlite(u):
        event.listen(engine, "connect", _sqlite_connect)
        event.listen(engine, "begin", _sqlite_begin)
    return engine
