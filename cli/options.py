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
import math
from collections.abc import Callable
from datetime import date
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar, cast

import click

from fieldbank.cli.table import fit_lines
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

    def __init__(self, not_after_today: str = "") -> None:
        #: When set, a day after today is refused with this reason.
        self.not_after_today = not_after_today

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
        if y < 1:
            self.fail(f"{text}: there is no year 0 (years run from 0001).", param, ctx)
        if not 1 <= m <= 12:
            self.fail(f"{text}: there is no month {m} (months run 01-12).", param, ctx)
        days = calendar.monthrange(y, m)[1]
        if not 1 <= d <= days:
            self.fail(f"{text}: {calendar.month_name[m]} {y} has {days} days.", param, ctx)
        day = date(y, m, d)
        if self.not_after_today and day > date.today():
            self.fail(f"{text} is in the future (today is {date.today().isoformat()}): "
                      f"{self.not_after_today}.", param, ctx)
        return day


#: The one date option type (``--date``, ``--since``, ``--until``).
DATE = DateParam()
#: The day a plan was carried out (``--given-on``, ``plans give --on``): never after today.
GIVEN_DATE = DateParam("a plan is recorded as given on the day it was carried out")


class IdParam(click.ParamType):
    """A stored row's id: a whole number from 1 to the largest id a database column holds
    (PostgreSQL's ``integer``), refused in words before the database is opened - never a
    traceback for ``abc`` or ``99999999999999999999999``."""

    name = "ID"
    MAX = 2**31 - 1

    def __init__(self, what: str) -> None:
        self.what = what

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> int:
        if isinstance(value, int) and not isinstance(value, bool):
            text = str(value)
        else:
            text = str(value).strip()
        if not text.isdigit() or not text.isascii():
            self.fail(f"{text!r} is not a {self.what} id: ids are whole numbers (1, 2, …).",
                      param, ctx)
        n = int(text)
        if not 1 <= n <= self.MAX:
            self.fail(f"{text} is not a {self.what} id: ids run from 1 to {self.MAX}.",
                      param, ctx)
        return n


class LabelParam(click.ParamType):
    """A label the user names a thing by (a session): not empty, nothing but spaces."""

    name = "LABEL"

    def __init__(self, what: str) -> None:
        self.what = what

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> str:
        text = str(value)
        if not text.strip():
            self.fail(f"a {self.what} must not be empty.", param, ctx)
        return text


#: A session's label (``--session``).
SESSION_LABEL = LabelParam("session label")

#: Typed ids of the stored things commands name.
MODEL_ID = IdParam("model")
PLAN_ID = IdParam("plan")
SESSION_ID = IdParam("haptic session")
RUN_ID = IdParam("batch run")

#: Settings whose flag may also be given before the command (``fieldbank --db URL patient
#: list``): flag -> the key under which the top-level group keeps it in ``ctx.meta``.
GLOBAL_FLAGS = {"--db": "fieldbank.db", "--robot": "fieldbank.robot",
                "--scheduler": "fieldbank.scheduler", "--socket": "fieldbank.socket"}


def from_top(flag: str, fallback: Any = None) -> Callable[[], Any]:
    """A callable default: the value the same flag had before the command
    (:data:`GLOBAL_FLAGS`), else ``fallback``. A flag given after the command wins."""
    key = GLOBAL_FLAGS[flag]

    def default() -> Any:
        ctx = click.get_current_context(silent=True)
        value = ctx.meta.get(key) if ctx is not None else None
        return fallback if value is None else value

    return default


def db_option(f: F) -> F:
    """``--db URL`` → parameter ``db_url``."""
    return click.option("--db", "db_url", default=from_top("--db"), metavar="URL",
                        help=DB_HELP)(f)


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
        click.option("--scheduler", "scheduler", default=from_top("--scheduler"),
                     metavar="ADDRESS",
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
    """``data`` as JSON with ``--json``, else the human text (every line within 100 columns:
    :func:`fieldbank.cli.table.fit_lines`)."""
    click.echo(to_json(data) if as_json else "\n".join(fit_lines(human.splitlines())))


def log_info_to_stderr() -> None:
    """fieldbank's own log messages at INFO on stderr, as ``LEVEL message`` (for the commands
    that run a service); other libraries' loggers (alembic's migration steps among them) keep
    their levels. Once per process: a second call adds no second handler."""
    import logging
    import sys

    log = logging.getLogger("fieldbank")
    if not log.handlers:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("%(levelname)s %(message)s"))
        log.addHandler(handler)
        log.setLevel(logging.INFO)


def say(msg: str) -> None:
    """A message for the person at the terminal: on stderr, so stdout stays the output; every
    line within 100 columns."""
    click.echo("\n".join(fit_lines(msg.splitlines())), err=True)


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
    if not (math.isfinite(a) and math.isfinite(b)):
        raise click.BadParameter(f"{name} must read X,Y in metres, two finite numbers; got "
                                 f"{text!r}")
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
