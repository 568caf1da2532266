"""The ``fieldbank`` command: a thin layer over the library.

Each command (or command group) lives in its own module, registered in :data:`COMMANDS` with
its one-line help and imported only when it runs (:class:`fieldbank.cli.lazy.LazyGroup`), so
``fieldbank --version``, ``--help`` and a live ``haptic switch`` answer without loading numpy,
SQLAlchemy or matplotlib. Commands build library objects, call them, and turn library errors
into a message on stderr and a non-zero exit at this edge. Machine-readable output goes to
stdout (``--json``); human messages and progress go to stderr.
"""

from __future__ import annotations

import click

from fieldbank.cli.lazy import LazyCommand, LazyGroup
from fieldbank.cli.options import GLOBAL_FLAGS
from fieldbank.errors import FieldbankError
from fieldbank.sanitize import printable

C = LazyCommand
#: command name -> where it lives and its one-line help (tests check the help is the command's)
COMMANDS: dict[str, LazyCommand] = {
    "field": C("fieldbank.cli.field", "field",
               "Compute a postural or stiffness map of an arm model."),
    "whatif": C("fieldbank.cli.whatif", "whatif",
                "Apply clinical interventions to a model and compare the fields before and after."),
    "fit": C("fieldbank.cli.fit", "fit",
             "Fit PATIENT's arm model to the patient's measured maps and store it."),
    "models": C("fieldbank.cli.fit", "models",
                "Stored arm models (fitted, synthetic, after interventions)."),
    "db": C("fieldbank.cli.db", "db",
            "The database itself: migrations and integrity."),
    "patient": C("fieldbank.cli.patient", "patient",
                 "Patients: a pseudonymous code, body mass, height and the measured side."),
    "maps": C("fieldbank.cli.maps", "maps",
              "Measured postural and stiffness maps."),
    "ingest": C("fieldbank.cli.ingest", "ingest",
                "Ingest postural and stiffness maps from FILES (CSV, HDF5, MATLAB .mat v5/v7.3)."),
    "inspect": C("fieldbank.cli.inspect", "inspect",
                 "Show what FILES hold (C3D markers, analog channels and events; NWB series "
                 "anywhere in the file; KINARM trials; MAT and HDF5 variables; CSV header) "
                 "and what ingest would map from each, or why not and the options that map "
                 "it."),
    "export": C("fieldbank.cli.export", "export",
                "Export maps matching the filters (SI units, arm-on-handle as stored)."),
    "samples": C("fieldbank.cli.samples", "samples",
                 "Write lab-style map files of synthetic patients into DIRECTORY (seeded)."),
    "haptic": C("fieldbank.cli.haptic", "haptic",
                "Feel arm models on a 2-DOF robot: serve, push, switch, abx, probe, status, "
                "replay."),
    "probe": C("fieldbank.cli.probe", "probe",
               "Design probing motions that tell candidate arms apart; classify recorded traces."),
    "plans": C("fieldbank.cli.plans", "plans",
               "Stored intervention plans: list, show, record the day one was given."),
    "report": C("fieldbank.cli.report", "report",
                "Report the field changes of stored intervention plans (HTML + CSV + JSON)."),
    "jobs": C("fieldbank.cli.jobs", "jobs",
              "Batch runs: what ran, what failed, what is left (RUN: each of its tasks)."),
    "validate": C("fieldbank.cli.validate", "validate",
                  "Check predictions against maps measured after the plan; --loo: leave maps "
                  "out of a fit."),
    "cluster": C("fieldbank.cli.cluster", "cluster",
                 "The Dask cluster of the batch commands: its certificates (docs/scale-out.md)."),
    "config": C("fieldbank.cli.config", "config",
                "Settings: fieldbank.toml, environment variables and their defaults."),
    "serve": C("fieldbank.cli.serve", "serve",
               "Serve the workspace: log in, find a patient, compose a plan, feel it on the "
               "robot."),
    "users": C("fieldbank.cli.users", "users",
               "Accounts of the workspace: add, list, passwords, roles, API tokens."),
    "audit": C("fieldbank.cli.audit", "audit",
               "Show the audit log, newest first: who did or read what, when, from where."),
    "demo": C("fieldbank.cli.demo", "demo",
              "Run the whole product once on synthetic sample data, saying what it does."),
}


class FieldbankGroup(LazyGroup):
    """Top-level group: the command line's one error edge. A library error
    (:class:`~fieldbank.errors.FieldbankError`) becomes a message with exit status 1; every
    message, a usage error's too, is shown without terminal escapes
    (:func:`fieldbank.sanitize.printable`). Commands let library errors through to here."""

    def invoke(self, ctx: click.Context) -> object:
        try:
            return super().invoke(ctx)
        except FieldbankError as exc:
            # messages quote file names and labels from outside: no terminal escapes
            raise click.ClickException(printable(str(exc), multiline=True)) from None
        except click.ClickException as exc:
            # usage errors quote what was typed, too. click types the message Final, but reads
            # it only when the error is shown, after this
            exc.message = printable(exc.message, multiline=True)  # type: ignore[misc]
            raise


def _keep(ctx: click.Context, param: click.Parameter, value: object) -> object:
    """A setting's flag given before the command: kept for every command that has the same
    option (:func:`fieldbank.cli.options.from_top`)."""
    if value is not None:
        ctx.meta[GLOBAL_FLAGS[param.opts[0]]] = value
    return value


@click.group(cls=FieldbankGroup, lazy=COMMANDS,
             context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--db", metavar="URL", expose_value=False, callback=_keep,
              help="Database URL for the command that follows (as its own --db).")
@click.option("--robot", metavar="PORT", expose_value=False, callback=_keep,
              help="Robot port for the command that follows (as its own --robot).")
@click.option("--scheduler", metavar="ADDRESS", expose_value=False, callback=_keep,
              help="Dask scheduler for the command that follows (as its own --scheduler).")
@click.option("--socket", metavar="SOCKET", expose_value=False, callback=_keep,
              help="Renderer's control socket for the command that follows (as its own "
                   "--socket).")
@click.version_option(package_name="fieldbank")
def cli() -> None:
    """fieldbank: force-field database and intervention what-if for hypertonic arms.

    Muscle groups: sf/se shoulder flexors/extensors, ef/ee elbow flexors/extensors, bf/be
    bi-articular flexors/extensors. Terms (R1, R2, catch, χ²/n, JND, under-determined, ...):
    docs/glossary.md. Settings in force: 'fieldbank config show'. A setting's flag may come
    before the command (fieldbank --db URL patient list) or after it; after it wins.
    """


def main() -> None:
    cli(prog_name="fieldbank")


if __name__ == "__main__":  # pragma: no cover
    main()
