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

Points are located as ``file.h5:/maps/<name>/positions[i]``. Files are read through
:class:`~fieldbank.ingest.h5safe.H5Reader`: hard links only, declared sizes checked before a
dataset is read, every h5py failure a located problem.
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from typing import Any

import h5py
import numpy as np

from fieldbank.errors import Problem
from fieldbank.ingest.h5safe import H5_ERRORS, H5Reader
from fieldbank.ingest.limits import DEFAULT_LIMITS, IngestLimits, LimitExceeded
from fieldbank.ingest.parsed import (
    PATIENT_KEYS,
    RESERVED_KEYS,
    ParsedMap,
    fill_defaults,
    parse_velocity,
)
from fieldbank.maps import VALUE_UNITS, FieldMap
from fieldbank.units import FORCE, LENGTH, STIFFNESS, factor

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


def _dataset(rd: H5Reader, g: h5py.Group, name: str, where: str, table: dict[str, float],
             dim: str, problems: list[Problem], required: bool = True) -> np.ndarray | None:
    loc = f"{where}/{name}"
    ds = rd.child(g, name, loc, problems)
    if ds is None:
        if required and not any(p.location == loc for p in problems):
            problems.append(Problem(where, f"missing dataset '{name}'"))
        return None
    if not isinstance(ds, h5py.Dataset) or ds.dtype.kind not in "iuf":
        kind = "a group" if isinstance(ds, h5py.Group) else (
            "logical (boolean)" if ds.dtype.kind == "b" else f"of type {ds.dtype}")
        problems.append(Problem(loc, f"must be a numeric dataset; it is {kind}"))
        return None
    unit = H5Reader.attrs(ds, loc, problems).get("unit")
    if unit is None:
        problems.append(Problem(loc, f"missing 'unit' attribute ({dim}: {', '.join(table)})"))
        return None
    f = factor(_text(unit), table)
    if f is None:
        problems.append(Problem(loc, f"unknown unit {_text(unit)!r}; known {dim} units: "
                                f"{', '.join(table)}"))
        return None
    try:
        return np.asarray(rd.read(ds, loc), dtype=float) * f
    except LimitExceeded as exc:
        problems.append(Problem(loc, str(exc).removeprefix(f"{loc}: ")))
    except H5_ERRORS as exc:
        problems.append(Problem(loc, f"unreadable: {exc}"))
    return None


def read_hdf5(name: str, data: bytes, limits: IngestLimits = DEFAULT_LIMITS,
              defaults: Mapping[str, str] | None = None,
              columns: Mapping[str, str] | None = None
              ) -> tuple[list[ParsedMap], list[Problem]]:
    """The maps of a fieldbank HDF5 file. ``defaults`` fill metadata a map's attributes lack
    (a map stating another value is a problem); ``columns`` is refused: the datasets' names
    are the format's own."""
    problems: list[Problem] = []
    if columns:
        return [], [Problem(name, f"--column {', '.join(f'{k}={v}' for k, v in columns.items())}"
                            ": a fieldbank HDF5 file names its datasets positions, values and "
                            "sd (docs/formats.md); --column does not apply to it")]
    maps: list[ParsedMap] = []
    try:
        f = h5py.File(io.BytesIO(data), "r")
    except H5_ERRORS as exc:
        return [], [Problem(name, f"not a readable HDF5 file ({exc})")]
    rd = H5Reader(len(data), limits)
    with f:
        root = H5Reader.attrs(f, f"{name}:/", problems)
        fmt = _text(root.get("format", ""))
        if fmt != FORMAT:
            problems.append(Problem(f"{name}:/", f"attribute format must be {FORMAT!r}; got "
                                    f"{fmt!r} (see docs/formats.md)"))
        root_meta = {k: _text(v) for k, v in root.items() if k.lower() in PATIENT_KEYS}
        group = rd.child(f, "maps", f"{name}:/maps", problems)
        if not isinstance(group, h5py.Group) or len(group) == 0:
            return [], [*problems, Problem(f"{name}:/", "no /maps group with at least one map")]
        if len(group) > limits.max_maps:
            return [], [*problems, Problem(f"{name}:/maps", f"{len(group):,} maps, more than "
                                           f"{limits.max_maps:,} {limits.hint('max_maps')}")]
        for key in sorted(group):
            where = f"{name}:/maps/{key}"
            g = rd.child(group, key, where, problems)
            if g is None:
                continue
            if not isinstance(g, h5py.Group):
                problems.append(Problem(where, "must be a group"))
                continue
            pm = _read_group(rd, g, where, problems, defaults or {})
            for k, v in root_meta.items():
                pm.metadata.setdefault(k, v)
            maps.append(pm)
    return maps, problems


def _read_group(rd: H5Reader, g: h5py.Group, where: str,
                problems: list[Problem], defaults: Mapping[str, str]) -> ParsedMap:
    attrs = H5Reader.attrs(g, where, problems)
    fill_defaults(attrs, defaults, where, problems, _text)
    kind = _text(attrs["kind"]) if "kind" in attrs else None
    mprobs: list[Problem] = []
    vel_text = None
    vec_text = None
    if "velocity_m_per_s" in attrs:
        try:
            v = np.atleast_1d(np.asarray(attrs["velocity_m_per_s"], dtype=float))
        except (ValueError, TypeError):
            v = np.zeros(0)
        if v.size == 2:
            vec_text = f"{float(v[0])!r}, {float(v[1])!r}"
            vel_text = repr(float(np.hypot(v[0], v[1])))
        elif v.size == 1:
            vel_text = repr(float(v[0]))
        else:
            mprobs.append(Problem(where, "velocity_m_per_s must hold 1 or 2 numbers (m/s); got "
                                  f"{_text(attrs['velocity_m_per_s'])[:80]!r}"))
    velocity, vmissing = (None, False) if mprobs else parse_velocity(
        vel_text, vec_text, where, kind, mprobs)
    vtable, vdim = (STIFFNESS, "stiffness") if kind == "stiffness" else (FORCE, "force")
    pos = _dataset(rd, g, "positions", where, LENGTH, "length", problems)
    vals = _dataset(rd, g, "values", where, vtable, vdim, problems)
    sd = _dataset(rd, g, "sd", where, vtable, vdim, problems, required=False)
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
    unread = pos is None and any(p.location.startswith(f"{where}/positions") or
                                 "'positions'" in p.reason for p in problems)
    return ParsedMap(
        location=where, kind=kind,
        frame=_text(attrs["frame"]) if "frame" in attrs else None,
        sign=_text(attrs["sign"]) if "sign" in attrs else None,
        source=_text(attrs.get("source", "")), metadata=other,
        positions_m=pos if pos is not None else np.zeros((0, 2)),
        values=vals if vals is not None else np.full((n, *vshape_tail), np.nan),
        sd=sd, velocity_m_per_s=velocity, velocity_missing=vmissing,
        point_location=lambda i: f"{where}/positions[{i}]", problems=mprobs,
        reported=set(range(n)) if vals is None else set(), rows_unread=unread,
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
