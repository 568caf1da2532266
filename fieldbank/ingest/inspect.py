"""What a lab file holds, and what ingest would make of it (``fieldbank inspect``).

:func:`inspect_file` reads one file as ingest would — the same format detection, the same
limits — and describes it without storing anything:

* C3D: processor type and storage, point and analog rates, frames, the markers with their
  unit, the analog channels with their units and ranges, the events, the parameter groups;
* NWB: every time series with its path (``acquisition/`` and ``processing/``), type, unit,
  shape, rate and duration, the trials table, the subject, the NWB version;
* KINARM exams: the robot, the trials with their channels and events;
* MATLAB and HDF5: every variable or dataset with its shape and type (and unit);
* CSV: the metadata lines, the header, the number of rows, the encoding;

then what ingest would map with the options given (:func:`fieldbank.ingest.batch.read_file`
without a patient, so without the reach check): the maps, or the refusal — which names what is
missing and the option that maps it. A part that cannot be read is described as such: inspect
never stops at it.
"""

from __future__ import annotations

import io
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fieldbank.errors import FileRefused, MapError, Problem
from fieldbank.files import read_regular_file
from fieldbank.ingest.batch import FORMAT_NAMES, detect_format, read_file
from fieldbank.ingest.csvfmt import decode_text
from fieldbank.ingest.limits import IngestLimits, LimitExceeded
from fieldbank.ingest.matfmt import inflate_mat5
from fieldbank.ingest.options import ReadOptions
from fieldbank.measure.budget import ReadBudget
from fieldbank.measure.c3dfile import describe_param, read_c3d
from fieldbank.measure.kinarm import exam_kind, exam_members
from fieldbank.measure.kinarmbin import read_exam
from fieldbank.measure.nwbseries import all_series


@dataclass
class Inspection:
    """One file described: ``sections`` (title → lines) for people, ``data`` for --json."""

    file: str
    format: str | None
    data: dict[str, Any] = field(default_factory=dict)
    sections: dict[str, list[str]] = field(default_factory=dict)
    readable: bool = True

    def to_json_dict(self) -> dict[str, Any]:
        return {"file": self.file, "format": self.format, "readable": self.readable,
                **self.data}

    def lines(self) -> list[str]:
        out = [f"{self.file}: {FORMAT_NAMES.get(self.format or '', 'unknown format')}"]
        for title, rows in self.sections.items():
            out.append(f"  {title}:")
            out += [f"    {r}" for r in rows]
        return out


def inspect_file(path: str | Path, limits: IngestLimits | None = None,
                 options: ReadOptions | None = None) -> Inspection:
    """Describe the file at ``path`` (see the module docstring)."""
    lim = limits or IngestLimits()
    p = Path(path)
    try:
        data = read_regular_file(p, lim.max_file_bytes, lim.hint("max_file_bytes"))
    except FileRefused as exc:
        return Inspection(p.name, None, {"error": str(exc)}, {"refused": [str(exc)]}, False)
    fmt = detect_format(data)
    ins = Inspection(p.name, fmt, {"bytes": len(data)})
    budget = ReadBudget(lim.max_decompressed_bytes, len(data), lim.max_compression_ratio,
                        lim.hint("max_decompressed_bytes"), lim.hint("max_compression_ratio"))
    describe = {"c3d": _c3d, "nwb": _nwb, "kinarm": _kinarm, "mat5": _mat5, "mat73": _h5,
                "hdf5": _h5, "csv": _csv}.get(fmt or "")
    if describe is None:
        ins.readable = False
        ins.sections["content"] = ["not a format fieldbank reads (map CSV, fieldbank HDF5, "
                                   "MATLAB .mat, NWB, C3D, KINARM exam)"]
        return ins
    try:
        describe(ins, data, budget)
    except MapError as exc:
        ins.readable = False
        ins.sections["unreadable"] = [str(exc)]
        ins.data["error"] = str(exc)
    except Exception as exc:  # a damaged file: described, never a traceback
        ins.readable = False
        msg = f"the file could not be read as {FORMAT_NAMES[fmt or 'csv']} ({type(exc).__name__})"
        ins.sections["unreadable"] = [msg]
        ins.data["error"] = msg
    _verdict(ins, p.name, data, lim, options)
    return ins


def _verdict(ins: Inspection, name: str, data: bytes, lim: IngestLimits,
             options: ReadOptions | None) -> None:
    """What ingest would store: its maps, or every problem (with the options that map)."""
    try:
        inc, probs = read_file(name, data, None, "", lim, options)
    except Exception as exc:  # inspect describes; it never stops at the verdict
        probs, inc = [Problem(name, f"ingest would stop: {type(exc).__name__}")], None
    if inc is not None:
        rows = [f"{m.kind}{'' if m.speed_m_per_s == 0 else f' at {m.speed_m_per_s:g} m/s'}: "
                f"{m.n} postures" for m in inc.maps]
        ins.sections["ingest would store"] = rows
        ins.data["ingest"] = {"maps": [{"kind": m.kind, "postures": m.n,
                                        "velocity_m_per_s": list(m.velocity_m_per_s)}
                                       for m in inc.maps]}
    else:
        reasons = [str(p).removeprefix(f"{name}: ") for p in probs]
        ins.sections["ingest would refuse it"] = reasons
        ins.data["ingest"] = {"refused": reasons}


def _c3d(ins: Inspection, data: bytes, budget: ReadBudget) -> None:
    f = read_c3d(data, budget.limit)
    dur = f.frames / f.point_rate_hz if f.point_rate_hz > 0 else 0.0
    ins.sections["file"] = [f"processor {f.processor}, {f.storage} storage",
                            f"{f.frames} frames at {f.point_rate_hz:g} Hz ({dur:.3g} s), "
                            f"first frame {f.first_frame}", *f.notes]
    ins.sections[f"markers ({len(f.point_labels)}, unit {f.point_unit or 'none'!r})"] = \
        [", ".join(f.point_labels)] if f.point_labels else ["none (no point data)"]
    rows = []
    for i, (lab, unit) in enumerate(zip(f.analog_labels, f.analog_units, strict=True)):
        v = f.analog[i]
        fin = v[np.isfinite(v)]
        rng = f"{fin.min():.4g} … {fin.max():.4g}" if fin.size else "no numbers"
        flat = " (flat)" if fin.size and fin.min() == fin.max() else ""
        rows.append(f"{lab} ({unit or 'no unit'}): {rng}{flat}")
    ins.sections[f"analog channels ({len(f.analog_labels)} at {f.analog_rate_hz:g} Hz)"] = \
        rows or ["none (markers only)"]
    events = f.events()
    ins.sections[f"events ({len(events)})"] = [f"{lab} at {t:.4g} s" + (f" ({c})" if c else "")
                                               for lab, t, c in events[:50]] or ["none"]
    ins.sections["parameter groups"] = [", ".join(sorted(f.groups))]
    ins.data["c3d"] = {
        "processor": f.processor, "storage": f.storage, "frames": f.frames,
        "point_rate_hz": f.point_rate_hz, "analog_rate_hz": f.analog_rate_hz,
        "markers": f.point_labels, "marker_unit": f.point_unit,
        "analog": [{"label": lab, "unit": u} for lab, u in zip(f.analog_labels,
                                                                f.analog_units, strict=True)],
        "events": [{"label": lab, "time_s": t, "context": c} for lab, t, c in events],
        "groups": {g: {n: describe_param(q) for n, q in ps.items() if n in (
            "USED", "RATE", "UNITS", "SCALE", "TYPE", "FORMAT")} for g, ps in f.groups.items()},
        "notes": f.notes}


def _nwb(ins: Inspection, data: bytes, budget: ReadBudget) -> None:
    import h5py
    from pynwb import NWBHDF5IO

    with h5py.File(io.BytesIO(data), "r") as h5:
        version = h5.attrs.get("nwb_version", "")
        version = version.decode() if isinstance(version, bytes) else str(version)
        with NWBHDF5IO(file=h5, mode="r", load_namespaces=True) as io_:
            nwb = io_.read()
            series = all_series(nwb)
            ins.sections["file"] = [f"NWB {version}", f"session: {nwb.session_description}",
                                    f"started {nwb.session_start_time.isoformat()}"]
            ins.sections[f"time series ({len(series)})"] = [i.line() for i, _ in series] or \
                ["none in acquisition/ or processing/"]
            trials = nwb.trials
            ins.sections["trials"] = [f"{len(trials)} rows; columns "
                                      f"{', '.join(trials.colnames)}"] if trials is not None \
                else ["no trials table"]
            subject = nwb.subject
            ins.sections["subject"] = [f"{subject.subject_id} ({subject.species})"] \
                if subject is not None else ["none"]
            mods = {m: sorted(nwb.processing[m].data_interfaces) for m in nwb.processing}
            ins.sections["processing modules"] = [f"{m}: {', '.join(v)}" for m, v in
                                                  mods.items()] or ["none"]
            ins.data["nwb"] = {
                "version": version, "series": [i.to_json_dict() for i, _ in series],
                "trials": None if trials is None else {"rows": len(trials),
                                                       "columns": list(trials.colnames)},
                "subject": None if subject is None else str(subject.subject_id),
                "processing": mods}
    del budget


def _kinarm(ins: Inspection, data: bytes, budget: ReadBudget) -> None:
    if exam_kind(data) == "binary":
        exam = read_exam(ins.file, data, budget)
        ins.sections["exam"] = [f".kinarm (binary channels), robot {exam.robot}, arm "
                                f"{exam.arm}"] + [f"{k}: {v}" for k, v in exam.info.items()
                                                  if k in ("protocol", "dex_ver", "posture")]
        rows = []
        for tr in exam.trials:
            chans = ", ".join(f"{k}{'' if not c.strings else ' (' + c.strings[-1] + ')'}"
                              for k, c in sorted(tr.channels.items()))
            rows.append(f"{tr.folder}: {tr.n} samples; {chans}; events "
                        f"{', '.join(e for e, _ in tr.events) or 'none'}")
        ins.sections[f"trials ({len(exam.trials)})"] = rows
        ins.data["kinarm"] = {"format": "binary", "robot": exam.robot, "info": exam.info,
                              "trials": [{"folder": t.folder, "samples": t.n,
                                          "channels": sorted(t.channels),
                                          "events": [list(e) for e in t.events]}
                                         for t in exam.trials]}
        return
    z, members = exam_members(ins.file, data, budget)
    with z:
        names = [m.filename for m in members]
    ins.sections["exam"] = [f"Dexterit-E ZIP of C3D trials: {len(names)} members"]
    ins.sections["members"] = names[:50]
    ins.data["kinarm"] = {"format": "c3d", "members": names}


def _mat5(ins: Inspection, data: bytes, budget: ReadBudget) -> None:
    import scipy.io

    try:
        image, _ = inflate_mat5(ins.file, data, IngestLimits(
            max_decompressed_bytes=budget.limit, max_compression_ratio=budget.max_ratio))
    except LimitExceeded as exc:
        raise MapError(str(exc)) from None
    rows = [f"{n}: {'×'.join(map(str, shape))} {cls}"
            for n, shape, cls in scipy.io.whosmat(io.BytesIO(image))]
    ins.sections["variables"] = rows or ["none"]
    ins.data["variables"] = rows


def _h5(ins: Inspection, data: bytes, budget: ReadBudget) -> None:
    import h5py

    rows: list[str] = []

    def visit(name: str, obj: Any) -> None:
        if len(rows) >= 200:
            return
        if isinstance(obj, h5py.Dataset):
            unit = obj.attrs.get("unit", obj.attrs.get("MATLAB_class", ""))
            unit = unit.decode() if isinstance(unit, bytes) else str(unit)
            rows.append(f"/{name}: {obj.shape} {obj.dtype}" + (f" ({unit})" if unit else ""))
        else:
            rows.append(f"/{name}/")

    with h5py.File(io.BytesIO(data), "r") as f:
        attrs = {k: (v.decode() if isinstance(v, bytes) else str(v))[:80]
                 for k, v in f.attrs.items()}
        f.visititems(visit)
    ins.sections["attributes"] = [f"{k}: {v}" for k, v in attrs.items()] or ["none"]
    ins.sections["datasets"] = rows or ["none"]
    ins.data["datasets"] = rows
    del budget


def _csv(ins: Inspection, data: bytes, budget: ReadBudget) -> None:
    text, encoding, why = decode_text(data)
    if text is None:
        raise MapError(why)
    lines = [ln for ln in text.splitlines() if ln.strip()]
    meta = [ln for ln in lines if ln.lstrip().startswith("#")]
    body = [ln for ln in lines if not ln.lstrip().startswith("#")]
    ins.sections["text"] = [f"encoding {encoding or 'UTF-8'}", f"{len(meta)} metadata or "
                            f"comment line(s), {max(0, len(body) - 1)} data row(s)"]
    ins.sections["metadata"] = [m.strip() for m in meta[:20]] or ["none"]
    ins.sections["header"] = [body[0][:300]] if body else ["none"]
    ins.data["csv"] = {"encoding": encoding or "utf-8", "metadata": meta[:50],
                       "header": body[0] if body else "", "rows": max(0, len(body) - 1)}
    del budget
