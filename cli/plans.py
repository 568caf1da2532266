"""``fieldbank plans list|show|give``: the stored intervention plans."""

from __future__ import annotations

import textwrap
from datetime import date

import click

from fieldbank.cli.options import (
    GIVEN_DATE,
    PLAN_ID,
    db_option,
    emit,
    emit_json,
    json_option,
    open_db,
    read_db,
    say,
)
from fieldbank.sanitize import printable

#: Widest line of the text output.
WIDTH = 100
KIND_HELP = ("A step of this kind: botulinum, lengthening, tenotomy, rhizotomy, baclofen, "
             "casting.")


@click.group("plans")
def plans() -> None:
    """Stored intervention plans: list, show, record the day one was given."""


@plans.command("list")
@click.option("--patient", metavar="CODE", help="Only this patient's plans.")
@click.option("--kind", metavar="KIND", help=KIND_HELP)
@click.option("--given/--not-given", "given", default=None,
              help="Only plans recorded as given (carried out), or only those explored.")
@db_option
@json_option
def list_cmd(patient: str | None, kind: str | None, given: bool | None, db_url: str | None,
             as_json: bool) -> None:
    """List stored plans: id, patient, given date, models before -> after, steps."""
    from fieldbank.interventions.plans import list_plans

    with read_db(db_url) as db:
        rows = list_plans(db, patient, kind, given)
        where = db.url_masked
    if as_json:
        emit_json([p.to_dict() for p in rows])
        return
    if rows:
        click.echo(f"{'plan':>5}  {'patient':<10} {'given':<10}  {'models':<9}  steps")
    for p in rows:
        when = p.given_on.isoformat() if p.given_on else "explored"
        models = f"{p.base_model_id}->{p.result_model_id}"
        head = f"{p.id:>5}  {p.patient_code or '-':<10} {when:<10}  {models:<9}  "
        click.echo("\n".join(textwrap.wrap(printable("; ".join(p.steps)), WIDTH,
                                            initial_indent=head,
                                            subsequent_indent=" " * len(head))))
    say(f"{len(rows)} plan(s) in {where}")


@plans.command("show")
@click.argument("plan_id", metavar="ID", type=PLAN_ID)
@db_option
@json_option
def show(plan_id: int, db_url: str | None, as_json: bool) -> None:
    """Show plan ID: steps, lineage, the fit behind it, its warnings, the day it was given."""
    from fieldbank.interventions.plandetail import show_plan

    with open_db(db_url) as db:
        d = show_plan(db, plan_id)
    s = d.summary
    lines = [f"plan {s.id}" + (f" of patient {s.patient_code}" if s.patient_code else "")
             + f": {printable(s.label)}",
             "  given: " + (s.given_on.isoformat() if s.given_on else
                            "not recorded (explored only; 'fieldbank plans give "
                            f"{s.id} --on DATE' records it)"),
             f"  stored: {s.created_at:%Y-%m-%d %H:%M} UTC",
             "  steps:", *[f"    {k + 1}. {printable(t)}" for k, t in enumerate(s.steps)],
             f"  model before: {d.base['id']} ({d.base['origin']}: {printable(d.base['label'])})",
             f"  model after:  {d.result['id']} ({d.result['origin']})"]
    if d.fit is None:
        lines.append("  fit: none behind the model before (not fitted to measured maps)")
    else:
        lines.append(f"  fit: {d.fit['id']} of model {d.fit['fitted_model_id']}, status "
                     f"{d.fit['status']} (goodness of fit {d.fit['verdict']})")
    if s.accepted_poor_fit:
        lines.append(f"  accepted a poor fit: {printable(s.accepted_poor_fit)}")
    if d.guesses:
        lines.append("  not identified by the maps (the unimpaired value is a guess): "
                     + ", ".join(str(g.get("name")) for g in d.guesses))
    lines += [f"  WARNING: {printable(w)}" for w in d.warnings]
    emit(d.to_dict(), as_json, "\n".join(w for line in lines for w in textwrap.wrap(
        line, WIDTH, subsequent_indent=" " * (len(line) - len(line.lstrip()) + 4),
        break_on_hyphens=False) or [""]))


@plans.command("give")
@click.argument("plan_id", metavar="ID", type=PLAN_ID)
@click.option("--on", "on", type=GIVEN_DATE, required=True,
              help="The day the plan was carried out, YYYY-MM-DD.")
@db_option
@json_option
def give(plan_id: int, on: date, db_url: str | None, as_json: bool) -> None:
    """Record that stored plan ID was given (carried out) on a day, for 'fieldbank validate'."""
    from fieldbank.interventions.plans import give_plan

    with open_db(db_url) as db:
        p, changed = give_plan(db, plan_id, on)
    if as_json:
        emit_json({**p.to_dict(), "changed": changed})
    say(f"plan {p.id} recorded as given on {on.isoformat()}" if changed else
        f"plan {p.id} was already recorded as given on {on.isoformat()}; nothing changed")
