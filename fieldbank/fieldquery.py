"""``fieldbank field``'s use case: a model's postural or stiffness map at the positions asked
for, with what the JSON form reports beside it (severity, potential, ellipses, damping).

The arm comes from a parameter file (optionally with severities added) or is synthetic
(anthropometric defaults, severities, body size); positions are given as text
(``x,y;x,y``, m), read from a CSV whose first columns are ``x_m,y_m``, or an N×N grid over the
reachable workspace. Every refusal is a :class:`~fieldbank.errors.ParameterError` naming the
option, file or row.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fieldbank import modelsource
from fieldbank.errors import FileRefused, ParameterError
from fieldbank.evaluate.severity import (
    GroupSeverity,
    classify,
    parse_severity_options,
    severity_dict,
    summary,
    synthesize,
)
from fieldbank.files import MAX_DOCUMENT_BYTES, read_regular_file
from fieldbank.maps import FieldMap, ellipse, postural_map, stiffness_map, workspace_grid
from fieldbank.model import Arm, FloatArray

KINDS = ("postural", "stiffness")
#: The grid's N (an N×N grid over the workspace).
GRID_RANGE = (2, 400)


def parse_pairs(text: str, what: str) -> FloatArray:
    """``'x,y;x,y'`` (or space-separated) as an (N, 2) array; ``what`` names the option."""
    pts = []
    for i, item in enumerate(t for t in text.replace(";", " ").split() if t):
        parts = item.split(",")
        if len(parts) != 2:
            raise ParameterError(f"{what} item {i + 1} {item!r} must be 'x,y' in metres.")
        try:
            pts.append([float(parts[0]), float(parts[1])])
        except ValueError:
            raise ParameterError(f"{what} item {i + 1} {item!r} is not two numbers.") from None
    if not pts:
        raise ParameterError(f"{what} is empty; give positions as 'x,y;x,y' in metres.")
    return np.array(pts)


def read_positions(path: Path) -> FloatArray:
    """The positions of a CSV whose first two columns are ``x_m,y_m`` (``#`` lines skipped)."""
    rows = []
    try:
        text = read_regular_file(path, MAX_DOCUMENT_BYTES).decode("utf-8")
    except (FileRefused, UnicodeDecodeError) as exc:
        raise ParameterError(f"{path}: cannot read positions ({exc}).") from None
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.startswith("#")]
    if not lines:
        raise ParameterError(f"{path}: no rows.")
    header = [h.strip() for h in lines[0].split(",")]
    if header[:2] != ["x_m", "y_m"]:
        raise ParameterError(f"{path}: the first two columns must be x_m,y_m; got {header[:2]}.")
    for n, ln in enumerate(lines[1:], start=2):
        parts = ln.split(",")
        try:
            rows.append([float(parts[0]), float(parts[1])])
        except (ValueError, IndexError):
            raise ParameterError(f"{path}: row {n}: expected two numbers, got {ln!r}.") from None
    return np.array(rows)


@dataclass(frozen=True, eq=False)
class FieldResult:
    """The map asked for, the arm it was computed on and that arm's grades."""

    kind: str
    arm: Arm
    map: FieldMap
    grades: Mapping[str, GroupSeverity]
    positions_m: FloatArray
    velocity_m_per_s: FloatArray

    def to_json_dict(self) -> dict[str, Any]:
        """The map's JSON form with the severity and, for a postural map, the potential; for a
        stiffness map, its ellipses and the damping."""
        m, pos = self.map, self.positions_m
        doc = m.to_json_dict()
        doc["severity"] = severity_dict(self.grades)
        if self.kind == "postural":
            doc["potential_j"] = self.arm.potential(pos).tolist()
            return doc
        e = ellipse(m.values)
        doc["ellipse"] = {
            "major_n_per_m": e.major_n_per_m.tolist(),
            "minor_n_per_m": e.minor_n_per_m.tolist(),
            "orientation_rad": e.orientation_rad.tolist(),
            "shape_ratio": [float(v) if np.isfinite(v) else None for v in e.shape_ratio],
            "area_n2_per_m2": e.area.tolist(),
            "curl_n_per_m": e.curl_n_per_m.tolist(),
        }
        doc["damping_n_s_per_m"] = self.arm.field(pos, self.velocity_m_per_s)[2].tolist()
        return doc


def field_map(kind: str, *, params_file: Path | None = None, severity: Sequence[str] = (),
              mass_kg: float | None = None, height_m: float | None = None,
              side: str | None = None, grid_n: int = 15, at: str | None = None,
              positions_file: Path | None = None, velocity: str = "0,0") -> FieldResult:
    """The ``kind`` map (postural or stiffness) of the arm described, at the positions given
    (``at`` text, ``positions_file``, else a ``grid_n``×``grid_n`` grid)."""
    if kind not in KINDS:
        raise ParameterError(f"the map kind must be one of {', '.join(KINDS)}; got {kind!r}.")
    if params_file is not None and (mass_kg is not None or height_m is not None
                                    or side is not None):
        raise ParameterError("--mass/--height/--side describe a synthetic arm; they cannot "
                             "be combined with --params (edit the file instead).")
    if params_file is not None:
        p = modelsource.from_file(params_file).params
        if severity:
            p = synthesize(parse_severity_options(severity), p)
    else:
        p = modelsource.synthetic(severity, body_mass_kg=mass_kg, height_m=height_m,
                                  side=side).params
    arm = Arm.from_params(p)
    if at is not None and positions_file is not None:
        raise ParameterError("Give positions with --at or --positions, not both.")
    if at is not None:
        pos = parse_pairs(at, "--at")
    elif positions_file is not None:
        pos = read_positions(positions_file)
    else:
        if not GRID_RANGE[0] <= grid_n <= GRID_RANGE[1]:
            raise ParameterError(f"--grid must be in [{GRID_RANGE[0]}, {GRID_RANGE[1]}]; "
                                 f"got {grid_n}.")
        pos = workspace_grid(arm, grid_n)
    vel = parse_pairs(velocity, "--velocity")[0]
    grades = classify(arm)
    source = f"fieldbank model (synthetic): {summary(grades)}"
    if kind == "postural":
        if np.any(vel != 0):
            raise ParameterError("A postural map is static; --velocity applies to stiffness.")
        m = postural_map(arm, pos, source=source)
    else:
        m = stiffness_map(arm, pos, vel, source=source)
    return FieldResult(kind, arm, m, grades, pos, vel)
