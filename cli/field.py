"""``fieldbank field postural|stiffness``: a model's maps as CSV, JSON or a figure (SVG, PNG or
PDF: :func:`fieldbank.figures.fields.map_figure`, the conventions of the report's field figures)."""

from __future__ import annotations

import sys
from pathlib import Path

import click
import numpy as np

from fieldbank import modelsource
from fieldbank.cli.options import json_option
from fieldbank.errors import FileRefused, ParameterError
from fieldbank.evaluate.severity import (
    classify,
    parse_severity_options,
    severity_dict,
    summary,
    synthesize,
)
from fieldbank.figures import save
from fieldbank.figures.fields import map_figure
from fieldbank.files import MAX_DOCUMENT_BYTES, read_regular_file, to_json, write_atomic
from fieldbank.maps import ellipse, postural_map, stiffness_map, workspace_grid
from fieldbank.model import Arm


def _parse_pairs(text: str, what: str) -> np.ndarray:
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


def _read_positions(path: Path) -> np.ndarray:
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


@click.command("field")
@click.argument("kind", type=click.Choice(["postural", "stiffness"]))
@click.option("--params", "params_file", type=click.Path(exists=True, dir_okay=False,
              path_type=Path), help="Arm parameter file (JSON, schema fieldbank.arm-params).")
@click.option("--severity", multiple=True, metavar="TARGET=LEVEL",
              help="Synthetic hypertonia, e.g. elbow=severe or elbow-flexors:dynamic=mild "
                   "(TARGET[:passive|dynamic]=LEVEL; targets shoulder, elbow, biarticular or a "
                   "muscle group sf..be / elbow-flexors; levels very-mild, mild, moderate, "
                   "severe). Repeatable.")
@click.option("--mass", type=float, help="Body mass, kg (synthetic arm; default 75).")
@click.option("--height", type=float, help="Height, m (synthetic arm; default 1.75).")
@click.option("--side", type=click.Choice(["right", "left"]), help="Arm side (default right).")
@click.option("--grid", "grid_n", type=int, default=15, show_default=True,
              help="N for an N×N grid over the reachable workspace.")
@click.option("--at", "at", metavar="X,Y;X,Y", help="Positions in metres (shoulder frame).")
@click.option("--positions", "positions_file", type=click.Path(exists=True, dir_okay=False,
              path_type=Path), help="CSV whose first columns are x_m,y_m.")
@click.option("--velocity", default="0,0", show_default=True, metavar="VX,VY",
              help="Endpoint velocity for a stiffness map, m/s.")
@click.option("--format", "fmt", type=click.Choice(["csv", "json", "svg", "png", "pdf"]),
              help="Output format (default from --out's suffix, else csv).")
@json_option
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path),
              help="Output file (default stdout for csv/json; required for plots).")
def field(kind: str, params_file: Path | None, severity: tuple[str, ...], mass: float | None,
          height: float | None, side: str | None, grid_n: int, at: str | None,
          positions_file: Path | None, velocity: str, fmt: str | None, as_json: bool,
          out: Path | None) -> None:
    """Compute a postural or stiffness map of an arm model.

    Examples: ``fieldbank field postural --severity elbow=severe --out elbow.csv``;
    ``fieldbank field stiffness --params arm.json --at 0.05,0.45 --json``.
    """
    if params_file is not None and (mass is not None or height is not None
                                    or side is not None):
        raise ParameterError("--mass/--height/--side describe a synthetic arm; they cannot "
                             "be combined with --params (edit the file instead).")
    if params_file is not None:
        p = modelsource.from_file(params_file).params
        if severity:
            p = synthesize(parse_severity_options(severity), p)
    else:
        p = modelsource.synthetic(severity, body_mass_kg=mass, height_m=height,
                                  side=side).params
    arm = Arm.from_params(p)
    if at is not None and positions_file is not None:
        raise ParameterError("Give positions with --at or --positions, not both.")
    if at is not None:
        pos = _parse_pairs(at, "--at")
    elif positions_file is not None:
        pos = _read_positions(positions_file)
    else:
        if grid_n < 2 or grid_n > 400:
            raise ParameterError(f"--grid must be in [2, 400]; got {grid_n}.")
        pos = workspace_grid(arm, grid_n)
    vel = _parse_pairs(velocity, "--velocity")[0]
    if as_json:
        fmt = "json"
    if fmt is None:
        suffix = out.suffix.lower().lstrip(".") if out else ""
        fmt = suffix if suffix in ("csv", "json", "svg", "png", "pdf") else "csv"
    grades = classify(arm)
    source = f"fieldbank model (synthetic): {summary(grades)}"
    if kind == "postural":
        if np.any(vel != 0):
            raise ParameterError("A postural map is static; --velocity applies to stiffness.")
        m = postural_map(arm, pos, source=source)
    else:
        m = stiffness_map(arm, pos, vel, source=source)
    if fmt in ("svg", "png", "pdf"):
        if out is None:
            raise ParameterError("A plot needs --out FILE.svg, FILE.png or FILE.pdf.")
        save(map_figure(arm, m), out, fmt)
        click.echo(f"wrote {out}", err=True)
        return
    if fmt == "json":
        doc = m.to_json_dict()
        doc["severity"] = severity_dict(grades)
        if kind == "postural":
            doc["potential_j"] = arm.potential(pos).tolist()
        else:
            e = ellipse(m.values)
            doc["ellipse"] = {
                "major_n_per_m": e.major_n_per_m.tolist(),
                "minor_n_per_m": e.minor_n_per_m.tolist(),
                "orientation_rad": e.orientation_rad.tolist(),
                "shape_ratio": [float(v) if np.isfinite(v) else None for v in e.shape_ratio],
                "area_n2_per_m2": e.area.tolist(),
                "curl_n_per_m": e.curl_n_per_m.tolist(),
            }
            doc["damping_n_s_per_m"] = arm.field(pos, vel)[2].tolist()
        text = to_json(doc)
    else:
        text = m.to_csv()
    if out is None:
        sys.stdout.write(text if text.endswith("\n") else text + "\n")
    else:
        write_atomic(out, text)
        click.echo(f"wrote {out} ({m.n} positions)", err=True)

