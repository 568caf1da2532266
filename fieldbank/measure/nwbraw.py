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
* ``postures`` (scratch): the planned grid, m;
* subject (the patient code), session description and start time, the device.

Read (:func:`read_recording`): the same layout, and a lab's own NWB file when it names its
channels: any TimeSeries of shape (N, 2) (or two (N,) series) whose name the caller maps to
x/y, vx/vy, fx/fy (:class:`fieldbank.measure.channels.ChannelMap`), converted from its own unit
with its ``conversion`` factor. Without velocity the velocity is differentiated from the
position (said in the provenance); without a trials table, holds are found by segmentation
(:func:`fieldbank.measure.segment.find_holds`).
"""

from __future__ import annotations

import io
import os
import tempfile
import uuid
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime

import numpy as np

from fieldbank.errors import MapError
from fieldbank.measure.recording import Recording, Trial, derive_velocity
from fieldbank.units import channel_factor

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


def write_recording(rec: Recording, info: RecordingInfo,
                    commanded_force_n: np.ndarray | None = None,
                    postures_m: np.ndarray | None = None) -> bytes:
    """The recording as the bytes of an NWB file."""
    from hdmf.backends.hdf5.h5_utils import H5DataIO
    from pynwb import NWBHDF5IO, NWBFile, TimeSeries
    from pynwb.behavior import SpatialSeries
    from pynwb.file import Subject

    start = info.start_time or datetime.now(UTC)
    nwb = NWBFile(session_description=f"{info.description}; session {info.session}",
                  identifier=str(uuid.uuid4()), session_start_time=start,
                  session_id=info.session, source_script="fieldbank",
                  source_script_file_name="fieldbank")
    nwb.subject = Subject(subject_id=info.patient, species="Homo sapiens",
                          description="patient (pseudonymous code)")
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
        name="hand_velocity", data=data(rec.velocity_m_per_s), timestamps=nwb.acquisition["hand_position"],
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
    fd, path = tempfile.mkstemp(suffix=".nwb")
    os.close(fd)
    try:
        with NWBHDF5IO(path, "w") as io_:
            io_.write(nwb)
        with open(path, "rb") as f:
            return f.read()
    finally:
        os.unlink(path)


def _series(nwb: object, name: str) -> object:
    acq = getattr(nwb, "acquisition")
    if name in acq:
        return acq[name]
    for ts in acq.values():
        # a Position/BehavioralTimeSeries container holds its series by name
        inner = getattr(ts, "spatial_series", None) or getattr(ts, "time_series", None)
        if inner and name in inner:
            return inner[name]
    raise MapError(f"no acquisition series {name!r}; found "
                   f"{', '.join(sorted(acq)) or 'none'}")


def _si(ts: object, where: str, quantity: str) -> np.ndarray:
    data = np.asarray(getattr(ts, "data")[:], dtype=float)
    unit = str(getattr(ts, "unit", "")).strip()
    scale = channel_factor(unit, quantity)
    if scale is None:
        raise MapError(f"{where}: unit {unit!r} is not a {quantity} unit fieldbank converts")
    conv = float(getattr(ts, "conversion", 1.0) or 1.0)
    off = float(getattr(ts, "offset", 0.0) or 0.0)
    return (data * conv + off) * scale


def _times(ts: object) -> np.ndarray:
    stamps = getattr(ts, "timestamps", None)
    if stamps is not None:
        if hasattr(stamps, "timestamps"):   # linked to another series
            stamps = stamps.timestamps
        return np.asarray(stamps[:], dtype=float)
    rate = float(getattr(ts, "rate"))
    n = len(getattr(ts, "data"))
    return float(getattr(ts, "starting_time", 0.0) or 0.0) + np.arange(n) / rate


def read_recording(name: str, data: bytes,
                   channels: Mapping[str, str] | None = None
                   ) -> tuple[Recording, np.ndarray | None, dict[str, str]]:
    """A recording, its planned postures (or None) and provenance from NWB bytes.

    ``channels`` maps 'position', 'velocity', 'force' to acquisition series names (default
    hand_position, hand_velocity, hand_force). Raises MapError naming the file and series.
    """
    import h5py
    from pynwb import NWBHDF5IO

    names = {"position": "hand_position", "velocity": "hand_velocity", "force": "hand_force",
             **dict(channels or {})}
    with h5py.File(io.BytesIO(data), "r") as h5, \
            NWBHDF5IO(file=h5, mode="r", load_namespaces=True) as io_:
        nwb = io_.read()
        try:
            pos_ts = _series(nwb, names["position"])
            force_ts = _series(nwb, names["force"])
        except MapError as exc:
            raise MapError(f"{name}: {exc}") from None
        pos = _si(pos_ts, f"{name}:{names['position']}", "length")
        force = _si(force_ts, f"{name}:{names['force']}", "force")
        t = _times(pos_ts)
        try:
            vel_ts = _series(nwb, names["velocity"])
            vel = _si(vel_ts, f"{name}:{names['velocity']}", "speed")
            derived = False
        except MapError:
            vel = derive_velocity(t, pos)
            derived = True
        for label, arr in (("position", pos), ("force", force), ("velocity", vel)):
            if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] != t.shape[0]:
                raise MapError(f"{name}:{names[label]}: shape {arr.shape}, expected "
                               f"({t.shape[0]}, 2) to match the position's timestamps")
        trials: list[Trial] = []
        table = nwb.trials
        if table is not None and len(table) > 0:
            df = table.to_dataframe()
            need = ("role", "posture", "window_start", "window_stop")
            missing = [c for c in need if c not in df.columns]
            if missing:
                raise MapError(f"{name}:/intervals/trials lacks the column(s) "
                               f"{', '.join(missing)} the estimator reads")
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
            postures = np.asarray(nwb.scratch["postures"].data[:], dtype=float)
        subject = nwb.subject.subject_id if nwb.subject is not None else ""
        prov = {"nwb_identifier": str(nwb.identifier),
                "session_start": nwb.session_start_time.isoformat()}
        if subject:
            prov["patient"] = str(subject)
        chans = {"x": f"{names['position']}[:, 0] ({pos_ts.unit})",
                 "y": f"{names['position']}[:, 1] ({pos_ts.unit})",
                 "fx": f"{names['force']}[:, 0] ({force_ts.unit})",
                 "fy": f"{names['force']}[:, 1] ({force_ts.unit})"}
        if not derived:
            chans["vx"] = f"{names['velocity']}[:, 0]"
            chans["vy"] = f"{names['velocity']}[:, 1]"
    rec = Recording(t, pos, vel, force, tuple(trials), chans, source=name,
                    velocity_derived=derived)
    return rec, postures, prov
