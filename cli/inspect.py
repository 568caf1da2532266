"""``fieldbank inspect``: what a lab file holds, and what ingest would make of it."""

from __future__ import annotations

import click

from fieldbank.cli.options import emit_json, json_option, xy_metres
from fieldbank.sanitize import printable


@click.command("inspect")
@click.argument("files", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option("--column", "columns", multiple=True, metavar="NAME=HEADER",
              help="As for ingest: the verdict is given with these channel names.")
@click.option("--trial-events", "trial_events", multiple=True, metavar="LABEL",
              help="As for ingest: the events that start trials.")
@click.option("--unit", "units", multiple=True, metavar="ROLE=UNIT",
              help="As for ingest: the unit of a channel the file states none for.")
@click.option("--sign", type=click.Choice(["arm-on-handle", "handle-on-arm"]),
              help="As for ingest.")
@click.option("--shoulder", metavar="X,Y", help="As for ingest (KINARM exams).")
@click.option("--limit", "limit_items", multiple=True, metavar="NAME=VALUE",
              help="Override an ingest limit (as for ingest).")
@json_option
def inspect(files: tuple[str, ...], columns: tuple[str, ...], trial_events: tuple[str, ...],
            units: tuple[str, ...], sign: str | None, shoulder: str | None,
            limit_items: tuple[str, ...], as_json: bool) -> None:
    """Show what FILES hold (C3D markers, analog channels and events; NWB series anywhere in
    the file; KINARM trials; MAT and HDF5 variables; CSV header) and what ingest would map
    from each, or why not and the options that map it. Stores nothing."""
    from fieldbank.ingest.inspect import inspect_file  # readers: when it runs
    from fieldbank.ingest.limits import IngestLimits
    from fieldbank.ingest.options import ReadOptions

    limits = IngestLimits.from_environment(limit_items)
    options = ReadOptions.from_flags(None, None, sign, None, columns,
                                     xy_metres(shoulder, "--shoulder") if shoulder else None,
                                     trial_events, units)
    results = [inspect_file(f, limits, options) for f in files]
    if as_json:
        emit_json({"files": [r.to_json_dict() for r in results]})
    else:
        for r in results:
            click.echo("\n".join(printable(line) for line in r.lines()))
    unreadable = [r.file for r in results if not r.readable]
    if unreadable:
        raise click.ClickException(f"could not read {', '.join(printable(u) for u in unreadable)}")
