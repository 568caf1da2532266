"""``fieldbank field postural|stiffness``: a model's maps as CSV, JSON or a figure (SVG, PNG or
PDF: :func:`fieldbank.figures.fields.map_figure`, the conventions of the report's field figures)."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from fieldbank.cli.options import json_option, output_file
from fieldbank.errors import ParameterError
from fieldbank.files import to_json, write_atomic


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
              callback=output_file,
              help="Output file (default stdout for csv/json; required for plots).")
def field(kind: str, params_file: Path | None, severity: tuple[str, ...], mass: float | None,
          height: float | None, side: str | None, grid_n: int, at: str | None,
          positions_file: Path | None, velocity: str, fmt: str | None, as_json: bool,
          out: Path | None) -> None:
    """Compute a postural or stiffness map of an arm model.

    Examples: ``fieldbank field postural --severity elbow=severe --out elbow.csv``;
    ``fieldbank field stiffness --params arm.json --at 0.05,0.45 --json``.
    """
    from fieldbank.fieldquery import field_map
    from fieldbank.figures import save
    from fieldbank.figures.fields import map_figure

    r = field_map(kind, params_file=params_file, severity=severity, mass_kg=mass,
                  height_m=height, side=side, grid_n=grid_n, at=at,
                  positions_file=positions_file, velocity=velocity)
    m = r.map
    if as_json:
        fmt = "json"
    if fmt is None:
        suffix = out.suffix.lower().lstrip(".") if out else ""
        fmt = suffix if suffix in ("csv", "json", "svg", "png", "pdf") else "csv"
    if fmt in ("svg", "png", "pdf"):
        if out is None:
            raise ParameterError("A plot needs --out FILE.svg, FILE.png or FILE.pdf.")
        save(map_figure(r.arm, m), out, fmt)
        click.echo(f"wrote {out}", err=True)
        return
    if fmt == "json":
        text = to_json(r.to_json_dict())
    else:
        text = m.to_csv()
    if out is None:
        sys.stdout.write(text if text.endswith("\n") else text + "\n")
    else:
        write_atomic(out, text)
        click.echo(f"wrote {out} ({m.n} positions)", err=True)

