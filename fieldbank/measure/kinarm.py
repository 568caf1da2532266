"""KINARM (Dexterit-E 3.0 and later) exam files: a ZIP of one C3D file per trial.

What is known publicly of the layout, from BKIN's own MATLAB reader ``zip_load.m`` (with
``c3d_load``; Copyright BKIN Technologies, published in several public research repositories)
— KINARM's official readers are MATLAB only:

* the exam is a ZIP archive holding ``raw/common.c3d`` (parameters common to every trial; a
  ZIP without it is "not a Dexterit-E zip file") and one ``raw/<name>.c3d`` per trial, and
  optionally ``description.txt`` and ``analysis/analysis.c3d``;
* in each trial file the hand trajectories are the C3D POINT data, right hand first, left hand
  second (x, y, z; ``c3d_load`` names them ``Right_HandX``/``Right_HandY``), in the POINT
  group's unit (m);
* the analog channels are named by ``ANALOG:LABELS``; the force/torque sensor of an end-point
  robot gives ``Right_FS_ForceX``, ``Right_FS_ForceY``, ``Right_FS_ForceZ`` (N), the
  sensor's clock ``Right_FS_TimeStamp``; joint angles and velocities ``Right_L1Ang``,
  ``Right_L2Ang``, ``Right_L1Vel``, ``Right_L2Vel``;
* events are the ``EVENTS`` group's ``LABELS`` and ``TIMES`` (2 × n; Dexterit-E leaves the
  first row unused: the second row is seconds from the trial's start); the trials run in the
  order of the ``TRIAL:TRIAL_NUM`` parameter (``sort_trials``).

What fieldbank reads (:func:`read_kinarm_zip`): every ``raw/*.c3d`` but ``common.c3d``, in
``TRIAL:TRIAL_NUM`` order (else name order), the right hand (or the left, ``--column
hand=Left``), the force sensor's x and y, placed end to end in time; the velocity is
differentiated from the position (the raw files hold joint velocities, not hand velocities).
KINARM's coordinates are the robot's global frame, not the shoulder frame, and its task
protocols are the lab's own: the shoulder's position in those coordinates and the force's sign
convention must be given (``--shoulder X,Y``, ``--sign``); the holds are found by stillness
(:mod:`fieldbank.measure.segment`). ZIP members are bounded like every ingested file
(decompressed size and ratio): an archive bomb is refused before it is inflated.

Checked against: the layout above as ``zip_load.m`` reads it — no real exam file was
available, so the tests build archives in that layout with the ``c3d`` library
(tests/test_measure_io.py).
"""

from __future__ import annotations

import io
import zipfile
from collections.abc import Mapping

import numpy as np

from fieldbank.errors import MapError
from fieldbank.measure.recording import Recording, derive_velocity
from fieldbank.units import channel_factor

ZIP_SIGNATURE = b"PK\x03\x04"
COMMON = "raw/common.c3d"


def is_kinarm_zip(data: bytes) -> bool:
    """True for a ZIP archive holding ``raw/common.c3d``."""
    if not data.startswith(ZIP_SIGNATURE):
        return False
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as z:
            return COMMON in z.namelist()
    except zipfile.BadZipFile:
        return False


def _member(z: zipfile.ZipFile, info: zipfile.ZipInfo, name: str, max_bytes: int,
            max_ratio: float) -> bytes:
    if info.file_size > max_bytes or (info.compress_size > 0 and
                                      info.file_size / info.compress_size > max_ratio):
        raise MapError(f"{name}:{info.filename}: {info.file_size:,} bytes unpacked from "
                       f"{info.compress_size:,} — over the limits ({max_bytes:,} bytes, "
                       f"ratio {max_ratio:g}); refused")
    with z.open(info) as f:
        data = f.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise MapError(f"{name}:{info.filename}: larger than declared; refused")
    return data


def read_kinarm_zip(name: str, data: bytes, channels: Mapping[str, str] | None = None,
                    max_bytes: int = 200_000_000, max_ratio: float = 200.0
                    ) -> tuple[Recording, dict[str, str]]:
    """The trials of a Dexterit-E exam ZIP end to end as one recording (no trial marks yet:
    the caller finds the holds), in the exam's own coordinates; and provenance."""
    import c3d

    hand = (dict(channels or {}).get("hand") or "Right").capitalize()
    fx_label = dict(channels or {}).get("fx") or f"{hand}_FS_ForceX"
    fy_label = dict(channels or {}).get("fy") or f"{hand}_FS_ForceY"
    try:
        z = zipfile.ZipFile(io.BytesIO(data))
    except zipfile.BadZipFile as exc:
        raise MapError(f"{name}: not a readable ZIP archive ({exc})") from None
    with z:
        infos = [i for i in z.infolist() if i.filename.lower().startswith("raw/")
                 and i.filename.lower().endswith(".c3d") and i.filename != COMMON]
        if COMMON not in z.namelist():
            raise MapError(f"{name}: not a Dexterit-E exam (no {COMMON})")
        if not infos:
            raise MapError(f"{name}: the exam holds no trial (no raw/*.c3d besides "
                           "common.c3d)")
        trials: list[tuple[int, str, float, np.ndarray, np.ndarray]] = []
        for info in infos:
            where = f"{name}:{info.filename}"
            blob = _member(z, info, name, max_bytes, max_ratio)
            try:
                r = c3d.Reader(io.BytesIO(blob))
                frames = list(r.read_frames())
            except Exception as exc:  # the library's own errors on damaged files
                raise MapError(f"{where}: unreadable C3D ({type(exc).__name__}: {exc})"
                               ) from None
            if not frames:
                raise MapError(f"{where}: no frames")
            labels = [str(s).strip() for s in r.analog_labels]
            for label in (fx_label, fy_label):
                if label not in labels:
                    raise MapError(f"{where}: no force-sensor channel {label!r} (channels: "
                                   f"{', '.join(labels[:12])}…); name it with --column "
                                   "fx=LABEL")
            units = []
            up = r.get("ANALOG:UNITS")
            if up is not None:
                units = [str(s).strip() for s in np.ravel(up.string_array)]
            pu = r.get("POINT:UNITS")
            punit = str(pu.string_value).strip() if pu is not None else "m"
            pf = channel_factor(punit, "length")
            if pf is None:
                raise MapError(f"{where}: POINT:UNITS {punit!r} is not a length unit")
            k = 0 if hand == "Right" else 1
            pts = np.array([p[k, :2] for _, p, _ in frames], dtype=float) * pf
            analog = np.concatenate([a for _, _, a in frames], axis=1).astype(float)
            per = analog.shape[1] // len(frames)
            cols = []
            for label in (fx_label, fy_label):
                i = labels.index(label)
                unit = units[i] if i < len(units) else "N"
                f = channel_factor(unit, "force")
                if f is None:
                    raise MapError(f"{where}: channel {label!r} has unit {unit!r}, not a force "
                                   "unit fieldbank converts")
                cols.append(analog[i, ::per] * f)         # at the point rate
            num = r.get("TRIAL:TRIAL_NUM")
            order = int(num.int16_value) if num is not None else len(trials)
            trials.append((order, info.filename, float(r.point_rate), pts,
                           np.column_stack(cols)))
    trials.sort(key=lambda x: (x[0], x[1]))
    ts, ps, fs = [], [], []
    t0 = 0.0
    for _, _, rate, pts, force in trials:
        n = len(pts)
        ts.append(t0 + np.arange(n) / rate)
        ps.append(pts)
        fs.append(force[:n])
        t0 += n / rate + 1.0      # a second's gap between trials keeps holds apart
    t = np.concatenate(ts)
    pos = np.concatenate(ps)
    rec = Recording(t, pos, derive_velocity(t, pos), np.concatenate(fs), (),
                    {"x": f"POINT {hand} hand x ({punit})", "y": f"POINT {hand} hand y "
                     f"({punit})", "fx": f"{fx_label}", "fy": f"{fy_label}"},
                    source=name, velocity_derived=True)
    return rec, {"kinarm_trials": str(len(trials)),
                 "kinarm_files": ", ".join(x[1] for x in trials[:20])
                 + (" …" if len(trials) > 20 else "")}
