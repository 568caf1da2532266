"""``fieldbank config show``: every setting in force and where its value came from."""

from __future__ import annotations

import click

from fieldbank.cli.options import GLOBAL_FLAGS, emit_json, json_option
from fieldbank.cli.table import table, wrap
from fieldbank.config import config_file, search_path, settings
from fieldbank.sanitize import printable


@click.group("config")
def config() -> None:
    """Settings: fieldbank.toml, environment variables and their defaults."""


@config.command("show")
@json_option
@click.pass_context
def show(ctx: click.Context, as_json: bool) -> None:
    """Print every setting in force and where it came from (flag > variable > file > default).

    The file is FIELDBANK_CONFIG, else fieldbank.toml in the current directory, else in the
    user configuration directory; the first found is read.
    """
    given = {name: ctx.meta.get(GLOBAL_FLAGS[flag]) for name, flag in
             (("db", "--db"), ("robot", "--robot"), ("scheduler", "--scheduler"),
              ("haptic_socket", "--socket"))}
    rows = settings(given)
    path = config_file()
    if as_json:
        emit_json({"file": None if path is None else str(path),
                   "searched": [str(p) for p in search_path()],
                   "settings": [s.to_dict() for s in rows]})
        return
    click.echo("\n".join(table(("setting", "value", "from"),
                               [(s.name, printable(s.shown), printable(s.source))
                                for s in rows])))
    where = (f"configuration file: {path}" if path is not None else
             "configuration file: none (looked for " + ", ".join(map(str, search_path())) + ")")
    click.echo(wrap(where), err=True)
