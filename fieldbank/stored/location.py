"""Where the database is, read without SQLAlchemy: the URL in force and where it came from, a
SQLite file's path, a PostgreSQL URL's connection arguments, the URL as messages show it, and
the refusal of a SQLite file that does not exist.

:func:`fieldbank.storage.config.resolve_url` is the authority on URLs: it parses any URL with
SQLAlchemy and refuses a broken one in words. :func:`locate` reads the forms the list commands
meet - the embedded database and ``sqlite:///FILE``, and ``postgresql+psycopg://USER@HOST/DB``
- and gives what SQLAlchemy gives for them: the same file, the connection arguments of its
psycopg dialect, the same masked text (``tests/test_listing.py`` holds the two readings
together over many URLs). Any other form, or one with a part it does not read the same way for
certain (an IPv6 or empty host, several hosts, a repeated query item, a fragment, a port out
of range), gives None: the caller goes through SQLAlchemy, which connects or refuses.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import parse_qsl, quote, quote_plus, unquote

from fieldbank.config import DEFAULT_DB_FILE, setting
from fieldbank.home import data_home
from fieldbank.redact import mask_url, quote_password

#: How long a SQLite connection waits for another writer before giving up, ms.
SQLITE_BUSY_TIMEOUT_MS = 60_000

_SQLITE = "sqlite:///"
_PSYCOPG = "postgresql+psycopg://"
#: ``[USER[:PASSWORD]@]HOST[:PORT][/DATABASE][?QUERY]`` after the scheme, the password's own
#: '@' already percent-encoded (:func:`fieldbank.redact.quote_password`, as resolve_url does).
_SERVER = re.compile(r"(?:(?P<user>[^:/@?#\[\]]*)(?::(?P<password>[^@]*))?@)?"
                     r"(?P<host>[A-Za-z0-9._-]+)(?::(?P<port>[0-9]{1,5}))?"
                     r"(?:/(?P<database>[^?]*))?(?:\?(?P<query>.*))?")


@dataclass(frozen=True)
class Location:
    """A database the light listing can reach.

    Attributes
    ----------
    backend : {'sqlite', 'postgresql'}
    masked : str
        The URL as every message shows it (:func:`fieldbank.redact.mask_url` of SQLAlchemy's
        rendering of it).
    text : str
        The URL as given (secrets included): driver errors are redacted against it.
    path : Path or None
        The SQLite file, as given (relative to the working directory when relative).
    connect : mapping
        ``psycopg.connect`` keyword arguments (PostgreSQL).
    """

    backend: str
    masked: str
    text: str
    path: Path | None = None
    connect: Mapping[str, str | int] = field(default_factory=dict)


def locate(explicit: str | None = None) -> Location | None:
    """The database in force (``explicit`` > ``FIELDBANK_DB`` > fieldbank.toml > the embedded
    file), or None when its URL is not one this module reads as SQLAlchemy does."""
    text = setting("db", explicit or None).value
    if not text:
        return _sqlite_file(str(data_home() / DEFAULT_DB_FILE))
    text = str(text)
    if text.startswith(_SQLITE) and "?" not in text:
        database = unquote(quote_password(text)[len(_SQLITE):])
        return None if database in ("", ":memory:") else _sqlite_file(database, text)
    if text.startswith(_PSYCOPG):
        return _server(text)
    return None


def _sqlite_file(database: str, text: str | None = None) -> Location:
    masked = mask_url(_SQLITE + quote(database, safe=" +/"))
    return Location("sqlite", masked, text if text is not None else masked, Path(database))


def _server(text: str) -> Location | None:
    m = _SERVER.fullmatch(quote_password(text)[len(_PSYCOPG):])
    if m is None:
        return None
    user, password, host, port, database, query = m.group(
        "user", "password", "host", "port", "database", "query")
    items: list[tuple[str, str]] = []
    if query is not None:
        if "#" in query or any("=" not in item for item in query.split("&")):
            return None
        items = parse_qsl(query)
        if len({k for k, _ in items}) != len(items):
            return None
    if port is not None and not 0 < int(port) < 65536:
        return None
    user, password, database = (None if v is None else unquote(v)
                                for v in (user, password, database))
    connect: dict[str, str | int] = {"host": host}
    if database:
        connect["dbname"] = database
    if user:
        connect["user"] = user
    if password:
        connect["password"] = password
    if port is not None and int(port):
        connect["port"] = int(port)
    connect.update(items)
    rendered = _PSYCOPG
    if user is not None:
        rendered += quote(user, safe=" +")
        if password is not None:
            rendered += ":" + quote(password, safe=" +")
        rendered += "@"
    rendered += host + (f":{int(port)}" if port is not None else "")
    if database is not None:
        rendered += "/" + quote(database, safe=" +/")
    if items:
        rendered += "?" + "&".join(f"{quote_plus(k)}={quote_plus(v)}" for k, v in sorted(items))
    return Location("postgresql", mask_url(rendered), text, connect=connect)


def url_source(explicit: str | None = None) -> str:
    """Where the URL in force came from, in words for a message: 'flag --db', 'variable
    FIELDBANK_DB', 'file …/fieldbank.toml', or the default database file in the data directory
    and where that directory came from."""
    db = setting("db", explicit or None)
    if db.value:
        return db.source
    home = setting("home")
    if home.source == "default":
        return ("the default database file in the platform's user data directory: neither "
                "FIELDBANK_HOME nor FIELDBANK_DB is set, and no fieldbank.toml names one")
    return f"the default database file in the data directory set by {home.source}"


def missing_message(path: Path, source: str) -> str:
    """Why there is no database at ``path`` and what to do (:class:`DatabaseMissing`)."""
    return (f"No database at {path} ({source}); nothing was created. To start one there: "
            "'fieldbank patient add CODE --mass-kg KG --height-m M --side right|left' or "
            "'fieldbank db upgrade'. If you meant another database, set FIELDBANK_HOME or "
            "FIELDBANK_DB, give --db, or name it in fieldbank.toml ('fieldbank config show' "
            "prints what is in force).")


def sqlite_read_only(path: Path) -> bool:
    """Whether an existing SQLite file cannot be written (file or file system read-only)."""
    if not path.exists():
        return False
    return not (os.access(path, os.W_OK) and os.access(path.parent, os.W_OK))
