"""How much one file may put in memory once decompressed: one budget across all its parts.

A file from outside can declare far more than it holds: an HDF5 dataset of gzip-compressed
zeros (3.5 MB on disk, 3.2 GB declared), a ZIP whose forty members each pass a per-member
limit. :class:`ReadBudget` is charged with every part's *declared* size before that part is
read (:meth:`ReadBudget.charge`), then reads HDF5 datasets a slab at a time with a running
total (:meth:`ReadBudget.read_dataset`) and ZIP members in pieces (:meth:`ReadBudget.inflate`),
so that a part that holds more than it declared is stopped once the budget is spent, not after.
Two bounds: the total (``limit_bytes``: ``max_decompressed_bytes`` of the ingest limits) and
its ratio to the file's size once the total passes 1 MiB (``max_ratio``:
``max_compression_ratio``; lab data compress 2–50×, a bomb 10⁶×).

Over either bound is a :class:`BudgetExceeded` (a :class:`~fieldbank.errors.MapError`) naming
the part, its declared size and the limit to raise.
"""

from __future__ import annotations

from typing import IO, Any

import numpy as np

from fieldbank.errors import MapError

MIB = 1 << 20
#: Bytes read from an HDF5 dataset or a ZIP member at a time.
SLAB_BYTES = 8 * MIB


class BudgetExceeded(MapError):
    """A part of a file over the decompressed-size budget."""


class ReadBudget:
    """The decompressed bytes one file may still produce (see the module docstring).

    Parameters
    ----------
    limit_bytes : int
        Largest total, bytes.
    file_bytes : int
        The file's size, for the ratio.
    max_ratio : float
        Largest ratio of the total to the file's size (checked past 1 MiB).
    hint_total, hint_ratio : str
        What to say about raising each limit.
    """

    def __init__(self, limit_bytes: int, file_bytes: int, max_ratio: float = 1000.0,
                 hint_total: str = "(limit max_decompressed_bytes)",
                 hint_ratio: str = "(limit max_compression_ratio)") -> None:
        self.limit = int(limit_bytes)
        self.file_bytes = max(1, int(file_bytes))
        self.max_ratio = float(max_ratio)
        self.hint_total = hint_total
        self.hint_ratio = hint_ratio
        self.used = 0

    def _check(self, total: int, where: str, what: str) -> None:
        if total > self.limit:
            raise BudgetExceeded(f"{where}: {what}; with what was read before, "
                                 f"{total:,} bytes, more than the {self.limit:,} bytes a file "
                                 f"may hold once decompressed {self.hint_total}")
        if total > MIB and total > self.max_ratio * self.file_bytes:
            raise BudgetExceeded(f"{where}: {what}; {total:,} bytes from a "
                                 f"{self.file_bytes:,}-byte file, a ratio of "
                                 f"{total / self.file_bytes:,.0f} (a decompression bomb?) "
                                 f"{self.hint_ratio}")

    def charge(self, nbytes: int, where: str, what: str = "") -> None:
        """Count ``nbytes`` (declared) against the budget, or raise BudgetExceeded."""
        total = self.used + max(0, int(nbytes))
        self._check(total, where, what or f"declares {int(nbytes):,} bytes")
        self.used = total

    def check_declared(self, nbytes: int, where: str, what: str = "") -> None:
        """Raise BudgetExceeded if ``nbytes`` more would be over, without counting them."""
        self._check(self.used + max(0, int(nbytes)), where,
                    what or f"declares {int(nbytes):,} bytes")

    def read_dataset(self, ds: Any, where: str) -> np.ndarray:
        """An h5py dataset's data: its declared shape × item size charged first, then read
        along its first axis a slab at a time."""
        shape = tuple(int(n) for n in (ds.shape or ()))
        item = int(ds.dtype.itemsize)
        declared = int(np.prod(shape, dtype=np.float64) * item) if shape else item
        self.charge(declared, where, f"declares {shape} {ds.dtype} = {declared:,} bytes")
        if not shape or shape[0] == 0 or declared <= SLAB_BYTES:
            return np.asarray(ds[()])
        row = max(1, declared // shape[0])
        step = max(1, SLAB_BYTES // row)
        out = np.empty(shape, dtype=ds.dtype)
        for i in range(0, shape[0], step):
            out[i:i + step] = ds[i:i + step]
        return out

    def inflate(self, stream: IO[bytes], declared: int, where: str) -> bytes:
        """Read a ZIP member's stream; stop once it passes what it declared or the budget."""
        parts = []
        got = 0
        while True:
            chunk = stream.read(SLAB_BYTES)
            if not chunk:
                break
            got += len(chunk)
            if got > declared:
                raise BudgetExceeded(f"{where}: holds more than the {declared:,} bytes its "
                                     "header declares; refused")
            parts.append(chunk)
        return b"".join(parts)
