"""Session traces of the haptic loop: an in-loop buffer, a storage seam, an HDF5 file format.

The loop writes one row per tick into preallocated float32 chunks (:class:`TraceBuffer`; time
is kept apart in float64). At the end of a session the buffer becomes a :class:`Trace`, a frozen
value with its columns, units, events (switches, A/B/X answers, faults) and the parameters of
the models rendered, and goes to a :class:`TraceSink`.

:class:`TraceSink` is the seam to storage: :class:`Hdf5TraceSink` writes a self-describing,
write-once HDF5 file (temp file, fsync, ``os.replace``, directory fsync; fletcher32 checksums;
unit next to every array) and returns its path and SHA-256. A database-backed sink implements
the same method and records the trace (and the file's checksum) as a row of the session.
"""

from __future__ import annotations

import array
import csv
import hashlib
import io
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from fieldbank.errors import ParameterError, StorageError
from fieldbank.files import DISK_FULL_ERRNOS, disk_full_message, write_new
from fieldbank.redact import mask_url
from fieldbank.sanitize import csv_comment

TRACE_FORMAT = "fieldbank-haptic-trace"
TRACE_FORMAT_VERSION = 1

#: (column name, unit) of every per-tick column after time.
COLUMNS: tuple[tuple[str, str], ...] = (
    ("x_m", "m"), ("y_m", "m"), ("vx_m_per_s", "m/s"), ("vy_m_per_s", "m/s"),
    ("fx_n", "N"), ("fy_n", "N"),                       # commanded force on the handle
    ("model_fx_n", "N"), ("model_fy_n", "N"),           # blended model force before safety
    ("blend", "1"),                                      # 0 = model A (before), 1 = B (after)
    ("gain", "1"),                                       # arming / push fade gain
    ("a_q1_rad", "rad"), ("a_q2_rad", "rad"), ("a_qd1_rad_per_s", "rad/s"),
    ("a_qd2_rad_per_s", "rad/s"),
    ("b_q1_rad", "rad"), ("b_q2_rad", "rad"), ("b_qd1_rad_per_s", "rad/s"),
    ("b_qd2_rad_per_s", "rad/s"),
    ("mode", "1"),                                       # haptic.safety.Mode
    ("faults", "1"),                                     # latched fault bitmask (bit code-1)
    ("new_state", "1"),                                  # STATE frames received this tick
    ("passivity_energy_j", "J"),
)
COLUMN_INDEX = {name: i for i, (name, _) in enumerate(COLUMNS)}
NCOL = len(COLUMNS)
_CHUNK_ROWS = 65_536


class TraceBuffer:
    """Growable per-tick storage used inside the loop (one ``add`` per tick).

    Rows go into fixed-size ``array`` chunks (float32 columns, float64 time): appending a tuple
    to an array costs well under a microsecond, and no chunk is ever reallocated, so a long
    session never stalls the loop on a large copy.
    """

    def __init__(self, expected_rows: int = _CHUNK_ROWS) -> None:
        self._chunk = min(_CHUNK_ROWS, max(1024, int(expected_rows)))
        self._t: list[array.array[float]] = []
        self._rows: list[array.array[float]] = []
        self.n = 0
        self._grow()

    def _grow(self) -> None:
        self._tcur: array.array[float] = array.array("d")
        self._rcur: array.array[float] = array.array("f")
        self._t.append(self._tcur)
        self._rows.append(self._rcur)

    def add(self, t_s: float, row: tuple[float, ...]) -> None:
        tc = self._tcur
        if len(tc) == self._chunk:
            self._grow()
            tc = self._tcur
        tc.append(t_s)
        self._rcur.extend(row)
        self.n += 1

    def arrays(self) -> tuple[NDArray[np.float64], NDArray[np.float32]]:
        """Time (N,) s and columns (N, NCOL) as contiguous copies."""
        t = np.concatenate([np.frombuffer(c, dtype=np.float64) for c in self._t])
        r = np.concatenate([np.frombuffer(c, dtype=np.float32) for c in self._rows])
        return t.copy(), r.reshape(-1, NCOL).copy()


@dataclass(frozen=True)
class Trace:
    """One session's record.

    Attributes
    ----------
    t_s : ndarray, shape (N,), s since the session start
    data : ndarray, shape (N, len(COLUMNS)), float32, columns and units in :data:`COLUMNS`
    rate_hz : float
    models : dict  name ('A', 'B') -> ArmParams dict of the model rendered
    events : list of dict  switches, A/B/X trials, pushes, arm/disarm, each with ``t_s``
    faults : list of dict  fault records (``t_s``, ``code``, ``name``, ``message``)
    stats : dict  loop statistics (period percentiles, overruns, tick cost)
    metadata : dict  robot URL, device info, frame offset, safety settings, software version
    """

    t_s: NDArray[np.float64]
    data: NDArray[np.float32]
    rate_hz: float
    models: dict[str, Any] = field(default_factory=dict)
    events: list[dict[str, Any]] = field(default_factory=list)
    faults: list[dict[str, Any]] = field(default_factory=list)
    stats: dict[str, Any] = field(default_factory=dict)
    metadata: dict[str, Any] = field(default_factory=dict)

    def column(self, name: str) -> NDArray[np.float32]:
        try:
            return self.data[:, COLUMN_INDEX[name]]
        except KeyError:
            raise ParameterError(f"no trace column {name!r}; known: "
                                 f"{', '.join(COLUMN_INDEX)}") from None

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    def to_csv(self) -> str:
        """CSV text: metadata as ``# key: value`` lines, then one row per tick."""
        out = io.StringIO()
        out.write(f"# format: {TRACE_FORMAT} {TRACE_FORMAT_VERSION}\n")
        out.write(f"# rate_hz: {self.rate_hz}\n")
        out.write("# frame: robot\n# sign: force on the handle\n")
        for k, v in public_metadata(self.metadata).items():
            out.write(f"# {csv_comment(k)}: {csv_comment(json.dumps(v))}\n")
        w = csv.writer(out, lineterminator="\n")
        w.writerow(["t_s"] + [name for name, _ in COLUMNS])
        for t, row in zip(self.t_s, self.data, strict=True):
            w.writerow([f"{t:.6f}"] + [f"{v:.7g}" for v in row])
        return out.getvalue()

    def summary(self) -> dict[str, Any]:
        f = np.hypot(self.column("fx_n"), self.column("fy_n"))
        return {
            "ticks": len(self),
            "duration_s": float(self.t_s[-1] - self.t_s[0]) if len(self) else 0.0,
            "rate_hz": self.rate_hz,
            "max_force_n": float(f.max()) if len(self) else 0.0,
            "faults": self.faults,
            "events": len(self.events),
            "stats": self.stats,
        }


class TraceSink(Protocol):
    """Where finished traces go. Implemented by :class:`Hdf5TraceSink` and the storage layer."""

    def write_trace(self, trace: Trace, name: str) -> str:
        """Store ``trace``; return a reference (path or database id) to find it again."""
        ...


class Hdf5TraceSink:
    """Writes each trace to ``directory/<name>.h5`` atomically; keeps the SHA-256 of each."""

    def __init__(self, directory: str | Path) -> None:
        self.directory = Path(directory)
        self.sha256: dict[str, str] = {}

    def write_trace(self, trace: Trace, name: str) -> str:
        path = self.directory / f"{name}.h5"
        write_trace_h5(trace, path)
        self.sha256[str(path)] = hashlib.sha256(path.read_bytes()).hexdigest()
        return str(path)


def public_metadata(metadata: dict[str, Any]) -> dict[str, Any]:
    """A trace's metadata as it may be written or printed: the robot URL masked
    (:func:`fieldbank.redact.mask_url`), also for traces recorded before it was."""
    out = dict(metadata)
    if "robot" in out:
        out["robot"] = mask_url(str(out["robot"]))
    return out


def write_trace_h5(trace: Trace, path: str | Path) -> None:
    """Write-once HDF5: built in memory, then written with plain system calls to a temporary
    file in the same directory, fsynced, linked into place (never over an existing file),
    directory fsynced. A full disk is a StorageError and leaves nothing behind."""
    import h5py

    path = Path(path)
    buf = io.BytesIO()
    with h5py.File(buf, "w") as h:
        h.attrs["format"] = TRACE_FORMAT
        h.attrs["format_version"] = TRACE_FORMAT_VERSION
        h.attrs["rate_hz"] = trace.rate_hz
        h.attrs["frame"] = "robot"
        h.attrs["sign"] = "force on the handle"
        h.attrs["models"] = json.dumps(trace.models)
        h.attrs["events"] = json.dumps(trace.events)
        h.attrs["faults"] = json.dumps(trace.faults)
        h.attrs["stats"] = json.dumps(trace.stats)
        h.attrs["metadata"] = json.dumps(public_metadata(trace.metadata))
        kw: dict[str, Any] = {"fletcher32": True, "compression": "gzip",
                              "compression_opts": 4}
        if len(trace) > 0:
            kw["chunks"] = True
        d = h.create_dataset("t_s", data=trace.t_s, **kw)
        d.attrs["unit"] = "s"
        g = h.create_group("columns")
        for i, (name, unit) in enumerate(COLUMNS):
            d = g.create_dataset(name, data=trace.data[:, i], **kw)
            d.attrs["unit"] = unit
    try:
        write_new(path, buf.getvalue())
    except FileExistsError:
        raise StorageError(f"{path}: a trace file by this name exists; traces are "
                           "write-once") from None
    except OSError as exc:
        if exc.errno in DISK_FULL_ERRNOS:
            raise StorageError(disk_full_message(path, exc)) from None
        raise StorageError(f"{path}: cannot write the trace ({exc.strerror})") from None


def read_trace_h5(path: str | Path) -> Trace:
    """Read a trace file written by :func:`write_trace_h5`; StorageError names what is wrong."""
    import h5py

    path = Path(path)
    try:
        with h5py.File(path, "r") as h:
            if h.attrs.get("format") != TRACE_FORMAT:
                raise StorageError(f"{path}: not a haptic trace (format attribute "
                                   f"{h.attrs.get('format')!r})")
            t = np.asarray(h["t_s"][...], dtype=np.float64)
            cols = []
            for name, _unit in COLUMNS:
                if f"columns/{name}" not in h:
                    raise StorageError(f"{path}: missing dataset /columns/{name}")
                cols.append(np.asarray(h[f"columns/{name}"][...], dtype=np.float32))
            data = (np.stack(cols, axis=1) if cols else np.empty((0, NCOL), np.float32))
            return Trace(
                t_s=t, data=data, rate_hz=float(h.attrs["rate_hz"]),
                models=json.loads(h.attrs["models"]), events=json.loads(h.attrs["events"]),
                faults=json.loads(h.attrs["faults"]), stats=json.loads(h.attrs["stats"]),
                metadata=public_metadata(json.loads(h.attrs["metadata"])),
            )
    except OSError as exc:
        raise StorageError(f"{path}: cannot read trace: {exc}") from None
