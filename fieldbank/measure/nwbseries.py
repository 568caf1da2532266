"""Every time series of an NWB file, wherever it lives, found by name or by path.

A lab's NWB file keeps raw channels in ``acquisition/`` and processed ones in processing
modules (``processing/behavior/Position/hand``), often inside a container (``Position``,
``BehavioralTimeSeries``). :func:`all_series` lists every :class:`pynwb.TimeSeries` of a read
file with its path in the HDF5 file, unit, shape, rate and duration, read from metadata only
(no data is read; a series' duration from its timestamps is read only when they are few).
:func:`find` resolves a role's name (``hand_force``) or path (``processing/behavior/…``):
the path exactly, else the one series of that name, else a :class:`SeriesMissing` whose
message lists what the file has and the option that maps it. :func:`nwb_bytes` and
:func:`opened` are the one way fieldbank writes an NWB file to bytes and reads one from them
(the raw recordings of :mod:`fieldbank.measure.nwbraw`, the exports of
:mod:`fieldbank.nwbexport`).
"""

from __future__ import annotations

import io
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from fieldbank.errors import MapError


def nwb_bytes(nwb: Any) -> bytes:
    """An NWB file (``pynwb.NWBFile``) as the bytes of its HDF5 file. pynwb writes through a
    path, so it goes through a private temporary file, always removed."""
    from pynwb import NWBHDF5IO

    fd, path = tempfile.mkstemp(suffix=".nwb")
    os.close(fd)
    try:
        with NWBHDF5IO(path, "w") as io_:
            io_.write(nwb)
        with open(path, "rb") as f:
            return f.read()
    finally:
        os.unlink(path)


@contextmanager
def opened(data: bytes) -> Iterator[Any]:
    """The NWB file held in ``data``, read in memory (its datasets are read while open)."""
    import h5py
    from pynwb import NWBHDF5IO

    with h5py.File(io.BytesIO(data), "r") as h5, \
            NWBHDF5IO(file=h5, mode="r", load_namespaces=True) as io_:
        yield io_.read()


class SeriesMissing(MapError):
    """No series (or more than one) for a role; the message lists the file's series."""


@dataclass(frozen=True)
class SeriesInfo:
    """One time series: where it is and what it says of itself (no data read)."""

    path: str
    name: str
    type: str
    unit: str
    shape: tuple[int, ...]
    rate_hz: float | None
    start_s: float
    duration_s: float | None
    description: str

    def to_json_dict(self) -> dict[str, object]:
        return {"path": self.path, "name": self.name, "type": self.type, "unit": self.unit,
                "shape": list(self.shape), "rate_hz": self.rate_hz, "start_s": self.start_s,
                "duration_s": self.duration_s, "description": self.description}

    def line(self) -> str:
        shape = "×".join(str(n) for n in self.shape) or "scalar"
        rate = f", {self.rate_hz:g} Hz" if self.rate_hz else ""
        dur = f", {self.duration_s:.4g} s" if self.duration_s is not None else ""
        unit = f"unit {self.unit!r}"
        if self.unit.strip().lower() in ("addme", "unknown", ""):
            unit += " — a placeholder: the writer set no unit"
        return f"{self.path} ({self.type}, {shape}, {unit}{rate}{dur})"


def _path(ts: Any) -> str:
    data = getattr(ts, "data", None)
    name = getattr(data, "name", None)
    if isinstance(name, str) and name.endswith("/data"):
        return name[1:-5]
    parts = [ts.name]
    p = getattr(ts, "parent", None)
    while p is not None and getattr(p, "parent", None) is not None:
        parts.append(p.name)
        p = p.parent
    return "/".join(reversed(parts))


def _info(ts: Any) -> SeriesInfo:
    data = getattr(ts, "data", None)
    shape = tuple(int(n) for n in getattr(data, "shape", ()) or ())
    rate = getattr(ts, "rate", None)
    start = float(getattr(ts, "starting_time", 0.0) or 0.0)
    duration: float | None = None
    n = shape[0] if shape else 0
    if rate:
        duration = n / float(rate)
    else:
        stamps = getattr(ts, "timestamps", None)
        if stamps is not None and hasattr(stamps, "timestamps"):
            stamps = stamps.timestamps
        shp = getattr(stamps, "shape", None)
        if stamps is not None and shp and 0 < shp[0] <= 10_000_000:
            first, last = float(stamps[0]), float(stamps[shp[0] - 1])
            start, duration = first, last - first
    return SeriesInfo(_path(ts), str(ts.name), type(ts).__name__,
                      str(getattr(ts, "unit", "") or ""), shape,
                      float(rate) if rate else None, start, duration,
                      str(getattr(ts, "description", "") or "")[:200])


def all_series(nwb: Any) -> list[tuple[SeriesInfo, Any]]:
    """(info, series) of every TimeSeries in the file, by path."""
    from pynwb import TimeSeries

    out = [(_info(o), o) for o in nwb.objects.values() if isinstance(o, TimeSeries)]
    return sorted(out, key=lambda x: x[0].path)


def find(nwb: Any, role: str, wanted: str, option: str,
         found: list[tuple[SeriesInfo, Any]] | None = None) -> tuple[SeriesInfo, Any]:
    """The series ``wanted`` names (a path or a name), or SeriesMissing."""
    series = found if found is not None else all_series(nwb)
    key = wanted.strip().strip("/")
    for info, ts in series:
        if info.path == key:
            return info, ts
    named = [(i, t) for i, t in series if i.name == key]
    if len(named) == 1:
        return named[0]
    if named:
        raise SeriesMissing(f"{len(named)} series are named {key!r} "
                            f"({', '.join(i.path for i, _ in named)}); give the path with "
                            f"--column {option}=PATH")
    raise SeriesMissing(f"no series {key!r} for the {role} ({listing(series)}); name one "
                        f"with --column {option}=NAME or --column {option}=PATH")


def listing(series: list[tuple[SeriesInfo, Any]], most: int = 12) -> str:
    """What the file has, in a sentence."""
    if not series:
        return "the file holds no time series at all, in acquisition/ or processing/"
    shown = "; ".join(i.line() for i, _ in series[:most])
    more = f"; … {len(series)} in all" if len(series) > most else ""
    return f"the file's series: {shown}{more}"
