"""``fieldbank report``: HTML, CSV and JSON reports of field changes for stored plans.

Select one patient (``--patient``), one or more plans (``--plan``), or a batch (``--patients``,
``--session``, ``--since``, ``--until``, ``--kind``; no filter: every stored plan). Writes
``report.html`` (self-contained, figures inline, dated unless ``--no-date``), ``metrics.csv``
and ``metrics.json`` into ``--out``. An empty selection or missing data is a clear message and
exit status 1.
"""

from __future__ import annotations

from datetime import date, datetime
from typing import TYPE_CHECKING

import click

from fieldbank.cli.options import (
    DATE,
    PLAN_ID,
    db_option,
    emit_json,
    json_option,
    open_db,
    say,
    scheduler_option,
)
from fieldbank.config import setting

if TYPE_CHECKING:  # typing only
    from fieldbank.scheduler import SchedulerFlags


def _codes(items: tuple[str, ...]) -> tuple[str, ...]:
    return tuple(dict.fromkeys(c.strip() for it in items for c in it.split(",") if c.strip()))


@click.command("report")
@db_option
@click.option("--patient", "patient", multiple=True, metavar="CODE",
              help="One patient's stored plans (repeatable).")
@click.option("--patients", "patients", multiple=True, metavar="CODE,...",
              help="Several patients, comma-separated.")
@click.option("--plan", "plan_ids", multiple=True, type=PLAN_ID, metavar="ID",
              help="One stored plan by id (repeatable).")
@click.option("--session", "sessions", multiple=True, metavar="LABEL",
              help="Plans whose model was fitted to maps of this session (repeatable).")
@click.option("--since", type=DATE, default=None,
              help="Cases dated on or after this day (session date, else plan date).")
@click.option("--until", type=DATE, default=None,
              help="Cases dated on or before this day.")
@click.option("--kind", "kinds", multiple=True, metavar="KIND",
              help="Plans with a step of this kind, e.g. botulinum, lengthening (repeatable).")
@click.option("--out", "out_dir", required=True, type=click.Path(file_okay=False),
              help="Directory for report.html, metrics.csv and metrics.json (a report "
                   "already there is refused unless --force).")
@click.option("--force", is_flag=True, help="Replace the report files already in --out.")
@click.option("--jobs", type=click.IntRange(min=1), default=None,
              help="Worker processes for batches (default: report.jobs in fieldbank.toml, "
                   "else the cores available).")
@scheduler_option
@click.option("--no-date/--date", "no_date", default=None,
              help="Leave the time of writing out, so that reruns give identical files "
                   "(default: report.no_date in fieldbank.toml, else dated).")
@click.option("--accept-poor-fit", is_flag=True,
              help="Report cases whose model comes from a poor fit anyway (recorded per case).")
@json_option
def report(db_url: str | None, patient: tuple[str, ...], patients: tuple[str, ...],
           plan_ids: tuple[int, ...], sessions: tuple[str, ...], since: date | None,
           until: date | None, kinds: tuple[str, ...], out_dir: str, force: bool,
           jobs: int | None, scheduler: SchedulerFlags | None, no_date: bool | None,
           accept_poor_fit: bool,
           as_json: bool) -> None:
    """Report the field changes of stored intervention plans (HTML + CSV + JSON).

    Terms (R1, R2, catch, χ²/n, under-determined, ...): docs/glossary.md.
    """
    # the report's numerics load when it runs, so 'report --help' starts at once
    from fieldbank.engine import default_jobs
    from fieldbank.interventions.catalogue import KINDS
    from fieldbank.interventions.report import Selection, build_report
    from fieldbank.scheduler import resolve_scheduler

    bad = [k for k in kinds if k not in KINDS]
    if bad:
        raise click.UsageError(f"--kind {bad[0]!r} is not an intervention kind "
                               f"(known: {', '.join(KINDS)}).")
    if since and until and since > until:
        raise click.UsageError("--since is after --until: the selection would be empty.")
    sel = Selection(patients=_codes(patient + patients), plan_ids=tuple(plan_ids),
                    sessions=tuple(sessions), since=since, until=until, kinds=tuple(kinds))
    jobs = setting("report.jobs", jobs).value
    when = (None if setting("report.no_date", no_date).value
            else datetime.now().astimezone().isoformat(timespec="seconds"))
    address = resolve_scheduler(scheduler)  # a bad address is refused before any work
    with open_db(db_url) as db:
        out = build_report(db, sel, out_dir, jobs=jobs or default_jobs(), progress=True,
                           stamp=when, accept_poor_fit=accept_poor_fit, force=force,
                           scheduler=address, say=say)
    if as_json:
        emit_json({"cases": out.n_cases, "jobs": out.jobs_used, "html": str(out.html),
                   "csv": str(out.csv), "json": str(out.json)})
    say(f"report of {out.n_cases} case(s) written to {out.html} "
        f"(metrics: {out.csv.name}, {out.json.name})")
