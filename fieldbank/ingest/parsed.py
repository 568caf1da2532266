"""What every reader produces, and the validation shared by all formats.

A reader turns a file into :class:`ParsedMap` objects — arrays already in SI, NaN where a cell
was not a number (the reader has reported that), metadata as read — plus the problems it found
in the file's structure. :func:`validate_map` then checks everything that does not depend on the
format (required metadata, NaN/inf, plausible magnitudes, duplicate positions, reachability by
the patient's arm, the patient the file names) and builds the :class:`~fieldbank.maps.FieldMap`.
Every problem is located (file, row or dataset).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fieldbank.errors import MapError, Problem
from fieldbank.ingest.limits import DEFAULT_LIMITS, IngestLimits
from fieldbank.maps import FRAMES, KINDS, SIGNS, FieldMap
from fieldbank.model import Arm

#: positions closer than this (m) in both coordinates count as the same position
DUPLICATE_TOLERANCE_M = 1e-6
#: metadata keys that the map itself holds; others are kept verbatim as provenance
RESERVED_KEYS = ("kind", "frame", "sign", "velocity_m_per_s", "velocity_vector_m_per_s", "source")
#: metadata keys that name the patient a file belongs to (compared with the ingest's patient)
PATIENT_KEYS = ("patient", "patient_code")


@dataclass
class ParsedMap:
    """A map as read from a file, before validation.

    positions_m : (N, 2) m; values : (N, 2) N or (N, 2, 2) N/m; sd : same as values or None.
    velocity_m_per_s : the velocity vector when the file states it unambiguously, else None;
    velocity_problem : why the file's velocity is unusable (already located), if so.
    point_location : gives the location of point i (e.g. ``f.csv:row 7``).
    """

    location: str
    kind: str | None
    frame: str | None
    sign: str | None
    source: str
    metadata: dict[str, str]
    positions_m: np.ndarray
    values: np.ndarray
    sd: np.ndarray | None
    velocity_m_per_s: tuple[float, float] | None
    point_location: Callable[[int], str]
    velocity_missing: bool = False
    problems: list[Problem] = field(default_factory=list)
    #: points whose unreadable cells the reader has already reported (NaN placeholders)
    reported: set[int] = field(default_factory=set)
    #: the reader did not read the rows (their header is broken and reported)
    rows_unread: bool = False


def parse_velocity(
    speed_text: str | None, vector_text: str | None, where: str, kind: str | None,
    problems: list[Problem],
) -> tuple[tuple[float, float] | None, bool]:
    """Velocity vector from the metadata texts; returns (vector or None, missing?)."""
    vec: tuple[float, float] | None = None
    if vector_text is not None:
        parts = [p for p in vector_text.replace(";", ",").split(",") if p.strip()]
        try:
            vals = [float(p) for p in parts]
        except ValueError:
            vals = []
        if len(vals) != 2 or not all(math.isfinite(v) for v in vals):
            problems.append(Problem(where, "velocity_vector_m_per_s must be two finite numbers "
                                    f"'vx, vy' in m/s; got {vector_text!r}"))
            return None, False
        vec = (vals[0], vals[1])
    if speed_text is None:
        if vec is not None:
            return vec, False
        return ((0.0, 0.0), False) if kind == "postural" else (None, True)
    try:
        speed = float(speed_text)
    except ValueError:
        problems.append(Problem(where, f"velocity_m_per_s must be a number in m/s; got "
                                f"{speed_text!r}"))
        return None, False
    if not math.isfinite(speed) or speed < 0:
        problems.append(Problem(where, f"velocity_m_per_s must be a finite speed ≥ 0; got "
                                f"{speed_text!r}"))
        return None, False
    if vec is None:
        if speed == 0:
            return (0.0, 0.0), False
        problems.append(Problem(where, f"velocity_m_per_s is {speed:g} but no direction is "
                                "given: add 'velocity_vector_m_per_s: vx, vy'"))
        return None, False
    if abs(math.hypot(*vec) - speed) > 1e-6 * max(1.0, speed):
        problems.append(Problem(where, f"velocity_m_per_s {speed:g} disagrees with the length "
                                f"{math.hypot(*vec):g} of velocity_vector_m_per_s"))
        return None, False
    return vec, False


def fill_defaults(found: dict[str, Any], defaults: Mapping[str, str], where: str,
                  problems: list[Problem], text_of: Callable[[Any], str]) -> None:
    """Metadata the command line supplies (``--kind``, ``--frame``, ``--sign``, ``--velocity``)
    put into a map file's own metadata ``found`` where it lacks them; a file that states
    another value is a problem naming both, never overridden (HDF5 attributes, MAT
    variables)."""
    for key in ("kind", "frame", "sign"):
        if key not in defaults:
            continue
        if key not in found:
            found[key] = defaults[key]
        elif text_of(found[key]).strip().lower() != defaults[key].strip().lower():
            problems.append(Problem(where, f"the file says {key}: {text_of(found[key])!r}, "
                                    f"the command line says {defaults[key]!r}; remove one"))
    if "velocity_m_per_s" in defaults and "velocity_m_per_s" not in found:
        vec = defaults.get("velocity_vector_m_per_s")
        if vec:
            found["velocity_m_per_s"] = np.array([float(x) for x in vec.split(",")])
        else:
            found["velocity_m_per_s"] = np.array([float(defaults["velocity_m_per_s"])])


def patient_problem(metadata: dict[str, str], patient: str, where: str) -> Problem | None:
    """The problem when ``metadata`` names a patient other than ``patient``, else None."""
    if not patient:
        return None
    for key, value in metadata.items():
        if key.lower() in PATIENT_KEYS and value.strip() != patient:
            return Problem(where, f"the file's {key!r} is {value.strip()!r}, but it is being "
                           f"ingested for patient {patient!r}; another patient's data is never "
                           "stored here (check the file and --patient)")
    return None


def _plausibility(pm: ParsedMap, limits: IngestLimits) -> list[Problem]:
    """A problem per point whose values or sds exceed the plausible magnitude."""
    if pm.kind == "stiffness":
        bound, what, unit, name = (limits.max_stiffness_n_per_m, "stiffness", "N/m",
                                   "max_stiffness_n_per_m")
    else:
        bound, what, unit, name = limits.max_force_n, "force", "N", "max_force_n"
    out = []
    n = pm.positions_m.shape[0]
    for label, arr in (("value", pm.values), ("standard deviation", pm.sd)):
        if arr is None or arr.shape[0] != n:
            continue
        if n == 0:
            continue
        flat = np.abs(arr.reshape(n, -1))
        worst_per_point = np.where(np.isfinite(flat), flat, 0.0).max(axis=1)
        for idx in np.flatnonzero(worst_per_point > bound):
            i = int(idx)
            worst = float(worst_per_point[i])
            out.append(Problem(pm.point_location(i), f"{what} {label} {worst:.4g} {unit} is "
                               f"implausible: above {bound:g} {unit}, more than any arm puts "
                               f"on a handle (a wrong unit?) {limits.hint(name)}"))
    return out


def validate_map(pm: ParsedMap, arm: Arm | None, patient: str = "",
                 limits: IngestLimits = DEFAULT_LIMITS) -> tuple[FieldMap | None,
                                                                 list[Problem]]:
    """Check a parsed map; the FieldMap when it has no problem, else None and the problems."""
    probs = list(pm.problems)
    loc = pm.location
    named = patient_problem(pm.metadata, patient, loc)
    if named is not None:
        probs.append(named)
    for key, value, allowed in (("kind", pm.kind, KINDS), ("frame", pm.frame, FRAMES),
                                ("sign", pm.sign, SIGNS)):
        if value is None:
            probs.append(Problem(loc, f"missing '{key}' ({' | '.join(allowed)})"))
        elif value not in allowed:
            probs.append(Problem(loc, f"unknown {key} {value!r}; expected "
                                 f"{' | '.join(allowed)}"))
    if pm.velocity_missing:
        probs.append(Problem(loc, "missing 'velocity_m_per_s' (a stiffness map must state the "
                             "endpoint velocity of its measurement; 0 = static)"))
    if (pm.kind == "postural" and pm.velocity_m_per_s is not None
            and any(v != 0 for v in pm.velocity_m_per_s)):
        probs.append(Problem(loc, "a postural map is static; velocity must be 0"))
    pos, vals, sd = pm.positions_m, pm.values, pm.sd
    n = pos.shape[0]
    if n == 0 and not pm.rows_unread:
        probs.append(Problem(loc, "no data rows"))
    if n > limits.max_rows:
        probs.append(Problem(loc, f"{n:,} points, more than {limits.max_rows:,} "
                             f"{limits.hint('max_rows')}"))
        return None, probs
    probs += _plausibility(pm, limits)
    for i in range(n):
        cells = [pos[i].ravel(), vals[i].ravel()] + ([sd[i].ravel()] if sd is not None else [])
        row = np.concatenate(cells)
        if i not in pm.reported:
            if np.any(np.isnan(row)):
                probs.append(Problem(pm.point_location(i), "NaN where a number is required"))
            if np.any(np.isinf(row)):
                probs.append(Problem(pm.point_location(i), "infinite value"))
        if sd is not None and np.any(sd[i] < 0):
            probs.append(Problem(pm.point_location(i), "standard deviation is negative"))
    finite = np.all(np.isfinite(pos), axis=1)
    seen: dict[tuple[int, int], int] = {}
    for idx in np.flatnonzero(finite):
        j = int(idx)
        cell = (round(pos[j, 0] / DUPLICATE_TOLERANCE_M), round(pos[j, 1] / DUPLICATE_TOLERANCE_M))
        if cell in seen:
            probs.append(Problem(pm.point_location(j), "duplicate position "
                                 f"({pos[j, 0]:.6g}, {pos[j, 1]:.6g}) m, first at "
                                 f"{pm.point_location(seen[cell])}"))
        else:
            seen[cell] = j
    if arm is not None and finite.any():
        ok = np.ones(n, dtype=bool)
        ok[finite] = arm.reachable(pos[finite])
        for idx in np.flatnonzero(~ok):
            j = int(idx)
            probs.append(Problem(pm.point_location(j), f"position ({pos[j, 0]:.4g}, "
                                 f"{pos[j, 1]:.4g}) m is out of reach of patient {patient}'s "
                                 f"{arm.params.side} arm (upper arm {arm.l1:.3f} m, forearm "
                                 f"and hand {arm.l2:.3f} m, within its range of motion)"))
    if probs or pm.rows_unread:
        return None, probs
    try:
        fm = FieldMap(kind=str(pm.kind), positions_m=pos, values=vals, sd=sd,
                      frame=str(pm.frame), sign=str(pm.sign),
                      velocity_m_per_s=pm.velocity_m_per_s or (0.0, 0.0), source=pm.source,
                      metadata=pm.metadata)
    except MapError as exc:
        return None, [Problem(loc, str(exc))]
    return fm, []
