"""Durable file writes, bounded file reads, and the one JSON encoder, shared by the CLI,
reports, stores and traces.

:func:`write_atomic` never leaves a half-written file: the data go to a temporary file in the
target's directory, are flushed and fsynced, renamed over the target with ``os.replace``
(atomic on POSIX), and the directory is fsynced so the rename itself survives a crash.

:func:`write_new` is the same for files a user asked for (exports): it refuses to overwrite an
existing file unless told to, and never writes through a symbolic link.

:func:`write_directory` does it for a set of files that belong together (a report, a
cluster's certificates): written in a temporary directory beside the target and renamed into
place once every file is complete, so a full disk leaves nothing behind.

:func:`read_regular_file` reads a file someone else made (lab files, plans, parameters): only
a regular file (a symlink is judged by its target), refused without opening it for reading
when it is a FIFO, a device or a directory, and never more than a limit, so ``/dev/zero``, a
named pipe with no writer or a file that grows as it is read cannot hang or exhaust memory.

:func:`read_json_document` is the one reader of a JSON document (parameters, plans, probes,
training protocols) from a file, :func:`parse_json_document` of one already in memory: UTF-8,
strict JSON (``NaN`` and ``Infinity`` are refused: JSON has no such numbers), bounded nesting;
a refusal is a :class:`~fieldbank.errors.ValidationError` located at the file.
"""

from __future__ import annotations

import errno
import json
import math
import os
import shutil
import stat
from collections.abc import Mapping
from datetime import date, datetime
from pathlib import Path
from typing import Any, ClassVar, Self

from fieldbank.errors import FieldbankError, FileRefused, Problem, ValidationError

#: Largest JSON document (plan, parameters) read from a file, bytes.
MAX_DOCUMENT_BYTES = 16 << 20
#: errno values that mean the disk (or the user's quota, or the file size limit) is full
DISK_FULL_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


def disk_full_message(where: str | Path, exc: OSError) -> str:
    """What to say when writing ``where`` failed because the disk is full."""
    return (f"No space left to write {where} ({exc.strerror}); nothing was stored. Free some "
            "space (or raise the quota) and try again.")


def fsync_dir(path: str | Path) -> None:
    """Make a directory's entries (a rename into it) durable."""
    if os.name != "posix":  # directories cannot be opened for fsync on Windows
        return
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_atomic(path: str | Path, data: bytes | str) -> Path:
    """Write ``data`` (text is UTF-8) to ``path`` all at once or not at all.

    The file gets the mode a plain ``open`` would give it (0666 less the umask); missing
    parent directories are created.
    """
    p = Path(path)
    tmp = _write_temp(p, data)
    try:
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    fsync_dir(p.parent)
    return p


def _write_temp(p: Path, data: bytes | str) -> str:
    """``data`` (text is UTF-8) written and synced to a new temporary file beside ``p``, with
    the mode a plain ``open`` would give it (0666 less the umask); its path. Missing parent
    directories are created; nothing is left behind on failure."""
    p.parent.mkdir(parents=True, exist_ok=True)
    raw = data.encode("utf-8") if isinstance(data, str) else data
    fd, tmp = _new_temp(p)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(raw)
            fh.flush()
            os.fsync(fh.fileno())
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return tmp


def _new_temp(p: Path) -> tuple[int, str]:
    """A new, empty temporary file beside ``p`` opened for writing, and its path. Created with
    mode 0666 so the kernel applies the umask (and a directory's default ACL) itself, as for a
    plain ``open``: reading the umask would mean setting it, for every thread at once."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC | os.O_NOFOLLOW
    for _ in range(100):
        # os.urandom is what secrets.token_hex reads; the secrets module would load hmac and
        # OpenSSL into every command at start-up
        tmp = os.path.join(p.parent, f".{p.name}.{os.urandom(6).hex()}")
        try:
            return os.open(tmp, flags, 0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(errno.EEXIST, "no free temporary name", str(p.parent))


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISFIFO, "a named pipe (FIFO)"), (stat.S_ISCHR, "a character "
                       "device"), (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"),
                       (stat.S_ISDIR, "a directory")):
        if test(mode):
            return name
    return "not a regular file"


def _size(n: int) -> str:
    return f"{n:,} bytes" if n < 1 << 20 else f"{n / (1 << 20):,.1f} MiB"


def read_regular_file(path: str | Path, max_bytes: int, limit_hint: str = "") -> bytes:
    """The bytes of a regular file of at most ``max_bytes`` (see the module docstring).

    Raises
    ------
    FileRefused
        Not a regular file, larger than ``max_bytes`` (``limit_hint`` is added to the
        message), changed while opened, or unreadable; the message names the file.
    """
    p = os.fspath(path)
    try:
        st = os.stat(p)  # follows a symlink: /dev/zero behind a link is refused as a device
    except OSError as exc:
        raise FileRefused(f"{p}: cannot read ({exc.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        raise FileRefused(f"{p}: {_kind(st.st_mode)}, not a regular file; refused without "
                          "reading it")
    if st.st_size > max_bytes:
        raise FileRefused(f"{p}: {_size(st.st_size)}, larger than {_size(max_bytes)} "
                          f"{limit_hint}".rstrip())
    try:
        # O_NONBLOCK: a FIFO swapped in after the stat cannot make the open wait for a writer
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | os.O_CLOEXEC)
    except OSError as exc:
        raise FileRefused(f"{p}: cannot read ({exc.strerror})") from None
    try:
        st2 = os.fstat(fd)
        if not stat.S_ISREG(st2.st_mode) or (st2.st_dev, st2.st_ino) != (st.st_dev, st.st_ino):
            raise FileRefused(f"{p}: changed while it was being opened; refused")
        chunks = []
        total = 0
        while True:
            chunk = os.read(fd, min(1 << 20, max_bytes + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
            if total > max_bytes:
                raise FileRefused(f"{p}: grew past {_size(max_bytes)} while being read "
                                  f"{limit_hint}".rstrip())
        return b"".join(chunks)
    except OSError as exc:
        raise FileRefused(f"{p}: cannot read ({exc.strerror})") from None
    finally:
        os.close(fd)


def parse_json_document(data: str | bytes, where: str) -> Any:
    """One JSON document (bytes must be UTF-8), ``where`` naming it in messages.

    Raises
    ------
    ValidationError
        One problem located at ``where``: not UTF-8, not valid JSON, a ``NaN`` or
        ``Infinity`` (no JSON number), or nested too deeply.
    """
    try:
        text = data.decode("utf-8") if isinstance(data, bytes) else data
    except UnicodeDecodeError as exc:
        raise ValidationError([Problem(where, f"not UTF-8 text ({exc.reason} at byte "
                                              f"{exc.start})")]) from None
    try:
        return json.loads(text, parse_constant=_refuse_constant)
    except _NotANumber as exc:
        raise ValidationError([Problem(where, f"not JSON: {exc}")]) from None
    except json.JSONDecodeError as exc:
        raise ValidationError([Problem(where, f"not valid JSON ({exc})")]) from None
    except RecursionError:
        raise ValidationError([Problem(where, "JSON nested too deeply")]) from None


def read_json_document(path: str | Path, max_bytes: int = MAX_DOCUMENT_BYTES) -> Any:
    """The JSON document in the regular file ``path`` (:func:`read_regular_file`, then
    :func:`parse_json_document`).

    Raises
    ------
    FileRefused
        Not a regular file, larger than ``max_bytes``, unreadable.
    ValidationError
        Not UTF-8, not JSON, or nested too deeply; located at the file.
    """
    return parse_json_document(read_regular_file(path, max_bytes), os.fspath(path))


class JsonDocument:
    """A value kept as a JSON document (an arm's parameters, a plan): ``from_json`` and
    ``from_file`` read the document the one way (:func:`parse_json_document`,
    :func:`read_json_document`) and hand it to the class's ``from_dict``; a document that is
    not one is raised as the class's ``document_error``, located."""

    #: What the document is called in messages when no file names it.
    document_name: ClassVar[str] = "document"
    #: The error a document that cannot be read is raised as.
    document_error: ClassVar[type[FieldbankError]] = FieldbankError

    @classmethod
    def from_dict(cls, data: Any, where: str) -> Self:
        raise NotImplementedError

    @classmethod
    def from_json(cls, text: str, where: str | None = None) -> Self:
        name = where or cls.document_name
        try:
            data = parse_json_document(text, name)
        except ValidationError as exc:
            raise cls.document_error(f"{exc}.") from None
        return cls.from_dict(data, name)

    @classmethod
    def from_file(cls, path: str | Path) -> Self:
        p = Path(path)
        try:
            data = read_json_document(p)
        except (FileRefused, ValidationError) as exc:
            raise cls.document_error(f"{exc}.") from None
        return cls.from_dict(data, str(p))


class _NotANumber(ValueError):
    pass


def _refuse_constant(name: str) -> float:
    raise _NotANumber(f"{name} is not a number JSON allows")


def write_new(path: str | Path, data: bytes | str, force: bool = False) -> Path:
    """Write a file a user asked for: atomically (as :func:`write_atomic`), never through a
    symbolic link, and never over an existing file unless ``force``.

    Raises
    ------
    FileExistsError
        ``path`` exists (as a file, a link or anything else) and ``force`` is False, or it is
        a symbolic link or not a regular file (refused even with ``force``).
    """
    p = Path(path)
    try:
        st = os.lstat(p)
    except FileNotFoundError:
        st = None
    if st is not None:
        if stat.S_ISLNK(st.st_mode):
            raise FileExistsError(errno.EEXIST, "is a symbolic link; fieldbank does not write "
                                  "through links", str(p))
        if not stat.S_ISREG(st.st_mode):
            raise FileExistsError(errno.EEXIST, f"exists and is {_kind(st.st_mode)}", str(p))
        if not force:
            raise FileExistsError(errno.EEXIST, "exists; give --force to replace it", str(p))
    tmp = _write_temp(p, data)
    try:
        if force:
            os.replace(tmp, p)  # replaces the directory entry; never follows a link
        else:
            os.link(tmp, p)  # fails if anything appeared at p meanwhile
            os.unlink(tmp)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    fsync_dir(p.parent)
    return p


def write_directory(path: str | Path, files: Mapping[str, bytes | str], *,
                    modes: Mapping[str, int] | None = None, private: bool = False) -> Path:
    """Write ``files`` (file name -> data; text is UTF-8) into the directory ``path`` all at
    once or not at all.

    Every file is written and synced in a new temporary directory beside ``path`` (so on the
    same file system). Then, when ``path`` does not exist, the temporary directory is renamed
    to it in one step; when it does, each file is renamed into it over what was there. A
    failure while writing - a full disk, a quota, a file size limit - removes the temporary
    directory: nothing is left behind and ``path`` keeps what it held. The parent of ``path``
    must exist.

    ``modes``: a file's permission bits from its creation (a private key: 0o600); the others
    get 0666 less the umask. ``private``: a new ``path`` is made 0700 (else 0777 less the
    umask).
    """
    out = Path(path)
    for name in files:
        if not name or name in (".", "..") or "/" in name or os.sep in name:
            raise ValueError(f"{name!r} is not a file name")
    tmp = _new_temp_dir(out, 0o700 if private else 0o777)
    try:
        for name, data in files.items():
            raw = data.encode("utf-8") if isinstance(data, str) else data
            fd = os.open(os.path.join(tmp, name), os.O_WRONLY | os.O_CREAT | os.O_EXCL
                         | os.O_CLOEXEC | os.O_NOFOLLOW, (modes or {}).get(name, 0o666))
            with os.fdopen(fd, "wb") as fh:
                fh.write(raw)
                fh.flush()
                os.fsync(fh.fileno())
        fsync_dir(tmp)
        try:
            os.rename(tmp, out)  # a new directory (or an empty one): one step
        except OSError as exc:
            if exc.errno not in (errno.EEXIST, errno.ENOTEMPTY, errno.ENOTDIR, errno.EISDIR):
                raise
            if not out.is_dir() or out.is_symlink():
                raise FileExistsError(errno.EEXIST, "exists and is not a directory",
                                      str(out)) from None
            for name in files:
                os.replace(os.path.join(tmp, name), out / name)
            fsync_dir(out)
            os.rmdir(tmp)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    fsync_dir(out.parent)
    return out


def _new_temp_dir(p: Path, mode: int) -> str:
    """A new, empty temporary directory beside ``p`` (``mode`` less the umask), its path."""
    for _ in range(100):
        tmp = os.path.join(p.parent, f".{p.name}.{os.urandom(6).hex()}")  # as in _new_temp
        try:
            os.mkdir(tmp, mode)
            return tmp
        except FileExistsError:
            continue
    raise FileExistsError(errno.EEXIST, "no free temporary name", str(p.parent))


def json_finite(obj: Any) -> Any:
    """NaN and infinities as None (JSON has neither), recursively; key order kept."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: json_finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_finite(v) for v in obj]
    return obj


#: Indentation of every JSON document fieldbank prints or writes for people to read.
JSON_INDENT = 2


def jsonable(obj: Any) -> Any:
    """``obj`` as plain JSON values: the one conversion every JSON output goes through.

    Objects with ``to_dict()`` become their dict; numpy arrays and scalars (anything with
    ``tolist()``) lists and numbers; paths strings; dates ISO 8601; NaN and infinities None
    (JSON has neither). Mapping keys become strings; key order is kept. Anything else is an
    error rather than a silent ``str()``.
    """
    if obj is None or isinstance(obj, (bool, int, str)):
        return obj
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, Mapping):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, (datetime, date)):
        return obj.isoformat()
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if hasattr(obj, "to_dict"):
        return jsonable(obj.to_dict())
    if hasattr(obj, "tolist"):  # numpy arrays and scalars, without importing numpy here
        return jsonable(obj.tolist())
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def to_json(obj: Any, *, indent: int | None = JSON_INDENT, sort_keys: bool = False) -> str:
    """The JSON text of ``obj`` (through :func:`jsonable`; strict: never NaN or Infinity)."""
    return json.dumps(jsonable(obj), indent=indent, sort_keys=sort_keys, allow_nan=False,
                      ensure_ascii=False)
