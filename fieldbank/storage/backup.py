"""A backup of the database before a destructive step (``fieldbank db downgrade``).

:func:`guarded_downgrade` is that command's use case: it says what a downgrade removes and does
nothing unless confirmed (``--yes``); then it backs up, then downgrades.

* **SQLite**: a consistent copy made with SQLite's online backup API (readers and writers may
  keep working), ``<database file>.backup-<revision>-<UTC time>.sqlite3`` beside the file unless
  another directory is given. The array store directory is left as it is: a downgrade never
  deletes its files.
* **PostgreSQL**: ``pg_dump --format=custom`` when it is on the ``PATH``, into
  ``<data directory>/backups/<database>-<revision>-<UTC time>.pgdump`` unless another directory
  is given; restore with ``pg_restore --clean -d DBNAME FILE``. The connection settings go to
  ``pg_dump`` through its environment (``PGPASSWORD`` among them), never on its command line,
  where other users could read them. Without ``pg_dump`` (or if it fails) nothing is done and
  the message says how to make the backup by hand; the caller may then go on only when told
  the user has one (``--no-backup``).
* Any other backend: refused with the same advice.
"""

from __future__ import annotations

import os
import shutil
import sqlite3
import subprocess
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from sqlalchemy import Engine

from fieldbank.errors import StorageError
from fieldbank.home import data_home
from fieldbank.redact import mask_url, redact
from fieldbank.storage import migrate
from fieldbank.storage.config import sqlite_path
from fieldbank.stored.revisions import known_revisions, revision_title

#: Longest time a pg_dump may take, s.
PG_DUMP_TIMEOUT_S = 3600


def _stamp() -> str:
    return datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")


def backup(engine: Engine, revision: str | None, directory: str | Path | None = None) -> Path:
    """Back the database up (see the module docstring); returns the backup file.

    Raises
    ------
    StorageError
        No backup could be made; the message says why and what to do instead.
    """
    rev = revision or "empty"
    name = engine.dialect.name
    if name == "sqlite":
        return _sqlite(engine, rev, directory)
    if name == "postgresql":
        return _postgresql(engine, rev, directory)
    raise StorageError(f"fieldbank cannot back up a {name} database ({mask_url(engine.url)}): "
                       "back it up with the server's own tools, then repeat with --no-backup.")


def _sqlite(engine: Engine, rev: str, directory: str | Path | None) -> Path:
    src = sqlite_path(engine.url)
    if src is None:
        raise StorageError("An in-memory SQLite database has nothing to back up.")
    out_dir = Path(directory) if directory is not None else src.parent
    dest = out_dir / f"{src.name}.backup-{rev}-{_stamp()}.sqlite3"
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        with sqlite3.connect(f"file:{src}?mode=ro", uri=True) as s, sqlite3.connect(dest) as d:
            s.backup(d)
        d.close()
        s.close()
    except (OSError, sqlite3.Error) as exc:
        Path(dest).unlink(missing_ok=True)
        raise StorageError(f"Cannot back up {src} to {dest}: {exc}; nothing was changed.") \
            from None
    return dest


def _postgresql(engine: Engine, rev: str, directory: str | Path | None) -> Path:
    u = engine.url
    advice = (f"back it up yourself (pg_dump --format=custom --file=FILE {u.database or 'DBNAME'}"
              ") and repeat with --no-backup")
    exe = shutil.which("pg_dump")
    if exe is None:
        raise StorageError(f"pg_dump was not found to back up {mask_url(u)}: {advice}; "
                           "nothing was changed.")
    out_dir = Path(directory) if directory is not None else data_home() / "backups"
    dest = out_dir / f"{u.database or 'postgres'}-{rev}-{_stamp()}.pgdump"
    env = {**os.environ}
    settings: tuple[tuple[str, object], ...] = (
        ("PGHOST", u.host), ("PGPORT", u.port), ("PGUSER", u.username),
        ("PGPASSWORD", u.password), ("PGDATABASE", u.database))
    for name, setting in settings:
        if setting is not None:
            env[name] = str(setting)
    query_vars = {"password": "PGPASSWORD", "sslmode": "PGSSLMODE", "host": "PGHOST",
                  "port": "PGPORT", "user": "PGUSER"}
    for key, qvalue in u.query.items():  # e.g. ?password=…, ?sslmode=…
        if key in query_vars:
            env[query_vars[key]] = qvalue if isinstance(qvalue, str) else qvalue[0]
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        r = subprocess.run([exe, "--format=custom", f"--file={dest}", "--no-password"],
                           env=env, capture_output=True, text=True, timeout=PG_DUMP_TIMEOUT_S)
    except (OSError, subprocess.TimeoutExpired) as exc:
        dest.unlink(missing_ok=True)
        raise StorageError(f"pg_dump of {mask_url(u)} failed ({exc}): {advice}; nothing was "
                           "changed.") from None
    if r.returncode != 0:
        dest.unlink(missing_ok=True)
        err = redact(r.stderr.strip(), u)
        raise StorageError(f"pg_dump of {mask_url(u)} failed: {err}\n{advice}; nothing was "
                           "changed.")
    return dest


@dataclass(frozen=True)
class DowngradeResult:
    """What ``fieldbank db downgrade`` did."""

    before: str | None
    after: str | None
    backup: Path | None


def removed_by(engine: Engine, current: str | None, target: str) -> str:
    """What a downgrade from ``current`` to ``target`` takes away, in words."""
    if target == "base":
        return "every table and all its data, the audit log included"
    known = known_revisions()
    if current is None or target not in known or current not in known:
        return "nothing (the database is not above that revision)"
    steps = known[known.index(target) + 1:known.index(current) + 1]
    if not steps:
        return "nothing (the database is not above that revision)"
    return "the schema of revision(s) " + ", ".join(
        f"{r} ({revision_title(r)})" for r in steps)


def guarded_downgrade(engine: Engine, revision: str, *, confirmed: bool, make_backup: bool,
                      backup_dir: str | Path | None = None,
                      store_root: Path | None = None) -> DowngradeResult:
    """Downgrade only when ``confirmed`` (``--yes``), after a backup unless ``make_backup`` is
    False (``--no-backup``: the user has one). Refused with what would be removed otherwise.
    """
    migrate.check_target(revision)
    current = migrate.current_revision(engine)
    migrate.refuse_newer(engine, current)
    what = removed_by(engine, current, revision)
    if not confirmed:
        raise StorageError(
            f"Downgrading {mask_url(engine.url)} from {current or '(empty)'} to {revision} "
            f"removes {what}. Nothing was changed: repeat with --yes to go ahead "
            "(a backup is made first; see 'fieldbank db downgrade --help').")
    path = backup(engine, current, backup_dir) if make_backup else None
    before, after = migrate.downgrade(engine, revision, store_root)
    return DowngradeResult(before, after, path)
