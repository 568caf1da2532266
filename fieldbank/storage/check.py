"""``fieldbank db check``: verify every reference and checksum of the database and its store.

Problems (the database is damaged; exit non-zero):

* schema not at head or different from the models (alembic check); SQLite ``quick_check``
  or ``foreign_key_check`` failures;
* a source file whose bytes do not hash to its SHA-256, or whose store array is missing or
  corrupt; a map whose arrays have the wrong size or non-finite numbers; a model whose
  parameters no longer validate; an ``arrays`` row whose file is missing or corrupt.

* the schema made by a newer fieldbank (a revision this program does not know);
* an array a server database keeps in a workstation's file store that this workstation
  cannot see (written before revision 0002; ``fieldbank db gc`` there moves it in).

Orphans (harmless; reported so they can be cleaned with ``fieldbank db gc``):

* a complete file in the array store that no ``arrays`` row names — the writer stored it and
  was killed before its database transaction committed; nothing refers to it;
* a temporary file left by a writer killed mid-write;
* an ``arrays`` row that neither a source file nor a trace uses.

Arrays are read where their row says (:mod:`fieldbank.storage.arrays`). A server database's
store directory is not its own (every database of the data directory shares it), so its files
are neither listed nor called orphans: a healthy server database checks the same from every
workstation.
"""

from __future__ import annotations

import hashlib
import json
from typing import Protocol

import numpy as np
from sqlalchemy import Engine, func, select, text

from fieldbank.errors import IntegrityError, ParameterError, StorageError
from fieldbank.params import ArmParams
from fieldbank.storage import migrate
from fieldbank.storage.arrays import ArrayAccess
from fieldbank.storage.core import read_session
from fieldbank.storage.orm import (
    ArrayRow,
    MapRow,
    ModelRow,
    SessionRow,
    SourceFileRow,
    TraceRow,
)
from fieldbank.storage.records import CheckReport


class Checkable(Protocol):
    """What :func:`check` reads: a database and its arrays (a
    :class:`~fieldbank.storage.Database` is one)."""

    @property
    def engine(self) -> Engine: ...

    @property
    def arrays(self) -> ArrayAccess: ...


def check(db: Checkable) -> CheckReport:
    """Verify the database ``db`` and its array store; nothing is changed.

    Returns
    -------
    CheckReport
        Every problem and orphan found (see the module docstring), and row counts per table.
    """
    problems: list[str] = []
    orphans: list[str] = []
    counts: dict[str, int] = {}
    head = migrate.head_revision()
    current = migrate.current_revision(db.engine)
    if migrate.schema_state(current) == "newer":
        problems.append(migrate.newer_message(db.engine, str(current)))
        return CheckReport(tuple(problems), (), counts)
    if current != head:
        problems.append(f"schema revision is {current}, expected {head}")
    else:
        try:
            migrate.check_drift(db.engine)
        except StorageError as exc:
            problems.append(str(exc))
    with read_session(db.engine) as s:
        if db.engine.dialect.name == "sqlite":
            res = [r[0] for r in s.execute(text("PRAGMA quick_check"))]
            if res != ["ok"]:
                problems += [f"sqlite quick_check: {r}" for r in res]
            for r in s.execute(text("PRAGMA foreign_key_check")):
                problems.append(f"table {r[0]} row {r[1]} refers to a missing row of {r[2]}")
        arrays = db.arrays
        array_keys: set[str] = set()
        for key in s.scalars(select(ArrayRow.sha256)):
            array_keys.add(key)
            reason = arrays.verify(s, key)
            if reason:
                problems.append(reason)
        counts["arrays"] = len(array_keys)
        used: set[str] = set()
        n_src = 0
        for sha, content, array_key in s.execute(
            select(SourceFileRow.sha256, SourceFileRow.content, SourceFileRow.array_sha256)
        ):
            n_src += 1
            if array_key is not None:
                used.add(array_key)
                if array_key not in array_keys:
                    problems.append(f"source file {sha} refers to unknown array {array_key}")
                    continue
                try:
                    data = arrays.get(s, array_key).tobytes()
                except IntegrityError as exc:  # reported above through verify
                    problems.append(f"source file {sha}: {exc}")
                    continue
            else:
                data = content or b""
            if hashlib.sha256(data).hexdigest() != sha:
                problems.append(f"source file {sha} does not match its SHA-256")
        counts["source_files"] = n_src
        used.update(s.scalars(select(TraceRow.array_sha256)))
        counts["traces"] = int(s.scalar(select(func.count()).select_from(TraceRow)) or 0)
        n_maps = 0
        for m in s.scalars(select(MapRow)):
            n_maps += 1
            per = 2 if m.kind == "postural" else 4
            want = {"positions": 2 * m.n_points * 8, "values": per * m.n_points * 8}
            got = {"positions": len(m.positions_m), "values": len(m.values)}
            if m.sd is not None:
                want["sd"] = want["values"]
                got["sd"] = len(m.sd)
            for k in want:
                if want[k] != got[k]:
                    problems.append(f"map {m.id}: {k} holds {got[k]} bytes, expected {want[k]}")
            if all(want[k] == got[k] for k in want):
                blobs = [m.positions_m, m.values] + ([m.sd] if m.sd is not None else [])
                if not all(np.all(np.isfinite(np.frombuffer(b, "<f8"))) for b in blobs):
                    problems.append(f"map {m.id}: arrays hold NaN or infinite numbers")
            try:
                json.loads(m.metadata_json)
            except ValueError:
                problems.append(f"map {m.id}: metadata is not valid JSON")
        counts["maps"] = n_maps
        mismatched = s.execute(
            select(MapRow.id).join(SessionRow, MapRow.session_id == SessionRow.id)
            .where(MapRow.patient_id != SessionRow.patient_id)).scalars().all()
        for mid in mismatched:
            problems.append(f"map {mid}: its patient differs from its session's patient")
        n_models = 0
        for mid, pj in s.execute(select(ModelRow.id, ModelRow.params_json)):
            n_models += 1
            try:
                ArmParams.from_json(pj, where=f"model {mid}")
            except ParameterError as exc:
                problems.append(str(exc))
        counts["models"] = n_models
    for key in sorted(array_keys - used):
        orphans.append(f"array {key} is recorded but used by no source file or trace")
    if db.arrays.owns_store:
        store = db.arrays.store
        for key in store.keys():
            if key not in array_keys:
                orphans.append(f"store file {store.relpath(key)} is not referenced by the "
                               "database (a write that did not commit)")
        for p in store.stray_temporaries():
            orphans.append(f"temporary file {p.name} left by an interrupted write")
    return CheckReport(tuple(problems), tuple(orphans), counts)
