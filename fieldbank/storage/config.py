"""Where the database lives and how an engine is made.

URL resolution, first match wins (the setting ``db`` of :mod:`fieldbank.config`):

1. an explicit URL (the CLI's ``--db``);
2. the environment variable ``FIELDBANK_DB``;
3. ``db`` in the configuration file ``fieldbank.toml``;
4. the embedded default: a SQLite file ``fieldbank.sqlite3`` in the data directory, which is
   ``FIELDBANK_HOME`` when set, else the file's ``home``, else the platform's user data
   directory (platformdirs). :func:`fieldbank.stored.location.url_source` says which, for
   messages.

SQLite connections are opened with WAL journaling, ``synchronous=FULL`` (a committed ingest
survives power loss), foreign keys on and a busy timeout so that several processes can write
one file in turn. The driver's own transaction handling is switched off so that fieldbank emits
``BEGIN`` itself: write transactions use ``BEGIN IMMEDIATE`` (execution option
``fieldbank_begin``), which takes the write lock up front and waits for it instead of failing
when two processes upgrade a read lock at once.

A SQLite file that cannot be written (a read-only file or file system, e.g. a database on a
write-protected medium) is opened read-only: ``mode=ro``, or ``immutable=1`` when there is no
write-ahead log next to it (SQLite could not create its shared-memory file). Reading works;
writing is refused with a clear message, and fieldbank never tries to migrate it.

A password in a URL is never printed or logged: every message shows :func:`mask_url`'s text
(:mod:`fieldbank.redact`), and driver errors go through :func:`db_failure`.
"""

from __future__ import annotations

import sqlite3
import warnings
import weakref
from collections.abc import Callable
from pathlib import Path
from urllib.parse import quote

from sqlalchemy import Connection, Engine, create_engine, event
from sqlalchemy.engine import URL, make_url
from sqlalchemy.exc import ArgumentError, SAWarning
from sqlalchemy.pool import ConnectionPoolEntry

from fieldbank.config import DEFAULT_DB_FILE, setting
from fieldbank.errors import StorageError
from fieldbank.home import data_home
from fieldbank.redact import blank_password, mask_url, quote_password, redact
from fieldbank.stored.location import SQLITE_BUSY_TIMEOUT_MS, sqlite_read_only

ENV_DB = "FIELDBANK_DB"
ENV_ARRAYS = "FIELDBANK_ARRAYS"


def resolve_url(explicit: str | None = None) -> URL:
    """The database URL: ``explicit`` > ``FIELDBANK_DB`` > the configuration file > SQLite
    file in :func:`data_home`."""
    text = setting("db", explicit or None).value
    if not text:
        home = data_home()
        return URL.create("sqlite", database=str(home / DEFAULT_DB_FILE))
    problem = _query_problem(text)
    if problem is None:
        try:
            url = make_url(quote_password(text))
        except (ArgumentError, ValueError) as exc:
            # SQLAlchemy raises ValueError for a port that is not a number or a broken
            # [IPv6] host; its message may quote the URL, so only the kind of fault is kept
            problem = ("its host or port cannot be read (a port must be a number, an IPv6 "
                       "host is written [::1])" if isinstance(exc, ValueError) else None)
        else:
            if url.port is not None and not 0 < url.port < 65536:
                problem = f"port {url.port} is not a TCP port (1-65535)"
            else:
                return url
    raise StorageError(
        f"Not a database URL{': ' + problem if problem else ''} (expected e.g. "
        "sqlite:///path/file.sqlite3 or postgresql+psycopg://user@host:5432/db; write '&', "
        "'@', '/' and '#' inside a password or a query value as %26, %40, %2F and %23)."
    ) from None


def _query_problem(text: str) -> str | None:
    """What is wrong with a URL's query part, or None: an item without '=' (an unencoded '&'
    inside a value, or a stray one) would be dropped without a word by the URL parser.
    The item itself is not quoted: it may be the tail of a password."""
    text = blank_password(text)
    if "?" not in text:
        return None
    items = text.split("?", 1)[1].split("#", 1)[0].split("&")
    for k, item in enumerate(items, start=1):
        if "=" not in item:
            return (f"item {k} of its query part has no NAME=VALUE form (an unencoded '&' "
                    "inside a value?)")
    return None


def default_store_root(url: URL) -> Path:
    """The array store directory of a database: ``FIELDBANK_ARRAYS``, else next to a SQLite
    file, else ``arrays/`` in the data directory (a server database keeps its arrays inside
    itself; there the directory only holds arrays written before revision 0002)."""
    configured: Path | None = setting("arrays").value
    if configured is not None:
        return configured
    if is_sqlite(url) and url.database not in (None, "", ":memory:"):
        return Path(str(url.database) + ".arrays")
    return data_home() / "arrays"


def db_failure(doing: str, url: URL, exc: Exception, verb: str = "failed") -> str:
    """``"<doing> <URL without secrets> failed: <driver message without secrets>"``."""
    orig = getattr(exc, "orig", None) or exc
    tail = f" {verb}" if verb else ""
    return f"{doing} {mask_url(url)}{tail}: {redact(str(orig), url)}"


def is_sqlite(url: URL) -> bool:
    return url.get_backend_name() == "sqlite"


def sqlite_path(url: URL) -> Path | None:
    """The file of a SQLite URL, or None for an in-memory database."""
    if not is_sqlite(url) or url.database in (None, "", ":memory:"):
        return None
    return Path(url.database)


#: Engines that make_engine opened read-only.
_READ_ONLY: weakref.WeakSet[Engine] = weakref.WeakSet()


def is_read_only(engine: Engine) -> bool:
    """Whether ``engine`` is a SQLite database opened read-only (see the module docstring)."""
    return engine in _READ_ONLY


def _read_only_creator(path: Path) -> Callable[[], sqlite3.Connection]:
    wal = Path(f"{path}-wal")
    shm = Path(f"{path}-shm")
    # Without a write-ahead log there is nothing SQLite must merge, and it cannot create the
    # shared-memory file beside a read-only database: 'immutable' reads the file as it is.
    flag = "mode=ro" if wal.exists() and shm.exists() else "immutable=1"
    uri = f"file:{quote(str(path))}?{flag}"

    def connect() -> sqlite3.Connection:
        return sqlite3.connect(uri, uri=True, check_same_thread=False)

    return connect


def _sqlite_connect_read_only(dbapi_connection: sqlite3.Connection,
                              _record: ConnectionPoolEntry) -> None:
    dbapi_connection.isolation_level = None
    cur = dbapi_connection.cursor()
    cur.execute(f"PRAGMA busy_timeout = {SQLITE_BUSY_TIMEOUT_MS}")
    cur.execute("PRAGMA query_only = ON")
    cur.close()


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
    read_only = False
    if is_sqlite(u):
        path = sqlite_path(u)
        if path is not None:
            read_only = sqlite_read_only(path)
            if not read_only:
                try:
                    path.parent.mkdir(parents=True, exist_ok=True)
                except OSError as exc:
                    raise StorageError(
                        f"Cannot create the data directory {path.parent} ({exc.strerror})."
                    ) from None
    try:
        with warnings.catch_warnings():
            # pysqlite ignores query arguments such as ?password= (a SQLite file has none) and
            # says so on stderr; nothing is connected with them, so the note is only noise
            warnings.filterwarnings("ignore", message="Query string argument",
                                    category=SAWarning)
            if read_only:
                assert path is not None
                engine = create_engine(u, creator=_read_only_creator(path))
            else:
                engine = create_engine(u)
    except (ArgumentError, ImportError) as exc:
        raise StorageError(f"Cannot open database {mask_url(u)}: "
                           f"{redact(str(exc), u)}") from None
    if read_only:
        _READ_ONLY.add(engine)
    if is_sqlite(u):
        event.listen(engine, "connect",
                     _sqlite_connect_read_only if read_only else _sqlite_connect)
        event.listen(engine, "begin", _sqlite_begin)
    return engine
