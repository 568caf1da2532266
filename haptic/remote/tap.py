"""Every tick of the link for another process: a ring of rows in shared memory.

The station (another process) needs more of the link than the loop's snapshot carries: the
patient's side as received, tick by tick, for the classifier; the delay, the loss and the
passivity controller's activity for the link's figures. The clinician's port appends each of
its log rows here (one ``struct.pack_into`` and one counter store, never a lock, never a wait);
a reader copies whatever is new since its last read.

Layout (little-endian)::

    0   8 bytes  magic  b"FBTAP1\\0\\0"
    8   uint32   columns      12  uint32  capacity (rows)
    16  uint64   rows written (the head; the newest row is head − 1)
    24  float64  × columns × capacity   the rows, row k at slot k mod capacity

The writer stores the row, then the new head. A reader reads the head, copies the rows it has
not seen (at most the capacity), and reads the head again: any row the writer may have
overwritten meanwhile (older than head − capacity at the second read) is dropped and counted
in :attr:`TapReader.missed`. The file lives in a fresh private directory (0700, ``/dev/shm``
where there is one), like :mod:`haptic.snapshot`.
"""

from __future__ import annotations

import mmap
import os
import shutil
import struct
import tempfile
from pathlib import Path

import numpy as np

from fieldbank.haptic.errors import HapticError

MAGIC = b"FBTAP1\0\0"
_HEAD = struct.Struct("<8sIIQ")
_HEAD_AT = 16
_ROWS_AT = _HEAD.size
#: Rows kept: 20 s at 1 kHz.
DEFAULT_CAPACITY = 20_000
FILE_NAME = "link.tap"


class TapWriter:
    """The loop's side: :meth:`add` one row per tick; :meth:`close` removes the file."""

    def __init__(self, columns: tuple[str, ...], capacity: int = DEFAULT_CAPACITY) -> None:
        base = "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) \
            else None
        self.directory = Path(tempfile.mkdtemp(prefix="fieldbank-tap-", dir=base))
        self.path = self.directory / FILE_NAME
        self.columns = columns
        self.capacity = capacity
        self._row = struct.Struct("<" + "d" * len(columns))
        size = _ROWS_AT + self._row.size * capacity
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o600)
        try:
            os.ftruncate(fd, size)
            self._mm = mmap.mmap(fd, size, access=mmap.ACCESS_WRITE)
        finally:
            os.close(fd)
        _HEAD.pack_into(self._mm, 0, MAGIC, len(columns), capacity, 0)
        self.head = 0
        self._pack = self._row.pack_into
        self._head = struct.Struct("<Q").pack_into

    def add(self, row: tuple[float, ...]) -> None:
        h = self.head
        self._pack(self._mm, _ROWS_AT + (h % self.capacity) * self._row.size, *row)
        self.head = h + 1
        self._head(self._mm, _HEAD_AT, h + 1)

    def close(self) -> None:
        if not self._mm.closed:
            self._mm.close()
        shutil.rmtree(self.directory, ignore_errors=True)

    def __enter__(self) -> TapWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class TapReader:
    """A display's side: :meth:`read` returns the rows written since the last read."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        try:
            fd = os.open(self.path, os.O_RDONLY)
        except OSError as exc:
            raise HapticError(f"no link tap at {self.path}: {exc.strerror or exc}") from None
        try:
            size = os.fstat(fd).st_size
            if size < _ROWS_AT:
                raise HapticError(f"{self.path} is not a link tap (too short)")
            self._mm = mmap.mmap(fd, size, access=mmap.ACCESS_READ)
        finally:
            os.close(fd)
        magic, self.ncols, self.capacity, _ = _HEAD.unpack_from(self._mm, 0)
        if magic != MAGIC or size < _ROWS_AT + 8 * self.ncols * self.capacity:
            self._mm.close()
            raise HapticError(f"{self.path} is not a link tap")
        self.seen = 0
        self.missed = 0

    def _head(self) -> int:
        return int(_HEAD.unpack_from(self._mm, 0)[3])

    def read(self) -> np.ndarray:
        """The new rows, shape (n, columns), oldest first."""
        head = self._head()
        start = max(self.seen, head - self.capacity)
        self.missed += start - self.seen
        if head <= start:
            return np.empty((0, self.ncols))
        cap, nc = self.capacity, self.ncols
        allrows = np.frombuffer(self._mm, dtype="<f8", count=nc * cap, offset=_ROWS_AT)
        allrows = allrows.reshape(cap, nc)
        idx = np.arange(start, head) % cap
        out = allrows[idx].copy()
        again = self._head()
        keep_from = max(start, again - cap)   # rows the writer may have overwritten meanwhile
        if keep_from > start:
            self.missed += keep_from - start
            out = out[keep_from - start:]
        self.seen = head
        return out

    def close(self) -> None:
        if not self._mm.closed:
            self._mm.close()
