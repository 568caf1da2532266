"""What the list commands read, through the database driver alone: no SQLAlchemy, no numpy.

``fieldbank patient list``, ``models list``, ``maps list``, ``plans list`` and ``jobs`` only
read what the database lists. Opening :class:`fieldbank.storage.Database` for them cost
SQLAlchemy, its ORM, numpy, the array store and the integrity check before a row was read -
about fourteen times the CPU time of importing click. :func:`open_listing` connects with the
standard library's ``sqlite3`` (a SQLite file) or ``psycopg`` (PostgreSQL) instead and reads
with a few fixed SELECTs; :class:`Listing` returns the records the database returns.

One source of truth for the schema: the ORM and the migrations (``fieldbank.storage.orm``,
``fieldbank.migrations``). A listing reads only a database at the head revision this program
knows (:func:`fieldbank.stored.revisions.head_revision`), the schema its SELECTs are written
against, and ``tests/test_listing.py`` holds every listing equal to the ORM's on SQLite and
PostgreSQL.

When the light path does not apply, :func:`open_listing` returns None and the caller opens
:class:`~fieldbank.storage.Database`, which migrates, refuses or fails in its own words: a URL
form :func:`~fieldbank.stored.location.locate` does not read, a database that is not at head
(SQLite is migrated on first use; one made by a newer fieldbank is refused), a read-only SQLite
file (opened specially), a server that does not answer. A SQLite file that does not exist is
refused here, in the same words. Both offer :class:`Reads`, so a command reads the same either
way.
"""

from __future__ import annotations

import json
import os
import sqlite3
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from datetime import UTC, date, datetime
from typing import TYPE_CHECKING, Any, Protocol, Self
from urllib.parse import quote

from fieldbank.errors import DatabaseMissing, StorageError
from fieldbank.redact import redact
from fieldbank.stored.location import (
    SQLITE_BUSY_TIMEOUT_MS,
    Location,
    locate,
    missing_message,
    sqlite_read_only,
    url_source,
)
from fieldbank.stored.records import (
    JOB_STATES,
    JobRecord,
    JobRunRecord,
    ListedModel,
    ModelEntry,
    PatientInfo,
    PlanRecord,
    StoredMap,
)
from fieldbank.stored.revisions import head_revision
from fieldbank.stored.words import no_patient, no_run

if TYPE_CHECKING:  # the driver is imported when a server database is listed
    import psycopg


class Reads(Protocol):
    """What the list commands read: :class:`Listing` and :class:`fieldbank.storage.Database`
    both offer it, with the same records and the same errors."""

    @property
    def url_masked(self) -> str: ...
    def get_patient(self, code: str) -> PatientInfo: ...
    def list_patients(self) -> list[PatientInfo]: ...
    def list_maps(self, patient_code: str | None = None, session_label: str | None = None,
                  kind: str | None = None, since: date | None = None,
                  until: date | None = None) -> list[StoredMap]: ...
    def list_models(self, patient_code: str | None = None) -> Sequence[ListedModel]: ...
    def list_plans(self, patient_code: str | None = None) -> list[PlanRecord]: ...
    def list_runs(self, kind: str | None = None,
                  limit: int | None = None) -> list[JobRunRecord]: ...
    def get_run(self, run_id: int) -> JobRunRecord: ...
    def list_jobs(self, run_id: int, states: Iterable[str] | None = None) -> list[JobRecord]: ...
    def close(self) -> None: ...
    def __enter__(self) -> Self: ...
    def __exit__(self, *exc: object) -> None: ...


def open_listing(db_url: str | None = None) -> Listing | None:
    """The database in force (``db_url`` > ``FIELDBANK_DB`` > fieldbank.toml > the embedded
    file) opened for listing, or None when it is to be opened through SQLAlchemy (module
    docstring).

    Raises
    ------
    DatabaseMissing
        A SQLite file that does not exist (nothing is created).
    """
    where = locate(db_url)
    if where is None:
        return None
    if where.path is not None:
        if not where.path.exists():
            raise DatabaseMissing(missing_message(where.path, url_source(db_url)))
        listing = None if sqlite_read_only(where.path) else _sqlite(where)
    else:
        listing = _server(where)
    if listing is None:
        return None
    if listing.at_head():
        return listing
    listing.close()
    return None


def _sqlite(where: Location) -> Listing | None:
    """The SQLite file read through a connection that cannot create or change it, or None when
    it cannot be opened (SQLAlchemy then says why, as every command does)."""
    assert where.path is not None
    try:
        conn = sqlite3.connect(f"file:{quote(os.path.abspath(where.path))}?mode=rw", uri=True,
                               isolation_level=None)
        conn.execute(f"PRAGMA busy_timeout = {SQLITE_BUSY_TIMEOUT_MS}")
        conn.execute("PRAGMA query_only = ON")
    except sqlite3.Error:
        return None
    return Listing(conn, where, sqlite3.Error)


def _server(where: Location) -> Listing | None:
    """The server database read in a read-only session, or None when the server does not
    answer (SQLAlchemy then says why, as every command does)."""
    import psycopg  # the driver: imported where a server is listed (heavy third party)

    try:
        conn = psycopg.connect(**where.connect)  # type: ignore[arg-type]
    except psycopg.Error:
        return None
    conn.read_only = True
    return Listing(conn, where, psycopg.Error)


def _when(v: datetime | str) -> datetime:
    """A stored timestamp (UTC without a zone; text on SQLite) as an aware UTC datetime."""
    d = datetime.fromisoformat(v) if isinstance(v, str) else v
    return d.replace(tzinfo=UTC) if d.tzinfo is None else d.astimezone(UTC)


def _when_opt(v: datetime | str | None) -> datetime | None:
    return None if v is None else _when(v)


def _day(v: date | str | None) -> date | None:
    return date.fromisoformat(v) if isinstance(v, str) else v


_MAPS = ("SELECT m.id, p.code, s.label, s.session_date, m.kind, m.frame, m.sign, "
         "m.velocity_x_m_per_s, m.velocity_y_m_per_s, m.n_points, m.value_unit, m.source_text, "
         "f.file_name, m.source_sha256, m.index_in_file, m.ingested_at, m.ingested_by "
         "FROM maps m JOIN patients p ON m.patient_id = p.id "
         "JOIN sessions s ON m.session_id = s.id "
         "JOIN source_files f ON m.source_sha256 = f.sha256")
_PATIENTS = "SELECT id, code, body_mass_kg, height_m, side, notes, created_at FROM patients"
_RUNS = ("SELECT id, kind, token, engine, args_json, actor, started_at, finished_at "
         "FROM job_runs")
_JOBS = ("SELECT id, run_id, key, patient_code, session_label, state, attempts, worker, "
         "started_at, finished_at, error, result_json FROM jobs WHERE run_id = ?")


class Listing:
    """A database read through its driver alone (see the module docstring); offers
    :class:`Reads`. Every read is one transaction; nothing is ever written."""

    def __init__(self, conn: sqlite3.Connection | psycopg.Connection[Any], where: Location,
                 error: type[Exception]) -> None:
        self._conn = conn
        self._where = where
        self._error = error  # the driver's base exception
        self._server = where.backend != "sqlite"

    @property
    def url_masked(self) -> str:
        """The database URL with any password replaced by ``***``."""
        return self._where.masked

    def close(self) -> None:
        self._conn.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- reading ----------------------------------------------------------------------------
    @contextmanager
    def _transaction(self) -> Iterator[None]:
        """One read transaction, ended without writing; a driver failure as StorageError
        naming the URL without its secrets (as :func:`fieldbank.storage.config.db_failure`
        words it)."""
        try:
            if not self._server:  # psycopg begins one itself (autocommit off)
                self._conn.execute("BEGIN")
            try:
                yield
            finally:
                if self._server:
                    self._conn.rollback()
                else:
                    self._conn.execute("ROLLBACK")
        except self._error as exc:
            raise StorageError(f"Database {self.url_masked} failed: "
                               f"{redact(str(exc), self._where.text)}") from None

    def _rows(self, sql: str, *params: object) -> list[tuple[Any, ...]]:
        """Rows of ``sql`` written with ``?`` placeholders (sqlite3's; psycopg's are %s)."""
        if self._server:
            sql = sql.replace("?", "%s")
        else:
            params = tuple(p.isoformat() if isinstance(p, date) else p for p in params)
        return list(self._conn.execute(sql, params).fetchall())

    def at_head(self) -> bool:
        """Whether the database is at the head revision (its schema is the one read here)."""
        try:
            with self._transaction():
                rows = self._rows("SELECT version_num FROM alembic_version")
        except StorageError:  # no such table, not a database: SQLAlchemy's path says what
            return False
        return [r[0] for r in rows] == [head_revision()]

    # --- patients ---------------------------------------------------------------------------
    def get_patient(self, code: str) -> PatientInfo:
        with self._transaction():
            rows = self._rows(f"{_PATIENTS} WHERE code = ?", code)
            if not rows:
                codes = [r[0] for r in self._rows("SELECT code FROM patients ORDER BY code")]
                raise StorageError(no_patient(code, codes, self.url_masked))
        return _patient(rows[0])

    def list_patients(self) -> list[PatientInfo]:
        with self._transaction():
            return [_patient(r) for r in self._rows(f"{_PATIENTS} ORDER BY code")]

    # --- maps -------------------------------------------------------------------------------
    def list_maps(self, patient_code: str | None = None, session_label: str | None = None,
                  kind: str | None = None, since: date | None = None,
                  until: date | None = None) -> list[StoredMap]:
        """Maps matching every given filter, by patient, session date and id."""
        where, params = _where((("p.code = ?", patient_code), ("s.label = ?", session_label),
                                ("m.kind = ?", kind), ("s.session_date >= ?", since),
                                ("s.session_date <= ?", until)))
        with self._transaction():
            rows = self._rows(f"{_MAPS}{where} ORDER BY p.code, s.session_date, m.id", *params)
        return [StoredMap(r[0], r[1], r[2], _day(r[3]), r[4], r[5], r[6], (r[7], r[8]), r[9],
                          r[10], r[11], r[12], r[13], r[14], _when(r[15]), r[16]) for r in rows]

    # --- models and plans -------------------------------------------------------------------
    def list_models(self, patient_code: str | None = None) -> list[ModelEntry]:
        """Models in id order, each with the plan that made it and the plans applied to it."""
        where, params = _where((("p.code = ?", patient_code),))
        with self._transaction():
            rows = self._rows("SELECT m.id, p.code, m.parent_id, m.origin, m.label, "
                              "m.created_at FROM models m LEFT JOIN patients p "
                              f"ON m.patient_id = p.id{where} ORDER BY m.id", *params)
            links = self._rows("SELECT id, base_model_id, result_model_id FROM plans "
                               "ORDER BY id") if rows else []
        made_by: dict[int, int] = {}
        applied: dict[int, list[int]] = {}
        for plan_id, base, result in links:
            made_by[result] = plan_id
            applied.setdefault(base, []).append(plan_id)
        return [ModelEntry(r[0], r[1], r[2], r[3], r[4], _when(r[5]), made_by.get(r[0]),
                           tuple(applied.get(r[0], ()))) for r in rows]

    def list_plans(self, patient_code: str | None = None) -> list[PlanRecord]:
        where, params = _where((("p.code = ?", patient_code),))
        with self._transaction():
            rows = self._rows("SELECT pl.id, p.code, pl.base_model_id, pl.result_model_id, "
                              "pl.label, pl.spec_json, pl.created_at FROM plans pl "
                              f"LEFT JOIN patients p ON pl.patient_id = p.id{where} "
                              "ORDER BY pl.id", *params)
        return [PlanRecord(r[0], r[1], r[2], r[3], r[4], json.loads(r[5]), _when(r[6]))
                for r in rows]

    # --- batch runs -------------------------------------------------------------------------
    def list_runs(self, kind: str | None = None, limit: int | None = None) -> list[JobRunRecord]:
        """Runs, newest first."""
        where, params = _where((("kind = ?", kind),))
        tail = "" if limit is None else " LIMIT ?"
        with self._transaction():
            rows = self._rows(f"{_RUNS}{where} ORDER BY id DESC{tail}",
                              *params, *(() if limit is None else (limit,)))
            counts = self._counts([r[0] for r in rows])
        return [_run(r, counts[r[0]]) for r in rows]

    def get_run(self, run_id: int) -> JobRunRecord:
        with self._transaction():
            row = self._run_row(run_id)
            return _run(row, self._counts([run_id])[run_id])

    def list_jobs(self, run_id: int, states: Iterable[str] | None = None) -> list[JobRecord]:
        """A run's jobs in the order they were created."""
        wanted = None if states is None else list(states)
        with self._transaction():
            self._run_row(run_id)
            if wanted == []:
                return []
            where = "" if wanted is None else f" AND state IN ({', '.join('?' * len(wanted))})"
            rows = self._rows(f"{_JOBS}{where} ORDER BY id", run_id, *(wanted or ()))
        return [JobRecord(r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], _when_opt(r[8]),
                          _when_opt(r[9]), r[10], None if r[11] is None else json.loads(r[11]))
                for r in rows]

    def _run_row(self, run_id: int) -> tuple[Any, ...]:
        rows = self._rows(f"{_RUNS} WHERE id = ?", run_id)
        if not rows:
            raise StorageError(no_run(run_id))
        return rows[0]

    def _counts(self, run_ids: Sequence[int]) -> dict[int, dict[str, int]]:
        """run id -> how many of its jobs are in each state (every state named, in order)."""
        if not run_ids:
            return {}
        out = {r: dict.fromkeys(JOB_STATES, 0) for r in run_ids}
        marks = ", ".join("?" * len(run_ids))
        for run_id, state, n in self._rows(
                f"SELECT run_id, state, COUNT(*) FROM jobs WHERE run_id IN ({marks}) "
                "GROUP BY run_id, state", *run_ids):
            out[run_id][str(state)] = int(n)
        return out


def _where(filters: Iterable[tuple[str, object]]) -> tuple[str, list[object]]:
    """`` WHERE a AND b`` of the filters whose value is given, and their values."""
    given = [(clause, value) for clause, value in filters if value is not None]
    if not given:
        return "", []
    return " WHERE " + " AND ".join(c for c, _ in given), [v for _, v in given]


def _patient(r: tuple[Any, ...]) -> PatientInfo:
    return PatientInfo(r[0], r[1], r[2], r[3], r[4], r[5], _when(r[6]))


def _run(r: tuple[Any, ...], counts: dict[str, int]) -> JobRunRecord:
    return JobRunRecord(r[0], r[1], r[2], r[3], json.loads(r[4]), r[5], _when(r[6]),
                        _when_opt(r[7]), counts)
