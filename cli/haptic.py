"""``fieldbank haptic``: render arm models on a robot, control a running renderer, probe, replay.

``serve`` owns the robot and the loop; the other commands talk to it over the local control
socket (``--socket``, default ``haptic.sock`` in the fieldbank data directory). ``probe`` and
``replay`` work on their own.

The group loads its commands lazily from two modules: the live control commands
(:mod:`fieldbank.cli.haptic_control`: ``switch``, ``status``, ``push``, ``arm``, ``abx`` …),
which load only click and the control client so they answer at once, and the commands that run
the loop or read traces (:mod:`fieldbank.cli.haptic_session`: ``serve``, ``probe``,
``replay``, ``sim-robot``), which load numpy and, when asked, the database layer.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from fieldbank.cli.lazy import LazyCommand, LazyGroup
from fieldbank.cli.options import from_top, open_db
from fieldbank.haptic.modelinfo import ModelInfo

if TYPE_CHECKING:  # typing only: parameters load with the commands that need them
    from fieldbank.modelsource import ModelSource
    from fieldbank.params import ArmParams

_CONTROL = "fieldbank.cli.haptic_control"
_SESSION = "fieldbank.cli.haptic_session"
C = LazyCommand
#: subcommand -> where it lives and its one-line help (a test checks it is the command's own)
COMMANDS: dict[str, LazyCommand] = {
    "serve": C(_SESSION, "serve",
               "Run the real-time renderer on ROBOT with models A (before) and B (after)."),
    "probe": C(_SESSION, "probe_cmd",
               "Run a scripted probing motion and report the force profile felt at the handle."),
    "replay": C(_SESSION, "replay",
                "Summarise a recorded session; export it; re-run it offline."),
    "measure": C("fieldbank.cli.haptic_measure", "measure",
                 "Measure PATIENT's postural and stiffness maps on the robot and store them."),
    "sim-robot": C(_SESSION, "sim_robot",
                   "Run the simulated robot on a pty and print the port to give to 'serve "
                   "--robot'."),
    "push": C(_CONTROL, "push",
              "Send models BEFORE (A) and AFTER (B) to the running renderer (faded swap)."),
    "switch": C(_CONTROL, "switch", "Crossfade the rendered model to A (before) or B (after)."),
    "status": C(_CONTROL, "status",
                "Show the running renderer's mode, model blend, force and faults."),
    "arm": C(_CONTROL, "arm", "Arm (or re-arm after a fault) the running renderer."),
    "disarm": C(_CONTROL, "disarm", "Zero the force and disarm."),
    "stop": C(_CONTROL, "stop", "End the session (the trace is written)."),
    "abx": C(_CONTROL, "abx", "Blinded A/B/X trials on the running renderer."),
    "train": C("fieldbank.cli.haptic_train", "train",
               "The seed's training protocol: run it live, simulate it, report its results."),
    "sessions": C("fieldbank.cli.haptic_sessions", "sessions",
                  "Recorded haptic sessions: when, which models, which patient, the answers."),
    "remote": C("fieldbank.cli.haptic_remote", "remote",
                "Remote assessment: the clinician's robot and the patient's, joined by a "
                "delayed link."),
}

socket_option = click.option(
    "--socket", "socket_path", type=click.Path(dir_okay=False, path_type=Path),
    default=from_top("--socket"),
    help="Control socket of the renderer (default: haptic.sock in the fieldbank data dir).")


@click.group("haptic", cls=LazyGroup, lazy=COMMANDS)
def haptic() -> None:
    """Feel arm models on a 2-DOF robot: serve, push, switch, abx, probe, status, replay."""


def resolve_models(db_url: str | None, files: tuple[Path | None, Path | None],
                   severities: tuple[str | None, str | None],
                   ids: tuple[int | None, int | None]
                   ) -> tuple[ArmParams, ArmParams, tuple[int | None, int | None]]:
    """Models A and B from files, severities or database ids (B defaults to A), and their ids.

    Loads :mod:`fieldbank.modelsource` (numpy; SQLAlchemy for ids) only when called.
    """
    a, b, out_ids, _ = resolve_sources(db_url, files, severities, ids)
    return a, b, out_ids


def resolve_sources(db_url: str | None, files: tuple[Path | None, Path | None],
                    severities: tuple[str | None, str | None],
                    ids: tuple[int | None, int | None]
                    ) -> tuple[ArmParams, ArmParams, tuple[int | None, int | None],
                               dict[str, ModelInfo]]:
    """As :func:`resolve_models`, with what the station says about each model (its
    description, id, patient, and for a stored what-if result the plan's label)."""
    from fieldbank import modelsource
    from fieldbank.params import ArmParams

    out: list[modelsource.ModelSource | None] = []
    for f, sev, mid, label in zip(files, severities, ids, ("before", "after"), strict=True):
        if sum(x is not None for x in (f, sev, mid)) > 1:
            raise click.UsageError(f"give the {label} model once: a file, a severity or an id")
        if f is None and not sev and mid is None:
            out.append(None)
            continue
        out.append(modelsource.resolve(
            params_file=f, severity=[sev] if sev else [], model_id=mid,
            open_db=lambda: open_db(db_url), what=f"{label} model"))
    a = out[0].params if out[0] is not None else ArmParams.from_anthropometry()
    b = out[1].params if out[1] is not None else a
    srcs = (out[0], out[1] if out[1] is not None else out[0])
    info = {k: _describe(db_url, s) for k, s in zip(("A", "B"), srcs, strict=True)}
    return a, b, (ids[0], ids[1] if out[1] is not None else ids[0]), info


def _describe(db_url: str | None, src: ModelSource | None) -> ModelInfo:
    if src is None:
        return ModelInfo.describe("synthetic arm (unimpaired)")
    plan = None
    if src.model_id is not None:
        with open_db(db_url) as db:
            plans = [p for p in db.list_plans(src.patient_code)
                     if p.result_model_id == src.model_id]
            plan = plans[-1].label if plans else None
    return ModelInfo.describe(src.description, src.model_id, src.patient_code, plan)
