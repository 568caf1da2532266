"""Content-addressed store of write-once HDF5 files for large arrays.

Large arrays (haptic traces, raw recordings, big source files) live here, each in its own HDF5
file named by its key, and the database refers to them by that key (``arrays.sha256``). Small
arrays — the measured maps — stay in the database, where they read faster (BRIEF §10).

Key: SHA-256 over ``b"fieldbank-array\\0"``, the dtype string, the shape and the C-order bytes
of the array, so equal arrays share one file and a file can be verified without trusting it.

Layout: ``<root>/<key[:2]>/<key>.h5`` holding one dataset ``/data`` (fletcher32-checksummed
chunks) with attributes ``unit``, ``sha256`` and ``provenance`` (a JSON object: source file,
software, who, when).

Writing: the HDF5 file is built in memory (:func:`encode_array`) and its bytes reach the disk
with plain system calls, so the HDF5 library never meets a failing disk: a full disk is a
clean :class:`~fieldbank.errors.StorageError` ("no space left"), never a half-written HDF5 file
or a crash inside the library (BRIEF §10). The same bytes are what a server database keeps in
its ``array_chunks`` table (:mod:`fieldbank.storage.arrays`), so both places hold the same
self-describing file.

Crash safety: a file is written once under a temporary name in the same directory (locked with
``flock`` while it is written, so ``fieldbank db gc`` never removes a temporary file a writer
is still using), flushed and fsynced, renamed into place with ``os.replace`` (atomic) and the
directory fsynced. A crash leaves either no file or a complete one; stray ``*.tmp`` files are
reported by :meth:`ArrayStore.stray_temporaries` and removed by :meth:`ArrayStore.remove_stray`.
A complete file not referenced by the database (the writer died before its database
transaction committed) is an *orphan*: harmless, reported by ``fieldbank db check`` and removed
by ``fieldbank db gc``.
"""

from __future__ import annotations

import fcntl
import hashlib
import io
import json
import os
import tempfile
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fieldbank.errors import IntegrityError, StorageError
from fieldbank.files import DISK_FULL_ERRNOS, disk_full_message, fsync_dir

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


def encode_array(array: ArrayLike, unit: str,
                 provenance: Mapping[str, Any] | None = None) -> tuple[ArrayRef, bytes]:
    """An array as a self-describing HDF5 file image in memory, and what the database records.

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
    ref = ArrayRef(key, relpath(key), int(arr.nbytes), tuple(arr.shape), arr.dtype.str, unit)
    buf = io.BytesIO()
    import h5py  # heavy: only where an HDF5 image is built or read (start-up time)

    with h5py.File(buf, "w", track_order=True) as f:
        chunks = arr.size > 0 and arr.ndim > 0
        ds = f.create_dataset("data", data=arr, fletcher32=bool(chunks),
                              chunks=True if chunks else None)
        ds.attrs["unit"] = unit
        ds.attrs["sha256"] = key
        ds.attrs["provenance"] = json.dumps(dict(provenance or {}), sort_keys=True)
    return ref, buf.getvalue()


def decode_array(key: str, image: bytes, where: str) -> NDArray[Any]:
    """The array of an HDF5 file image, verified against ``key``; IntegrityError otherwise."""
    import h5py

    try:
        with h5py.File(io.BytesIO(image), "r") as f:
            arr = np.asarray(f["data"][()])
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise IntegrityError(f"Array {where} is unreadable: {exc}") from None
    if array_key(arr) != key:
        raise IntegrityError(f"Array {where} does not match its checksum.")
    return arr


def image_attrs(image: bytes) -> dict[str, Any]:
    """The unit, sha256 and provenance (decoded) of an HDF5 file image."""
    import h5py

    with h5py.File(io.BytesIO(image), "r") as f:
        a = dict(f["data"].attrs)
    a["provenance"] = json.loads(a.get("provenance", "{}"))
    return {k: (v.decode() if isinstance(v, bytes) else v) for k, v in a.items()}


def relpath(key: str) -> str:
    """Where the file of ``key`` lives under a store's root."""
    return f"{key[:2]}/{key}.h5"


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
        return relpath(key)

    def path(self, key: str) -> Path:
        return self.root / self.relpath(key)

    def has(self, key: str) -> bool:
        """Whether the complete file of ``key`` is in the store (not checked: see verify)."""
        return self.path(key).is_file()

    def put(
        self, array: ArrayLike, unit: str, provenance: Mapping[str, Any] | None = None
    ) -> ArrayRef:
        """Store an array (no-op if the same content is already stored) and describe it.

        Parameters are those of :func:`encode_array`.
        """
        ref, image = encode_array(array, unit, provenance)
        self.write_image(ref.sha256, image)
        return ref

    def write_image(self, key: str, image: bytes) -> None:
        """Write the HDF5 file image of ``key`` once, atomically (see the module docstring).

        Raises
        ------
        StorageError
            The disk is full or the directory cannot be written; nothing is left behind.
        """
        final = self.path(key)
        if final.exists():
            return
        try:
            final.parent.mkdir(parents=True, exist_ok=True)
            fd, tmpname = self._locked_temporary(final.parent, key)
        except OSError as exc:
            raise self._write_error(final, exc) from None
        tmp = Path(tmpname)
        try:
            view = memoryview(image)
            while view:
                view = view[os.write(fd, view):]
            os.fsync(fd)
            os.replace(tmp, final)
            fsync_dir(final.parent)
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            raise self._write_error(final, exc) from None
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
        finally:
            os.close(fd)

    @staticmethod
    def _locked_temporary(directory: Path, key: str) -> tuple[int, str]:
        """A new temporary file in ``directory``, open and locked (``flock``) by this writer.

        ``db gc`` removes a temporary file only when it can take the lock itself; a file it
        removed between our creating and locking it is noticed (no links left) and replaced.
        """
        while True:
            fd, name = tempfile.mkstemp(prefix=f".{key[:16]}.", suffix=".tmp", dir=directory)
            fcntl.flock(fd, fcntl.LOCK_EX)
            if os.fstat(fd).st_nlink > 0:
                return fd, name
            os.close(fd)

    def _write_error(self, where: Path, exc: OSError) -> StorageError:
        if exc.errno in DISK_FULL_ERRNOS:
            return StorageError(disk_full_message(where, exc))
        return StorageError(f"Cannot write the array store file {where} ({exc.strerror}); "
                            "nothing was stored.")

    def read_image(self, key: str) -> bytes:
        """The bytes of the file of ``key``; IntegrityError if it is missing or unreadable."""
        p = self.path(key)
        try:
            return p.read_bytes()
        except FileNotFoundError:
            raise IntegrityError(f"Array {key} is missing from the store "
                                 f"({self.relpath(key)}).") from None
        except OSError as exc:
            raise IntegrityError(f"Array file {self.relpath(key)} is unreadable: "
                                 f"{exc.strerror}") from None

    def get(self, key: str) -> NDArray[Any]:
        """Read an array back; raises IntegrityError if missing or its content does not match."""
        return decode_array(key, self.read_image(key), f"file {self.relpath(key)}")

    def attrs(self, key: str) -> dict[str, Any]:
        """The unit, sha256 and provenance (decoded) of a stored array."""
        return image_attrs(self.read_image(key))

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

    def remove(self, key: str) -> bool:
        """Delete the file of ``key`` (``db gc``, under the database's lock); True if it was
        there."""
        try:
            self.path(key).unlink()
        except FileNotFoundError:
            return False
        fsync_dir(self.path(key).parent)
        return True

    def stray_temporaries(self) -> list[Path]:
        """Temporary files left by a writer that died before renaming (safe to delete)."""
        if not self.root.exists():
            return []
        return sorted(self.root.glob("??/.*.tmp"))

    def remove_stray(self, path: Path) -> bool:
        """Delete a temporary file unless a live writer holds it (its lock); True if deleted."""
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
        except FileNotFoundError:
            return False
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                return False  # a writer is still writing it
            path.unlink(missing_ok=True)
            return True
        finally:
            os.close(fd)
