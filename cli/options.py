"""Options and output shared by every command: ``--db``, ``--json``, opening the database, and
the one JSON emitter (:func:`fieldbank.files.to_json`: one indent, one encoder).

This module imports nothing heavy: ``fieldbank.storage`` (SQLAlchemy, alembic, numpy) is
imported only when :func:`open_db` runs, so commands that never open the database - ``haptic
switch``, ``--help`` - start at once; the commands that list what the database holds open it
with :func:`read_db`, through its driver alone when they can.
"""

from __future__ import annotations

import calendar
import functools
from collections.abc import Callable
from datetime import date
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar, cast

import click

from fieldbank.files import to_json

if TYPE_CHECKING:  # typing only; the storage layer loads when a command opens the database
    from fieldbank.storage import Database
    from fieldbank.stored.listing import Reads

F = TypeVar("F", bound=Callable[..., Any])

DB_HELP = ("SQLAlchemy database URL; default: $FIELDBANK_DB, else the embedded SQLite file in "
           "$FIELDBANK_HOME (or the platform's user data directory).")


class DateParam(click.ParamType):
    """A calendar date written YYYY-MM-DD, refused with the reason when it is not one
    ("2024-02-30: February 2024 has 29 days", not "does not match the format")."""

    name = "YYYY-MM-DD"

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> date:
        if isinstance(value, date):
            return value
        text = str(value).strip()
        parts = text.split("-")
        if len(parts) != 3 or not all(p.isdigit() for p in parts) or len(parts[0]) != 4:
            self.fail(f"{text!r} is not a date written YYYY-MM-DD (e.g. 2024-02-21).",
                      param, ctx)
        y, m, d = (int(p) for p in parts)
        if not 1 <= m <= 12:
            self.fail(f"{text}: there is no month {m} (months run 01-12).", param, ctx)
        days = calendar.monthrange(y, m)[1]
        if not 1 <= d <= days:
            self.fail(f"{text}: {calendar.month_name[m]} {y} has {days} days.", param, ctx)
        return date(y, m, d)


#: The one date option type (``--date``, ``--since``, ``--until``, ``--given-on``, ``--on``).
DATE = DateParam()


def db_option(f: F) -> F:
    """``--db URL`` → parameter ``db_url``."""
    return click.option("--db", "db_url", default=None, metavar="URL", help=DB_HELP)(f)


SCHEDULER_HELP = ("Run on the Dask cluster of this scheduler: tls://HOST:PORT with the "
                  "cluster's certificates (tcp:// only on this machine's loopback); default: "
                  "$FIELDBANK_SCHEDULER, else fieldbank.toml, else worker processes on this "
                  "machine (--jobs).")


def scheduler_option(f: F) -> F:
    """The scheduler options → one parameter ``scheduler``: a
    :class:`~fieldbank.scheduler.SchedulerFlags` of what was given, or None when none was
    (resolved with the settings by :func:`fieldbank.scheduler.resolve_scheduler` when the
    command runs).

    ``--scheduler ADDRESS``; ``--tls-ca``, ``--tls-cert``, ``--tls-key`` FILE (the cluster's
    certificates); ``--insecure-scheduler`` (a plain address beyond the loopback).
    """
    from fieldbank.scheduler import SchedulerFlags  # standard library only

    names = ("tls_ca", "tls_cert", "tls_key", "insecure_scheduler")

    @functools.wraps(f)
    def combined(*args: Any, **kwargs: Any) -> Any:
        ca, cert, key, insecure = (kwargs.pop(n) for n in names)
        address = kwargs["scheduler"]
        given = (address, ca, cert, key, insecure or None)
        kwargs["scheduler"] = (None if all(v is None for v in given) else
                               SchedulerFlags(address, ca, cert, key, insecure or None))
        return f(*args, **kwargs)

    return option_group(
        click.option("--scheduler", "scheduler", default=None, metavar="ADDRESS",
                     help=SCHEDULER_HELP),
        click.option("--tls-ca", "tls_ca", default=None, metavar="FILE",
                     help="The cluster's CA certificate (PEM) for a tls:// scheduler; "
                          "default: $FIELDBANK_SCHEDULER_TLS_CA, else [scheduler] tls_ca."),
        click.option("--tls-cert", "tls_cert", default=None, metavar="FILE",
                     help="This client's certificate (PEM) for a tls:// scheduler ('fieldbank "
                          "cluster certs' makes one)."),
        click.option("--tls-key", "tls_key", default=None, metavar="FILE",
                     help="This client's private key (PEM, readable by you only)."),
        click.option("--insecure-scheduler", "insecure_scheduler", is_flag=True, default=False,
                     help="Accept a tcp:// scheduler on another machine: it is neither "
                          "encrypted nor authenticated, so anyone who can reach it can run "
                          "code on its workers and read the tasks."),
    )(cast(F, combined))


def json_option(f: F) -> F:
    """``--json`` → parameter ``as_json``: one JSON document on stdout, messages on stderr."""
    return click.option("--json", "as_json", is_flag=True,
                        help="Machine-readable output: one JSON document on stdout.")(f)


def open_db(db_url: str | None, upgrade: str = "auto", create: bool = False) -> Database:
    """The field database at ``db_url`` (see :meth:`fieldbank.storage.Database.open`).

    A database that does not exist is refused with its path and how to create it, unless
    ``create`` (``patient add`` and ``db upgrade``, the commands that start one): reading or
    adding to a database never creates an empty one by surprise.
    """
    from fieldbank.storage import Database  # heavy; deferred so light commands stay instant

    return Database.open(db_url, upgrade=upgrade, create=create)


def read_db(db_url: str | None) -> Reads:
    """The database at ``db_url`` for a command that only lists what it holds: read through
    its driver alone (:func:`fieldbank.stored.listing.open_listing`: no SQLAlchemy, numpy or
    array store to load) when it is at head, else opened as :func:`open_db` opens it (migrated,
    or refused in the same words). The records and the errors are the same either way."""
    from fieldbank.stored.listing import open_listing

    return open_listing(db_url) or open_db(db_url)


def emit_json(data: Any) -> None:
    """Print ``data`` as one JSON document on stdout."""
    click.echo(to_json(data))


def emit(data: Any, as_json: bool, human: str) -> None:
    """``data`` as JSON with ``--json``, else the human text."""
    click.echo(to_json(data) if as_json else human)


def say(msg: str) -> None:
    """A message for the person at the terminal: on stderr, so stdout stays the output."""
    click.echo(msg, err=True)


def output_file(ctx: click.Context, param: click.Parameter, value: Any) -> Any:
    """Callback of an option naming a file the command writes: its directory must exist.
    A typo in a directory name is refused with the directory, not created silently."""
    if value is None:
        return value
    parent = Path(value).expanduser().parent
    if not parent.is_dir():
        raise click.BadParameter(f"the directory {parent} does not exist; create it first "
                                 "(fieldbank does not create directories for a file you name).")
    return value


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
    before any work is done; a wrong one is a library error, reported at the error edge. Its
    directory must exist (:func:`output_file`)."""
    if value is not None:
        from fieldbank.figures import figure_format  # numpy: only when a figure is asked for

        figure_format(value)
    return output_file(ctx, param, value)


def option_group(*opts: Callable[[F], F]) -> Callable[[F], F]:
    """Several click options as one decorator, listed in ``--help`` in the order given."""
    def apply(f: F) -> F:
        for o in reversed(opts):
            f = o(f)
        return f
    return apply
