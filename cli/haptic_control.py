"""The live commands of ``fieldbank haptic``: talk to a running renderer over its socket.

Each sends one request (:mod:`fieldbank.haptic.client`) and prints the answer. Only click, the
shared options and the control client load, so ``fieldbank haptic switch B`` answers at once;
``push`` loads the model layer only when it resolves its models.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import click

from fieldbank.cli.haptic import resolve_models, socket_option
from fieldbank.cli.options import db_option, emit, json_option
from fieldbank.haptic.client import ControlClient, push_models


def _request(socket_path: Path | None, cmd: str, **args: Any) -> Any:
    return ControlClient(socket_path).request(cmd, **args)


@click.command("push")
@click.argument("before_file", required=False, type=click.Path(exists=True, path_type=Path))
@click.argument("after_file", required=False, type=click.Path(exists=True, path_type=Path))
@click.option("--before-severity")
@click.option("--after-severity")
@click.option("--before-id", type=int, help="Model A by its id in the field database.")
@click.option("--after-id", type=int, help="Model B by its id in the field database.")
@socket_option
@db_option
@json_option
def push(before_file: Path | None, after_file: Path | None, before_severity: str | None,
         after_severity: str | None, before_id: int | None, after_id: int | None,
         socket_path: Path | None, db_url: str | None, as_json: bool) -> None:
    """Send models BEFORE (A) and AFTER (B) to the running renderer (faded swap)."""
    if before_file is None and not before_severity and before_id is None:
        raise click.UsageError("give BEFORE_FILE, --before-severity or --before-id")
    before, after, ids = resolve_models(db_url, (before_file, after_file),
                                        (before_severity, after_severity), (before_id, after_id))
    res = push_models(before, after, socket_path,
                      ids if any(i is not None for i in ids) else None)
    emit(res, as_json, "models pushed")


@click.command("switch")
@click.argument("to", type=click.Choice(["A", "B", "before", "after"], case_sensitive=False))
@socket_option
@json_option
def switch(to: str, socket_path: Path | None, as_json: bool) -> None:
    """Crossfade the rendered model to A (before) or B (after)."""
    to = to.upper() if len(to) == 1 else to.lower()
    emit(_request(socket_path, "switch", to=to), as_json, f"switching to {to}")


@click.command("status")
@socket_option
@json_option
def status(socket_path: Path | None, as_json: bool) -> None:
    """Show the running renderer's mode, model blend, force and faults."""
    s = _request(socket_path, "status")
    emit(s, as_json, "\n".join(f"{k}: {v}" for k, v in s.items()))


def _plain(name: str, help_text: str) -> click.Command:
    """A command that sends ``name`` without arguments and reports it done."""

    @socket_option
    @json_option
    def cmd(socket_path: Path | None, as_json: bool) -> None:
        emit(_request(socket_path, name), as_json, f"{name}: done")

    return click.command(name, help=help_text)(cmd)


arm = _plain("arm", "Arm (or re-arm after a fault) the running renderer.")
disarm = _plain("disarm", "Zero the force and disarm.")
stop = _plain("stop", "End the session (the trace is written).")


@click.group("abx")
def abx() -> None:
    """Blinded A/B/X trials on the running renderer."""


@abx.command("start")
@click.option("--trials", type=click.IntRange(1, 1000), default=10, show_default=True)
@click.option("--seed", type=int, default=None, help="Randomization seed (default: random).")
@click.option("--show-labels", is_flag=True, help="A = before and B = after (not hidden).")
@socket_option
@json_option
def abx_start(trials: int, seed: int | None, show_labels: bool, socket_path: Path | None,
              as_json: bool) -> None:
    """Start a block of TRIALS A/B/X trials."""
    seed = seed if seed is not None else int.from_bytes(os.urandom(4), "little")
    r = _request(socket_path, "abx", action="start", n_trials=trials, seed=seed,
                 hide_labels=not show_labels)
    emit(r, as_json, f"A/B/X block of {trials} trials started (seed {seed})")


@abx.command("present")
@click.argument("label", type=click.Choice(["A", "B", "X"], case_sensitive=False))
@socket_option
@json_option
def abx_present(label: str, socket_path: Path | None, as_json: bool) -> None:
    """Render A, B or this trial's X."""
    r = _request(socket_path, "abx", action="present", label=label.upper())
    emit(r, as_json, f"presenting {label.upper()} (trial {r['trial'] + 1})")


@abx.command("answer")
@click.argument("answer", type=click.Choice(["A", "B"], case_sensitive=False))
@socket_option
@json_option
def abx_answer(answer: str, socket_path: Path | None, as_json: bool) -> None:
    """Record that X felt like A or B; go to the next trial."""
    r = _request(socket_path, "abx", action="answer", answer=answer.upper())
    msg = f"answer recorded; next trial {r['trial'] + 1}"
    if r.get("done"):
        res = r["result"]
        msg = f"block done: {res['correct']} of {res['answered']} correct"
    emit(r, as_json, msg)
