"""The ``--db`` option shared by every command that opens the field database."""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any, TypeVar

import click

from fieldbank.storage import Database

F = TypeVar("F", bound=Callable[..., Any])


def db_option(f: F) -> F:
    return click.option(
        "--db",
        "db_url",
        default=None,
        metavar="URL",
        help="SQLAlchemy database URL; default: $FIELDBANK_DB, else the embedded SQLite file "
        "in $FIELDBANK_HOME (or the platform's user data directory).",
    )(f)


def open_db(db_url: str | None, upgrade: str = "auto") -> Database:
    return Database.open(db_url, upgrade=upgrade)


def emit_json(data: Any) -> None:
    click.echo(json.dumps(data, indent=2, default=str))
