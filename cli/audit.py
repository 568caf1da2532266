"""``fieldbank audit``: read the audit log (every write, and reads of patients' data)."""

from __future__ import annotations

import json
from datetime import datetime

import click

from fieldbank.cli.options import db_option, emit_json, json_option, open_db, say
from fieldbank.sanitize import printable

#: Widest line of the text output.
WIDTH = 100


class WhenParam(click.ParamType):
    """A day (YYYY-MM-DD, from its start) or a time (YYYY-MM-DDTHH:MM[:SS]), UTC."""

    name = "DATE|TIME"

    def convert(self, value: object, param: click.Parameter | None,
                ctx: click.Context | None) -> datetime:
        if isinstance(value, datetime):
            return value
        try:
            return datetime.fromisoformat(str(value).strip())
        except ValueError:
            self.fail(f"{value!r} is not a date (YYYY-MM-DD) or a time (YYYY-MM-DDTHH:MM), UTC.",
                      param, ctx)


@click.command("audit")
@click.option("--patient", metavar="CODE", help="Entries about this patient (its rows and "
              "reads of its data).")
@click.option("--user", "actor", metavar="NAME", help="Entries by this account or login.")
@click.option("--since", type=WhenParam(), help="Entries at or after this day or time (UTC).")
@click.option("--action", help="Only this action (add, read, login, give, ...).")
@click.option("--limit", type=click.IntRange(1, 1_000_000), default=200, show_default=True,
              help="Newest entries shown at most.")
@db_option
@json_option
def audit(patient: str | None, actor: str | None, since: datetime | None, action: str | None,
          limit: int, db_url: str | None, as_json: bool) -> None:
    """Show the audit log, newest first: who did or read what, when, from where."""
    with open_db(db_url) as db:
        rows = db.audit_entries(limit, patient=patient, actor=actor, since=since,
                                action=action)
    if as_json:
        emit_json([{"id": e.id, "at": e.at.isoformat(), "actor": e.actor, "action": e.action,
                    "entity": e.entity, "entity_id": e.entity_id, "detail": e.detail}
                   for e in rows])
        return
    for e in rows:
        detail = dict(e.detail)
        req = detail.pop("request", None)
        where = f" [{req.get('via', '')} from {req.get('from', '?')}]" if isinstance(
            req, dict) else ""
        text = (f"{e.at:%Y-%m-%d %H:%M:%S}  {printable(e.actor):<14} {e.action:<13} "
                f"{e.entity} {printable(e.entity_id)}{where} "
                + printable(json.dumps(detail, ensure_ascii=False, sort_keys=True)))
        click.echo(text if len(text) <= WIDTH else text[:WIDTH - 1] + "…")
    say(f"{len(rows)} entr{'y' if len(rows) == 1 else 'ies'} (newest first; --json: whole)")
