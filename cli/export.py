"""``fieldbank export``: write stored maps as fieldbank HDF5 or CSV, or a raw source file."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path

import click

from fieldbank.cli.options import db_option, emit_json, json_option, open_db
from fieldbank.errors import StorageError
from fieldbank.ingest import write_hdf5


@click.command("export")
@db_option
@click.option("--patient", "patient_code", help="Patient code.")
@click.option("--session", "session_label", help="Session label.")
@click.option("--kind", type=click.Choice(["postural", "stiffness"]))
@click.option("--since", type=click.DateTime(["%Y-%m-%d"]))
@click.option("--until", type=click.DateTime(["%Y-%m-%d"]))
@click.option("--format", "fmt", type=click.Choice(["hdf5", "csv"]), default="hdf5",
              show_default=True, help="hdf5: one file (docs/formats.md); csv: a directory "
              "with one file per map.")
@click.option("--raw", "raw_sha", metavar="SHA256",
              help="Instead: write the source file with this SHA-256 exactly as ingested.")
@click.option("-o", "--output", type=click.Path(), required=True)
@json_option
def export(db_url: str | None, patient_code: str | None, session_label: str | None,
           kind: str | None, since: datetime | None, until: datetime | None, fmt: str,
           raw_sha: str | None, output: str, as_json: bool) -> None:
    """Export maps matching the filters (SI units, arm-on-handle as stored)."""
    out = Path(output)
    with open_db(db_url) as db:
        if raw_sha:
            out.write_bytes(db.source_bytes(raw_sha))
            click.echo(f"wrote {out}", err=True)
            return
        rows = db.list_maps(patient_code, session_label, kind,
                            since.date() if since else None, until.date() if until else None)
        if not rows:
            raise StorageError("No map matches these filters; nothing exported.")
        maps = db.get_maps([r.id for r in rows])
    extra = [{"patient": r.patient_code, "session": r.session_label,
              "session_date": str(r.session_date or ""), "fieldbank_map_id": r.id,
              "source_file": r.source_file, "source_sha256": r.source_sha256} for r in rows]
    if fmt == "hdf5":
        write_hdf5(out, maps, extra)
        written = [str(out)]
    else:
        out.mkdir(parents=True, exist_ok=True)
        written = []
        for r, m in zip(rows, maps, strict=True):
            p = out / f"{r.patient_code}_{r.session_label}_{r.kind}_{r.id}.csv"
            p.write_text(m.to_csv(), encoding="utf-8")
            written.append(str(p))
    if as_json:
        emit_json({"maps": [r.id for r in rows], "files": written})
    click.echo(f"exported {len(rows)} map(s) to {out}", err=True)
