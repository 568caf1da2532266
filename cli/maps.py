"""``fieldbank maps``: list stored maps."""

from __future__ import annotations

import dataclasses
from datetime import date

import click

from fieldbank.cli.options import DATE, db_option, emit_json, json_option, read_db
from fieldbank.sanitize import printable


@click.group("maps")
def maps() -> None:
    """Measured postural and stiffness maps."""


@maps.command("list")
@db_option
@click.option("--patient", "patient_code", help="Patient code.")
@click.option("--session", "session_label", help="Session label, e.g. pre-BoNT.")
@click.option("--kind", type=click.Choice(["postural", "stiffness"]))
@click.option("--since", type=DATE, help="Sessions on or after.")
@click.option("--until", type=DATE, help="Sessions on or before.")
@json_option
def list_(db_url: str | None, patient_code: str | None, session_label: str | None,
          kind: str | None, since: date | None, until: date | None,
          as_json: bool) -> None:
    """List maps matching every filter given."""
    with read_db(db_url) as db:
        rows = db.list_maps(patient_code, session_label, kind, since, until)
    if as_json:
        emit_json([dataclasses.asdict(m) for m in rows])
        return
    for m in rows:
        v = "static" if m.velocity_m_per_s == (0.0, 0.0) else (
            "v=({:g}, {:g}) m/s".format(*m.velocity_m_per_s))
        # labels and file names come from outside: no terminal escapes reach the screen
        click.echo(f"{m.id:>6} {m.patient_code:<12} {printable(m.session_label):<14} "
                   f"{m.session_date or ''!s:<10} {m.kind:<9} {m.n_points:>4} pts {v:<18} "
                   f"{printable(m.source_file)}")
    click.echo(f"{len(rows)} map(s)", err=True)
