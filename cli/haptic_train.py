"""``fieldbank haptic train``: the seed's training protocol (:mod:`fieldbank.haptic.training`).

The live commands (``start``, ``next``, ``answer``, ``stop``) talk to a running renderer over
its control socket, like the station's buttons, and load nothing heavy; ``simulate`` and
``results`` (:mod:`fieldbank.cli.haptic_train_run`) load the loop, the simulated trainee and the
database when they run.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import click

from fieldbank.cli.haptic import socket_option
from fieldbank.cli.lazy import LazyCommand, LazyGroup
from fieldbank.cli.options import emit, json_option
from fieldbank.haptic.client import ControlClient
from fieldbank.probepath import MAX_DRAWN_PROBES, read_probes

_RUN = "fieldbank.cli.haptic_train_run"
#: subcommands that load the loop or the database, with their one-line help
HEAVY: dict[str, LazyCommand] = {
    "simulate": LazyCommand(_RUN, "simulate",
                            "Run the protocol with a simulated trainee on the simulated robot."),
    "results": LazyCommand(_RUN, "results",
                           "Confusion matrix and accuracy per severity of stored training "
                           "sessions."),
}


@click.group("train", cls=LazyGroup, lazy=HEAVY)
def train() -> None:
    """The seed's training protocol: run it live, simulate it, report its results."""


def _state_text(st: dict[str, Any]) -> str:
    if st.get("done"):
        a = ((st.get("result") or {}).get("summary") or {}).get("accuracy") or {}
        return f"training done: {a.get('correct', 0)} of {a.get('n', 0)} correct"
    if not st.get("trial"):
        return f"training started: {st.get('n_trials')} trials ({st.get('instruction')})"
    legend = f": {st['legend']}" if st.get("legend") else ""
    return (f"{st.get('phase')} trial {st['trial']} of {st.get('n_trials')}{legend}"
            + (" - answer shoulder, elbow or both" if st.get("phase") == "assessment" else ""))


def probes_option(f: Any) -> Any:
    """``--probes FILE`` and ``--seed-probes/--no-seed-probes``: which probes instructed
    training draws."""
    f = click.option("--seed-probes/--no-seed-probes", default=True, show_default=True,
                     help="Draw the seed's pull and semi-ellipse in instructed mode.")(f)
    return click.option("--probes", "probes_file", type=click.Path(dir_okay=False,
                                                                   path_type=Path),
                        help="Also draw these designed probes (the file 'fieldbank probe "
                             "design --out' writes; at most "
                             f"{MAX_DRAWN_PROBES}); implies --instructed.")(f)


def probe_choice(probes_file: Path | None, seed_probes: bool) -> dict[str, Any]:
    """The protocol fields for ``--probes`` and ``--no-seed-probes``: read and checked here,
    so a bad file is refused naming the file and the field before anything starts."""
    out: dict[str, Any] = {}
    if probes_file is not None:
        out["extra_probes"] = [p.to_dict() for p in read_probes(probes_file, MAX_DRAWN_PROBES)]
        out["instruction"] = "instructed"
    if not seed_probes:
        out["probes"] = []
    return out


@train.command("start")
@click.option("--instructed", is_flag=True, help="Draw the probing paths to follow.")
@probes_option
@click.option("--short", is_flag=True, help="1 familiarisation round, 1 repetition of each "
              "group and severity (16 trials).")
@click.option("--familiarisation-rounds", type=click.IntRange(0, 50), default=None,
              help="Rounds of the four familiarisation arms (seed: 8).")
@click.option("--familiarisation-s", type=click.FloatRange(1, 600), default=None,
              help="Length of a familiarisation trial, s (seed: 30).")
@click.option("--repetitions", type=click.IntRange(0, 50), default=None,
              help="Repetitions of each group × severity (seed: 9).")
@click.option("--assessment-s", type=click.FloatRange(1, 600), default=None,
              help="Length of an assessment trial, s (seed: 15).")
@click.option("--seed", type=click.IntRange(0, 2**63 - 1), default=None,
              help="Order of the assessment trials (default: random).")
@socket_option
@json_option
def train_start(instructed: bool, probes_file: Path | None, seed_probes: bool, short: bool,
                familiarisation_rounds: int | None, familiarisation_s: float | None,
                repetitions: int | None, assessment_s: float | None, seed: int | None,
                socket_path: Path | None, as_json: bool) -> None:
    """Start the training protocol on the running renderer (then 'train next')."""
    proto: dict[str, Any] = {"instruction": "instructed" if instructed else "non-instructed",
                             "seed": seed if seed is not None
                             else int.from_bytes(os.urandom(4), "little")}
    proto.update(probe_choice(probes_file, seed_probes))
    if short:
        proto.update(familiarisation_rounds=1, assessment_repetitions=1)
    for k, v in (("familiarisation_rounds", familiarisation_rounds),
                 ("familiarisation_s", familiarisation_s),
                 ("assessment_repetitions", repetitions), ("assessment_s", assessment_s)):
        if v is not None:
            proto[k] = v
    st = ControlClient(socket_path).request("train", action="start", protocol=proto)
    emit(st, as_json, _state_text(st))


@train.command("next")
@socket_option
@json_option
def train_next(socket_path: Path | None, as_json: bool) -> None:
    """Present the next trial (after the last one, close the protocol)."""
    st = ControlClient(socket_path).request("train", action="next")
    emit(st, as_json, _state_text(st))


@train.command("answer")
@click.argument("answer", type=click.Choice(["shoulder", "elbow", "both"], case_sensitive=False))
@socket_option
@json_option
def train_answer(answer: str, socket_path: Path | None, as_json: bool) -> None:
    """Answer the current assessment trial: shoulder, elbow or both."""
    r = ControlClient(socket_path).request("train", action="answer", answer=answer.lower())
    msg = f"answer recorded (trial {r['trial']})"
    if r.get("done"):
        a = r["result"]["summary"]["accuracy"]
        msg = f"training done: {a['correct']} of {a['n']} correct"
    emit(r, as_json, msg)


@train.command("stop")
@socket_option
@json_option
def train_stop(socket_path: Path | None, as_json: bool) -> None:
    """End the training protocol early (the trials so far are kept)."""
    st = ControlClient(socket_path).request("train", action="stop")
    emit(st, as_json, _state_text(st))
