"""A patient's database content as one NWB file (pynwb), and its maps read back.

NWB holds one subject per file, so an export is one patient's. The file holds:

* the subject (the pseudonymous code; body mass, height and side in its description; age as
  the open range ``P0Y/``, since fieldbank keeps no ages) and ``session_start_time`` = the
  earliest session date (UTC midnight), every other time relative to it;
* ``intervals/clinical_sessions``: one row per session (label, date; a day long);
* processing module ``maps``: one table per map (``map_<id>``) with columns ``x_m``, ``y_m`` and
  ``fx_n``, ``fy_n`` (postural) or ``kxx_n_per_m`` … ``kyy_n_per_m`` (stiffness), and the
  ``sd_…`` columns when stored; each column's description names its unit; the table's
  description holds kind, frame, sign, velocity, session, source, the map's provenance and id
  as JSON (``fieldbank_map``), which :func:`read_nwb_maps` reads back;
* processing module ``models``: table ``models`` (id, origin, label, parent, parameters as
  JSON) and table ``fitted_parameters`` (fit, model, parameter, value, sd, 95 % low and high,
  basis, unit, identified, reason), with a ``fits`` table (algorithm, seed, cost, status,
  maps);
* haptic sessions: per session and per recorded column a TimeSeries
  ``haptic_<id>_<column>`` in ``acquisition`` with its unit, timed by the session's ``t_s``
  (relative to the session start); ``intervals/haptic_trials``: every trial with its answer
  (kind, block, trial, phase, condition, answer, correct, response time).

``nwbinspector`` finds no critical or error message in such a file (tests/test_measure_io.py).
"""

from __future__ import annotations

import io
import json
import uuid
from datetime import UTC, date, datetime, time
from typing import Any

import numpy as np

from fieldbank.errors import MapError, StorageError
from fieldbank.maps import (
    POSTURAL_COLUMNS,
    POSTURAL_SD_COLUMNS,
    STIFFNESS_COLUMNS,
    STIFFNESS_SD_COLUMNS,
    FieldMap,
)
from fieldbank.measure.budget import ReadBudget
from fieldbank.measure.nwbseries import nwb_bytes, opened
from fieldbank.storage import Database

#: Unit of each exported column (NWB's DynamicTable columns carry it in the description).
COLUMN_UNITS = {"x_m": "m", "y_m": "m", "fx_n": "N", "fy_n": "N", "sd_fx_n": "N",
                "sd_fy_n": "N", **{c: "N/m" for c in STIFFNESS_COLUMNS[2:]},
                **{c: "N/m" for c in STIFFNESS_SD_COLUMNS}}
MAP_TAG = "fieldbank_map"


def _midnight(d: date) -> datetime:
    return datetime.combine(d, time(0, 0), tzinfo=UTC)


def _utc(t: datetime) -> datetime:
    return t.replace(tzinfo=UTC) if t.tzinfo is None else t.astimezone(UTC)


def patient_nwb(db: Database, patient_code: str) -> bytes:
    """Everything stored about ``patient_code`` as the bytes of one NWB file."""
    from hdmf.common import DynamicTable, VectorData
    from pynwb import NWBFile, TimeSeries
    from pynwb.epoch import TimeIntervals
    from pynwb.file import Subject

    patient = db.get_patient(patient_code)
    sessions = db.list_sessions(patient_code)
    maps = db.list_maps(patient_code)
    models = db.list_models(patient_code)
    fits = db.list_fits(patient_code)
    haptic = db.list_haptic_sessions(patient_code)
    if not (maps or models or haptic):
        raise StorageError(f"Patient {patient_code!r} has no maps, models or haptic sessions "
                           "to export.")
    days = [s.session_date for s in sessions if s.session_date is not None]
    starts = [_midnight(d) for d in days] + [_utc(h.started_at) for h in haptic]
    start = min(starts) if starts else _utc(patient.created_at)
    start = start.replace(hour=0, minute=0, second=0, microsecond=0)
    nwb = NWBFile(session_description=f"fieldbank export of patient {patient_code}: maps, "
                                      "models, fits, haptic sessions",
                  identifier=str(uuid.uuid4()), session_start_time=start,
                  source_script="fieldbank", source_script_file_name="fieldbank",
                  experiment_description="postural and stiffness maps of a hypertonic arm")
    nwb.subject = Subject(
        subject_id=patient_code, species="Homo sapiens", age="P0Y/", sex="U",
        description=(f"patient (pseudonymous code); body mass {patient.body_mass_kg:g} kg, "
                     f"height {patient.height_m:g} m, measured side {patient.side}; age not "
                     "kept"))
    # clinical sessions
    table = TimeIntervals(name="clinical_sessions", description="clinical sessions: label "
                          "and date (a day from the date's midnight, UTC)")
    table.add_column("label", "session label")
    table.add_column("date", "session date, ISO 8601 (empty when not recorded)")
    for s in sessions:
        t0 = (_midnight(s.session_date) - start).total_seconds() if s.session_date else 0.0
        table.add_row(start_time=t0, stop_time=t0 + 86400.0, label=s.label,
                      date=str(s.session_date or ""))
    nwb.add_time_intervals(table)
    # maps
    if maps:
        mod = nwb.create_processing_module("maps", "measured postural and stiffness maps, SI "
                                                   "units, as stored")
        for row, m in zip(maps, db.get_maps([r.id for r in maps]), strict=True):
            cols = list(m.columns())
            data = m.table()
            vectors = [VectorData(name=c, description=f"{c} in {COLUMN_UNITS[c]}",
                                  data=data[:, j]) for j, c in enumerate(cols)]
            about: dict[str, object] = {"kind": m.kind, "frame": m.frame, "sign": m.sign,
                    "velocity_m_per_s": list(m.velocity_m_per_s), "session": row.session_label,
                    "session_date": str(row.session_date or ""), "source": m.source,
                    "source_file": row.source_file, "map_id": row.id,
                    "metadata": dict(m.metadata),
                    "units": {c: COLUMN_UNITS[c] for c in cols}}
            mod.add(DynamicTable(name=f"map_{row.id}", description=json.dumps(
                {MAP_TAG: about}, ensure_ascii=False), columns=vectors))
    # models and fits
    if models:
        mod = nwb.create_processing_module("models", "arm models and fits")
        mt = DynamicTable(name="models", description="stored arm models (fieldbank.arm-params "
                                                     "documents, SI units)")
        for name, desc in (("model_id", "model id"), ("origin", "fitted | synthetic | plan"),
                           ("label", "label"), ("parent_id", "parent model id, -1 for none"),
                           ("params_json", "the parameters, JSON (SI units)")):
            mt.add_column(name, desc)
        for md in models:
            mt.add_row(model_id=md.id, origin=md.origin, label=md.label,
                       parent_id=md.parent_id if md.parent_id is not None else -1,
                       params_json=md.params.to_json())
        mod.add(mt)
        if fits:
            ft = DynamicTable(name="fits", description="fits of the patient's maps")
            for name, desc in (("fit_id", "fit id"), ("model_id", "the fitted model"),
                               ("algorithm", "search algorithm"), ("seed", "seed, -1 none"),
                               ("cost", "final cost (weighted least squares, 1)"),
                               ("status", "good | under-determined | poor"),
                               ("map_ids", "maps fitted, JSON list")):
                ft.add_column(name, desc)
            pt = DynamicTable(name="fitted_parameters",
                              description="each fitted parameter with its sd and 95 % interval")
            for name, desc in (("fit_id", "fit id"), ("parameter", "name (km_ef, alpha_ef, "
                                                                   "beta_ef, ...)"),
                               ("value", "fitted value, in unit"), ("sd", "standard deviation"),
                               ("low", "95 % interval, low"), ("high", "95 % interval, high"),
                               ("unit", "N/m (km), N (alpha), 1 (beta), rad (q_rest)"),
                               ("basis", "what the interval rests on"),
                               ("identified", "identified by the maps (else a guess)")):
                pt.add_column(name, desc)
            for fr in fits:
                ft.add_row(fit_id=fr.id, model_id=fr.model_id, algorithm=fr.algorithm,
                           seed=fr.seed if fr.seed is not None else -1, cost=float(fr.cost),
                           status=str(fr.result.get("status", "")),
                           map_ids=json.dumps(list(fr.map_ids)))
                unid = {str(u.get("name")) for u in fr.result.get("unidentified", ())
                        if isinstance(u, dict)}
                for pname, iv in dict(fr.result.get("intervals", {})).items():
                    pt.add_row(fit_id=fr.id, parameter=pname, value=float(iv["value"]),
                               sd=float(iv["sd"]), low=float(iv["low"]),
                               high=float(iv["high"]), unit=_param_unit(pname),
                               basis=str(iv.get("basis", "")), identified=pname not in unid)
            mod.add(ft)
            mod.add(pt)
    # haptic sessions: traces and trials
    trials = TimeIntervals(name="haptic_trials", description="trials of haptic sessions "
                           "(A/B/X, training) with their answers")
    for name, desc in (("haptic_session", "haptic session id"), ("kind", "abx | training"),
                       ("block", "block"), ("trial", "trial in the block"),
                       ("phase", "phase"), ("condition", "what was rendered"),
                       ("answer", "the answer given (empty: none)"),
                       ("correct", "1 correct, 0 wrong, -1 not scored"),
                       ("response_time_s", "response time, s (NaN: none)")):
        trials.add_column(name, desc)
    n_trials = 0
    for h in haptic:
        offset = (_utc(h.started_at) - start).total_seconds()
        traces = {t.name: t for t in db.list_traces(h.id)}
        if "t_s" in traces:
            t_s = np.asarray(db.get_trace_array(traces["t_s"].id), dtype=float) + offset
            first: Any = None
            for name, rec in traces.items():
                if name == "t_s":
                    continue
                arr = np.asarray(db.get_trace_array(rec.id))
                unit = str(db.trace_attrs(rec.id).get("unit", "")) or "n.a."
                ts = TimeSeries(name=f"haptic_{h.id}_{name}", data=arr,
                                timestamps=t_s if first is None else first, unit=unit,
                                description=f"haptic session {h.id}: {name} ({unit}), robot "
                                            "frame, per loop tick")
                first = first if first is not None else ts
                nwb.add_acquisition(ts)
        for tr in db.list_haptic_trials(h.id):
            t0 = offset + (tr.started_s or 0.0)
            t1 = offset + (tr.answered_s if tr.answered_s is not None else
                           (tr.started_s or 0.0)) + 1e-3
            trials.add_row(start_time=t0, stop_time=max(t1, t0 + 1e-3), haptic_session=h.id,
                           kind=tr.kind, block=tr.block, trial=tr.trial, phase=tr.phase,
                           condition=tr.condition, answer=tr.answer or "",
                           correct=-1 if tr.correct is None else int(tr.correct),
                           response_time_s=(float("nan") if tr.response_time_s is None
                                            else tr.response_time_s))
            n_trials += 1
    if n_trials:
        nwb.add_time_intervals(trials)
    return nwb_bytes(nwb)


def _param_unit(name: str) -> str:
    if name.startswith("km"):
        return "N/m"
    if name.startswith("alpha"):
        return "N"
    if name.startswith("q_rest") or name.startswith("q"):
        return "rad"
    return "1"


def has_nwb_maps(data: bytes) -> bool:
    """True when NWB bytes hold a fieldbank export's ``maps`` module."""
    import h5py

    with h5py.File(io.BytesIO(data), "r") as f:
        return "processing/maps" in f


def read_nwb_maps(name: str, data: bytes, budget: ReadBudget | None = None
                  ) -> list[tuple[FieldMap, str]]:
    """The maps of a fieldbank NWB export, each with its location in the file; each map's
    ``session`` (and ``session_date``) of the export in its metadata, so that an export of
    several sessions goes back into them (:mod:`fieldbank.ingest.batch`). Every column is
    charged to ``budget`` by its declared size before it is read."""
    bud = budget or ReadBudget(1 << 30, len(data))
    out = []
    with opened(data) as nwb:
        mod = nwb.processing["maps"]
        for tname in sorted(mod.data_interfaces, key=lambda s: (len(s), s)):
            where = f"{name}:/processing/maps/{tname}"
            tab = mod.data_interfaces[tname]
            for col in getattr(tab, "columns", ()):
                d: Any = getattr(col, "data", None)
                if hasattr(d, "shape") and hasattr(d, "dtype"):
                    bud.charge(int(np.prod(d.shape, dtype=np.float64)) * d.dtype.itemsize,
                               f"{where}/{col.name}")
            try:
                desc = json.loads(tab.description)[MAP_TAG]
                df = tab.to_dataframe()
                kind = str(desc["kind"])
                want = POSTURAL_COLUMNS if kind == "postural" else STIFFNESS_COLUMNS
                sdc = POSTURAL_SD_COLUMNS if kind == "postural" else STIFFNESS_SD_COLUMNS
                pos = df[list(want[:2])].to_numpy(float)
                vals = df[list(want[2:])].to_numpy(float)
                sd = df[list(sdc)].to_numpy(float) if all(c in df for c in sdc) else None
                n = len(pos)
                shape = (n, 2) if kind == "postural" else (n, 2, 2)
                meta = {str(k): str(v) for k, v in dict(desc.get("metadata", {})).items()}
                meta["nwb_map_id"] = str(desc.get("map_id", ""))
                if desc.get("session"):
                    meta["session"] = str(desc["session"])
                    meta["session_date"] = str(desc.get("session_date", ""))
                fm = FieldMap(kind, pos, vals.reshape(shape),
                              None if sd is None else sd.reshape(shape), str(desc["frame"]),
                              str(desc["sign"]), tuple(desc["velocity_m_per_s"]),
                              str(desc.get("source", "")), meta)
            except (KeyError, ValueError, TypeError, MapError) as exc:
                raise MapError(f"{where}: not a fieldbank map table ({exc})") from None
            out.append((fm, where))
    return out
