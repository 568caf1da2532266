"""``fieldbank jobs [RUN]``: batch runs - what ran, what failed, what is left.

Without RUN: the latest runs, one line each (kind, when, where, how many tasks ended in each
state). With RUN: every task of that run - its state, attempts, worker, time and error.
"""

from __future__ import annotations

from datetime import datetime
from typing import TYPE_CHECKING

import click

from fieldbank.cli.options import RUN_ID, db_option, emit_json, json_option, read_db
from fieldbank.cli.table import table, wrap
from fieldbank.sanitize import printable
from fieldbank.stored.records import JOB_KINDS

if TYPE_CHECKING:  # typing only: the storage layer loads when the command runs
    from fieldbank.stored.records import JobRecord, JobRunRecord


def _when(t: datetime | None) -> str:
    return "-" if t is None else t.astimezone().strftime("%Y-%m-%d %H:%M:%S")


def _run_dict(r: JobRunRecord) -> dict[str, object]:
    return {"id": r.id, "kind": r.kind, "engine": r.engine, "actor": r.actor,
            "started_at": r.started_at, "finished_at": r.finished_at, "counts": r.counts,
            "left": r.left, "args": r.args}


def _job_dict(j: JobRecord) -> dict[str, object]:
    return {"key": j.key, "patient": j.patient_code, "session": j.session_label,
            "state": j.state, "attempts": j.attempts, "worker": j.worker,
            "started_at": j.started_at, "finished_at": j.finished_at, "error": j.error,
            "result": j.result}


def _status(r: JobRunRecord) -> str:
    if r.finished_at is None:
        return "running (or stopped before it ended)"
    return "ended, " + (f"{r.left} left" if r.left else "nothing left")


@click.command("jobs")
@click.argument("run_id", type=RUN_ID, required=False)
@click.option("--kind", type=click.Choice(JOB_KINDS), default=None, help="Only runs of this kind.")
@click.option("--limit", type=click.IntRange(min=1), default=20, show_default=True,
              help="How many of the latest runs to list.")
@click.option("--state", "states", multiple=True,
              type=click.Choice(("pending", "running", "done", "skipped", "failed")),
              help="With RUN: only tasks in this state (repeatable).")
@json_option
@db_option
def jobs(run_id: int | None, kind: str | None, limit: int, states: tuple[str, ...],
         as_json: bool, db_url: str | None) -> None:
    """Batch runs: what ran, what failed, what is left (RUN: each of its tasks)."""
    with read_db(db_url) as db:
        if run_id is None:
            runs = db.list_runs(kind, limit)
            if as_json:
                emit_json([_run_dict(r) for r in runs])
                return
            if not runs:
                click.echo("no batch runs", err=True)
                return
            click.echo("\n".join(table(
                ("run", "kind", "started", "done", "skipped", "failed", "left",
                 "engine; status"),
                [(str(r.id), r.kind, _when(r.started_at), str(r.counts["done"]),
                  str(r.counts["skipped"]), str(r.counts["failed"]), str(r.left),
                  f"{printable(r.engine)}; {_status(r)}") for r in runs], "><<>>>>")))
            return
        run = db.get_run(run_id)
        tasks = db.list_jobs(run_id, states or None)
    if as_json:
        emit_json({**_run_dict(run), "tasks": [_job_dict(j) for j in tasks]})
        return
    c = run.counts
    click.echo(wrap(f"run {run.id}: {run.kind} on {printable(run.engine)}, started "
                    f"{_when(run.started_at)} by {printable(run.actor)}, {_status(run)}"))
    click.echo(f"  {c['done']} done, {c['skipped']} skipped, {c['failed']} failed, "
               f"{run.left} left")
    click.echo("\n".join("  " + line for line in table(
        ("task", "state", "tries", "finished", "worker / error"),
        [(printable(j.key), j.state, str(j.attempts), _when(j.finished_at),
          printable((j.error if j.state == "failed" else j.worker) or "")) for j in tasks],
        "<<><", width=98)))
