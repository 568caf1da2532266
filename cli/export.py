"""``fieldbank export``: write stored maps as fieldbank HDF5 or CSV, or a raw source file."""

from __future__ import annotations

from datetime import date

import click

from fieldbank.cli.options import (
    DATE,
    MODEL_ID,
    SESSION_ID,
    db_option,
    emit_json,
    json_option,
    open_db,
)


@click.command("export")
@db_option
@click.option("--patient", "patient_code", help="Patient code.")
@click.option("--session", "session_label", help="Session label.")
@click.option("--kind", type=click.Choice(["postural", "stiffness"]))
@click.option("--since", type=DATE)
@click.option("--until", type=DATE)
@click.option("--format", "fmt", type=click.Choice(["hdf5", "csv", "nwb"]), default=None,
              help="Optional; must agree with the output's name: .h5/.hdf5 one HDF5 file, "
                   ".csv one map, no suffix a directory with one CSV per map, .nwb one "
                   "patient (maps, models, fits, haptic sessions).")
@click.option("--trace", "trace_id", type=SESSION_ID, metavar="SESSION_ID",
              help="Instead: a haptic session's trace as OpenSim .mot or .sto.")
@click.option("--model", "model_id", type=MODEL_ID, metavar="ID",
              help="Instead: a stored model as an OpenSim .osim.")
@click.option("--raw", "raw_sha", metavar="SHA256",
              help="Instead: write the source file with this SHA-256 exactly as ingested.")
@click.option("-o", "--output", type=click.Path(), required=True)
@click.option("--force", is_flag=True, help="Replace existing files (never through a link).")
@json_option
def export(db_url: str | None, patient_code: str | None, session_label: str | None,
           kind: str | None, since: date | None, until: date | None, fmt: str | None,
           raw_sha: str | None, trace_id: int | None, model_id: int | None, output: str,
           force: bool, as_json: bool) -> None:
    """Export maps matching the filters (SI units, arm-on-handle as stored), a patient as
    NWB, a haptic trace as OpenSim .mot/.sto, or a model as OpenSim .osim."""
    # numerics: when the command runs
    from fieldbank.exports import export_maps, export_osim, export_raw, export_trace

    with open_db(db_url) as db:
        if raw_sha:
            click.echo(f"wrote {export_raw(db, raw_sha, output, force)}", err=True)
            return
        if trace_id is not None:
            click.echo(f"wrote {export_trace(db, trace_id, output, force)}", err=True)
            return
        if model_id is not None:
            click.echo(f"wrote {export_osim(db, model_id, output, force)}", err=True)
            return
        res = export_maps(db, output, patient_code=patient_code, session_label=session_label,
                          kind=kind, since=since, until=until, fmt=fmt, force=force)
    if as_json:
        emit_json({"maps": list(res.map_ids), "files": list(res.files)})
    click.echo(f"exported {len(res.map_ids)} map(s) to {output}", err=True)
