"""``fieldbank users``: the workspace's accounts (``fieldbank serve``) and their API tokens."""

from __future__ import annotations

import sys

import click

from fieldbank.cli.options import db_option, emit, emit_json, json_option, open_db, say
from fieldbank.sanitize import printable

ROLES = ("clinician", "data-manager", "viewer")


def read_password(from_stdin: bool) -> str:
    """The new password: one line of standard input (its line end removed), else asked for
    twice at the terminal without echo."""
    if from_stdin:
        line = sys.stdin.readline()
        return line[:-1] if line.endswith("\n") else line
    return str(click.prompt("Password", hide_input=True, confirmation_prompt=True))


@click.group("users")
def users() -> None:
    """Accounts of the workspace: add, list, passwords, roles, API tokens."""


@users.command("add")
@click.argument("name")
@click.option("--role", type=click.Choice(ROLES), required=True,
              help="viewer: reads; clinician: plans and drives the robot; data-manager: "
                   "manages patients and files.")
@click.option("--password-stdin", is_flag=True,
              help="Read the password from standard input (one line) instead of asking.")
@db_option
@json_option
def add(name: str, role: str, password_stdin: bool, db_url: str | None, as_json: bool) -> None:
    """Add account NAME with a role; the password is hashed (Argon2id), never stored."""
    from fieldbank.web.accounts import add_user

    password = read_password(password_stdin)
    with open_db(db_url) as db:
        u = add_user(db, name, role, password)
    emit({"name": u.name, "role": u.role, "id": u.id}, as_json,
         f"added account {u.name} ({u.role})")


@users.command("list")
@db_option
@json_option
def list_(db_url: str | None, as_json: bool) -> None:
    """List accounts: name, role, since when, disabled or not."""
    with open_db(db_url) as db:
        rows = db.list_users()
    if as_json:
        emit_json([{"name": u.name, "role": u.role, "created_at": u.created_at.isoformat(),
                    "disabled_at": u.disabled_at.isoformat() if u.disabled_at else None}
                   for u in rows])
        return
    for u in rows:
        state = f"disabled {u.disabled_at:%Y-%m-%d}" if u.disabled_at else "active"
        click.echo(f"{printable(u.name):<24} {u.role:<13} since {u.created_at:%Y-%m-%d}  "
                   f"{state}")
    say(f"{len(rows)} account(s)")


@users.command("passwd")
@click.argument("name")
@click.option("--password-stdin", is_flag=True,
              help="Read the new password from standard input (one line).")
@db_option
def passwd(name: str, password_stdin: bool, db_url: str | None) -> None:
    """Set a new password for account NAME."""
    from fieldbank.web.accounts import set_password

    password = read_password(password_stdin)
    with open_db(db_url) as db:
        set_password(db, name, password)
    say(f"password of {name} changed")


@users.command("role")
@click.argument("name")
@click.argument("role", type=click.Choice(ROLES))
@db_option
def role(name: str, role: str, db_url: str | None) -> None:
    """Give account NAME another role (it counts from its next request)."""
    with open_db(db_url) as db:
        u = db.set_user(name, role=role)
    say(f"{u.name} is now a {u.role}")


@users.command("disable")
@click.argument("name")
@click.option("--enable", is_flag=True, help="Enable the account again instead.")
@db_option
def disable(name: str, enable: bool, db_url: str | None) -> None:
    """Disable account NAME: no login, no tokens (it is kept: the audit log names it)."""
    with open_db(db_url) as db:
        u = db.set_user(name, disabled=not enable)
    say(f"{u.name} is {'disabled' if u.disabled_at else 'enabled'}")


@users.command("token")
@click.argument("name")
@click.option("--label", default="", help="What the token is for (shown by 'users tokens').")
@db_option
@json_option
def token(name: str, label: str, db_url: str | None, as_json: bool) -> None:
    """Make an API token for account NAME (shown once; send it as 'Authorization: Bearer
    TOKEN'); revoke it with 'fieldbank users revoke ID'."""
    from fieldbank.web.accounts import new_token

    with open_db(db_url) as db:
        secret, rec = new_token(db, name, label)
    emit({"id": rec.id, "user": rec.user, "label": rec.label, "token": secret}, as_json, secret)
    if not as_json:
        say(f"token {rec.id} of {rec.user}: shown once, keep it like a password "
            f"(revoke: fieldbank users revoke {rec.id})")


@users.command("tokens")
@click.argument("name", required=False)
@db_option
@json_option
def tokens(name: str | None, db_url: str | None, as_json: bool) -> None:
    """List API tokens (of account NAME): id, owner, label, made, revoked."""
    with open_db(db_url) as db:
        rows = db.list_tokens(name)
    if as_json:
        emit_json([{"id": t.id, "user": t.user, "label": t.label,
                    "created_at": t.created_at.isoformat(),
                    "revoked_at": t.revoked_at.isoformat() if t.revoked_at else None}
                   for t in rows])
        return
    for t in rows:
        state = f"revoked {t.revoked_at:%Y-%m-%d %H:%M}" if t.revoked_at else "live"
        click.echo(f"{t.id:>5}  {printable(t.user):<20} {t.created_at:%Y-%m-%d}  {state:<24}"
                   f"{printable(t.label)}")
    say(f"{len(rows)} token(s)")


@users.command("revoke")
@click.argument("token_id", metavar="ID", type=click.IntRange(1, 2**62))
@db_option
def revoke(token_id: int, db_url: str | None) -> None:
    """Revoke API token ID (it stops working at once)."""
    with open_db(db_url) as db:
        t, changed = db.revoke_token(token_id)
    say(f"token {t.id} of {t.user} revoked" if changed else
        f"token {t.id} of {t.user} was already revoked; nothing changed")
