"""The loop's state for other processes: a seqlock over a small memory-mapped file.

The 1 kHz loop publishes one fixed-size record per tick (:data:`FIELDS`: time, then the tick's
trace row - handle, force, blend, both virtual arms' joint angles, mode and faults, in the
columns and units of :data:`haptic.recording.COLUMNS`, robot frame - then the count of
renderer events and whether the model is hidden); a display in another
process (:mod:`haptic.station`) reads the newest record whenever it draws. The loop never waits:
publishing packs the row the trace already built, in three ``struct.pack_into`` calls into
memory (about 2 µs, ``benchmarks/bench_tick_cost.py``), with no lock, no system call and no
allocation that could block.

Layout (little-endian)::

    0   8 bytes  magic  b"FBSNAP1\\0"
    8   uint64   sequence number: odd while the loop writes, even when the record is whole
    16  float64  × len(FIELDS)   the record

The writer makes the sequence odd, writes the record, makes it even again (seqlock). A reader
reads the sequence, copies the record, reads the sequence again, and keeps the copy only if both
reads are equal and even; otherwise the loop was writing and it simply reads again. The order of
the writer's stores and of the reader's loads is the program order on x86-64 (total store order);
on a weakly ordered CPU a torn record could in principle pass, so the reader also refuses a
record with a non-finite time.

The file lives in a fresh private directory (mode 0700, in ``/dev/shm`` where there is one, so it
never touches a disk); only this user can map it. The reader maps it read-only.
"""

from __future__ import annotations

import math
import mmap
import os
import shutil
import struct
import tempfile
import time
from pathlib import Path

from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.recording import COLUMNS

MAGIC = b"FBSNAP1\0"
#: The record's fields, in order, each a float64: session time, tick count, the trace columns
#: (:data:`haptic.recording.COLUMNS`: names carry units; robot frame; ``mode`` is
#: haptic.safety.Mode, ``faults`` the latched bitmask), then ``events`` - the count of logged
#: renderer events, which changes whenever a command changes what a display shows - and
#: ``blinded`` - 1 while an A/B/X block or a training assessment hides which model is rendered.
FIELDS: tuple[str, ...] = ("t_s", "ticks", *(name for name, _ in COLUMNS), "events", "blinded")
_SEQ = struct.Struct("<Q")
_RECORD = struct.Struct("<" + "d" * len(FIELDS))
_SEQ_AT = len(MAGIC)
_RECORD_AT = _SEQ_AT + _SEQ.size
SIZE = _RECORD_AT + _RECORD.size
FILE_NAME = "loop.snapshot"


def _private_dir() -> Path:
    base = "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else None
    return Path(tempfile.mkdtemp(prefix="fieldbank-station-", dir=base))


class SnapshotWriter:
    """The loop's side: creates the file, publishes records; :meth:`close` removes it.

    Parameters
    ----------
    directory : str or Path, optional
        Where the file goes (default: a new private directory, removed on close).
    """

    def __init__(self, directory: str | Path | None = None) -> None:
        self._own_dir = directory is None
        self.directory = _private_dir() if directory is None else Path(directory)
        self.path = self.directory / FILE_NAME
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o600)
        try:
            os.ftruncate(fd, SIZE)
            self._mm = mmap.mmap(fd, SIZE, access=mmap.ACCESS_WRITE)
        finally:
            os.close(fd)
        self._mm[0:len(MAGIC)] = MAGIC
        self._seq = 0
        self._pack_seq = _SEQ.pack_into
        self._pack_record = _RECORD.pack_into
        self.publish(*([0.0] * len(FIELDS)))

    def publish(self, *values: float) -> None:
        """Write one record (the values of :data:`FIELDS`, in order); never blocks."""
        mm = self._mm
        seq = self._seq + 1
        self._pack_seq(mm, _SEQ_AT, seq)            # odd: a record is being written
        self._pack_record(mm, _RECORD_AT, *values)
        self._seq = seq + 1
        self._pack_seq(mm, _SEQ_AT, seq + 1)        # even: whole again

    def publish_row(self, t_s: float, ticks: int, row: tuple[float, ...], events: int,
                    blinded: bool) -> None:
        """Write one record from a tick's trace row (the loop's call); never blocks."""
        mm = self._mm
        seq = self._seq + 1
        self._pack_seq(mm, _SEQ_AT, seq)
        self._pack_record(mm, _RECORD_AT, t_s, ticks, *row, events, blinded)
        self._seq = seq + 1
        self._pack_seq(mm, _SEQ_AT, seq + 1)

    def close(self) -> None:
        """Unmap and remove the file (and the directory this writer made)."""
        if not self._mm.closed:
            self._mm.close()
        try:
            self.path.unlink()
        except FileNotFoundError:
            pass
        if self._own_dir:
            shutil.rmtree(self.directory, ignore_errors=True)

    def __enter__(self) -> SnapshotWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class SnapshotReader:
    """A display's side: maps the file read-only; :meth:`read` returns the newest whole record.

    Parameters
    ----------
    path : str or Path
        The writer's :attr:`SnapshotWriter.path`.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        try:
            fd = os.open(self.path, os.O_RDONLY)
        except OSError as exc:
            raise HapticError(f"no loop snapshot at {self.path}: {exc.strerror or exc}") from None
        try:
            if os.fstat(fd).st_size < SIZE:
                raise HapticError(f"{self.path} is not a loop snapshot (too short)")
            self._mm = mmap.mmap(fd, SIZE, access=mmap.ACCESS_READ)
        finally:
            os.close(fd)
        magic = self._mm[0:len(MAGIC)]
        if magic != MAGIC:
            self._mm.close()
            raise HapticError(f"{self.path} is not a loop snapshot (magic {magic!r})")
        self.retries = 0

    def read(self, timeout_s: float = 0.1) -> dict[str, float]:
        """The newest whole record by field name; HapticError if none within ``timeout_s``."""
        mm = self._mm
        deadline = time.monotonic() + timeout_s
        while True:
            s1 = _SEQ.unpack_from(mm, _SEQ_AT)[0]
            raw = mm[_RECORD_AT:SIZE]
            s2 = _SEQ.unpack_from(mm, _SEQ_AT)[0]
            if s1 == s2 and not s1 & 1:
                values = _RECORD.unpack(raw)
                if math.isfinite(values[0]):
                    return dict(zip(FIELDS, values, strict=True)) | {"seq": float(s1)}
            self.retries += 1
            if time.monotonic() > deadline:
                raise HapticError(f"no whole record in {self.path} within {timeout_s} s")
            time.sleep(0)  # the writer holds the record for about a microsecond

    def close(self) -> None:
        if not self._mm.closed:
            self._mm.close()

    def __enter__(self) -> SnapshotReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
