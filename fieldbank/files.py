"""Durable file writes and the one JSON encoder, shared by the CLI, reports, stores and traces.

:func:`write_atomic` never leaves a half-written file: the data go to a temporary file in the
target's directory, are flushed and fsynced, renamed over the target with ``os.replace``
(atomic on POSIX), and the directory is fsynced so the rename itself survives a crash.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from collections.abc import Mapping
from datetime import date, datetime
from pathlib import Path
from typing import Any


def fsync_dir(path: str | Path) -> None:
    """Make a directory's entries (a rename into it) durable."""
    if os.name != "posix":  # directories cannot be opened for fsync on Windows
        return
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def write_atomic(path: str | Path, data: bytes | str) -> Path:
    """Write ``data`` (text is UTF-8) to ``path`` all at once or not at all.

    The file gets the mode a plain ``open`` would give it (0666 less the umask); missing
    parent directories are created.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    raw = data.encode("utf-8") if isinstance(data, str) else data
    fd, tmp = tempfile.mkstemp(dir=p.parent, prefix=f".{p.name}.")
    try:
        os.chmod(tmp, 0o666 & ~_umask())
        with os.fdopen(fd, "wb") as fh:
            fh.write(raw)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    fsync_dir(p.parent)
    return p


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
