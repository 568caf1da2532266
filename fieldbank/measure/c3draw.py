"""Raw recordings as C3D files: read by fieldbank's own reader, written with ``c3d``.

Reading goes through :mod:`fieldbank.measure.c3dfile` (why: its docstring and
``docs/measuring.md``, measured with ``benchmarks/bench_c3d_readers.py``); writing, for
fieldbank's own recordings and the tests, through the ``c3d`` package's writer.

Layout fieldbank reads (and writes with :func:`write_c3d`):

* analog channels, at ``ANALOG:RATE``, named by ``ANALOG:LABELS`` with ``ANALOG:UNITS``:
  hand position x, y (length), velocity vx, vy (speed; optional — differentiated from the
  position when absent), force fx, fy (force of the arm on the handle). Default labels
  ``HandX HandY HandVX HandVY ForceX ForceY``; another lab's names are given with
  ``--column x=Right_HandX`` (:func:`read_c3d_recording` ``channels``). Units are converted to
  SI from the table of :mod:`fieldbank.units`; a unit it does not know is refused;
* or a marker's coordinate as the hand position: ``--column x=Right_Hand:x`` (POINT data in
  ``POINT:UNITS``, at the point rate; the analog channels are then averaged over each frame);
* trials as events, in fieldbank's layout: one event per trial at its start,
  ``EVENT:LABELS`` the role (base, displaced, pass) and ``EVENT:DESCRIPTIONS``
  ``posture=3;stop=2.45;window=1.2,2.45;v=0,1``
  (+ ``label=`` and ``status=`` when there are), times in ``EVENT:TIMES`` (minutes, seconds);
* ``FIELDBANK:POSTURES`` (optional): the planned grid, m, shoulder frame.

Other events (a gait lab's foot strikes, KINARM's task events) are not trials: they are listed
in the provenance and ignored, unless ``--trial-events LABEL`` names the ones that start a
trial (each then runs to the next event; roles by position, as holds found by stillness).
Every channel that is missing or unusable is reported at once, with the file's channels and
the option that maps one.

The hand position is taken in the shoulder frame, the force as the arm exerts it on the
handle; a file in another frame or sign is converted by the caller before it is written.
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from fieldbank.errors import MapError
from fieldbank.measure.c3dfile import C3DError, C3DFile, read_c3d
from fieldbank.measure.channels import unit_factor
from fieldbank.measure.recording import ChannelProblems, Recording, Trial, derive_velocity
from fieldbank.measure.segment import holds_in_spans

C3D_ROLES = {"x": "HandX", "y": "HandY", "vx": "HandVX", "vy": "HandVY", "fx": "ForceX",
             "fy": "ForceY"}
_UNITS = {"x": "m", "y": "m", "vx": "m/s", "vy": "m/s", "fx": "N", "fy": "N"}
#: Points per analog frame in a written file (the point rate is the analog rate over this).
ANALOG_PER_FRAME = 10


def _fixed(strings: list[str]) -> tuple[str, int, int]:
    # C3D strings are bytes: keep them ASCII so a character is a byte
    strings = [s.replace("°", " deg").encode("ascii", "replace").decode("ascii")
               for s in strings]
    width = max(1, max((len(s) for s in strings), default=1))
    return "".join(s.ljust(width) for s in strings), width, len(strings)


def is_c3d(data: bytes) -> bool:
    """True for the bytes of a C3D file (byte 2 is the 0x50 key of the header)."""
    return len(data) >= 512 and data[1:2] == b"\x50"


def write_c3d(rec: Recording, postures_m: np.ndarray | None = None) -> bytes:
    """The recording as C3D bytes (the layout above), written by the ``c3d`` library."""
    import c3d

    n = rec.n - rec.n % ANALOG_PER_FRAME
    if n < ANALOG_PER_FRAME:
        raise MapError(f"a C3D file needs at least {ANALOG_PER_FRAME} samples; got {rec.n}")
    if len(rec.trials) > 255:
        raise MapError(f"a C3D parameter holds at most 255 entries per dimension; this "
                       f"recording has {len(rec.trials)} trials: write it as NWB")
    rate = rec.rate_hz
    w = c3d.Writer(point_rate=rate / ANALOG_PER_FRAME, analog_rate=rate)
    analog = np.vstack([rec.position_m[:n].T, rec.velocity_m_per_s[:n].T,
                        rec.force_n[:n].T]).astype(np.float32)     # (6, n)
    frames = []
    for i in range(n // ANALOG_PER_FRAME):
        pts = np.zeros((1, 5), dtype=np.float32)
        pts[0, :2] = rec.position_m[i * ANALOG_PER_FRAME] * 1000.0   # mm, the point unit
        frames.append((pts, analog[:, i * ANALOG_PER_FRAME:(i + 1) * ANALOG_PER_FRAME]))
    w.add_frames(frames)
    w.set_point_labels(["Hand"])
    roles = ("x", "y", "vx", "vy", "fx", "fy")
    w.set_analog_labels([C3D_ROLES[r] for r in roles])
    units, width, count = _fixed([_UNITS[r] for r in roles])
    w.analog_group.add_str("UNITS", "unit of each channel", units, width, count)
    ev = w.add_group(20, "EVENT", "trials: one event at the start of each")
    trials = list(rec.trials)
    t0 = float(rec.t_s[0])
    ev.add_array("USED", "number of events", np.array([len(trials)], dtype=np.int16))
    pairs = np.array([[0.0, t.start_s - t0] for t in trials], dtype=np.float32)
    # C3D arrays run first dimension fastest: dims [2, n] hold (minutes, seconds) per event
    ev.add_array("TIMES", "minutes, seconds from the first sample",
                 pairs.ravel().reshape(2, len(trials)))
    labels, lw, lc = _fixed([t.role for t in trials])
    ev.add_str("LABELS", "role", labels, lw, lc)
    desc = [f"posture={t.posture};stop={t.stop_s - t0:.6f};"
            f"window={t.window_s[0] - t0:.6f},{t.window_s[1] - t0:.6f};"
            f"v={t.velocity_m_per_s[0]:.6g},{t.velocity_m_per_s[1]:.6g}"
            + (f";label={t.label.replace(';', ',')}" if t.label else "")
            + (f";status={t.status.replace(';', ',')}" if t.status else "")
            for t in trials]
    d, dw, dc = _fixed(desc)
    ev.add_str("DESCRIPTIONS", "posture, stop, window, velocity", d, dw, dc)
    if postures_m is not None and len(postures_m):
        g = w.add_group(21, "FIELDBANK", "fieldbank measurement")
        pts = np.asarray(postures_m, dtype=np.float32)
        g.add_array("POSTURES", "planned posture grid, m, shoulder frame (x, y per posture)",
                    pts.ravel().reshape(2, len(pts)))
    buf = io.BytesIO()
    w.write(buf)
    return buf.getvalue()


def _parse_desc(text: str) -> dict[str, str] | None:
    """A fieldbank trial description as keys, or None when it is not one."""
    out = {}
    for part in text.split(";"):
        if "=" in part:
            k, v = part.split("=", 1)
            out[k.strip()] = v.strip()
    return out if all(k in out for k in ("posture", "stop", "window")) else None


def _fieldbank_trials(f: C3DFile, name: str) -> list[Trial] | None:
    """The trials of a file in fieldbank's layout (every event described), else None."""
    events = f.events()
    descs = f.strings("EVENT:DESCRIPTIONS")
    if not events or len(descs) != len(events):
        return None
    parsed = [_parse_desc(d) for d in descs]
    if not all(parsed):
        return None
    trials = []
    for i, ((role, start, _), d) in enumerate(zip(events, parsed, strict=True)):
        assert d is not None
        try:
            w0, w1 = (float(v) for v in d["window"].split(","))
            vx, vy = (float(v) for v in d.get("v", "0,0").split(","))
            trials.append(Trial(i, role, int(d["posture"]), start, float(d["stop"]), (w0, w1),
                                (vx, vy), d.get("label", ""), d.get("status", "")))
        except (ValueError, MapError) as exc:
            raise MapError(f"{name}: event {i} ({role}): {exc}") from None
    return trials


def _source(f: C3DFile, spec: str) -> tuple[str, str, int, int] | None:
    """('analog', label, index, -1) or ('point', label, index, axis) for a --column value."""
    if spec in f.analog_labels:
        return "analog", spec, f.analog_labels.index(spec), -1
    label, sep, axis = spec.rpartition(":")
    if sep and axis.lower() in ("x", "y", "z") and label in f.point_labels:
        return "point", label, f.point_labels.index(label), "xyz".index(axis.lower())
    return None


def _has_force_sensor(f: C3DFile) -> bool:
    return any("_FS_FORCE" in s.upper() for s in f.analog_labels)


def _is_kinarm(f: C3DFile) -> bool:
    return "RIGHT_KINARM" in f.groups or "LEFT_KINARM" in f.groups


def read_c3d_recording(name: str, data: bytes, channels: Mapping[str, str] | None = None,
                       trial_events: Sequence[str] = (), units: Mapping[str, str] | None = None,
                       budget_bytes: int = 1 << 30
                       ) -> tuple[Recording, np.ndarray | None, dict[str, str]]:
    """A recording, its planned postures (or None) and provenance from C3D bytes.

    ``channels`` maps roles (x, y, vx, vy, fx, fy) to the file's analog labels or to a marker's
    coordinate (``Right_Hand:x``); ``trial_events`` names the event labels that start trials
    (other events are ignored); ``units`` gives units the file does not state. Raises
    MapError naming the file and every channel that is missing or unusable at once
    (:class:`~fieldbank.measure.recording.ChannelProblems`).
    """
    try:
        f = read_c3d(data, budget_bytes)
    except C3DError as exc:
        raise MapError(f"{name}: {exc}") from None
    want = {**C3D_ROLES, **dict(channels or {})}
    given = dict(channels or {})
    reasons: list[str] = []
    found: dict[str, tuple[str, str, int, int]] = {}
    for role in ("x", "y", "vx", "vy", "fx", "fy"):
        src = _source(f, want[role])
        if src is not None:
            found[role] = src
        elif role not in ("vx", "vy") or role in given:   # velocity is optional
            reasons.append(_missing(f, role, want[role], role in given))
    reasons = list(dict.fromkeys(reasons))     # fx and fy may give the same reason
    if reasons:
        raise ChannelProblems([f"{name}: {r}" for r in [*reasons, _listing(f)]])
    on_points = any(src[0] == "point" for src in found.values())
    per = max(1, round(f.analog_rate_hz / f.point_rate_hz)) if f.point_rate_hz > 0 else 1
    rate = f.point_rate_hz if on_points else f.analog_rate_hz
    cols: dict[str, np.ndarray] = {}
    used: dict[str, str] = {}
    for role, (kind, label, i, axis) in found.items():
        if kind == "point":
            v = f.points[:, i, axis]
            unit = f.point_unit
        else:
            v = f.analog[i]
            if on_points:      # the analog samples of each frame averaged: the frame's value
                n = v.size // per
                v = v[:n * per].reshape(n, per).mean(axis=1)
            unit = f.analog_units[i]
        try:
            factor, unit_used = unit_factor(role, unit, dict(units or {}), label)
        except ValueError as exc:
            reasons.append(f"{name}: {exc}")
            continue
        cols[role] = np.asarray(v, dtype=float) * factor
        used[role] = (f"{label}:{'xyz'[axis]}" if kind == "point" else label) + \
            f" ({unit_used})"
    if reasons:
        raise ChannelProblems(reasons)
    n = min(c.size for c in cols.values())
    if n < 2 or rate <= 0:
        raise MapError(f"{name}: {n} samples at {rate:g} Hz: nothing to estimate from")
    cols = {k: v[:n] for k, v in cols.items()}
    t = np.arange(n) / rate
    pos = np.column_stack([cols["x"], cols["y"]])
    derived = "vx" not in cols or "vy" not in cols
    vel = derive_velocity(t, np.nan_to_num(pos)) if derived else \
        np.column_stack([cols["vx"], cols["vy"]])
    force = np.column_stack([cols["fx"], cols["fy"]])
    prov = {"c3d_rate_hz": f"{rate:g}", "c3d_processor": f.processor,
            "c3d_storage": f.storage}
    events = f.events()
    trials: list[Trial] = []
    rec = Recording(t, pos, vel, force, (), used, source=name, velocity_derived=derived)
    if trial_events:
        names = {s.strip().lower() for s in trial_events}
        starts = [tm for lab, tm, _ in events if lab.strip().lower() in names]
        if not starts:
            labels = sorted({lab for lab, _, _ in events})
            raise MapError(f"{name}: no event named {', '.join(trial_events)} (the file's "
                           f"events: {', '.join(labels) or 'none'})")
        ends = sorted(tm for _, tm, _ in events)
        spans = [(s0, next((tm for tm in ends if tm > s0), float(t[-1])))
                 for s0 in sorted(starts)]
        trials = holds_in_spans(rec, spans)
        prov["trials_from_events"] = ", ".join(trial_events)
    else:
        ours = _fieldbank_trials(f, name)
        if ours is not None:
            trials = ours
        elif events:
            counts: dict[str, int] = {}
            for lab, _, _ in events:
                counts[lab] = counts.get(lab, 0) + 1
            prov["events_ignored"] = ", ".join(f"{k} ×{v}" for k, v in counts.items()) + \
                " (not trials; --trial-events LABEL makes an event start a trial)"
    postures = None
    pp = f.param("FIELDBANK:POSTURES")
    if pp is not None and pp.type != -1:
        postures = pp.numbers().reshape(-1, 2)
    return replace(rec, trials=tuple(trials)), postures, prov


def _missing(f: C3DFile, role: str, label: str, named: bool) -> str:
    """Why a role has no channel (the file's channels are listed once, by :func:`_listing`)."""
    what = {"x": "hand position x", "y": "hand position y", "vx": "hand velocity x",
            "vy": "hand velocity y", "fx": "hand force x", "fy": "hand force y"}[role]
    if role in ("fx", "fy"):
        if not f.analog_labels:
            return (f"no hand force: this file has no analog channels (markers only: "
                    f"{len(f.point_labels)} markers), and a force needs one")
        if _is_kinarm(f) and not _has_force_sensor(f):
            return ("no hand force: this robot has no force sensor (a KINARM exoskeleton "
                    "file, no *_FS_Force channel)")
    hint = f"--column {role}=LABEL" + (f" or --column {role}=MARKER:{role[-1]}"
                                       if role in ("x", "y", "vx", "vy") else "")
    if named:
        return f"no channel {label!r} for the {what} (name one with {hint})"
    return f"no channel for the {what} (looked for {label!r}; name one with {hint})"


def _listing(f: C3DFile) -> str:
    """The file's channels in one sentence, for a refusal."""
    analog = ", ".join(f"{a} ({u or 'no unit'})" for a, u in
                       zip(f.analog_labels[:24], f.analog_units[:24], strict=True))
    if len(f.analog_labels) > 24:
        analog += f", … ({len(f.analog_labels)} in all)"
    markers = ", ".join(f.point_labels[:16]) + (f", … ({len(f.point_labels)} in all)"
                                                 if len(f.point_labels) > 16 else "")
    return (f"the file has analog channels: {analog or 'none'}; markers "
            f"({f.point_unit or 'no unit'}): {markers or 'none'} ('fieldbank inspect' shows "
            "them with their rates)")
