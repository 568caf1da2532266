"""Ingest of a batch of files: detect, read, validate every file, then store all at once.

1. Each file is read whole - only a regular file, at most ``max_file_bytes``
   (:func:`fieldbank.files.read_regular_file`: a FIFO, a device or a link to one is refused
   without being read); its SHA-256 is taken over the exact bytes.
2. The format is detected from the content (not the extension): fieldbank HDF5, MATLAB v5,
   MATLAB v7.3, CSV text, or a raw recording — NWB (an HDF5 file with ``nwb_version``) or C3D
   — whose maps the estimator computes (:mod:`fieldbank.ingest.rawfmt`). Readers are bounded
   (:mod:`fieldbank.ingest.limits`); anything a
   reader did not foresee in a damaged file is still a located problem, never a traceback.
3. Every map of every file is validated against the patient's arm and the plausibility
   limits, and must not name another patient; every problem of every file is collected,
   located (at most ``max_problems`` listed per file and per batch, the rest counted). If
   there is any, :class:`~fieldbank.errors.ValidationError` lists them and nothing is written.
4. Otherwise all files go to :meth:`Database.ingest_files` in one transaction: the batch lands
   whole or not at all. A file already stored (same SHA-256) is reported as a duplicate.
"""

from __future__ import annotations

import hashlib
import io
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from datetime import date
from pathlib import Path
from typing import Any

from fieldbank.errors import FileRefused, Problem, ValidationError
from fieldbank.files import read_regular_file
from fieldbank.ingest.csvfmt import read_csv
from fieldbank.ingest.hdf5fmt import read_hdf5
from fieldbank.ingest.limits import DEFAULT_LIMITS, IngestLimits
from fieldbank.ingest.matfmt import read_mat5, read_mat73
from fieldbank.ingest.options import ReadOptions
from fieldbank.ingest.parsed import ParsedMap, validate_map
from fieldbank.ingest.rawfmt import read_c3d, read_kinarm, read_nwb
from fieldbank.maps import FieldMap
from fieldbank.measure.c3draw import is_c3d
from fieldbank.measure.kinarm import is_kinarm_zip
from fieldbank.model import Arm
from fieldbank.storage import Database, IncomingFile, IngestOutcome

HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
FORMATS = ("csv", "hdf5", "mat5", "mat73", "nwb", "c3d", "kinarm")
FORMAT_NAMES = {"csv": "CSV", "hdf5": "HDF5", "mat5": "MATLAB v5", "mat73": "MATLAB v7.3",
                "nwb": "NWB", "c3d": "C3D", "kinarm": "KINARM exam"}

Reader = Callable[[str, bytes, IngestLimits, Mapping[str, str], Mapping[str, str]],
                  tuple[list[ParsedMap], list[Problem]]]
#: Map files: (name, data, limits, metadata defaults, column names).
READERS: dict[str, Reader] = {"csv": read_csv, "hdf5": read_hdf5, "mat5": read_mat5,
                              "mat73": read_mat73}
RawReader = Callable[[str, bytes, IngestLimits, Arm | None, ReadOptions | None],
                     tuple[list[ParsedMap], list[Problem]]]
#: Raw recordings: the estimator needs the patient's arm and the user's options.
RAW_READERS: dict[str, RawReader] = {"nwb": read_nwb, "c3d": read_c3d, "kinarm": read_kinarm}


def _is_nwb(data: bytes) -> bool:
    import h5py

    try:
        with h5py.File(io.BytesIO(data), "r") as f:
            return "nwb_version" in f.attrs
    except (OSError, ValueError):
        return False


def detect_format(data: bytes) -> str | None:
    """'csv', 'hdf5', 'mat5', 'mat73', or None when the content is none of them."""
    if data.startswith(b"MATLAB 7.3 MAT-file"):
        return "mat73"
    if data.startswith(b"MATLAB 5.0 MAT-file"):
        return "mat5"
    if data.startswith(HDF5_SIGNATURE):
        return "nwb" if _is_nwb(data) else "hdf5"
    if is_c3d(data):
        return "c3d"
    if is_kinarm_zip(data):
        return "kinarm"
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):   # UTF-16 text (csvfmt decodes it)
        return "csv"
    if data[:1024].find(b"\0") >= 0:
        return None
    try:
        head = data[:4096].decode("utf-8-sig", errors="strict")
    except UnicodeDecodeError:
        head = data[:4095].decode("utf-8-sig", errors="ignore")
    first = next((ln.strip() for ln in head.splitlines() if ln.strip()), "")
    if first.startswith("#") or any(d in first for d in ",;\t"):
        return "csv"
    return None


@dataclass(frozen=True)
class IngestReport:
    """Result of a batch: one outcome per file, in the order given."""

    patient_code: str
    session_label: str
    dry_run: bool
    outcomes: tuple[IngestOutcome, ...]

    @property
    def n_stored(self) -> int:
        return sum(o.status == "stored" for o in self.outcomes)

    @property
    def n_duplicates(self) -> int:
        return sum(o.status == "duplicate" for o in self.outcomes)

    def to_json_dict(self) -> dict[str, Any]:
        return {
            "patient": self.patient_code,
            "session": self.session_label,
            "dry_run": self.dry_run,
            "files": [
                {"file": o.file_name, "sha256": o.sha256, "status": o.status,
                 "maps": o.n_maps, "map_ids": list(o.map_ids)}
                for o in self.outcomes
            ],
            "stored": self.n_stored,
            "duplicates": self.n_duplicates,
        }


def read_file(name: str, data: bytes, arm: Arm | None, patient: str = "",
              limits: IngestLimits = DEFAULT_LIMITS,
              options: ReadOptions | None = None) -> tuple[IncomingFile | None,
                                                           list[Problem]]:
    """Detect, read and validate one file's bytes; the IncomingFile or its problems.

    ``patient``: the code the file is ingested for; a file whose metadata names another
    patient is refused. At most ``limits.max_problems`` problems are returned, the last one
    saying how many more there were.
    """
    if len(data) > limits.max_file_bytes:
        return None, [Problem(name, f"{len(data):,} bytes, larger than "
                              f"{limits.max_file_bytes:,} {limits.hint('max_file_bytes')}")]
    sha = hashlib.sha256(data).hexdigest()
    fmt = detect_format(data)
    if fmt is None:
        return None, [Problem(name, "unknown format: expected map CSV, fieldbank HDF5, "
                              "MATLAB .mat v5/v7.3, or a raw NWB, C3D or KINARM recording")]
    opts = options or ReadOptions()
    misplaced = _misplaced_options(fmt, opts)
    if misplaced:
        return None, [Problem(name, misplaced)]
    try:
        if fmt in RAW_READERS:
            parsed, problems = RAW_READERS[fmt](name, data, limits, arm, opts)
        else:
            parsed, problems = READERS[fmt](name, data, limits, opts.csv_defaults(),
                                            opts.columns)
        if len(parsed) > limits.max_maps:
            return None, [Problem(name, f"{len(parsed):,} maps, more than {limits.max_maps:,} "
                                  f"{limits.hint('max_maps')}")]
        maps = []
        for pm in parsed:
            fm, probs = validate_map(pm, arm, patient, limits)
            problems += probs
            if fm is not None:
                maps.append(fm)
    except MemoryError:
        return None, [Problem(name, f"too large to read as {FORMAT_NAMES[fmt]} in the memory "
                              "available; refused")]
    except Exception as exc:  # a damaged file no reader check foresaw: still a message
        return None, [Problem(name, f"unreadable {FORMAT_NAMES[fmt]} file: the reader met "
                              f"something it does not understand ({type(exc).__name__} at "
                              f"{_where(exc)}); 'fieldbank inspect' shows what it holds")]
    if not problems and not maps:
        problems.append(Problem(name, "no map in file"))
    if problems:
        return None, _capped(problems, limits.max_problems, name)
    return IncomingFile(name, sha, fmt, data, tuple(maps), _own_sessions(maps)), []


def _misplaced_options(fmt: str, opts: ReadOptions) -> str:
    """Why an option given does not apply to a file of this format ('' when all do): an
    option is refused in words, never silently ignored."""
    if fmt in RAW_READERS:
        wrong = [f"--{k}" for k in ("kind", "velocity") if k in opts.defaults or
                 (k == "velocity" and "velocity_vector_m_per_s" in opts.defaults)]
        if wrong:
            return (f"{' and '.join(dict.fromkeys(wrong))} do not apply to a raw "
                    f"{FORMAT_NAMES[fmt]} recording: the estimator makes every map its trials "
                    "hold (kind and velocity from the trials); remove them for this file")
        return ""
    raw = opts.raw_only()
    if raw:
        return (f"{', '.join(raw)} apply to raw recordings (NWB, C3D, KINARM) only; this is "
                f"a {FORMAT_NAMES[fmt]} map file")
    return ""


def _own_sessions(maps: list[FieldMap]) -> tuple[tuple[str, date | None] | None, ...]:
    """The session each map of an NWB export was exported from (it goes back there), else
    None (the batch's session)."""
    out: list[tuple[str, date | None] | None] = []
    for m in maps:
        label = m.metadata.get("session", "") if "nwb_map_id" in m.metadata else ""
        if not label:
            out.append(None)
            continue
        try:
            day = date.fromisoformat(m.metadata.get("session_date", "")) \
                if m.metadata.get("session_date") else None
        except ValueError:
            day = None
        out.append((label, day))
    return tuple(out) if any(out) else ()


def _where(exc: BaseException) -> str:
    """The innermost fieldbank function an unexpected error came from (for a report)."""
    tb = exc.__traceback__
    last = "the reader"
    while tb is not None:
        code = tb.tb_frame.f_code
        if "fieldbank" in code.co_filename:
            last = code.co_name
        tb = tb.tb_next
    return last


def _capped(problems: list[Problem], most: int, where: str) -> list[Problem]:
    """At most ``most`` problems, then one counting the rest."""
    if len(problems) <= most:
        return problems
    return [*problems[:most], Problem(where, f"... and {len(problems) - most:,} more "
                                      "problem(s) in this file not listed")]


def ingest_paths(
    db: Database,
    paths: Sequence[str | Path],
    patient_code: str,
    session_label: str,
    session_date: date | None = None,
    dry_run: bool = False,
    progress: Callable[[int, int, str], None] | None = None,
    limits: IngestLimits = DEFAULT_LIMITS,
    options: ReadOptions | None = None,
) -> IngestReport:
    """Validate then store a batch of files for one patient's session (see module docstring).

    ``progress(done, total, file_name)`` is called as files are read and as they are stored;
    ``options`` supplies what plain files lack (:class:`~fieldbank.ingest.options.ReadOptions`).
    """
    blobs: list[tuple[str, bytes | None]] = []
    refused: list[Problem] = []
    for p in paths:
        path = Path(p)
        try:
            blobs.append((str(path), read_regular_file(path, limits.max_file_bytes,
                                                       limits.hint("max_file_bytes"))))
        except FileRefused as exc:
            refused.append(Problem(str(path), str(exc).removeprefix(f"{path}: ")))
            blobs.append((str(path), None))
    return _ingest(db, blobs, refused, patient_code, session_label, session_date, dry_run,
                   progress, limits, options)


def ingest_data(db: Database, blobs: Sequence[tuple[str, bytes]], patient_code: str,
                session_label: str, session_date: date | None = None,
                limits: IngestLimits = DEFAULT_LIMITS,
                options: ReadOptions | None = None) -> IngestReport:
    """As :func:`ingest_paths`, for files already in memory as (name, bytes)."""
    return _ingest(db, list(blobs), [], patient_code, session_label, session_date, False,
                   None, limits, options)


def _ingest(db: Database, blobs: Sequence[tuple[str, bytes | None]], problems: list[Problem],
            patient_code: str, session_label: str, session_date: date | None, dry_run: bool,
            progress: Callable[[int, int, str], None] | None, limits: IngestLimits,
            options: ReadOptions | None) -> IngestReport:
    patient = db.get_patient(patient_code)
    arm = Arm.from_params(patient.arm_params())
    files: list[IncomingFile] = []
    bad: set[str] = {p.location for p in problems}
    total = len(blobs)
    for k, (where, data) in enumerate(blobs):
        if data is None:
            continue
        inc, probs = read_file(Path(where).name, data, arm, patient.code, limits, options)
        problems += probs
        if probs:
            bad.add(where)
        if inc is not None:
            files.append(inc)
        if progress is not None:
            progress(k + 1, 2 * total, Path(where).name)
    if problems:
        n = sum(not p.reason.startswith("... and ") for p in problems)
        raise ValidationError(problems, header=f"Nothing was stored: {n} problem(s) in "
                              f"{len(bad)} file(s):", max_shown=limits.max_problems)
    if dry_run:
        seen: set[str] = set()
        outcomes = []
        for f in files:
            dup = f.sha256 in seen or db.has_source(f.sha256)
            seen.add(f.sha256)
            outcomes.append(IngestOutcome(f.file_name, f.sha256,
                                          "duplicate" if dup else "would-store", (),
                                          len(f.maps)))
        return IngestReport(patient.code, session_label, True, tuple(outcomes))
    done = [total]

    def stored(outcome: IngestOutcome) -> None:
        done[0] += 1
        if progress is not None:
            progress(done[0], 2 * total, outcome.file_name)

    outcomes = db.ingest_files(patient.code, session_label, files, session_date,
                               progress=stored)
    return IngestReport(patient.code, session_label, False, tuple(outcomes))
