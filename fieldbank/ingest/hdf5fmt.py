"""The fieldbank HDF5 map file: read by ``ingest``, written by ``export`` (docs/formats.md).

Layout::

    /                      attrs: format = "fieldbank.maps", format_version = 1,
                                  [patient, exported_at, software]
    /maps/<name>           one group per map (read in name order); attrs:
                             kind, frame, sign, source (text),
                             velocity_m_per_s (2 floats, vx vy; or one 0 for static),
                             any other text/number attribute = provenance metadata
    /maps/<name>/positions (N, 2) float, attr unit: m | cm | mm
    /maps/<name>/values    (N, 2) forces, attr unit: N | mN | kgf | lbf
                           or (N, 2, 2) stiffness K[i, j] = -dF_i/dx_j, attr unit: N/m | N/mm …
    /maps/<name>/sd        optional, shape and unit of values

Points are located as ``file.h5:/maps/<name>/positions[i]``.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from datetime import UTC, datetime
from typing import Any

import h5py
import numpy as np

from fieldbank.errors import Problem
from fieldbank.ingest.parsed import RESERVED_KEYS, ParsedMap, parse_velocity
from fieldbank.ingest.units import FORCE, LENGTH, STIFFNESS, factor
from fieldbank.maps import VALUE_UNITS, FieldMap

FORMAT = "fieldbank.maps"
FORMAT_VERSION = 1


def _text(v: Any) -> str:
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    if isinstance(v, np.ndarray):
        return ", ".join(_text(x) for x in v.ravel())
    if isinstance(v, np.generic):
        return str(v.item())
    return str(v)


def _dataset(g: h5py.Group, name: str, where: str, table: dict[str, float], dim: str,
             problems: list[Problem], required: bool = True) -> np.ndarray | None:
    loc = f"{where}/{name}"
    if name not in g:
        if required:
            problems.append(Problem(where, f"missing dataset '{name}'"))
        return None
    ds = g[name]
    if not isinstance(ds, h5py.Dataset) or ds.dtype.kind not in "iuf":
        problems.append(Problem(loc, "must be a numeric dataset"))
        return None
    unit = ds.attrs.get("unit")
    if unit is None:
        problems.append(Problem(loc, f"missing 'unit' attribute ({dim}: {', '.join(table)})"))
        return None
    f = factor(_text(unit), table)
    if f is None:
        problems.append(Problem(loc, f"unknown unit {_text(unit)!r}; known {dim} units: "
                                f"{', '.join(table)}"))
        return None
    return np.asarray(ds[()], dtype=float) * f


def read_hdf5(name: str, data: bytes) -> tuple[list[ParsedMap], list[Problem]]:
    problems: list[Problem] = []
    maps: list[ParsedMap] = []
    try:
        f = h5py.File(io.BytesIO(data), "r")
    except OSError as exc:
        return [], [Problem(name, f"not a readable HDF5 file ({exc})")]
    with f:
        fmt = _text(f.attrs.get("format", ""))
        if fmt != FORMAT:
            problems.append(Problem(f"{name}:/", f"attribute format must be {FORMAT!r}; got "
                                    f"{fmt!r} (see docs/formats.md)"))
        if "maps" not in f or not isinstance(f["maps"], h5py.Group) or len(f["maps"]) == 0:
            return [], [*problems, Problem(f"{name}:/", "no /maps group with at least one map")]
        for key in sorted(f["maps"]):
            g = f["maps"][key]
            where = f"{name}:/maps/{key}"
            if not isinstance(g, h5py.Group):
                problems.append(Problem(where, "must be a group"))
                continue
            maps.append(_read_group(g, where, problems))
    return maps, problems


def _read_group(g: h5py.Group, where: str, problems: list[Problem]) -> ParsedMap:
    attrs = {k: g.attrs[k] for k in g.attrs}
    kind = _text(attrs["kind"]) if "kind" in attrs else None
    mprobs: list[Problem] = []
    vel_text = None
    vec_text = None
    if "velocity_m_per_s" in attrs:
        v = np.atleast_1d(np.asarray(attrs["velocity_m_per_s"], dtype=float))
        if v.size == 2:
            vec_text = f"{float(v[0])!r}, {float(v[1])!r}"
            vel_text = repr(float(np.hypot(v[0], v[1])))
        elif v.size == 1:
            vel_text = repr(float(v[0]))
        else:
            mprobs.append(Problem(where, "velocity_m_per_s must hold 1 or 2 numbers"))
    velocity, vmissing = (None, False) if mprobs else parse_velocity(
        vel_text, vec_text, where, kind, mprobs)
    vtable, vdim = (STIFFNESS, "stiffness") if kind == "stiffness" else (FORCE, "force")
    pos = _dataset(g, "positions", where, LENGTH, "length", problems)
    vals = _dataset(g, "values", where, vtable, vdim, problems)
    sd = _dataset(g, "sd", where, vtable, vdim, problems, required=False)
    vshape_tail = (2, 2) if kind == "stiffness" else (2,)
    n = 0
    if pos is not None and (pos.ndim != 2 or pos.shape[1] != 2):
        problems.append(Problem(f"{where}/positions", f"shape must be (N, 2); got {pos.shape}"))
        pos = None
    if pos is not None:
        n = pos.shape[0]
    for label, arr in (("values", vals), ("sd", sd)):
        if arr is not None and arr.shape != (n, *vshape_tail):
            problems.append(Problem(f"{where}/{label}", f"shape must be {(n, *vshape_tail)} for "
                                    f"a {kind or 'postural'} map; got {arr.shape}"))
            if label == "values":
                vals = None
            else:
                sd = None
    other = {k: _text(v) for k, v in attrs.items() if k not in RESERVED_KEYS}
    return ParsedMap(
        location=where, kind=kind,
        frame=_text(attrs["frame"]) if "frame" in attrs else None,
        sign=_text(attrs["sign"]) if "sign" in attrs else None,
        source=_text(attrs.get("source", "")), metadata=other,
        positions_m=pos if pos is not None else np.zeros((0, 2)),
        values=vals if vals is not None else np.full((n, *vshape_tail), np.nan),
        sd=sd, velocity_m_per_s=velocity, velocity_missing=vmissing,
        point_location=lambda i: f"{where}/positions[{i}]", problems=mprobs,
    )


def write_hdf5(path: Any, maps: Sequence[FieldMap],
               extra: Sequence[dict[str, Any]] | None = None,
               root_attrs: dict[str, Any] | None = None) -> None:
    """Write maps in the layout above (SI units). ``extra``: per-map attributes to add."""
    with h5py.File(path, "w", track_order=True) as f:
        f.attrs["format"] = FORMAT
        f.attrs["format_version"] = FORMAT_VERSION
        f.attrs["exported_at"] = datetime.now(UTC).isoformat(timespec="seconds")
        f.attrs["software"] = "fieldbank"
        for k, v in (root_attrs or {}).items():
            f.attrs[k] = v
        grp = f.create_group("maps")
        width = max(3, len(str(len(maps))))
        for i, m in enumerate(maps):
            g = grp.create_group(f"{i:0{width}d}")
            g.attrs["kind"] = m.kind
            g.attrs["frame"] = m.frame
            g.attrs["sign"] = m.sign
            g.attrs["source"] = m.source
            g.attrs["velocity_m_per_s"] = np.asarray(m.velocity_m_per_s, dtype=float)
            for k, v in m.metadata.items():
                if k not in RESERVED_KEYS:
                    g.attrs[k] = v
            for k, v in ((extra or [{}] * len(maps))[i]).items():
                g.attrs[k] = v
            g.create_dataset("positions", data=m.positions_m).attrs["unit"] = "m"
            g.create_dataset("values", data=m.values).attrs["unit"] = VALUE_UNITS[m.kind]
            if m.sd is not None:
                g.create_dataset("sd", data=m.sd).attrs["unit"] = VALUE_UNITS[m.kind]
