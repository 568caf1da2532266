"""Raw recordings as NWB files (pynwb): what the robot measured, and what labs send in.

Written (:func:`write_recording`), one file per measurement:

* ``acquisition/hand_position`` — :class:`pynwb.behavior.SpatialSeries` (x, y), unit m, with
  its ``reference_frame`` (the shoulder frame of BRIEF §3);
* ``acquisition/hand_velocity`` — TimeSeries (vx, vy), unit m/s;
* ``acquisition/hand_force`` — TimeSeries (fx, fy), unit N, the force of the arm on the handle;
* ``acquisition/commanded_force`` — TimeSeries, unit N (the robot's own, when present);
* the ``trials`` table: start and stop time, and the columns ``role``, ``posture``,
  ``window_start``, ``window_stop`` (s), ``vx``, ``vy`` (m/s, passes), ``label`` and
  ``status`` (why the robot dropped a trial, empty when kept);
* ``postures`` (scratch): the planned grid, m; ``protocol`` (scratch): the protocol's settings
  (grid, displacement, directions, holds, transient window, speeds), JSON, which every map
  estimated from the file carries as its ``protocol`` provenance;
* the patient code (scratch ``patient``), session description and start time, the device.

Read (:func:`read_recording`): the same layout, and a lab's own NWB file when it names its
channels: any TimeSeries of shape (N, 2) or more columns (x and y first), in ``acquisition/``
or a processing module, found by name or path (:mod:`fieldbank.measure.nwbseries`), converted
from its own unit with its ``conversion`` and ``offset``; a series without a real unit
(pynwb's ``unknown``, an extension's ``ADDME``) is refused as such unless ``--unit`` gives it
(:mod:`fieldbank.measure.channels`). Every dataset is checked by its declared size before it
is read (:class:`fieldbank.measure.budget.ReadBudget`). Without velocity the velocity is
differentiated from the position (said in the provenance); without a trials table, holds are
found by segmentation (:func:`fieldbank.measure.segment.find_holds`); a trials table without
fieldbank's columns gives its rows' spans, the roles found by position.
"""

from __future__ import annotations

import uuid
from collections.abc import Mapping
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from typing import Any

import numpy as np

from fieldbank.errors import MapError
from fieldbank.measure.budget import ReadBudget
from fieldbank.measure.channels import unit_factor
from fieldbank.measure.nwbseries import (
    SeriesInfo,
    SeriesMissing,
    all_series,
    find,
    nwb_bytes,
    opened,
)
from fieldbank.measure.recording import ChannelProblems, Recording, Trial, derive_velocity
from fieldbank.measure.segment import holds_in_spans

NWB_SIGNATURE = b"\x89HDF\r\n\x1a\n"
REFERENCE_FRAME = ("shoulder frame (BRIEF §3): origin at the shoulder, +x to the patient's "
                   "right, +y forward")


@dataclass(frozen=True)
class RecordingInfo:
    """Who and what a written recording is about."""

    patient: str
    session: str
    device: str = "fieldbank"
    description: str = "arm on a robot handle: holds, displacements and passes"
    start_time: datetime | None = None
    #: The protocol's settings (``fieldbank.measure.protocol.ProtocolConfig``), JSON text.
    protocol_json: str = ""


def write_recording(rec: Recording, info: RecordingInfo,
                    commanded_force_n: np.ndarray | None = None,
                    postures_m: np.ndarray | None = None) -> bytes:
    """The recording as the bytes of an NWB file."""
    from hdmf.backends.hdf5.h5_utils import H5DataIO
    from pynwb import NWBFile, TimeSeries
    from pynwb.behavior import SpatialSeries
    from pynwb.file import Subject

    start = info.start_time or datetime.now(UTC)
    nwb = NWBFile(session_description=f"{info.description}; session {info.session}",
                  identifier=str(uuid.uuid4()), session_start_time=start,
                  session_id=info.session, source_script="fieldbank",
                  source_script_file_name="fieldbank")
    # fieldbank keeps no ages: 'P0Y/' is NWB's open range "0 years or older", i.e. unknown
    nwb.subject = Subject(subject_id=info.patient, species="Homo sapiens", age="P0Y/",
                          sex="U", description="patient (pseudonymous code); age not kept")
    dev = nwb.create_device(name="robot", description=info.device)
    del dev
    t = rec.t_s

    def data(a: np.ndarray) -> H5DataIO:
        return H5DataIO(np.asarray(a, dtype=np.float64), compression="gzip",
                        compression_opts=4, shuffle=True)

    nwb.add_acquisition(SpatialSeries(
        name="hand_position", data=data(rec.position_m), timestamps=data(t),
        reference_frame=REFERENCE_FRAME, unit="meters",
        description="hand (handle) position, shoulder frame; columns x, y",
        comments=f"channels: {rec.channels.get('x', 'x')}, {rec.channels.get('y', 'y')}"))
    nwb.add_acquisition(TimeSeries(
        name="hand_velocity", data=data(rec.velocity_m_per_s),
        timestamps=nwb.acquisition["hand_position"],
        unit="m/s",
        description="hand velocity, shoulder frame; columns vx, vy"
        + (" (differentiated from the position)" if rec.velocity_derived else "")))
    nwb.add_acquisition(TimeSeries(
        name="hand_force", data=data(rec.force_n), timestamps=nwb.acquisition["hand_position"],
        unit="N", description="force of the arm on the handle (arm-on-handle), shoulder "
                              "frame; columns fx, fy"))
    if commanded_force_n is not None:
        nwb.add_acquisition(TimeSeries(
            name="commanded_force", data=data(commanded_force_n),
            timestamps=nwb.acquisition["hand_position"], unit="N",
            description="force the host commanded to the robot's motors, shoulder frame"))
    if info.protocol_json:
        nwb.add_scratch(info.protocol_json, name="protocol",
                        description="the measuring protocol's settings (SI units), JSON")
    if postures_m is not None and len(postures_m):
        nwb.add_scratch(np.asarray(postures_m, dtype=float), name="postures",
                        description="planned posture grid, m, shoulder frame; rows x, y")
    for name, desc in (("role", "base | displaced | pass"),
                       ("posture", "index of the posture (-1: a pass)"),
                       ("window_start", "start of the window the estimator reads, s"),
                       ("window_stop", "end of the window the estimator reads, s"),
                       ("vx", "x velocity of a pass, m/s"), ("vy", "y velocity of a pass, m/s"),
                       ("label", "what the trial is, in words"),
                       ("status", "why the robot dropped the trial; empty when kept")):
        nwb.add_trial_column(name=name, description=desc)
    for tr in rec.trials:
        nwb.add_trial(start_time=tr.start_s, stop_time=tr.stop_s, role=tr.role,
                      posture=tr.posture, window_start=tr.window_s[0],
                      window_stop=tr.window_s[1], vx=tr.velocity_m_per_s[0],
                      vy=tr.velocity_m_per_s[1], label=tr.label, status=tr.status)
    return nwb_bytes(nwb)


def _si(role: str, info: SeriesInfo, ts: Any, budget: ReadBudget, units: Mapping[str, str],
        quantity: str) -> np.ndarray:
    """The series' first two columns in SI (its unit, ``conversion`` and ``offset``)."""
    where = info.path
    data = budget.read_dataset(ts.data, where) if hasattr(ts.data, "dtype") and \
        hasattr(ts.data, "id") else np.asarray(ts.data)
    arr = np.asarray(data, dtype=float)
    if arr.ndim != 2 or arr.shape[1] < 2:
        raise MapError(f"{where}: shape {arr.shape}; the {role} needs (N, 2) — x and y in "
                       "columns")
    scale, _unit = unit_factor({"position": "x", "velocity": "vx", "force": "fx"}[role],
                               info.unit, units, where)
    conv = float(getattr(ts, "conversion", 1.0) or 1.0)
    off = float(getattr(ts, "offset", 0.0) or 0.0)
    del quantity
    return np.asarray((arr[:, :2] * conv + off) * scale, dtype=float)


def _times(info: SeriesInfo, ts: Any, n: int, budget: ReadBudget) -> np.ndarray:
    stamps = getattr(ts, "timestamps", None)
    if stamps is not None:
        if hasattr(stamps, "timestamps"):   # linked to another series
            stamps = stamps.timestamps
        t = np.asarray(budget.read_dataset(stamps, f"{info.path}/timestamps")
                       if hasattr(stamps, "id") else stamps, dtype=float)
    else:
        rate = float(ts.rate)
        t = float(getattr(ts, "starting_time", 0.0) or 0.0) + np.arange(n) / rate
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        k = int(back[0])
        raise MapError(f"{info.path}: time runs backwards or stands still at sample {k + 1} "
                       f"({t[k]:.6g} s, then {t[k + 1]:.6g} s; {back.size} place(s) in all): "
                       "the timestamps cannot order the samples")
    return t


def read_recording(name: str, data: bytes, channels: Mapping[str, str] | None = None,
                   units: Mapping[str, str] | None = None, budget: ReadBudget | None = None
                   ) -> tuple[Recording, np.ndarray | None, dict[str, str]]:
    """A recording, its planned postures (or None) and provenance from NWB bytes.

    ``channels`` maps 'position', 'velocity', 'force' to series names or paths anywhere in the
    file (default hand_position, hand_velocity, hand_force); ``units`` gives the unit of a
    series that states none. Every dataset is charged to ``budget`` by its declared size before
    it is read. Raises MapError naming the file and series; a missing position and force are
    reported together (ChannelProblems).
    """
    bud = budget or ReadBudget(1 << 30, len(data))
    given = dict(channels or {})
    names = {"position": "hand_position", "velocity": "hand_velocity", "force": "hand_force",
             **given}
    with opened(data) as nwb:
        series = all_series(nwb)
        found: dict[str, tuple[SeriesInfo, Any]] = {}
        reasons = []
        for role in ("position", "force", "velocity"):
            try:
                found[role] = find(nwb, role if role != "position" else "hand position",
                                   names[role], role, series)
            except SeriesMissing as exc:
                if role != "velocity" or role in given:
                    reasons.append(f"{name}: {exc}")
        if reasons:
            raise ChannelProblems(reasons)
        pinfo, pos_ts = found["position"]
        finfo, force_ts = found["force"]
        try:
            pos = _si("position", pinfo, pos_ts, bud, dict(units or {}), "length")
        except ValueError as exc:
            reasons.append(f"{name}: {exc}")
        try:
            force = _si("force", finfo, force_ts, bud, dict(units or {}), "force")
        except ValueError as exc:
            reasons.append(f"{name}: {exc}")
        if reasons:
            raise ChannelProblems(reasons)
        t = _times(pinfo, pos_ts, pos.shape[0], bud)
        derived = "velocity" not in found
        if not derived:
            vinfo, vel_ts = found["velocity"]
            try:
                vel = _si("velocity", vinfo, vel_ts, bud, dict(units or {}), "speed")
            except ValueError as exc:
                raise MapError(f"{name}: {exc}") from None
        else:
            vel = derive_velocity(t, pos)
        for label, arr in (("position", pos), ("force", force), ("velocity", vel)):
            if arr.shape[0] != t.shape[0]:
                raise MapError(f"{name}:{found.get(label, (pinfo,))[0].path}: {arr.shape[0]} "
                               f"samples, the position's timestamps {t.shape[0]}: they must "
                               "match")
        names = {k: found[k][0].path for k in found}
        trials: list[Trial] = []
        table = nwb.trials
        spans: list[tuple[float, float]] = []
        if table is not None and len(table) > 0:
            for col in table.columns:
                d: Any = getattr(col, "data", None)
                if hasattr(d, "shape") and hasattr(d, "dtype"):
                    bud.charge(int(np.prod(d.shape, dtype=np.float64)) * d.dtype.itemsize,
                               f"{name}:/intervals/trials/{col.name}")
            df = table.to_dataframe()
            need = ("role", "posture", "window_start", "window_stop")
            if any(c not in df.columns for c in need):   # a lab's own trials: their spans
                spans = [(float(a), float(b)) for a, b in zip(df["start_time"],
                                                             df["stop_time"], strict=True)]
                df = df.iloc[0:0]
            for i, row in enumerate(df.itertuples()):
                try:
                    trials.append(Trial(
                        i, str(row.role), int(row.posture), float(row.start_time),
                        float(row.stop_time),
                        (float(row.window_start), float(row.window_stop)),
                        (float(getattr(row, "vx", 0.0)), float(getattr(row, "vy", 0.0))),
                        str(getattr(row, "label", "")), str(getattr(row, "status", ""))))
                except MapError as exc:
                    raise MapError(f"{name}:/intervals/trials row {i}: {exc}") from None
        postures = None
        if "postures" in nwb.scratch:
            postures = np.asarray(bud.read_dataset(nwb.scratch["postures"].data,
                                                   f"{name}:/scratch/postures"), dtype=float)
        protocol = ""
        if "protocol" in nwb.scratch:
            protocol = str(nwb.scratch["protocol"].data)
        subject = ""
        if "patient" in nwb.scratch:
            subject = str(nwb.scratch["patient"].data)
        elif nwb.subject is not None:
            subject = str(nwb.subject.subject_id)
        prov = {"nwb_identifier": str(nwb.identifier),
                "session_start": nwb.session_start_time.isoformat()}
        if subject:
            prov["patient"] = str(subject)
        if protocol:
            prov["protocol"] = protocol
        chans = {"x": f"{names['position']}[:, 0] ({pinfo.unit})",
                 "y": f"{names['position']}[:, 1] ({pinfo.unit})",
                 "fx": f"{names['force']}[:, 0] ({finfo.unit})",
                 "fy": f"{names['force']}[:, 1] ({finfo.unit})"}
        if not derived:
            chans["vx"] = f"{names['velocity']}[:, 0]"
            chans["vy"] = f"{names['velocity']}[:, 1]"
    rec = Recording(t, pos, vel, force, tuple(trials), chans, source=name,
                    velocity_derived=derived)
    if spans:
        rec = replace(rec, trials=tuple(holds_in_spans(rec, spans)))
        prov["trials_from"] = "the trials table's start and stop times; roles by position"
    return rec, postures, prov
