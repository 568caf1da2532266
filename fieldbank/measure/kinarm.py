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
(:mod:`fieldbank.measure.segment`). The members' declared sizes are charged all together to the
file's budget before any is inflated (:func:`exam_members`), each member is stopped if it
holds more than it declared: an archive bomb, or forty members each within the limits, is
refused before it is inflated. Newer exams (``.kinarm``, binary channels) are read by
:mod:`fieldbank.measure.kinarmbin`.

Checked against: the layout above as ``zip_load.m`` reads it — no real exam file was
available, so the tests build archives in that layout with the ``c3d`` library
(tests/test_measure_io.py); a single KINARM trial C3D (c3d.org's sample 22, an exoskeleton)
is read by :mod:`fieldbank.measure.c3draw`.
"""

from __future__ import annotations

import io
import zipfile
from collections.abc import Mapping

import numpy as np

from fieldbank.errors import MapError
from fieldbank.measure.budget import MIB, BudgetExceeded, ReadBudget
from fieldbank.measure.c3dfile import C3DError, read_c3d
from fieldbank.measure.recording import Recording, derive_velocity
from fieldbank.units import channel_factor

ZIP_SIGNATURE = b"PK\x03\x04"
COMMON = "raw/common.c3d"
#: Most members an exam archive may list (an exam of a few hundred trials holds a few
#: thousand channel files).
MAX_MEMBERS = 100_000


def exam_kind(data: bytes) -> str | None:
    """'c3d' for an exam of C3D trials (``raw/common.c3d``), 'binary' for a ``.kinarm`` exam
    of binary channel files (``raw/<trial>/*.kinematics``, ``*.position``), else None."""
    if not data.startswith(ZIP_SIGNATURE):
        return None
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as z:
            names = z.namelist()
    except (zipfile.BadZipFile, ValueError, OSError):
        return None
    if COMMON in names:
        return "c3d"
    if any(n.startswith("raw/") and n.endswith((".kinematics", ".position")) for n in names):
        return "binary"
    return None


def is_kinarm_zip(data: bytes) -> bool:
    """True for a KINARM exam archive of either kind (:func:`exam_kind`)."""
    return exam_kind(data) is not None


def exam_members(name: str, data: bytes, budget: ReadBudget
                 ) -> tuple[zipfile.ZipFile, list[zipfile.ZipInfo]]:
    """The open archive and its members under ``raw/`` (and ``exam_info*``), their declared
    sizes charged to ``budget`` all together before any is inflated: forty members each
    within the limits are refused when their total is not."""
    try:
        z = zipfile.ZipFile(io.BytesIO(data))
        infos = z.infolist()
    except (zipfile.BadZipFile, ValueError, OSError) as exc:
        raise MapError(f"{name}: not a readable ZIP archive ({exc})") from None
    if len(infos) > MAX_MEMBERS:
        z.close()
        raise MapError(f"{name}: {len(infos):,} members, more than the {MAX_MEMBERS:,} an exam "
                       "holds; refused")
    wanted = [i for i in infos if not i.is_dir() and (
        i.filename.lower().startswith("raw/") or i.filename.lower().startswith("exam_info"))]
    total = sum(i.file_size for i in wanted)
    try:
        budget.charge(total, name, f"its {len(wanted)} members declare {total:,} bytes "
                      "unpacked")
        for i in wanted:
            if i.compress_size > 0 and i.file_size > MIB and \
                    i.file_size / i.compress_size > budget.max_ratio:
                raise BudgetExceeded(f"{name}:{i.filename}: {i.file_size:,} bytes unpacked from "
                                     f"{i.compress_size:,}, a ratio over {budget.max_ratio:g} "
                                     f"{budget.hint_ratio}")
    except BudgetExceeded:
        z.close()
        raise
    return z, wanted


def member_bytes(z: zipfile.ZipFile, info: zipfile.ZipInfo, name: str,
                 budget: ReadBudget) -> bytes:
    """One member inflated, stopped if it holds more than it declared."""
    try:
        with z.open(info) as f:
            return budget.inflate(f, info.file_size, f"{name}:{info.filename}")
    except (zipfile.BadZipFile, OSError, EOFError, NotImplementedError) as exc:
        raise MapError(f"{name}:{info.filename}: unreadable ZIP member ({exc})") from None


def read_kinarm_zip(name: str, data: bytes, channels: Mapping[str, str] | None = None,
                    budget: ReadBudget | None = None) -> tuple[Recording, dict[str, str]]:
    """The trials of a Dexterit-E exam ZIP end to end as one recording (no trial marks yet:
    the caller finds the holds), in the exam's own coordinates; and provenance."""
    bud = budget or ReadBudget(1 << 28, len(data))
    hand = (dict(channels or {}).get("hand") or "Right").capitalize()
    fx_label = dict(channels or {}).get("fx") or f"{hand}_FS_ForceX"
    fy_label = dict(channels or {}).get("fy") or f"{hand}_FS_ForceY"
    z, members = exam_members(name, data, bud)
    with z:
        infos = [i for i in members if i.filename.lower().endswith(".c3d")
                 and i.filename != COMMON]
        if COMMON not in z.namelist():
            raise MapError(f"{name}: not a Dexterit-E exam (no {COMMON})")
        if not infos:
            raise MapError(f"{name}: the exam holds no trial (no raw/*.c3d besides "
                           "common.c3d)")
        trials: list[tuple[int, str, float, np.ndarray, np.ndarray]] = []
        punit = "m"
        for info in infos:
            where = f"{name}:{info.filename}"
            blob = member_bytes(z, info, name, bud)
            try:
                r = read_c3d(blob, bud.limit)
            except C3DError as exc:
                raise MapError(f"{where}: {exc}") from None
            if r.frames == 0:
                raise MapError(f"{where}: no frames")
            labels = r.analog_labels
            missing = [lab for lab in (fx_label, fy_label) if lab not in labels]
            if missing:
                why = ("no hand force: this robot has no force sensor (no *_FS_Force "
                       "channel)" if not any("_FS_FORCE" in s.upper() for s in labels) else
                       f"no force-sensor channel {', '.join(missing)}")
                raise MapError(f"{where}: {why}; analog channels: {', '.join(labels[:12])}"
                               f"{'…' if len(labels) > 12 else ''}; name one with --column "
                               "fx=LABEL --column fy=LABEL")
            punit = r.point_unit or "m"
            pf = channel_factor(punit, "length")
            if pf is None:
                raise MapError(f"{where}: POINT:UNITS {punit!r} is not a length unit")
            k = 0 if hand == "Right" else 1
            if r.points.shape[1] <= k:
                raise MapError(f"{where}: no {hand.lower()} hand among the points "
                               f"({', '.join(r.point_labels) or 'none'})")
            pts = r.points[:, k, :2] * pf
            per = max(1, r.analog.shape[1] // r.frames)
            cols = []
            for label in (fx_label, fy_label):
                i = labels.index(label)
                unit = r.analog_units[i] or "N"
                f = channel_factor(unit, "force")
                if f is None:
                    raise MapError(f"{where}: channel {label!r} has unit {unit!r}, not a force "
                                   "unit fieldbank converts")
                cols.append(r.analog[i, ::per] * f)         # at the point rate
            num = r.param("TRIAL:TRIAL_NUM")
            order = int(num.first(len(trials))) if num is not None and num.type != -1 \
                else len(trials)
            trials.append((order, info.filename, float(r.point_rate_hz), pts,
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
