"""Content-addressed store of write-once HDF5 files for large arrays.

Large arrays (haptic traces, raw recordings, big source files) live here, each in its own HDF5
file named by its key, and the database refers to them by that key (``arrays.sha256``). Small
arrays — the measured maps — stay in the database, where they read faster (BRIEF §10).

Key: SHA-256 over ``b"fieldbank-array\\0"``, the dtype string, the shape and the C-order bytes
of the array, so equal arrays share one file and a file can be verified without trusting it.

Layout: ``<root>/<key[:2]>/<key>.h5`` holding one dataset ``/data`` (fletcher32-checksummed
chunks) with attributes ``unit``, ``sha256`` and ``provenance`` (a JSON object: source file,
software, who, when).

Crash safety: HDF5 does not survive a crash in the middle of a write, so a file is written once
under a temporary name in the same directory, flushed and fsynced, renamed into place with
``os.replace`` (atomic) and the directory fsynced. A crash leaves either no file or a complete
one; stray ``*.tmp`` files are reported by :meth:`ArrayStore.stray_temporaries` and are safe to
delete. A complete file not referenced by the database (the writer died before its database
transaction committed) is an *orphan*: harmless, reported by ``fieldbank db check``.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from numpy.typing import ArrayLike, NDArray

from fieldbank.errors import IntegrityError, StorageError
from fieldbank.files import fsync_dir

_PREFIX = b"fieldbank-array\0"


def array_key(a: NDArray[Any]) -> str:
    """The content key of an array (see module docstring)."""
    arr = np.ascontiguousarray(a)
    h = hashlib.sha256(_PREFIX)
    h.update(arr.dtype.str.encode() + b"\0" + repr(tuple(arr.shape)).encode() + b"\0")
    h.update(arr.tobytes())
    return h.hexdigest()


@dataclass(frozen=True)
class ArrayRef:
    """What the database records of a stored array."""

    sha256: str
    relpath: str
    nbytes: int
    shape: tuple[int, ...]
    dtype: str
    unit: str


class ArrayStore:
    """A directory of write-once, content-addressed HDF5 array files.

    Parameters
    ----------
    root : path
        The store's directory (created on first write).
    """

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)

    def relpath(self, key: str) -> str:
        return f"{key[:2]}/{key}.h5"

    def path(self, key: str) -> Path:
        return self.root / self.relpath(key)

    def put(
        self, array: ArrayLike, unit: str, provenance: Mapping[str, Any] | None = None
    ) -> ArrayRef:
        """Store an array (no-op if the same content is already stored) and describe it.

        Parameters
        ----------
        array : array_like
            Any numeric array; stored with its dtype and shape.
        unit : str
            Unit of the values ('N', 'm', 'rad', 'bytes', ...); required, never guessed.
        provenance : mapping
            JSON-serialisable description of where the array came from.
        """
        if not unit:
            raise StorageError("An array must be stored with its unit.")
        arr = np.ascontiguousarray(np.asarray(array))
        if arr.dtype.kind not in "biuf":
            raise StorageError(f"Only numeric arrays are stored; got dtype {arr.dtype}.")
        key = array_key(arr)
        ref = ArrayRef(key, self.relpath(key), int(arr.nbytes), tuple(arr.shape), arr.dtype.str,
                       unit)
        final = self.path(key)
        if final.exists():
            return ref
        final.parent.mkdir(parents=True, exist_ok=True)
        fd, tmpname = tempfile.mkstemp(prefix=f".{key[:16]}.", suffix=".tmp", dir=final.parent)
        os.close(fd)
        tmp = Path(tmpname)
        try:
            with h5py.File(tmp, "w", track_order=True) as f:
                chunks = arr.size > 0 and arr.ndim > 0
                ds = f.create_dataset(
                    "data", data=arr, fletcher32=bool(chunks), chunks=True if chunks else None
                )
                ds.attrs["unit"] = unit
                ds.attrs["sha256"] = key
                ds.attrs["provenance"] = json.dumps(dict(provenance or {}), sort_keys=True)
                f.flush()
            with open(tmp, "rb+") as fh:
                os.fsync(fh.fileno())
            os.replace(tmp, final)
            fsync_dir(final.parent)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
        return ref

    def get(self, key: str) -> NDArray[Any]:
        """Read an array back; raises IntegrityError if missing or its content does not match."""
        p = self.path(key)
        if not p.exists():
            raise IntegrityError(f"Array {key} is missing from the store ({self.relpath(key)}).")
        try:
            with h5py.File(p, "r") as f:
                arr = np.asarray(f["data"][()])
        except (OSError, KeyError) as exc:
            raise IntegrityError(f"Array file {self.relpath(key)} is unreadable: {exc}") from None
        if array_key(arr) != key:
            raise IntegrityError(f"Array file {self.relpath(key)} does not match its checksum.")
        return arr

    def attrs(self, key: str) -> dict[str, Any]:
        """The unit, sha256 and provenance (decoded) of a stored array."""
        with h5py.File(self.path(key), "r") as f:
            a = dict(f["data"].attrs)
        a["provenance"] = json.loads(a.get("provenance", "{}"))
        return {k: (v.decode() if isinstance(v, bytes) else v) for k, v in a.items()}

    def verify(self, key: str) -> str | None:
        """None when the array is present and intact, else the reason."""
        try:
            self.get(key)
        except IntegrityError as exc:
            return str(exc)
        return None

    def keys(self) -> Iterator[str]:
        """Keys of every complete file in the store."""
        if not self.root.exists():
            return
        for p in sorted(self.root.glob("??/*.h5")):
            yield p.stem

    def stray_temporaries(self) -> list[Path]:
        """Temporary files left by a writer that died before renaming (safe to delete)."""
        if not self.root.exists():
            return []
        return sorted(self.root.glob("??/.*.tmp"))
