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
"""

from __future__ import annotations

import io
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import scipy.io

from fieldbank.errors import Problem
from fieldbank.ingest.parsed import RESERVED_KEYS, ParsedMap, parse_velocity
from fieldbank.ingest.units import FORCE, LENGTH, STIFFNESS, factor
from fieldbank.maps import VALUE_UNITS, FieldMap

MAT_KEYS = ("kind", "frame", "sign", "source", "velocity_m_per_s", "positions",
            "positions_unit", "values", "values_unit", "sd")


def read_mat5(name: str, data: bytes) -> tuple[list[ParsedMap], list[Problem]]:
    try:
        raw = scipy.io.loadmat(io.BytesIO(data), squeeze_me=False, chars_as_strings=True)
    except Exception as exc:  # scipy raises several types for damaged files
        return [], [Problem(name, f"not a readable MATLAB v5 file ({exc})")]
    variables: dict[str, Any] = {}
    for k, v in raw.items():
        if k.startswith("__"):
            continue
        if isinstance(v, np.ndarray) and v.dtype.kind == "U":
            variables[k] = "".join(str(x) for x in v.ravel())
        else:
            variables[k] = v
    return _from_variables(name, variables)


def read_mat73(name: str, data: bytes) -> tuple[list[ParsedMap], list[Problem]]:
    try:
        f = h5py.File(io.BytesIO(data), "r")
    except OSError as exc:
        return [], [Problem(name, f"not a readable MATLAB v7.3 file ({exc})")]
    variables: dict[str, Any] = {}
    with f:
        for k in f:
            if k.startswith("#"):
                continue
            ds = f[k]
            if not isinstance(ds, h5py.Dataset):
                variables[k] = None
                continue
            cls = ds.attrs.get("MATLAB_class", b"")
            cls = cls.decode() if isinstance(cls, bytes) else str(cls)
            arr = np.asarray(ds[()])
            if ds.attrs.get("MATLAB_empty", 0):  # the dataset holds only the dimensions
                variables[k] = "" if cls == "char" else np.zeros((0, 0))
            elif cls == "char":  # UTF-16 code units, as MATLAB stores text
                units = np.ascontiguousarray(arr.T.ravel(), dtype="<u2")
                variables[k] = units.tobytes().decode("utf-16-le", errors="replace")
            else:
                variables[k] = arr.T
    return _from_variables(name, variables)


def _from_variables(name: str, v: dict[str, Any]) -> tuple[list[ParsedMap], list[Problem]]:
    problems: list[Problem] = []

    def text(key: str) -> str | None:
        x = v.get(key)
        if x is None:
            return None
        if not isinstance(x, str):
            problems.append(Problem(f"{name}:{key}", "must be a char array"))
            return None
        return x

    kind = text("kind")
    mprobs: list[Problem] = []
    vel_text = vec_text = None
    if "velocity_m_per_s" in v:
        vel = np.asarray(v["velocity_m_per_s"])
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
        arr = np.asarray(v[key])
        if arr.dtype.kind not in "iuf" or arr.ndim != 2 or arr.shape[1] != cols:
            problems.append(Problem(f"{name}:{key}", f"must be a numeric N×{cols} matrix; got "
                                    f"{'×'.join(map(str, arr.shape))} {arr.dtype.kind}"))
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
    for key, arr in (("values", vals), ("sd", sd)):
        if arr is not None and arr.shape[0] != n:
            problems.append(Problem(f"{name}:{key}", f"{arr.shape[0]} rows; positions has {n}"))
    if vals is not None and vals.shape[0] != n:
        vals = None
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
        problems=mprobs,
    )
    return [pm], problems


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
