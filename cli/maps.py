"""``fieldbank maps``: list stored maps."""

from __future__ import annotations

import dataclasses
from datetime import date

import click

from fieldbank.cli.options import DATE, db_option, emit_json, json_option, read_db
from fieldbank.cli.table import table
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
        if patient_code is not None:  # an unknown patient: the one "not found" message
            db.get_patient(patient_code)
        rows = db.list_maps(patient_code, session_label, kind, since, until)
    if as_json:
        emit_json([dataclasses.asdict(m) for m in rows])
        return
    if rows:
        # labels and file names come from outside: no terminal escapes reach the screen
        click.echo("\n".join(table(
            ("id", "patient", "session", "date", "kind", "points", "velocity", "file"),
            [(str(m.id), m.patient_code, printable(m.session_label), str(m.session_date or ""),
              m.kind, str(m.n_points), "static" if m.velocity_m_per_s == (0.0, 0.0) else
              "({:g}, {:g}) m/s".format(*m.velocity_m_per_s), printable(m.source_file))
             for m in rows], "><<<<><")))
    click.echo(f"{len(rows)} map(s)", err=True)
