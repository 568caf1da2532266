"""Options and output shared by every command: ``--db``, ``--json``, opening the database, and
the one JSON emitter (:func:`fieldbank.files.to_json`: one indent, one encoder).

This module imports nothing heavy: ``fieldbank.storage`` (SQLAlchemy, alembic, numpy) is
imported only when :func:`open_db` runs, so commands that never open the database - ``haptic
switch``, ``--help`` - start at once.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

import click

from fieldbank.files import to_json

if TYPE_CHECKING:  # typing only; the storage layer loads when a command opens the database
    from fieldbank.storage import Database

F = TypeVar("F", bound=Callable[..., Any])

DB_HELP = ("SQLAlchemy database URL; default: $FIELDBANK_DB, else the embedded SQLite file in "
           "$FIELDBANK_HOME (or the platform's user data directory).")


def db_option(f: F) -> F:
    """``--db URL`` → parameter ``db_url``."""
    return click.option("--db", "db_url", default=None, metavar="URL", help=DB_HELP)(f)


def json_option(f: F) -> F:
    """``--json`` → parameter ``as_json``: one JSON document on stdout, messages on stderr."""
    return click.option("--json", "as_json", is_flag=True,
                        help="Machine-readable output: one JSON document on stdout.")(f)


def open_db(db_url: str | None, upgrade: str = "auto") -> Database:
    """The field database at ``db_url`` (see :meth:`fieldbank.storage.Database.open`)."""
    from fieldbank.storage import Database  # heavy; deferred so light commands stay instant

    return Database.open(db_url, upgrade=upgrade)


def emit_json(data: Any) -> None:
    """Print ``data`` as one JSON document on stdout."""
    click.echo(to_json(data))


def emit(data: Any, as_json: bool, human: str) -> None:
    """``data`` as JSON with ``--json``, else the human text."""
    click.echo(to_json(data) if as_json else human)


def say(msg: str) -> None:
    """A message for the person at the terminal: on stderr, so stdout stays the output."""
    click.echo(msg, err=True)


def xy_metres(text: str | None, name: str) -> tuple[float, float]:
    """``X,Y`` in metres from the option ``name`` (0,0 when not given)."""
    if text is None:
        return (0.0, 0.0)
    try:
        a, b = (float(v) for v in text.split(","))
    except ValueError:
        raise click.BadParameter(f"{name} must read X,Y in metres; got {text!r}") from None
    return (a, b)


def figure_path(ctx: click.Context, param: click.Parameter, value: Any) -> Any:
    """Callback of a ``--plot`` option: the figure's format (.svg, .png or .pdf) is checked
    before any work is done; a wrong one is a library error, reported at the error edge."""
    del ctx, param
    if value is not None:
        from fieldbank.figures import figure_format  # numpy: only when a figure is asked for

        figure_format(value)
    return value


def option_group(*opts: Callable[[F], F]) -> Callable[[F], F]:
    """Several click options as one decorator, listed in ``--help`` in the order given."""
    def apply(f: F) -> F:
        for o in reversed(opts):
            f = o(f)
        return f
    return apply
