"""Raw recordings as C3D files, through the ``c3d`` library (pure Python).

Why ``c3d`` and not ``ezc3d`` (measured on this project's machine, c3d 0.6.0 against ezc3d
1.7.2; ``docs/formats.md``): both round-trip analog channels exactly at float32 precision and
read each other's units and events, but ezc3d (a C++ core, 4.3 MB installed against 0.3 MB)
crashed the Python process with a segmentation fault on a valid file written by ``c3d`` and on
1 of 40 damaged variants of its own file, where ``c3d`` raised an exception on every damaged
file (0 of 80). An ingest service must turn a bad file into a message, never die of it.

Layout fieldbank reads (and writes with :func:`write_c3d`):

* analog channels, at ``ANALOG:RATE``, named by ``ANALOG:LABELS`` with ``ANALOG:UNITS``:
  hand position x, y (length), velocity vx, vy (speed; optional — differentiated from the
  position when absent), force fx, fy (force of the arm on the handle). Default labels
  ``HandX HandY HandVX HandVY ForceX ForceY``; another lab's names are given with
  ``--column x=Right_HandX`` (:func:`read_c3d_recording` ``channels``). Units are converted to
  SI from the table of :mod:`fieldbank.units`; a unit it does not know is refused;
* trials as events: one event per trial at its start, ``EVENT:LABELS`` the role (base,
  displaced, pass) and ``EVENT:DESCRIPTIONS`` ``posture=3;stop=2.45;window=1.2,2.45;v=0,1``
  (+ ``label=`` and ``status=`` when there are), times in ``EVENT:TIMES`` (minutes, seconds);
* ``FIELDBANK:POSTURES`` (optional): the planned grid, m, shoulder frame.

The hand position is taken in the shoulder frame, the force as the arm exerts it on the
handle; a file in another frame or sign is converted by the caller before it is written.
"""

from __future__ import annotations

import io
from collections.abc import Mapping

import numpy as np

from fieldbank.errors import MapError
from fieldbank.measure.recording import Recording, Trial, derive_velocity
from fieldbank.units import channel_factor

C3D_ROLES = {"x": "HandX", "y": "HandY", "vx": "HandVX", "vy": "HandVY", "fx": "ForceX",
             "fy": "ForceY"}
_QUANTITY = {"x": "length", "y": "length", "vx": "speed", "vy": "speed", "fx": "force",
             "fy": "force"}
_UNITS = {"x": "m", "y": "m", "vx": "m/s", "vy": "m/s", "fx": "N", "fy": "N"}
#: Points per analog frame in a written file (the point rate is the analog rate over this).
ANALOG_PER_FRAME = 10


def _fixed(strings: list[str]) -> tuple[str, int, int]:
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
    ev.add_array("USED", "number of events", np.array(len(trials), dtype=np.int16))
    times = np.array([[0.0] * len(trials), [t.start_s - t0 for t in trials]],
                     dtype=np.float32)
    ev.add_array("TIMES", "minutes, seconds from the first sample", times)
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
        g.add_array("POSTURES", "planned posture grid, m, shoulder frame",
                    np.asarray(postures_m, dtype=np.float32))
    buf = io.BytesIO()
    w.write(buf)
    return buf.getvalue()


def _strings(reader: object, key: str) -> list[str]:
    p = getattr(reader, "get")(key)
    if p is None:
        return []
    arr = p.string_array
    return [str(s).strip() for s in np.ravel(arr)]


def _parse_desc(text: str, where: str) -> dict[str, str]:
    out = {}
    for part in text.split(";"):
        if "=" in part:
            k, v = part.split("=", 1)
            out[k.strip()] = v.strip()
    for key in ("posture", "stop", "window"):
        if key not in out:
            raise MapError(f"{where}: event description lacks {key}= (got {text!r})")
    return out


def read_c3d_recording(name: str, data: bytes, channels: Mapping[str, str] | None = None
                       ) -> tuple[Recording, np.ndarray | None, dict[str, str]]:
    """A recording, its planned postures (or None) and provenance from C3D bytes.

    ``channels`` maps roles (x, y, vx, vy, fx, fy) to the file's analog labels. Raises
    MapError naming the file, the channel or the event and the reason.
    """
    import c3d

    try:
        reader = c3d.Reader(io.BytesIO(data))
        blocks = [a for _, _, a in reader.read_frames()]
    except Exception as exc:  # the library's own errors on damaged files: a message
        raise MapError(f"{name}: unreadable C3D ({type(exc).__name__}: {exc})") from None
    if not blocks:
        raise MapError(f"{name}: the C3D file has no frames")
    analog = np.concatenate(blocks, axis=1).astype(float)          # (channels, n)
    labels = [str(s).strip() for s in reader.analog_labels]
    units = _strings(reader, "ANALOG:UNITS")
    rate = float(reader.analog_rate)
    if rate <= 0 or analog.shape[0] == 0:
        raise MapError(f"{name}: the C3D file has no analog channels")
    want = {**C3D_ROLES, **dict(channels or {})}
    cols: dict[str, np.ndarray] = {}
    used: dict[str, str] = {}
    for role in ("x", "y", "vx", "vy", "fx", "fy"):
        label = want[role]
        if label not in labels:
            if role in ("vx", "vy"):
                continue
            raise MapError(f"{name}: no analog channel {label!r} for {role} (channels: "
                           f"{', '.join(labels)}); name it with --column {role}=LABEL")
        i = labels.index(label)
        unit = units[i] if i < len(units) else ""
        f = channel_factor(unit, _QUANTITY[role])
        if f is None:
            raise MapError(f"{name}: channel {label!r} has unit {unit!r}, not a "
                           f"{_QUANTITY[role]} unit fieldbank converts")
        cols[role] = analog[i] * f
        used[role] = f"{label} ({unit})"
    n = analog.shape[1]
    t = np.arange(n) / rate
    pos = np.column_stack([cols["x"], cols["y"]])
    derived = "vx" not in cols or "vy" not in cols
    vel = derive_velocity(t, pos) if derived else np.column_stack([cols["vx"], cols["vy"]])
    force = np.column_stack([cols["fx"], cols["fy"]])
    roles = _strings(reader, "EVENT:LABELS")
    descs = _strings(reader, "EVENT:DESCRIPTIONS")
    tp = reader.get("EVENT:TIMES")
    trials: list[Trial] = []
    if roles:
        times = np.asarray(tp.float_array if tp is not None else [], dtype=float).reshape(-1, 2)
        if times.shape[0] != len(roles) or len(descs) != len(roles):
            raise MapError(f"{name}: EVENT:LABELS, TIMES and DESCRIPTIONS disagree in length "
                           f"({len(roles)}, {times.shape[0]}, {len(descs)})")
        for i, (role, desc) in enumerate(zip(roles, descs, strict=True)):
            where = f"{name}: event {i} ({role})"
            d = _parse_desc(desc, where)
            try:
                start = 60.0 * times[i, 0] + times[i, 1]
                w0, w1 = (float(v) for v in d["window"].split(","))
                vx, vy = (float(v) for v in d.get("v", "0,0").split(","))
                trials.append(Trial(i, role, int(d["posture"]), start, float(d["stop"]),
                                    (w0, w1), (vx, vy), d.get("label", ""),
                                    d.get("status", "")))
            except (ValueError, MapError) as exc:
                raise MapError(f"{where}: {exc}") from None
    postures = None
    pp = reader.get("FIELDBANK:POSTURES")
    if pp is not None:
        postures = np.asarray(pp.float_array, dtype=float).reshape(-1, 2)
    rec = Recording(t, pos, vel, force, tuple(trials), used, source=name,
                    velocity_derived=derived)
    return rec, postures, {"c3d_analog_rate_hz": f"{rate:g}"}
