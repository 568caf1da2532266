"""Where a database keeps its large arrays, and the one way to write, read, check and collect
them.

Large arrays (haptic traces, source files over 1 MiB) are self-describing HDF5 file images
(:func:`fieldbank.arraystore.encode_array`). Where the bytes live is recorded per array in
``arrays.location``:

* ``file`` - a **SQLite** database keeps them in its array store directory, next to the
  database file: whoever can open the file sees its store, and large files read faster from
  the file system than from SQLite (BRIEF §10);
* ``database`` - every **server** database (PostgreSQL) keeps them in ``array_chunks`` rows
  (pieces of :data:`CHUNK_BYTES`), so every workstation of a clinic sees the same arrays. A
  directory on one workstation would be invisible from the others.

Writing is two steps. :meth:`ArrayAccess.prepare` runs before the write transaction: it
encodes the image and, for ``file``, writes the store file (large I/O outside the database
lock; a crash then leaves a complete, unreferenced file, an *orphan*). :meth:`ArrayAccess.record`
runs inside the transaction: it adds the ``arrays`` row and the chunks, or - for ``file`` -
makes sure the store file is still there, writing it again from memory if ``fieldbank db gc``
removed it as an orphan in the meantime.

Collecting (:meth:`ArrayAccess.collect_rows`, :meth:`ArrayAccess.collect_files`, run by
``fieldbank db gc``) removes ``arrays`` rows nothing refers to, then store files no row names
and temporary files of interrupted writes. It never removes what a concurrent writer is about
to reference:

* gc removes files only inside a write transaction that holds the database's writer lock
  (SQLite: ``BEGIN IMMEDIATE``; PostgreSQL: the exclusive advisory lock
  :data:`PG_ARRAYS_LOCK_KEY`, which every :meth:`~ArrayAccess.record` takes shared). A writer
  checks for its file inside its own transaction, after gc's has committed, and rewrites it;
  if the writer committed first, gc sees the row and keeps the file;
* a temporary file is removed only when gc can take its ``flock``, which a live writer holds
  until it has renamed the file into place (:meth:`ArrayStore.remove_stray`);
* a server database's store directory is shared by every database of the data directory, so
  gc and ``db check`` leave it alone (its arrays are in the database anyway).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from numpy.typing import ArrayLike, NDArray
from sqlalchemy import Engine, delete, insert, select, text
from sqlalchemy.orm import Session

from fieldbank.arraystore import ArrayRef, ArrayStore, decode_array, encode_array, image_attrs
from fieldbank.errors import IntegrityError
from fieldbank.storage.orm import ArrayChunkRow, ArrayRow, SourceFileRow, TraceRow

#: Size of one ``array_chunks`` row, bytes.
CHUNK_BYTES = 4 << 20
#: Key of the PostgreSQL advisory lock between writers of arrays (shared) and gc (exclusive).
PG_ARRAYS_LOCK_KEY = 0x6172726179  # "array"


def location_for(engine: Engine) -> str:
    """Where new arrays of this database go: 'file' for SQLite, 'database' otherwise."""
    return "file" if engine.dialect.name == "sqlite" else "database"


@dataclass(frozen=True, eq=False)
class PendingArray:
    """An array on its way into the database: its description and HDF5 file image."""

    ref: ArrayRef
    image: bytes


@dataclass(frozen=True)
class CollectReport:
    """What ``fieldbank db gc`` removed (and moved) - each a human-readable line."""

    rows: tuple[str, ...] = ()
    files: tuple[str, ...] = ()
    temporaries: tuple[str, ...] = ()
    in_use: tuple[str, ...] = ()
    moved: tuple[str, ...] = ()

    def merged(self, other: CollectReport) -> CollectReport:
        return CollectReport(*(a + b for a, b in zip(
            (self.rows, self.files, self.temporaries, self.in_use, self.moved),
            (other.rows, other.files, other.temporaries, other.in_use, other.moved),
            strict=True)))

    def to_dict(self) -> dict[str, list[str]]:
        return {"rows": list(self.rows), "files": list(self.files),
                "temporaries": list(self.temporaries), "in_use": list(self.in_use),
                "moved": list(self.moved)}


def array_row(ref: ArrayRef, location: str, created_at: Any) -> ArrayRow:
    """The ``arrays`` row recording an array."""
    return ArrayRow(sha256=ref.sha256, relpath=ref.relpath, nbytes=ref.nbytes,
                    shape_json=json.dumps(list(ref.shape)), dtype=ref.dtype, unit=ref.unit,
                    created_at=created_at, location=location)


def array_ref(r: ArrayRow) -> ArrayRef:
    """What an ``arrays`` row says of its array."""
    return ArrayRef(r.sha256, r.relpath, r.nbytes, tuple(json.loads(r.shape_json)), r.dtype,
                    r.unit)


def insert_chunks(s: Session, key: str, image: bytes) -> None:
    """The image of ``key`` as ``array_chunks`` rows (inside the caller's transaction)."""
    rows = [{"sha256": key, "idx": i, "data": image[off:off + CHUNK_BYTES]}
            for i, off in enumerate(range(0, max(1, len(image)), CHUNK_BYTES))]
    for row in rows:  # one at a time: a batch would hold every chunk twice in memory
        s.execute(insert(ArrayChunkRow), [row])


def read_chunks(s: Session, key: str) -> bytes:
    """The image of ``key`` from its ``array_chunks`` rows, in order."""
    parts = s.scalars(select(ArrayChunkRow.data).where(ArrayChunkRow.sha256 == key)
                      .order_by(ArrayChunkRow.idx)).all()
    if not parts:
        raise IntegrityError(f"Array {key} has no data in the database (array_chunks).")
    return b"".join(parts)


class ArrayAccess:
    """The arrays of one database: its engine and, for SQLite, its store directory.

    Parameters
    ----------
    engine : sqlalchemy.Engine
    store : ArrayStore
        The store directory: where a SQLite database's arrays live; for a server database,
        only where arrays written before revision 0002 may still be (read and moved in).
    """

    def __init__(self, engine: Engine, store: ArrayStore) -> None:
        self.engine = engine
        self.store = store
        self.location = location_for(engine)

    @property
    def owns_store(self) -> bool:
        """Whether the store directory belongs to this database alone (SQLite)."""
        return self.location == "file"

    # --- writing ----------------------------------------------------------------------------
    def prepare(self, array: ArrayLike, unit: str,
                provenance: Mapping[str, Any] | None = None) -> PendingArray:
        """Encode an array and, for a file store, write its file (before the transaction)."""
        ref, image = encode_array(array, unit, provenance)
        if self.location == "file":
            self.store.write_image(ref.sha256, image)
        return PendingArray(ref, image)

    def lock(self, s: Session, exclusive: bool = False) -> None:
        """Take the arrays lock in the transaction ``s`` (PostgreSQL; SQLite's write
        transactions already exclude each other)."""
        if self.engine.dialect.name == "postgresql":
            fn = "pg_advisory_xact_lock" if exclusive else "pg_advisory_xact_lock_shared"
            s.execute(text(f"SELECT {fn}(:k)"), {"k": PG_ARRAYS_LOCK_KEY})

    def record(self, s: Session, pending: PendingArray, at: Any) -> None:
        """Inside the write transaction ``s``: the ``arrays`` row if new, and the bytes where
        it says (rewritten if gc removed the file; moved into the database if a server
        database still had them in a workstation's file store)."""
        self.lock(s)
        key = pending.ref.sha256
        row = s.get(ArrayRow, key)
        if row is None:
            s.add(array_row(pending.ref, self.location, at))
            s.flush()
            if self.location == "database":
                insert_chunks(s, key, pending.image)
        elif row.location == "database":
            return
        elif self.location == "database":
            insert_chunks(s, key, pending.image)
            row.location = "database"
        if self.location == "file" and not self.store.has(key):
            self.store.write_image(key, pending.image)

    # --- reading ----------------------------------------------------------------------------
    def image(self, s: Session, key: str) -> bytes:
        """The HDF5 file image of ``key``, from wherever its row says."""
        row = s.get(ArrayRow, key)
        if row is None:
            raise IntegrityError(f"Array {key} is not recorded in the database.")
        if row.location == "database":
            return read_chunks(s, key)
        if not self.owns_store and not self.store.has(key):
            raise IntegrityError(
                f"Array {key} is kept in the file store of the workstation that stored it "
                f"({row.relpath}), which this workstation cannot see: run 'fieldbank db gc' "
                "there to move it into the database.")
        return self.store.read_image(key)

    def get(self, s: Session, key: str) -> NDArray[Any]:
        """The array ``key``, verified against its SHA-256."""
        row = s.get(ArrayRow, key)
        where = "in the database" if row is not None and row.location == "database" else (
            f"file {self.store.relpath(key)}")
        return decode_array(key, self.image(s, key), where)

    def attrs(self, s: Session, key: str) -> dict[str, Any]:
        """Unit, sha256 and provenance stored beside the array."""
        return image_attrs(self.image(s, key))

    def verify(self, s: Session, key: str) -> str | None:
        """None when the array is present and intact, else the reason."""
        try:
            self.get(s, key)
        except IntegrityError as exc:
            return str(exc)
        return None

    # --- collecting (fieldbank db gc) -------------------------------------------------------
    def collect_rows(self, s: Session) -> CollectReport:
        """Inside a write transaction: remove ``arrays`` rows (and chunks) nothing refers to;
        on a server database, move arrays this workstation still holds as files into it."""
        self.lock(s, exclusive=True)
        used = set(s.scalars(select(SourceFileRow.array_sha256)
                             .where(SourceFileRow.array_sha256.is_not(None))))
        used.update(s.scalars(select(TraceRow.array_sha256)))
        rows = list(s.execute(select(ArrayRow.sha256, ArrayRow.location)))
        unused = sorted(k for k, _ in rows if k not in used)
        for key in unused:
            s.execute(delete(ArrayChunkRow).where(ArrayChunkRow.sha256 == key))
            s.execute(delete(ArrayRow).where(ArrayRow.sha256 == key))
        moved = []
        if self.location == "database":
            for key, loc in rows:
                if key in used and loc == "file" and self.store.has(key):
                    image = self.store.read_image(key)
                    decode_array(key, image, f"file {self.store.relpath(key)}")
                    insert_chunks(s, key, image)
                    r = s.get(ArrayRow, key)
                    assert r is not None
                    r.location = "database"
                    moved.append(f"array {key} moved from {self.store.relpath(key)} into the "
                                 "database")
        return CollectReport(rows=tuple(f"array {k} (used by no source file or trace)"
                                        for k in unused), moved=tuple(moved))

    def collect_files(self, s: Session) -> CollectReport:
        """Inside a write transaction (the writers' lock held): remove store files no row
        names and temporary files no writer holds. Only for a store this database owns."""
        if not self.owns_store:
            return CollectReport()
        self.lock(s, exclusive=True)
        named = set(s.scalars(select(ArrayRow.sha256).where(ArrayRow.location == "file")))
        files = []
        for key in list(self.store.keys()):
            if key not in named and self.store.remove(key):
                files.append(f"store file {self.store.relpath(key)}")
        temporaries, in_use = [], []
        for p in self.store.stray_temporaries():
            if self.store.remove_stray(p):
                temporaries.append(f"temporary file {p.name}")
            else:
                in_use.append(f"temporary file {p.name} (a writer is using it)")
        return CollectReport(files=tuple(files), temporaries=tuple(temporaries),
                             in_use=tuple(in_use))
