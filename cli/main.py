"""The ``fieldbank`` command: a thin layer over the library.

Each command group lives in its own module and is registered in :data:`COMMAND_MODULES`.
Commands build library objects, call them, and turn library errors into a message on stderr
and a non-zero exit at this edge. Machine-readable output goes to stdout (``--json``); human
messages and progress go to stderr.
"""

from __future__ import annotations

import importlib

import click

from fieldbank.errors import FieldbankError

#: module name -> attribute holding a click command or group
COMMAND_MODULES: tuple[tuple[str, str], ...] = (
    ("fieldbank.cli.field", "field"),
    ("fieldbank.cli.whatif", "whatif"),
    ("fieldbank.cli.fit", "fit"),
    ("fieldbank.cli.fit", "models"),
    ("fieldbank.cli.db", "db"),
    ("fieldbank.cli.patient", "patient"),
    ("fieldbank.cli.maps", "maps"),
    ("fieldbank.cli.ingest", "ingest"),
    ("fieldbank.cli.export", "export"),
    ("fieldbank.cli.samples", "samples"),
    ("fieldbank.cli.haptic", "haptic"),
    ("fieldbank.cli.report", "report"),
    ("fieldbank.cli.demo", "demo"),
)


class FieldbankGroup(click.Group):
    """Top-level group that reports library errors as clean messages with exit code 1."""

    def invoke(self, ctx: click.Context) -> object:
        try:
            return super().invoke(ctx)
        except FieldbankError as exc:
            raise click.ClickException(str(exc)) from None


@click.group(cls=FieldbankGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="fieldbank")
def cli() -> None:
    """fieldbank: force-field database and intervention what-if for hypertonic arms."""


for _module, _attr in COMMAND_MODULES:
    cli.add_command(getattr(importlib.import_module(_module), _attr))


def main() -> None:
    cli(prog_name="fieldbank")


if __name__ == "__main__":  # pragma: no cover
    main()
