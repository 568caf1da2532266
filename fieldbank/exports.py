"""``fieldbank export``: stored maps as fieldbank HDF5 or CSV, a patient as NWB, a haptic
session's trace as OpenSim ``.mot``/``.sto``, a model as an OpenSim ``.osim``, or a source
file as ingested.

Where the output goes is decided here, once, and never surprises:

* the format follows the output's suffix: ``.h5`` / ``.hdf5`` one HDF5 file with every map;
  ``.csv`` one CSV file, which holds exactly one map (BRIEF §11); no suffix a directory with
  one CSV per map; ``.nwb`` one patient's maps, models, fits and haptic sessions
  (:mod:`fieldbank.nwbexport`); ``.mot`` / ``.sto`` one haptic session's trace and ``.osim``
  one stored model (:mod:`fieldbank.opensimio`). A ``--format`` that disagrees with the
  suffix, or another suffix, is refused before anything is written;
* nothing is overwritten unless ``force``, and nothing is written through a symbolic link
  (:func:`fieldbank.files.write_new`); every file is written atomically;
* in a directory export each file name is built from stored labels made safe
  (:func:`fieldbank.sanitize.file_component`), and every path is checked to lie inside the
  directory, so a session label such as ``x/../../y`` cannot leave it;
* CSV text is neutralised against formula injection (:meth:`fieldbank.maps.FieldMap.to_csv`).
"""

from __future__ import annotations

import io
import os
from dataclasses import dataclass
from datetime import date
from pathlib import Path

from fieldbank.errors import FieldbankError, StorageError
from fieldbank.files import DISK_FULL_ERRNOS, disk_full_message, write_new
from fieldbank.ingest import write_hdf5
from fieldbank.nwbexport import patient_nwb
from fieldbank.opensimio import COORDINATES, arm_osim, storage_text
from fieldbank.sanitize import file_component
from fieldbank.storage import Database

HDF5_SUFFIXES = (".h5", ".hdf5")
FORMATS = ("hdf5", "csv", "nwb", "mot", "sto", "osim")


class ExportError(FieldbankError, ValueError):
    """An export refused before anything was written (format, existing file, path)."""


@dataclass(frozen=True)
class ExportResult:
    """What an export wrote: the map ids and the files."""

    map_ids: tuple[int, ...]
    files: tuple[str, ...]


def output_format(output: Path, fmt: str | None) -> str:
    """'hdf5', 'csv' (one file) or 'csvdir' from the output's suffix; ``fmt`` must agree."""
    suffix = output.suffix.lower()
    if suffix in HDF5_SUFFIXES:
        found = "hdf5"
    elif suffix == ".csv":
        found = "csv"
    elif suffix in (".nwb", ".mot", ".sto", ".osim"):
        found = suffix[1:]
    elif suffix == "" or output.is_dir():
        found = "csvdir"
    else:
        raise ExportError(f"{output}: unknown export suffix {output.suffix!r}; use .h5 or "
                          ".hdf5 (HDF5), .csv (one map), a directory (one CSV per map), .nwb "
                          "(a patient), .mot/.sto (a haptic trace) or .osim (a model).")
    if fmt is not None and fmt != ("csv" if found == "csvdir" else found):
        raise ExportError(f"{output}: --format {fmt} disagrees with the name, which says "
                          f"{'a CSV directory' if found == 'csvdir' else found}; nothing was "
                          "written.")
    return found


def _write(path: Path, data: bytes | str, force: bool) -> str:
    try:
        write_new(path, data, force)
    except FileExistsError as exc:
        raise ExportError(f"{path}: {exc.strerror}; nothing was written.") from None
    except OSError as exc:
        if exc.errno in DISK_FULL_ERRNOS:
            raise StorageError(disk_full_message(path, exc)) from None
        raise StorageError(f"{path}: cannot write ({exc.strerror}).") from None
    return str(path)


def export_raw(db: Database, sha256: str, output: str | Path, force: bool = False) -> str:
    """Write the source file ``sha256`` exactly as ingested."""
    return _write(Path(output), db.source_bytes(sha256), force)


def export_nwb(db: Database, patient_code: str | None, output: str | Path,
               force: bool = False) -> str:
    """One patient's maps, models, fits and haptic sessions as an NWB file."""
    out = Path(output)
    output_format(out, "nwb")
    if not patient_code:
        raise ExportError(f"{out}: an NWB file holds one subject: give --patient.")
    return _write(out, patient_nwb(db, patient_code), force)


#: Trace columns written under the .osim coordinates' names (fieldbank.opensimio.COORDINATES).
TRACE_COORDINATES = dict(zip(("a_q1_rad", "a_q2_rad"), COORDINATES, strict=True))


def export_trace(db: Database, haptic_session_id: int, output: str | Path,
                 force: bool = False) -> str:
    """A haptic session's recorded trace (every column, with time) as ``.mot``/``.sto``."""
    out = Path(output)
    fmt = output_format(out, None)
    if fmt not in ("mot", "sto"):
        raise ExportError(f"{out}: a trace is written as .mot or .sto.")
    sess = db.get_haptic_session(haptic_session_id)
    traces = {t.name: t for t in db.list_traces(sess.id)}
    if "t_s" not in traces:
        raise StorageError(f"Haptic session {sess.id} has no recorded trace (no t_s).")
    t = db.get_trace_array(traces["t_s"].id)
    cols, units = {}, {}
    for name, tr in traces.items():
        if name == "t_s":
            continue
        # arm A's joint angles under the .osim model's coordinate names, so the table plays
        # on the exported model (export --model); every other column keeps its name
        label = TRACE_COORDINATES.get(name, name)
        cols[label] = db.get_trace_array(tr.id)
        units[label] = str(db.trace_attrs(tr.id).get("unit", ""))
    text = storage_text(f"fieldbank haptic session {sess.id}", t, cols, units)
    return _write(out, text, force)


def export_osim(db: Database, model_id: int, output: str | Path, force: bool = False) -> str:
    """A stored model as an OpenSim ``.osim`` model."""
    out = Path(output)
    if output_format(out, None) != "osim":
        raise ExportError(f"{out}: a model is written as .osim.")
    m = db.get_model(model_id)
    return _write(out, arm_osim(m.params, f"fieldbank_model_{m.id}"), force)


def export_maps(db: Database, output: str | Path, *, patient_code: str | None = None,
                session_label: str | None = None, kind: str | None = None,
                since: date | None = None, until: date | None = None, fmt: str | None = None,
                force: bool = False) -> ExportResult:
    """Export the maps matching every filter (see the module docstring)."""
    out = Path(output)
    form = output_format(out, fmt)
    if form == "nwb":
        return ExportResult(tuple(r.id for r in db.list_maps(patient_code)),
                            (export_nwb(db, patient_code, out, force),))
    if form in ("mot", "sto", "osim"):
        raise ExportError(f"{out}: .{form} is written from a haptic session (--trace ID) or "
                          "a model (--model ID), not from maps.")
    if patient_code is not None:
        db.get_patient(patient_code)  # an unknown patient: the one "not found" message
        if session_label is not None:
            db.get_session(patient_code, session_label)  # its sessions listed
    rows = db.list_maps(patient_code, session_label, kind, since, until)
    if not rows:
        raise StorageError("No map matches these filters; nothing exported.")
    maps = db.get_maps([r.id for r in rows])
    ids = tuple(r.id for r in rows)
    if form == "hdf5":
        extra = [{"patient": r.patient_code, "session": r.session_label,
                  "session_date": str(r.session_date or ""), "fieldbank_map_id": r.id,
                  "source_file": r.source_file, "source_sha256": r.source_sha256}
                 for r in rows]
        buf = io.BytesIO()
        write_hdf5(buf, maps, extra)
        return ExportResult(ids, (_write(out, buf.getvalue(), force),))
    if form == "csv":
        if len(maps) != 1:
            raise ExportError(f"{out}: a CSV file holds one map and {len(maps)} match; give a "
                              "directory (no suffix) for one CSV per map, or an .h5 file.")
        return ExportResult(ids, (_write(out, maps[0].to_csv(), force),))
    root = out.resolve()
    targets = []
    for r in rows:
        name = "_".join(file_component(x) for x in (r.patient_code, r.session_label, r.kind,
                                                     r.id)) + ".csv"
        if os.path.dirname(os.path.normpath(root / name)) != str(root):
            raise ExportError(f"{name}: would be written outside {out}; nothing was written.")
        targets.append(out / name)
    if not force:
        clash = [str(p) for p in targets if os.path.lexists(p)]
        if clash:
            raise ExportError(f"{clash[0]} exists ({len(clash)} file(s) in all); give --force "
                              "to replace them; nothing was written.")
    if out.is_symlink():
        raise ExportError(f"{out}: is a symbolic link; fieldbank does not write through links.")
    out.mkdir(parents=True, exist_ok=True)
    written = tuple(_write(p, m.to_csv(), force) for p, m in zip(targets, maps, strict=True))
    return ExportResult(ids, written)
