"""``fieldbank db``: schema revision, upgrade, downgrade and integrity check."""

from __future__ import annotations

import click

from fieldbank.cli.options import db_option, emit_json, json_option, open_db
from fieldbank.storage import migrate


@click.group("db")
def db() -> None:
    """The database itself: migrations and integrity."""


@db.command("upgrade")
@db_option
@click.option("--revision", default="head", show_default=True, help="Target revision.")
def upgrade(db_url: str | None, revision: str) -> None:
    """Migrate the database to REVISION (safe to run from several processes at once)."""
    database = open_db(db_url, upgrade="never")
    try:
        before, after = migrate.upgrade(database.engine, revision)
    finally:
        database.close()
    click.echo(f"{database.url_masked}: {before or 'empty'} -> {after}", err=True)


@db.command("downgrade")
@db_option
@click.argument("revision")
def downgrade(db_url: str | None, revision: str) -> None:
    """Migrate the database down to REVISION ('base' removes every table and its data)."""
    database = open_db(db_url, upgrade="never")
    try:
        before, after = migrate.downgrade(database.engine, revision)
    finally:
        database.close()
    click.echo(f"{database.url_masked}: {before} -> {after or 'empty'}", err=True)


@db.command("current")
@db_option
@json_option
def current(db_url: str | None, as_json: bool) -> None:
    """Show the database's schema revision and the newest one this program knows."""
    database = open_db(db_url, upgrade="never")
    try:
        cur = migrate.current_revision(database.engine)
    finally:
        database.close()
    head = migrate.head_revision()
    if as_json:
        emit_json({"url": database.url_masked, "current": cur, "head": head,
                   "up_to_date": cur == head})
    else:
        state = "up to date" if cur == head else "behind: run 'fieldbank db upgrade'"
        click.echo(f"{database.url_masked}\ncurrent {cur or '(empty)'}, head {head} ({state})")


@db.command("check")
@db_option
@json_option
def check(db_url: str | None, as_json: bool) -> None:
    """Verify every reference and checksum; report orphans. Exit 1 on any problem."""
    database = open_db(db_url, upgrade="never")
    try:
        report = database.check()
    finally:
        database.close()
    if as_json:
        emit_json({"url": database.url_masked, "ok": report.ok,
                   "problems": list(report.problems), "orphans": list(report.orphans),
                   "counts": report.counts})
    else:
        for p in report.problems:
            click.echo(f"problem: {p}")
        for o in report.orphans:
            click.echo(f"orphan (harmless): {o}")
        counts = ", ".join(f"{v} {k}" for k, v in report.counts.items())
        click.echo(f"{database.url_masked}: {'OK' if report.ok else 'DAMAGED'} ({counts}; "
                   f"{len(report.problems)} problem(s), {len(report.orphans)} orphan(s))",
                   err=True)
    if not report.ok:
        raise SystemExit(1)
