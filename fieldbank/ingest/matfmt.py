"""MATLAB ``.mat`` maps, version 5 (scipy.io) and version 7.3 (HDF5, read with h5py).

One map per file, as top-level variables (docs/formats.md)::

    kind            char     'postural' | 'stiffness'
    frame           char     'shoulder'
    sign            char     'arm-on-handle' | 'handle-on-arm'
    velocity_m_per_s double  [vx vy] in m/s, or 0 for static
    source          char     free text (lab, robot, software and version)
    positions       N×2      hand positions;      positions_unit char: m | cm | mm
    values          N×2      fx fy (postural)  or N×4 kxx kxy kyx kyy (stiffness)
    values_unit     char     N | mN | kgf | lbf, or N/m | N/mm | N/cm | kgf/m …
    sd              N×2/N×4  optional standard deviations, unit of values

Any other char or scalar variable is kept as provenance metadata. Points are located as
``file.mat:positions(i,:)`` with MATLAB's 1-based row index. Version 7.3 files are HDF5 with
MATLAB's 512-byte header; MATLAB stores matrices column-major, so h5py sees them transposed.

Numbers must be numeric classes (double, single, integers): a ``logical`` array is refused as
forces or positions, a cell array or struct where text or a matrix belongs is a located
problem. Bounds (:mod:`fieldbank.ingest.limits`): version 5 files are read through
:func:`inflate_mat5`, which checks every variable's declared dimensions and inflates each
compressed variable with a bounded decompressor before scipy sees it; version 7.3 files through
:class:`~fieldbank.ingest.h5safe.H5Reader`.
"""

from __future__ import annotations

import io
import struct
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import scipy.io

from fieldbank.errors import Problem
from fieldbank.ingest.h5safe import H5_ERRORS, H5Reader
from fieldbank.ingest.limits import DEFAULT_LIMITS, MIB, IngestLimits, LimitExceeded
from fieldbank.ingest.parsed import RESERVED_KEYS, ParsedMap, fill_defaults, parse_velocity
from fieldbank.maps import VALUE_UNITS, FieldMap
from fieldbank.units import FORCE, LENGTH, STIFFNESS, factor

MAT_KEYS = ("kind", "frame", "sign", "source", "velocity_m_per_s", "positions",
            "positions_unit", "values", "values_unit", "sd")
#: MATLAB classes that hold numbers (``logical`` does not: true/false are not forces).
NUMERIC_CLASSES = ("double", "single", "int8", "uint8", "int16", "uint16", "int32", "uint32",
                   "int64", "uint64")

_MI_MATRIX = 14
_MI_COMPRESSED = 15
_MAT5_HEADER = 128


class Logical(np.ndarray):
    """Marks an array that MATLAB stored as ``logical`` (refused where numbers belong)."""


def _tag(data: bytes, pos: int, endian: str) -> tuple[int, int, int]:
    """(type, nbytes, header size) of the data element tag at ``pos`` (v5 small format too)."""
    first, second = struct.unpack_from(endian + "II", data, pos)
    if first >> 16:  # small data element: 2-byte size, 2-byte type, data in the next 4 bytes
        return first & 0xFFFF, first >> 16, 4
    return first, second, 8


def _declared_bytes(element: bytes, endian: str) -> int:
    """Bytes an miMATRIX element declares (product of its dimensions × 8), from its header."""
    try:
        # tag (8) | array flags sub-element (8 + 8) | dimensions sub-element
        pos = 8 + 16
        _t, nbytes, head = _tag(element, pos, endian)
        dims = struct.unpack_from(f"{endian}{nbytes // 4}i", element, pos + head)
    except struct.error:
        return 0  # too short to say: scipy reports the damage
    total = 8.0
    for d in dims:
        total *= max(0, d)
    return int(min(total, float(1 << 62)))


def _matrix_name(element: bytes, endian: str) -> str | None:
    """The variable name in the header of an miMATRIX element, if it can be read."""
    try:
        pos = 8 + 16  # tag | array flags
        _t, nbytes, head = _tag(element, pos, endian)
        pos += head + (4 if head == 4 else nbytes + (-nbytes % 8))
        _t, nbytes, head = _tag(element, pos, endian)
        raw = element[pos + head:pos + head + nbytes]
    except struct.error:
        return None
    return raw.decode("ascii", "replace") if raw else None


def _is_logical(element: bytes, endian: str) -> bool:
    """Whether an miMATRIX element has MATLAB's logical flag (scipy reads it as uint8)."""
    try:
        (flags,) = struct.unpack_from(endian + "I", element, 16)
    except struct.error:
        return False
    return bool(flags & 0x0200)


def inflate_mat5(name: str, data: bytes, limits: IngestLimits) -> tuple[bytes, set[str]]:
    """The v5 file with every compressed variable inflated, within the limits, and the names
    of its logical variables.

    Each top-level variable's declared size (dimensions × 8 bytes) and each inflated size count
    against ``max_decompressed_bytes``; inflating stops one byte past what is left, so a bomb
    never allocates more than the limit. The ratio to the file's size is checked as for HDF5.

    Raises
    ------
    LimitExceeded
        A variable is over a limit (the message names it).
    """
    logical: set[str] = set()
    if len(data) < _MAT5_HEADER:
        return data, logical
    endian = "<" if data[126:128] == b"IM" else ">"
    out = [data[:_MAT5_HEADER]]
    budget = limits.max_decompressed_bytes
    total = 0
    pos = _MAT5_HEADER
    k = 0
    while pos + 8 <= len(data):
        k += 1
        mtype, nbytes, head = _tag(data, pos, endian)
        end = pos + head + nbytes
        label = f"variable {k}"
        if mtype == _MI_COMPRESSED:
            try:
                head_bytes = zlib.decompressobj().decompress(data[pos + head:end], 512)
                var = _matrix_name(head_bytes, endian)
                label = f"variable {var!r}" if var else label
                element = zlib.decompressobj().decompress(data[pos + head:end],
                                                          budget - total + 1)
            except zlib.error as exc:
                raise LimitExceeded(f"{name}: {label} is not valid compressed data "
                                    f"({exc})") from None
            if len(element) > budget - total:
                raise LimitExceeded(
                    f"{name}: {label} inflates to more than the {budget:,} bytes a file "
                    f"may hold once decompressed {limits.hint('max_decompressed_bytes')}")
        else:
            end = pos + 8 if head == 4 else end + (-nbytes % 8)  # elements are 8-byte aligned
            element = data[pos:end]
        if mtype in (_MI_COMPRESSED, _MI_MATRIX):
            declared = _declared_bytes(element, endian)
            var = _matrix_name(element, endian)
            label = f"variable {var!r}" if var else label
            if var and _is_logical(element, endian):
                logical.add(var)
            if declared > budget - total:
                raise LimitExceeded(
                    f"{name}: {label} declares {declared:,} bytes, more than the "
                    f"{budget:,} bytes a file may hold {limits.hint('max_decompressed_bytes')}")
        total += len(element)
        if total > MIB and total > limits.max_compression_ratio * max(1, len(data)):
            raise LimitExceeded(
                f"{name}: inflates to {total:,} bytes from a {len(data):,}-byte file, a ratio "
                f"of {total / len(data):,.0f} (a decompression bomb?) "
                f"{limits.hint('max_compression_ratio')}")
        out.append(element)
        pos = end
    return b"".join(out), logical


def read_mat5(name: str, data: bytes, limits: IngestLimits = DEFAULT_LIMITS,
              defaults: Mapping[str, str] | None = None,
              columns: Mapping[str, str] | None = None
              ) -> tuple[list[ParsedMap], list[Problem]]:
    try:
        image, logical = inflate_mat5(name, data, limits)
    except LimitExceeded as exc:
        return [], [Problem(name, str(exc).removeprefix(f"{name}: "))]
    try:
        raw = scipy.io.loadmat(io.BytesIO(image), squeeze_me=False, chars_as_strings=True)
    except Exception as exc:  # scipy raises several types for damaged files
        return [], [Problem(name, f"not a readable MATLAB v5 file ({exc})")]
    variables: dict[str, Any] = {}
    for k, v in raw.items():
        if k.startswith("__"):
            continue
        if isinstance(v, np.ndarray) and v.dtype.kind == "U":
            variables[k] = "".join(str(x) for x in v.ravel())
        elif k in logical and isinstance(v, np.ndarray):
            variables[k] = v.astype(bool).view(Logical)
        else:
            variables[k] = v
    return _from_variables(name, variables, defaults, columns)


def _mat73_text(arr: np.ndarray) -> str | None:
    """A v7.3 char variable as text: UTF-16 code units as MATLAB writes them, or bytes as
    other writers do; None for anything else (references, numbers of other sizes)."""
    if arr.dtype.kind == "S":
        return b"".join(np.atleast_1d(arr).ravel().tolist()).decode("utf-8", "replace")
    if arr.dtype.kind not in "iu":
        return None
    if arr.dtype.itemsize == 1:
        return np.ascontiguousarray(arr.T).tobytes().decode("utf-8", "replace")
    if arr.dtype.itemsize == 2:
        units = np.ascontiguousarray(arr.T.ravel(), dtype="<u2")
        return units.tobytes().decode("utf-16-le", errors="replace")
    return None


def read_mat73(name: str, data: bytes, limits: IngestLimits = DEFAULT_LIMITS,
               defaults: Mapping[str, str] | None = None,
               columns: Mapping[str, str] | None = None
               ) -> tuple[list[ParsedMap], list[Problem]]:
    try:
        f = h5py.File(io.BytesIO(data), "r")
    except H5_ERRORS as exc:
        return [], [Problem(name, f"not a readable MATLAB v7.3 file ({exc})")]
    rd = H5Reader(len(data), limits)
    problems: list[Problem] = []
    variables: dict[str, Any] = {}
    with f:
        for k in sorted(f):
            if k.startswith("#"):
                continue
            where = f"{name}:{k}"
            ds = rd.child(f, k, where, problems)
            if ds is None:
                continue
            if not isinstance(ds, h5py.Dataset):
                variables[k] = Unsupported("a struct or group")
                continue
            attrs = H5Reader.attrs(ds, where, problems)
            cls = attrs.get("MATLAB_class", b"")
            cls = cls.decode("utf-8", "replace") if isinstance(cls, bytes) else str(cls)
            if attrs.get("MATLAB_empty", 0):  # the dataset holds only the dimensions
                variables[k] = "" if cls == "char" else np.zeros((0, 0))
                continue
            if ds.dtype.kind == "O" or cls in ("cell", "struct"):
                variables[k] = Unsupported(f"a MATLAB {cls or 'reference'} array")
                continue
            try:
                arr = rd.read(ds, where)
            except LimitExceeded as exc:
                problems.append(Problem(where, str(exc).removeprefix(f"{where}: ")))
                continue
            except H5_ERRORS as exc:
                problems.append(Problem(where, f"unreadable: {exc}"))
                continue
            if cls == "char":
                text = _mat73_text(arr)
                variables[k] = text if text is not None else Unsupported(
                    f"char data of type {arr.dtype}")
            elif cls == "logical":
                variables[k] = arr.T.astype(bool).view(Logical)
            else:
                variables[k] = arr.T
    parsed, more = _from_variables(name, variables, defaults, columns)
    return parsed, problems + more


@dataclass(frozen=True)
class Unsupported:
    """A variable of a kind no map variable can be (struct, cell, reference, odd text)."""

    what: str


def _from_variables(name: str, v: dict[str, Any], defaults: Mapping[str, str] | None = None,
                    columns: Mapping[str, str] | None = None
                    ) -> tuple[list[ParsedMap], list[Problem]]:
    problems: list[Problem] = []
    for ours, theirs in (columns or {}).items():   # --column positions=pos: a variable's name
        if ours not in MAT_KEYS:
            problems.append(Problem(name, f"--column {ours}={theirs}: {ours!r} is not a map "
                                    f"variable (a MAT map's variables: {', '.join(MAT_KEYS)})"))
        elif theirs not in v:
            problems.append(Problem(name, f"--column {ours}={theirs}: the file has no variable "
                                    f"{theirs!r} (variables: {', '.join(sorted(v)) or 'none'})"))
        else:
            v[ours] = v.pop(theirs)
    fill_defaults(v, defaults or {}, name, problems,
                  lambda x: x if isinstance(x, str) else str(x))

    def text(key: str) -> str | None:
        x = v.get(key)
        if x is None:
            return None
        if not isinstance(x, str):
            what = x.what if isinstance(x, Unsupported) else _describe(x)
            problems.append(Problem(f"{name}:{key}", f"must be a char array; it is {what}"))
            return None
        return x

    kind = text("kind")
    mprobs: list[Problem] = []
    vel_text = vec_text = None
    if "velocity_m_per_s" in v:
        vel = np.asarray(v["velocity_m_per_s"]) if not isinstance(
            v["velocity_m_per_s"], Unsupported) else np.zeros(0)
        if vel.dtype.kind not in "iuf" or vel.size not in (1, 2):
            mprobs.append(Problem(f"{name}:velocity_m_per_s", "must be [vx vy] or 0 (m/s)"))
        elif vel.size == 2:
            vx, vy = (float(x) for x in vel.ravel())
            vec_text = f"{vx!r}, {vy!r}"
            vel_text = repr(float(np.hypot(vx, vy)))
        else:
            vel_text = repr(float(vel.ravel()[0]))
    velocity, vmissing = (None, False) if mprobs else parse_velocity(
        vel_text, vec_text, name, kind, mprobs)
    width = 4 if kind == "stiffness" else 2
    vtable, vdim = (STIFFNESS, "stiffness") if kind == "stiffness" else (FORCE, "force")

    def matrix(key: str, unit_key: str, table: dict[str, float], dim: str, cols: int,
               required: bool = True) -> np.ndarray | None:
        if key not in v:
            if required:
                problems.append(Problem(name, f"missing variable '{key}'"))
            return None
        x = v[key]
        if isinstance(x, Unsupported) or isinstance(x, str):
            what = x.what if isinstance(x, Unsupported) else "text"
            problems.append(Problem(f"{name}:{key}", f"must be a numeric N×{cols} matrix; it "
                                    f"is {what}"))
            return None
        arr = np.asarray(x)
        if isinstance(x, Logical) or arr.dtype.kind == "b":
            problems.append(Problem(f"{name}:{key}", f"is a logical (true/false) array; "
                                    f"{key} must be numbers (double)"))
            return None
        if arr.dtype.kind not in "iuf" or arr.ndim != 2 or arr.shape[1] != cols:
            problems.append(Problem(f"{name}:{key}", f"must be a numeric N×{cols} matrix; got "
                                    f"{_describe(arr)}"))
            return None
        unit = text(unit_key)
        if unit is None:
            problems.append(Problem(name, f"missing variable '{unit_key}' ({dim}: "
                                    f"{', '.join(table)})"))
            return None
        f = factor(unit, table)
        if f is None:
            problems.append(Problem(f"{name}:{unit_key}", f"unknown unit {unit!r}; known {dim} "
                                    f"units: {', '.join(table)}"))
            return None
        return arr.astype(float) * f

    pos = matrix("positions", "positions_unit", LENGTH, "length", 2)
    vals = matrix("values", "values_unit", vtable, vdim, width)
    sd = matrix("sd", "values_unit", vtable, vdim, width, required=False)
    n = 0 if pos is None else pos.shape[0]
    tail = (2, 2) if kind == "stiffness" else (2,)
    unread = pos is None and any(p.location.startswith(f"{name}:positions") or
                                 "'positions'" in p.reason for p in problems)
    for key, arr in (("values", vals), ("sd", sd)):
        if arr is not None and arr.shape[0] != n:
            problems.append(Problem(f"{name}:{key}", f"{arr.shape[0]} rows; positions has {n}"))
    if vals is not None and vals.shape[0] != n:
        vals = None
    # points whose values were refused above are reported already: no NaN per point
    reported = set(range(n)) if vals is None else set()
    if sd is not None and sd.shape[0] != n:
        sd = None
    other: dict[str, str] = {}
    for k, x in v.items():
        if k in MAT_KEYS or k in RESERVED_KEYS:
            continue
        if isinstance(x, str):
            other[k] = x
        elif isinstance(x, np.ndarray) and x.size == 1 and x.dtype.kind in "iuf":
            other[k] = repr(x.ravel()[0].item())
    pm = ParsedMap(
        location=name, kind=kind, frame=text("frame"), sign=text("sign"),
        source=text("source") or "", metadata=other,
        positions_m=pos if pos is not None else np.zeros((0, 2)),
        values=(vals.reshape(n, *tail) if vals is not None else np.full((n, *tail), np.nan)),
        sd=None if sd is None else sd.reshape(n, *tail), velocity_m_per_s=velocity,
        velocity_missing=vmissing, point_location=lambda i: f"{name}:positions({i + 1},:)",
        problems=mprobs, reported=reported, rows_unread=unread,
    )
    return [pm], problems


def _describe(x: Any) -> str:
    arr = np.asarray(x)
    kinds = {"b": "logical", "i": "integer", "u": "integer", "f": "double", "U": "text",
             "O": "cell/struct", "c": "complex"}
    return f"{'×'.join(map(str, arr.shape))} {kinds.get(arr.dtype.kind, str(arr.dtype))}"


def _variables(m: FieldMap) -> dict[str, Any]:
    n = m.n
    d: dict[str, Any] = {
        "kind": m.kind, "frame": m.frame, "sign": m.sign, "source": m.source,
        "velocity_m_per_s": np.asarray([m.velocity_m_per_s], dtype=float),
        "positions": m.positions_m, "positions_unit": "m",
        "values": m.values.reshape(n, -1), "values_unit": VALUE_UNITS[m.kind],
    }
    if m.sd is not None:
        d["sd"] = m.sd.reshape(n, -1)
    for k, val in m.metadata.items():
        if k.isidentifier() and k not in d:
            d[k] = val
    return d


def write_mat5(path: str | Path, m: FieldMap) -> None:
    """Write one map as a MATLAB v5 file in the layout above."""
    scipy.io.savemat(str(path), _variables(m), format="5", oned_as="row")


def write_mat73(path: str | Path, m: FieldMap) -> None:
    """Write one map as a MATLAB v7.3 (HDF5) file as MATLAB lays it out."""
    with h5py.File(path, "w", userblock_size=512) as f:
        for k, val in _variables(m).items():
            if isinstance(val, str):
                codes = np.frombuffer(val.encode("utf-16-le"), dtype="<u2")[None, :]
                ds = f.create_dataset(k, data=codes.T if codes.size else np.zeros((2,), "<u8"))
                if not codes.size:  # MATLAB writes an empty char array as its dimensions
                    ds.attrs["MATLAB_empty"] = np.uint8(1)
                ds.attrs["MATLAB_class"] = np.bytes_("char")
                ds.attrs["MATLAB_int_decode"] = np.int32(2)
            else:
                ds = f.create_dataset(k, data=np.atleast_2d(np.asarray(val, dtype=float)).T)
                ds.attrs["MATLAB_class"] = np.bytes_("double")
    stamp = datetime.now(UTC).strftime("%a %b %d %H:%M:%S %Y")
    head = f"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: {stamp} HDF5 schema 1.00 ."
    header = head.encode("ascii").ljust(116, b" ") + b"\0" * 8 + b"\x00\x02" + b"IM"
    with open(path, "r+b") as fh:
        fh.write(header.ljust(512, b"\0"))
