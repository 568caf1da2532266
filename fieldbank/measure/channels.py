"""The channels of a raw recording: their units, and what their values may not be.

Every raw reader (C3D, NWB, KINARM) names, for each role — hand position ``x``, ``y``,
velocity ``vx``, ``vy``, force ``fx``, ``fy`` — the file's channel and the unit the file gives
it. :func:`unit_factor` turns that unit into SI or says why it cannot: a unit fieldbank does not
know, or no unit at all — an empty text, pynwb's ``unknown`` (what pynwb reads when a file
states none) and ``ADDME`` (the placeholder an extension's writer left unset) are named as
such. ``--unit ROLE=UNIT`` supplies the unit a file does not state; it never overrides one the
file does state.

:func:`check_channels` refuses what would store a wrong map, each naming the channel:

* a **flat** channel (every sample the same: an unloaded force plate, an unplugged sensor) —
  a force of exactly 0 N with an sd of 0 is not a measurement;
* values its **unit contradicts**: a hand position more than ``MAX_REACH_M`` (2 m) from the
  origin of the file's coordinates in metres (960 "m" is a centre of pressure in mm), a force
  over the ingest's ``max_force_n``, a speed over ``MAX_SPEED_M_PER_S``;
* a channel that holds **no finite number** at all.

Bounds are assumptions, stated where they are used: an arm's reach is under 1 m (BRIEF §3,
0.186 H + 0.2 H for H up to 2.1 m) and a robot's workspace, in its own coordinates, lies within
2 m of its origin; a hand on a robot moves at under 3 m/s (MAS-4 probing runs at 1 m/s).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from fieldbank.measure.recording import Recording
from fieldbank.units import channel_factor

#: Role → quantity of its unit.
QUANTITY = {"x": "length", "y": "length", "vx": "speed", "vy": "speed", "fx": "force",
            "fy": "force"}
#: Placeholder units, in the words a user is told.
PLACEHOLDERS = {
    "": "no unit",
    "addme": "the unit 'ADDME', the placeholder an NWB extension's writer leaves when no unit "
             "was set",
    "unknown": "the unit 'unknown', what pynwb reads when a file states no unit",
    "n.a.": "the unit 'n.a.'",
}
MAX_REACH_M = 2.0
MAX_SPEED_M_PER_S = 10.0


def unit_factor(role: str, file_unit: str, given: Mapping[str, str], channel: str
                ) -> tuple[float, str]:
    """(SI factor, unit used) for a channel, or raise ValueError with the reason in words.

    ``given``: ``--unit`` values by role (used only when the file states no real unit)."""
    quantity = QUANTITY[role]
    unit = (file_unit or "").strip()
    key = unit.lower()
    opt = given.get(role) or given.get({"x": "position", "y": "position", "vx": "velocity",
                                        "vy": "velocity", "fx": "force", "fy": "force"}[role])
    if key in PLACEHOLDERS:
        if opt:
            f = channel_factor(opt, quantity)
            if f is None:
                raise ValueError(f"--unit {role}={opt}: not a {quantity} unit fieldbank "
                                 "converts")
            return f, opt
        raise ValueError(f"channel {channel!r} ({role}) has {PLACEHOLDERS[key]}: fieldbank "
                         f"cannot tell its scale; if you know it, give it with --unit "
                         f"{role}=UNIT (e.g. {_example(quantity)})")
    f = channel_factor(unit, quantity)
    if f is None:
        raise ValueError(f"channel {channel!r} ({role}) has unit {unit!r}, not a {quantity} "
                         f"unit fieldbank converts ({_example(quantity)}): is it the "
                         f"{quantity} you meant? name another channel with --column "
                         f"{role}=LABEL")
    if opt and channel_factor(opt, quantity) != f:
        raise ValueError(f"channel {channel!r} ({role}): the file says its unit is {unit!r}, "
                         f"--unit says {opt!r}; remove one")
    return f, unit


def _example(quantity: str) -> str:
    return {"length": "m, cm, mm", "force": "N, mN, kgf, lbf",
            "speed": "m/s, cm/s, mm/s"}[quantity]


def check_channels(rec: Recording, max_force_n: float) -> list[str]:
    """Reasons the recording's channels cannot give a map (see the module docstring); []
    when none. ``rec`` is in SI."""
    out: list[str] = []
    cols = {"x": rec.position_m[:, 0], "y": rec.position_m[:, 1], "fx": rec.force_n[:, 0],
            "fy": rec.force_n[:, 1]}
    if not rec.velocity_derived:
        cols["vx"] = rec.velocity_m_per_s[:, 0]
        cols["vy"] = rec.velocity_m_per_s[:, 1]
    for role, v in cols.items():
        name = rec.channels.get(role, role)
        fin = v[np.isfinite(v)]
        if fin.size == 0:
            out.append(f"channel {name} ({role}) holds no finite number")
            continue
        lo, hi = float(fin.min()), float(fin.max())
        if hi == lo:
            unit = {"x": "m", "y": "m", "fx": "N", "fy": "N"}.get(role, "m/s")
            out.append(f"channel {name} ({role}) is flat: every sample is {lo:g} {unit} "
                       "(an unloaded or unconnected sensor, or an empty channel), so it "
                       "measures nothing")
            continue
        big = max(abs(lo), abs(hi))
        if role in ("x", "y") and big > MAX_REACH_M:
            out.append(f"channel {name} ({role}) reads up to {big:,.4g} m: a hand is within "
                       f"{MAX_REACH_M:g} m of the robot's origin, so the unit the file gives "
                       "cannot be right (millimetres? a centre of pressure?)")
        elif role in ("fx", "fy") and big > max_force_n:
            out.append(f"channel {name} ({role}) reads up to {big:,.4g} N, more than the "
                       f"{max_force_n:g} N an arm puts on a handle (limit max_force_n): a "
                       "wrong unit or not a hand force")
        elif role in ("vx", "vy") and big > MAX_SPEED_M_PER_S:
            out.append(f"channel {name} ({role}) reads up to {big:,.4g} m/s, faster than "
                       f"{MAX_SPEED_M_PER_S:g} m/s: a wrong unit or not a hand velocity")
    return out
