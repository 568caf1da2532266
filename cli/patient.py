"""``fieldbank patient``: register and look up patients (pseudonymous codes only)."""

from __future__ import annotations

import dataclasses

import click

from fieldbank.cli.options import db_option, emit_json, json_option, open_db, read_db
from fieldbank.cli.table import fit_lines
from fieldbank.sanitize import printable


@click.group("patient")
def patient() -> None:
    """Patients: a pseudonymous code, body mass, height and the measured side."""


@patient.command("add")
@db_option
@click.argument("code")
@click.option("--mass-kg", type=float, required=True, help="Body mass, kg.")
@click.option("--height-m", type=float, required=True, help="Height, m.")
@click.option("--side", type=click.Choice(["right", "left"]), required=True,
              help="The arm that is measured.")
@click.option("--notes", default="", help="Free text (no identifying details).")
@json_option
def add(db_url: str | None, code: str, mass_kg: float, height_m: float, side: str, notes: str,
        as_json: bool) -> None:
    """Register patient CODE (a pseudonym; never a name or birth date)."""
    with open_db(db_url, create=True) as db:
        p = db.add_patient(code, mass_kg, height_m, side, notes)
    if as_json:
        emit_json(dataclasses.asdict(p))
    else:
        click.echo(f"added patient {p.code} (id {p.id})", err=True)


@patient.command("list")
@db_option
@json_option
def list_(db_url: str | None, as_json: bool) -> None:
    """List patients."""
    with read_db(db_url) as db:
        rows = db.list_patients()
    if as_json:
        emit_json([dataclasses.asdict(p) for p in rows])
        return
    for p in rows:
        click.echo(f"{p.code:<16} {p.body_mass_kg:6.1f} kg {p.height_m:5.2f} m {p.side}")
    click.echo(f"{len(rows)} patient(s) in {db.url_masked}", err=True)


@patient.command("show")
@db_option
@click.argument("code")
@json_option
def show(db_url: str | None, code: str, as_json: bool) -> None:
    """Show a patient with sessions, map counts and models."""
    with open_db(db_url) as db:
        p = db.get_patient(code)
        sessions = db.list_sessions(code)
        models = db.list_models(code)
    if as_json:
        emit_json({
            **dataclasses.asdict(p),
            "sessions": [dataclasses.asdict(s) for s in sessions],
            "models": [{"id": m.id, "origin": m.origin, "label": m.label,
                        "parent_id": m.parent_id} for m in models],
        })
        return
    lines = [f"patient {p.code}: {p.body_mass_kg:g} kg, {p.height_m:g} m, {p.side} arm"]
    if p.notes:
        lines.append(f"notes: {printable(p.notes)}")
    lines += [f"  session {printable(s.label)!r} {s.session_date or '(no date)'}: "
              f"{s.n_maps} map(s)" for s in sessions]
    lines += [f"  model {m.id} ({m.origin}"
              + (f" from model {m.parent_id}" if m.parent_id else "") + f"): {printable(m.label)}"
              for m in models]
    click.echo("\n".join(fit_lines(lines)))
