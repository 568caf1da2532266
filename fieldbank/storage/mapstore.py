"""Measured maps and the source files they came from: ingest, listing, reading back.

A map's arrays are little-endian float64 blobs in its ``maps`` row (small: 9-100 points read
faster from the database than from a file each); its source file is kept byte for byte, inline
up to :data:`INLINE_MAX_BYTES` and as an array above that (:mod:`fieldbank.storage.arrays`:
the store directory of a SQLite database, ``array_chunks`` of a server database).

An ingest batch is one transaction: every file and every map of the batch lands, or none does.
Large source files of a SQLite database go to the write-once array store *before* the
transaction, so a crash in between leaves only complete, unreferenced store files (orphans
that ``fieldbank db check`` reports, ``fieldbank db gc`` removes and a new ingest of the same
file adopts); a server database writes them inside the transaction, so nothing is left.
``progress`` is called after each file is written, inside the transaction, with its
:class:`~fieldbank.stored.records.IngestOutcome`.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Sequence
from datetime import date, datetime
from typing import TypeAlias

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sqlalchemy import Row, Select, select, text
from sqlalchemy import exc as sa_exc

from fieldbank.errors import IntegrityError, StorageError
from fieldbank.maps import VALUE_UNITS, FieldMap
from fieldbank.storage.arrays import PendingArray
from fieldbank.storage.config import db_failure
from fieldbank.storage.core import DatabaseCore, chunks, now, to_utc
from fieldbank.storage.orm import MapRow, PatientRow, SessionRow, SourceFileRow
from fieldbank.storage.records import IncomingFile, IngestOutcome, SourceFileInfo
from fieldbank.stored.records import StoredMap

#: Source files up to this size are kept inside the database; larger ones in the array store.
INLINE_MAX_BYTES = 1 << 20
#: Arbitrary constant key of the PostgreSQL advisory lock held by an ingest transaction.
PG_INGEST_LOCK_KEY = 0x696E676573  # "inges"

#: Called after each file of an ingest batch is written, inside the transaction.
IngestProgress: TypeAlias = Callable[[IngestOutcome], None]

#: The columns of a map listing, in :meth:`MapStore._map_query` order.
_MapListing: TypeAlias = tuple[int, str, str, date | None, str, str, str, float, float, int, str,
                               str, str, str, int, datetime, str]


def _blob(a: ArrayLike) -> bytes:
    return np.ascontiguousarray(np.asarray(a, dtype="<f8")).tobytes()


def _unblob(b: bytes, shape: tuple[int, ...]) -> NDArray[np.float64]:
    return np.frombuffer(b, dtype="<f8").reshape(shape).copy()


def _field_map(r: MapRow) -> FieldMap:
    n = r.n_points
    vshape = (n, 2) if r.kind == "postural" else (n, 2, 2)
    return FieldMap(
        kind=r.kind, positions_m=_unblob(r.positions_m, (n, 2)),
        values=_unblob(r.values, vshape),
        sd=None if r.sd is None else _unblob(r.sd, vshape), frame=r.frame, sign=r.sign,
        velocity_m_per_s=(r.velocity_x_m_per_s, r.velocity_y_m_per_s),
        source=r.source_text, metadata=json.loads(r.metadata_json))


def _map_query() -> Select[*_MapListing]:
    return (select(MapRow.id, PatientRow.code, SessionRow.label, SessionRow.session_date,
                   MapRow.kind, MapRow.frame, MapRow.sign, MapRow.velocity_x_m_per_s,
                   MapRow.velocity_y_m_per_s, MapRow.n_points, MapRow.value_unit,
                   MapRow.source_text, SourceFileRow.file_name, MapRow.source_sha256,
                   MapRow.index_in_file, MapRow.ingested_at, MapRow.ingested_by)
            .join(PatientRow, MapRow.patient_id == PatientRow.id)
            .join(SessionRow, MapRow.session_id == SessionRow.id)
            .join(SourceFileRow, MapRow.source_sha256 == SourceFileRow.sha256))


def _stored_map(r: Row[*_MapListing]) -> StoredMap:
    (map_id, code, label, session_date, kind, frame, sign, vx, vy, n, unit, source_text,
     file_name, sha, index, ingested_at, ingested_by) = r
    return StoredMap(map_id, code, label, session_date, kind, frame, sign, (vx, vy), n, unit,
                     source_text, file_name, sha, index, to_utc(ingested_at), ingested_by)


class MapStore(DatabaseCore):
    """Ingest, maps and source files of :class:`~fieldbank.storage.Database`."""

    def has_source(self, sha256: str) -> bool:
        """Whether a source file with this SHA-256 is stored."""
        with self._read() as s:
            return s.get(SourceFileRow, sha256) is not None

    def ingest_files(self, patient_code: str, session_label: str,
                     files: Sequence[IncomingFile], session_date: date | None = None,
                     progress: IngestProgress | None = None) -> list[IngestOutcome]:
        """Store validated files and their maps in ONE transaction: all or nothing.

        Large source files are written to the array store first (write-once; if the
        transaction then fails they stay as harmless orphans that ``db check`` reports). A file
        whose SHA-256 is already stored is reported as 'duplicate' and not stored again.

        Parameters
        ----------
        patient_code : str
            A stored patient.
        session_label : str
            The patient's session, created (and dated with ``session_date``) if absent; not
            created when every file is a duplicate.
        files : sequence of IncomingFile
            Validated files (:func:`fieldbank.ingest.read_file`).
        progress : callable, optional
            Called with the outcome of each file stored, right after it is written and before
            the transaction commits.

        Returns
        -------
        list of IngestOutcome
            One per file, in order: 'stored' with the new map ids, or 'duplicate'.
        """
        refs: dict[str, PendingArray] = {}
        for f in files:
            if len(f.content) > INLINE_MAX_BYTES and f.sha256 not in refs:
                refs[f.sha256] = self.arrays.prepare(
                    np.frombuffer(f.content, dtype=np.uint8), "bytes",
                    {"file_name": f.file_name, "file_sha256": f.sha256,
                     "format": f.file_format, "stored_by": self.actor})
        outcomes: list[IngestOutcome] = []
        with self._write() as s:
            if self.engine.dialect.name == "postgresql":
                # Serialise ingests as BEGIN IMMEDIATE does on SQLite, so that two processes
                # storing the same file see each other's commit instead of colliding.
                s.execute(text("SELECT pg_advisory_xact_lock(:k)"), {"k": PG_INGEST_LOCK_KEY})
            p = self._patient_row(s, patient_code)
            shas = [f.sha256 for f in files]
            existing = set(s.scalars(select(SourceFileRow.sha256)
                                     .where(SourceFileRow.sha256.in_(shas))))
            if set(shas) <= existing:  # nothing new: do not create an empty session
                return [IngestOutcome(f.file_name, f.sha256, "duplicate", (), len(f.maps))
                        for f in files]
            sess = self._session_row(s, p, session_label, session_date, create=True)
            at = now()
            for f in files:
                if f.sha256 in existing:
                    outcomes.append(IngestOutcome(f.file_name, f.sha256, "duplicate", (),
                                                  len(f.maps)))
                    continue
                existing.add(f.sha256)
                pending = refs.get(f.sha256)
                if pending is not None:
                    self.arrays.record(s, pending, at)
                s.add(SourceFileRow(
                    sha256=f.sha256, file_name=f.file_name, file_format=f.file_format,
                    nbytes=len(f.content), content=None if pending else f.content,
                    array_sha256=pending.ref.sha256 if pending else None, ingested_at=at,
                    ingested_by=self.actor))
                s.flush()  # rows refer to each other by foreign key only, not relationships
                own = f.map_sessions or (None,) * len(f.maps)
                rows = [self._map_row(m, p.id, sess.id if at_ is None else self._session_row(
                    s, p, at_[0], at_[1], create=True).id, f.sha256, i, at)
                        for i, (m, at_) in enumerate(zip(f.maps, own, strict=True))]
                s.add_all(rows)
                s.flush()
                ids = tuple(r.id for r in rows)
                self._audit(s, "ingest", "source_file", f.sha256,
                            {"file": f.file_name, "patient": p.code, "session": sess.label,
                             "maps": list(ids)})
                outcome = IngestOutcome(f.file_name, f.sha256, "stored", ids, len(f.maps))
                outcomes.append(outcome)
                if progress is not None:
                    progress(outcome)
        return outcomes

    def _map_row(self, m: FieldMap, patient_id: int, session_id: int, sha: str, index: int,
                 at: datetime) -> MapRow:
        return MapRow(
            patient_id=patient_id, session_id=session_id, source_sha256=sha,
            index_in_file=index, kind=m.kind, frame=m.frame, sign=m.sign,
            velocity_x_m_per_s=m.velocity_m_per_s[0], velocity_y_m_per_s=m.velocity_m_per_s[1],
            n_points=m.n, value_unit=VALUE_UNITS[m.kind], positions_m=_blob(m.positions_m),
            values=_blob(m.values), sd=None if m.sd is None else _blob(m.sd),
            source_text=m.source, metadata_json=json.dumps(dict(m.metadata), sort_keys=True),
            ingested_at=at, ingested_by=self.actor)

    def list_maps(self, patient_code: str | None = None, session_label: str | None = None,
                  kind: str | None = None, since: date | None = None,
                  until: date | None = None) -> list[StoredMap]:
        """Maps matching every given filter, by patient, session date and id."""
        q = _map_query()
        if patient_code is not None:
            q = q.where(PatientRow.code == patient_code)
        if session_label is not None:
            q = q.where(SessionRow.label == session_label)
        if kind is not None:
            q = q.where(MapRow.kind == kind)
        if since is not None:
            q = q.where(SessionRow.session_date >= since)
        if until is not None:
            q = q.where(SessionRow.session_date <= until)
        q = q.order_by(PatientRow.code, SessionRow.session_date, MapRow.id)
        # Core, not the ORM session: listing is on the interactive path (target ≤ 5 ms).
        try:
            with self.engine.connect() as conn:
                rows = conn.execute(q).all()
        except sa_exc.DBAPIError as exc:
            raise StorageError(db_failure("Database", self.engine.url, exc)) from None
        return [_stored_map(r) for r in rows]

    def maps_of(self, patient_codes: Sequence[str]) -> list[StoredMap]:
        """The maps of every patient of ``patient_codes``, ordered as :meth:`list_maps`
        orders them (by patient, session date and id), in one query per thousand patients."""
        rows: list[Row[*_MapListing]] = []
        try:
            with self.engine.connect() as conn:
                for part in chunks(sorted(set(patient_codes))):
                    rows += conn.execute(_map_query().where(PatientRow.code.in_(part)).order_by(
                        PatientRow.code, SessionRow.session_date, MapRow.id)).all()
        except sa_exc.DBAPIError as exc:
            raise StorageError(db_failure("Database", self.engine.url, exc)) from None
        return [_stored_map(r) for r in rows]

    def get_stored_map(self, map_id: int) -> StoredMap:
        """What the database holds about a map besides its arrays."""
        with self._read() as s:
            r = s.execute(_map_query().where(MapRow.id == map_id)).first()
            if r is None:
                raise self._no_row(s, MapRow, "map", map_id)
            return _stored_map(r)

    def get_map(self, map_id: int) -> FieldMap:
        """The map's arrays and metadata as a :class:`FieldMap` (SI, as ingested)."""
        with self._read() as s:
            r = s.get(MapRow, map_id)
            if r is None:
                raise self._no_row(s, MapRow, "map", map_id)
            return _field_map(r)

    def get_maps(self, map_ids: Sequence[int]) -> list[FieldMap]:
        """The maps ``map_ids`` in that order; one query for all."""
        with self._read() as s:
            rows = {r.id: r for r in s.scalars(select(MapRow).where(MapRow.id.in_(map_ids)))}
            missing = [i for i in map_ids if i not in rows]
            if missing:
                raise self._no_row(s, MapRow, "map", ", ".join(map(str, missing)))
        return [_field_map(rows[i]) for i in map_ids]

    def maps_by_id(self, map_ids: Sequence[int]) -> dict[int, FieldMap]:
        """The stored maps among ``map_ids``, by id (an id not stored is left out), in one
        query per thousand ids."""
        out: dict[int, FieldMap] = {}
        with self._read() as s:
            for part in chunks(sorted({int(i) for i in map_ids})):
                out.update((r.id, _field_map(r))
                           for r in s.scalars(select(MapRow).where(MapRow.id.in_(part))))
        return out

    def source_file(self, sha256: str) -> SourceFileInfo:
        """What is recorded of an ingested file."""
        with self._read() as s:
            r = s.get(SourceFileRow, sha256)
            if r is None:
                raise StorageError(f"No source file with SHA-256 {sha256}.")
            return SourceFileInfo(r.sha256, r.file_name, r.file_format, r.nbytes,
                                  to_utc(r.ingested_at), r.ingested_by,
                                  r.array_sha256 is not None)

    def source_bytes(self, sha256: str) -> bytes:
        """The raw file exactly as ingested.

        Raises
        ------
        IntegrityError
            The stored bytes (or their store array) no longer hash to ``sha256``.
        """
        with self._read() as s:
            r = s.get(SourceFileRow, sha256)
            if r is None:
                raise StorageError(f"No source file with SHA-256 {sha256}.")
            content, key = r.content, r.array_sha256
            data = content if content is not None else self.arrays.get(s, str(key)).tobytes()
        if hashlib.sha256(data).hexdigest() != sha256:
            raise IntegrityError(f"Source file {sha256} does not match its SHA-256.")
        return data
