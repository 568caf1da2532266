"""KINARM exams as ``.kinarm`` files (newer Dexterit-E releases): a ZIP of binary channels.

The layout, as publicly described by the open-source ``kinarm-binary-converter`` (its README,
"What's in a .kinarm file"; MIT licence) — BKIN's own readers (``exam_load`` in the KINARM
Analysis Scripts) are MATLAB only:

* a ZIP archive; ``exam_info_5.txt`` (older: ``exam_info_3.txt``) holds the exam's metadata as
  Java properties (``key=value`` lines: ``model`` the subject, ``protocol``, ``dex_ver``,
  ``robot_arm`` right/left, ``robotver`` e.g. ``KINARM_EP_Rev2`` for an end-point robot);
* ``raw/common/`` the exam's parameters; ``raw/<BB_TT_RR>/`` one folder per trial (block,
  trial, repeat), holding one file per channel: ``<Arm>_Hand.position`` (the hand's x, y
  pairs, m), ``<name>.kinematics`` one channel each (joint angles ``Right_L1Ang``, the
  force/torque sensor ``Right_FS_ForceX``, hand velocities ``Right_HandXVel`` …) and
  ``examevents.bin`` (the trial's events);
* every number little-endian; a channel file is ``version (uint32)``, its name as a UTF-16LE
  string (``uint32`` count of code units, then the units), possibly more such strings
  (description, unit), ``sample count (uint32)``, then the samples as float32 (pairs for a
  ``.position``); ``examevents.bin`` is ``version, count (uint32)``, then per event its name
  (UTF-16LE; some files write it twice) and its time (float32, s from the trial's start);
* Dexterit-E samples at 1 kHz; hand position in m, the force sensor in N, joint angles in rad
  (the units the format documents; a file naming a unit is read in that unit).

What fieldbank reads (:func:`read_kinarm_binary`): the trials in folder-name order, placed end
to end in time with a second between them, the hand of ``robot_arm`` (or ``--column
hand=Left``), the force sensor's x and y (``--column fx=…`` for another channel), the hand
velocity when the exam has it (else differentiated). An exoskeleton without a force sensor has
no ``*_FS_Force`` channel: it is inspected like any exam, and refused for maps in words. The
holds are found by stillness (:mod:`fieldbank.measure.segment`); the shoulder and the sign must
be given, as for every KINARM exam. Members are bounded by the file's budget before they are
inflated (:func:`fieldbank.measure.kinarm.exam_members`).

Checked against: archives written in this layout by :func:`write_kinarm_binary` from seeded
recordings (tests/test_kinarm_binary.py); no real ``.kinarm`` exam was available.
"""

from __future__ import annotations

import io
import struct
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from fieldbank.errors import MapError
from fieldbank.measure.budget import ReadBudget
from fieldbank.measure.kinarm import exam_members, member_bytes
from fieldbank.measure.recording import Recording, derive_velocity
from fieldbank.units import channel_factor

RATE_HZ = 1000.0
#: The units the format documents, by channel suffix (a file that names one wins).
DEFAULT_UNITS = {"Hand": "m", "HandX": "m", "HandY": "m", "FS_ForceX": "N", "FS_ForceY": "N",
                 "FS_ForceZ": "N", "HandXVel": "m/s", "HandYVel": "m/s"}
#: Most strings read between a channel's name and its sample count.
MAX_STRINGS = 8


@dataclass
class Channel:
    """One channel file: its name, the strings after it, its samples ((N,) or (N, 2))."""

    name: str
    strings: list[str]
    samples: np.ndarray

    def unit(self, quantity: str) -> str | None:
        """The first string after the name that is a unit of ``quantity``, if any."""
        return next((s for s in self.strings if channel_factor(s, quantity) is not None),
                    None)


@dataclass
class ExamTrial:
    """One trial folder: its channels by name and its events (name, s)."""

    folder: str
    channels: dict[str, Channel] = field(default_factory=dict)
    events: list[tuple[str, float]] = field(default_factory=list)

    @property
    def n(self) -> int:
        return max((len(c.samples) for c in self.channels.values()), default=0)


@dataclass
class Exam:
    """A ``.kinarm`` exam: its metadata and trials."""

    info: dict[str, str]
    trials: list[ExamTrial]

    @property
    def robot(self) -> str:
        return self.info.get("robotver", "") or "KINARM (robot version not stated)"

    @property
    def arm(self) -> str:
        return (self.info.get("robot_arm") or "right").strip().capitalize()


def _utf16(buf: bytes, off: int) -> tuple[str, int] | None:
    if off + 4 > len(buf):
        return None
    (n,) = struct.unpack_from("<I", buf, off)
    end = off + 4 + 2 * n
    if n > 4096 or end > len(buf):
        return None
    return buf[off + 4:end].decode("utf-16-le", "replace"), end


def parse_channel(buf: bytes, width: int, where: str) -> Channel:
    """A channel file (the layout above); ``width`` values per sample (1, or 2 for x, y)."""
    if len(buf) < 12:
        raise MapError(f"{where}: {len(buf)} bytes, too short for a channel file")
    first = _utf16(buf, 4)
    if first is None:
        raise MapError(f"{where}: no channel name after the version word")
    name, off = first
    strings: list[str] = []
    for _ in range(MAX_STRINGS + 1):
        if off + 4 <= len(buf):
            (count,) = struct.unpack_from("<I", buf, off)
            if count * 4 * width == len(buf) - off - 4:
                data = np.frombuffer(buf, dtype="<f4", count=count * width, offset=off + 4)
                return Channel(name, strings,
                               data.reshape(count, width) if width > 1 else data.copy())
        nxt = _utf16(buf, off)
        if nxt is None or len(strings) >= MAX_STRINGS:
            break
        strings.append(nxt[0])
        off = nxt[1]
    raise MapError(f"{where}: no sample count matches the file's length ({len(buf):,} bytes "
                   f"after the name {name!r}): not a Dexterit-E channel file")


def parse_events(buf: bytes, where: str) -> list[tuple[str, float]]:
    """``examevents.bin``: (name, time s) of each event."""
    if len(buf) < 8:
        return []
    _version, n = struct.unpack_from("<II", buf, 0)
    off = 8
    out: list[tuple[str, float]] = []
    for _ in range(min(n, 100_000)):
        got = _utf16(buf, off)
        if got is None:
            raise MapError(f"{where}: event {len(out)} is cut short")
        label, off = got
        again = _utf16(buf, off)     # some files write the name twice
        if again is not None and again[0] == label and again[1] + 4 <= len(buf):
            off = again[1]
        if off + 4 > len(buf):
            raise MapError(f"{where}: event {label!r} has no time")
        (t,) = struct.unpack_from("<f", buf, off)
        off += 4
        out.append((label, float(t)))
    return out


def read_exam(name: str, data: bytes, budget: ReadBudget | None = None) -> Exam:
    """Every trial's channels and events of a ``.kinarm`` exam, bounded by ``budget``."""
    bud = budget or ReadBudget(1 << 28, len(data))
    z, members = exam_members(name, data, bud)
    info: dict[str, str] = {}
    trials: dict[str, ExamTrial] = {}
    with z:
        for m in sorted(members, key=lambda i: i.filename):
            fname = m.filename
            if fname.lower().startswith("exam_info"):
                text = member_bytes(z, m, name, bud).decode("utf-8", "replace")
                if not info or fname.startswith("exam_info_5"):
                    info = _properties(text)
                continue
            parts = fname.split("/")
            if len(parts) != 3 or parts[1] in ("", "common"):
                continue
            folder, leaf = parts[1], parts[2]
            where = f"{name}:{fname}"
            if leaf.endswith(".position"):
                ch = parse_channel(member_bytes(z, m, name, bud), 2, where)
                trials.setdefault(folder, ExamTrial(folder)).channels[leaf[:-9]] = ch
            elif leaf.endswith(".kinematics"):
                ch = parse_channel(member_bytes(z, m, name, bud), 1, where)
                trials.setdefault(folder, ExamTrial(folder)).channels[leaf[:-11]] = ch
            elif leaf == "examevents.bin":
                trials.setdefault(folder, ExamTrial(folder)).events = parse_events(
                    member_bytes(z, m, name, bud), where)
    return Exam(info, [trials[k] for k in sorted(trials)])


def _properties(text: str) -> dict[str, str]:
    out = {}
    for line in text.splitlines():
        line = line.strip()
        if not line or line[0] in "#!" or "=" not in line:
            continue
        k, _, v = line.partition("=")
        out[k.strip()] = v.strip()
    return out


def _unit(ch: Channel, stem: str, quantity: str) -> tuple[float, str]:
    unit = ch.unit(quantity) or DEFAULT_UNITS.get(stem.split("_", 1)[-1], "")
    f = channel_factor(unit, quantity)
    if f is None:
        raise MapError(f"channel {ch.name or stem!r} has no {quantity} unit fieldbank converts")
    return f, unit


def read_kinarm_binary(name: str, data: bytes, channels: Mapping[str, str] | None = None,
                       budget: ReadBudget | None = None) -> tuple[Recording, dict[str, str]]:
    """The trials of a ``.kinarm`` exam end to end as one recording in the exam's own
    coordinates (no trial marks: the caller finds the holds), and provenance."""
    exam = read_exam(name, data, budget)
    given = dict(channels or {})
    hand = (given.get("hand") or exam.arm).capitalize()
    fx, fy = given.get("fx", f"{hand}_FS_ForceX"), given.get("fy", f"{hand}_FS_ForceY")
    if not exam.trials:
        raise MapError(f"{name}: the exam holds no trial (no raw/<trial>/ folder)")
    ts, ps, vs, fs = [], [], [], []
    t0 = 0.0
    have_vel = True
    units: dict[str, str] = {}
    for tr in exam.trials:
        where = f"{name}:raw/{tr.folder}"
        names = sorted(tr.channels)
        pos_ch = tr.channels.get(f"{hand}_Hand")
        if pos_ch is None:
            raise MapError(f"{where}: no {hand}_Hand.position (channels: {', '.join(names)}); "
                           "the other hand with --column hand=Left")
        missing = [c for c in (fx, fy) if c not in tr.channels]
        if missing:
            if not any("_FS_Force" in c for c in names):
                raise MapError(f"{where}: no hand force: this robot has no force sensor "
                               f"({exam.robot}; channels: {', '.join(names)}); a force from "
                               "another channel is given with --column fx=NAME --column "
                               "fy=NAME")
            raise MapError(f"{where}: no channel {', '.join(missing)} (channels: "
                           f"{', '.join(names)}); name it with --column fx=NAME")
        pf, units["x"] = _unit(pos_ch, "Hand", "length")
        pos = np.asarray(pos_ch.samples, dtype=float) * pf
        cols = []
        for c in (fx, fy):
            ff, units[c] = _unit(tr.channels[c], c, "force")
            cols.append(np.asarray(tr.channels[c].samples, dtype=float) * ff)
        vx, vy = tr.channels.get(f"{hand}_HandXVel"), tr.channels.get(f"{hand}_HandYVel")
        n = min([len(pos)] + [len(c) for c in cols] +
                ([len(vx.samples), len(vy.samples)] if vx and vy else []))
        if n < 2:
            raise MapError(f"{where}: {n} samples")
        t = t0 + np.arange(n) / RATE_HZ
        ts.append(t)
        ps.append(pos[:n])
        fs.append(np.column_stack([c[:n] for c in cols]))
        if vx is not None and vy is not None and have_vel:
            sv, _ = _unit(vx, "HandXVel", "speed")
            vs.append(np.column_stack([vx.samples[:n], vy.samples[:n]]).astype(float) * sv)
        else:
            have_vel = False
        t0 = float(t[-1]) + 1.0      # a second's gap between trials keeps holds apart
    t = np.concatenate(ts)
    pos = np.concatenate(ps)
    vel = np.concatenate(vs) if have_vel else derive_velocity(t, pos)
    rec = Recording(t, pos, vel, np.concatenate(fs), (),
                    {"x": f"{hand}_Hand.position x ({units['x']})",
                     "y": f"{hand}_Hand.position y ({units['x']})",
                     "fx": f"{fx} ({units[fx]})", "fy": f"{fy} ({units[fy]})"},
                    source=name, velocity_derived=not have_vel)
    prov = {"kinarm_format": ".kinarm (binary channels)", "kinarm_robot": exam.robot,
            "kinarm_trials": str(len(exam.trials)),
            "kinarm_sample_rate": f"{RATE_HZ:g} Hz (Dexterit-E's; the file does not state it)"}
    for k in ("dex_ver", "protocol"):
        if exam.info.get(k):
            prov[f"kinarm_{k}"] = exam.info[k]
    return rec, prov


# --- writing, for tests and examples: the layout above ----------------------------------------
def _w_utf16(text: str) -> bytes:
    raw = text.encode("utf-16-le")
    return struct.pack("<I", len(raw) // 2) + raw


def channel_bytes(name: str, samples: np.ndarray, unit: str = "", version: int = 1) -> bytes:
    """A channel file: version, name, (unit), count, float32 samples."""
    arr = np.asarray(samples, dtype="<f4")
    count = arr.shape[0]
    return (struct.pack("<I", version) + _w_utf16(name) + (_w_utf16(unit) if unit else b"")
            + struct.pack("<I", count) + arr.tobytes())


def events_bytes(events: Sequence[tuple[str, float]], twice: bool = False) -> bytes:
    out = struct.pack("<II", 1, len(events))
    for label, t in events:
        out += _w_utf16(label) + (_w_utf16(label) if twice else b"") + struct.pack("<f", t)
    return out


def write_kinarm_binary(trials: Sequence[Mapping[str, np.ndarray]],
                        info: Mapping[str, str],
                        events: Sequence[Sequence[tuple[str, float]]] = (),
                        units: Mapping[str, str] | None = None) -> bytes:
    """A ``.kinarm`` exam: each trial's channels (name → (N,) or (N, 2) for a ``.position``),
    ``exam_info_5.txt`` from ``info``, events per trial; channel units from ``units``."""
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("exam_info_5.txt", "".join(f"{k}={v}\n" for k, v in info.items()))
        z.writestr("raw/common/params.bin", struct.pack("<I", 1))
        for k, chans in enumerate(trials):
            folder = f"raw/{k // 10 + 1:02d}_{k % 10 + 1:02d}_01"
            for cname, arr in chans.items():
                a = np.asarray(arr)
                leaf = f"{cname}.position" if a.ndim == 2 else f"{cname}.kinematics"
                z.writestr(f"{folder}/{leaf}",
                           channel_bytes(cname, a, (units or {}).get(cname, "")))
            if k < len(events):
                z.writestr(f"{folder}/examevents.bin", events_bytes(events[k], twice=k % 2 == 1))
    return out.getvalue()
