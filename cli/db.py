"""``fieldbank db``: schema revision, upgrade, downgrade, integrity check and clean-up."""

from __future__ import annotations

from pathlib import Path

import click

from fieldbank.cli.options import db_option, emit_json, json_option, open_db
from fieldbank.cli.table import wrap

# The storage layer (SQLAlchemy) loads inside the commands, so 'db --help' starts at once.

STATES = {
    "current": "up to date",
    "behind": "behind: run 'fieldbank db upgrade'",
    "empty": "empty: run 'fieldbank db upgrade'",
    "newer": "created by a newer fieldbank: use that version with it",
}


@click.group("db")
def db() -> None:
    """The database itself: migrations and integrity."""


@db.command("upgrade")
@db_option
@click.option("--revision", default="head", show_default=True, help="Target revision.")
def upgrade(db_url: str | None, revision: str) -> None:
    """Migrate the database to REVISION (safe to run from several processes at once)."""
    from fieldbank.storage import migrate

    database = open_db(db_url, upgrade="never", create=True)
    try:
        before, after = migrate.upgrade(database.engine, revision, database.store.root)
    finally:
        database.close()
    click.echo(f"{database.url_masked}: {before or 'empty'} -> {after}", err=True)


@db.command("downgrade")
@db_option
@click.argument("revision")
@click.option("--yes", is_flag=True, help="Really downgrade (it removes schema and data).")
@click.option("--no-backup", is_flag=True,
              help="Do not back up first (you have a backup of your own).")
@click.option("--backup-dir", type=click.Path(file_okay=False, path_type=Path),
              help="Where the backup goes (default: beside a SQLite file; backups/ in the "
                   "data directory for PostgreSQL).")
def downgrade(db_url: str | None, revision: str, yes: bool, no_backup: bool,
              backup_dir: Path | None) -> None:
    """Migrate the database down to REVISION ('base' removes every table and its data).

    Refused unless --yes. First a backup: SQLite, a copy of the file beside it; PostgreSQL,
    pg_dump (custom format) when it is installed, else refused with what to do.
    """
    from fieldbank.storage.backup import guarded_downgrade

    database = open_db(db_url, upgrade="never")
    try:
        res = guarded_downgrade(database.engine, revision, confirmed=yes,
                                make_backup=not no_backup, backup_dir=backup_dir,
                                store_root=database.store.root)
    finally:
        database.close()
    if res.backup is not None:
        click.echo(f"backup: {res.backup}", err=True)
    click.echo(f"{database.url_masked}: {res.before} -> {res.after or 'empty'}", err=True)


@db.command("current")
@db_option
@json_option
def current(db_url: str | None, as_json: bool) -> None:
    """Show the database's schema revision and the newest one this program knows."""
    from fieldbank.storage import migrate

    database = open_db(db_url, upgrade="never")
    try:
        cur = migrate.current_revision(database.engine)
    finally:
        database.close()
    head = migrate.head_revision()
    state = migrate.schema_state(cur)
    if as_json:
        emit_json({"url": database.url_masked, "current": cur, "head": head,
                   "state": state, "up_to_date": state == "current"})
    else:
        click.echo(f"{database.url_masked}\ncurrent {cur or '(empty)'}, head {head} "
                   f"({STATES[state]})")
    if state == "newer":
        click.echo(f"Error: {migrate.newer_message(database.engine, str(cur))}", err=True)
        raise SystemExit(1)


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
            click.echo(f"orphan (harmless; 'fieldbank db gc' removes it): {o}")
        counts = ", ".join(f"{v} {k}" for k, v in report.counts.items())
        click.echo(wrap(f"{database.url_masked}: {'OK' if report.ok else 'DAMAGED'} "
                        f"({counts}; {len(report.problems)} problem(s), "
                        f"{len(report.orphans)} orphan(s))"), err=True)
    if not report.ok:
        raise SystemExit(1)


@db.command("gc")
@db_option
@json_option
def gc(db_url: str | None, as_json: bool) -> None:
    """Remove orphans: unused array records, unreferenced store files, stray temporaries.

    Safe while others write: nothing a concurrent transaction is about to use is removed.
    """
    with open_db(db_url) as database:
        report = database.gc()
    if as_json:
        emit_json({"url": database.url_masked, **report.to_dict()})
        return
    for line in report.rows + report.files + report.temporaries:
        click.echo(f"removed: {line}")
    for line in report.moved:
        click.echo(f"moved: {line}")
    for line in report.in_use:
        click.echo(f"kept: {line}")
    n = len(report.rows) + len(report.files) + len(report.temporaries)
    click.echo(wrap(f"{database.url_masked}: removed {n} orphan(s), moved {len(report.moved)} "
                    "array(s) into the database"), err=True)
