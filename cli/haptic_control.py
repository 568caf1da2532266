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
from fieldbank.cli.options import MODEL_ID, db_option, emit, json_option
from fieldbank.haptic.client import ControlClient, push_models
from fieldbank.haptic.clock import Grant
from fieldbank.haptic.modelinfo import describe_text


def _request(socket_path: Path | None, cmd: str, **args: Any) -> Any:
    return ControlClient(socket_path).request(cmd, **args)


@click.command("push")
@click.argument("before_file", required=False, type=click.Path(exists=True, path_type=Path))
@click.argument("after_file", required=False, type=click.Path(exists=True, path_type=Path))
@click.option("--before-severity")
@click.option("--after-severity")
@click.option("--before-id", type=MODEL_ID, help="Model A by its id in the field database.")
@click.option("--after-id", type=MODEL_ID, help="Model B by its id in the field database.")
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
    emit(res, as_json, "models pushed; " + state_words(res)
         + (" (fading out, swapping, fading in)" if res.get("swapping") else ""))


@click.command("switch")
@click.argument("to", type=click.Choice(["A", "B", "before", "after"], case_sensitive=False))
@socket_option
@json_option
def switch(to: str, socket_path: Path | None, as_json: bool) -> None:
    """Crossfade the rendered model to A (before) or B (after)."""
    to = to.upper() if len(to) == 1 else to.lower()
    res = _request(socket_path, "switch", to=to)
    emit(res, as_json, f"switching to {to}; {state_words(res)}")


def state_words(res: dict[str, Any]) -> str:
    """The renderer's true state from a ``push`` or ``switch`` answer, in words."""
    mode = res.get("mode")
    if mode == "ARMED":
        return f"renderer armed, felt now: {res.get('felt')}"
    return f"renderer {str(mode).lower()}: no force until it is armed ('fieldbank haptic arm')"


@click.command("status")
@socket_option
@json_option
def status(socket_path: Path | None, as_json: bool) -> None:
    """Show the running renderer's mode, model blend, force and faults."""
    s = _request(socket_path, "status")
    emit(s, as_json, status_table(s))


def _model_line(m: Any) -> str:
    if not isinstance(m, dict):
        return "hidden (a blinded block is running)"
    return describe_text(m)


def status_table(s: dict[str, Any]) -> str:
    """The renderer's status as an aligned, readable table (``--json`` gives every field)."""
    rows: list[tuple[str, str]] = []
    run = "running" if s.get("running") else "not running"
    rows.append(("renderer", f"{run} · {s.get('mode')} · t = {s.get('t_s', 0):.2f} s "
                             f"({s.get('ticks', 0)} ticks)"))
    models = s.get("models")
    if isinstance(models, dict):
        rows.append(("A · before", _model_line(models.get("A"))))
        rows.append(("B · after", _model_line(models.get("B"))))
    elif models is not None:
        rows.append(("models", _model_line(models)))
    blend = s.get("blend")
    if isinstance(blend, (int, float)):
        felt = s.get("felt") or ("A (before)" if blend < 0.5 else "B (after)")
        moving = " crossfading" if 0.02 < blend < 0.98 else ""
        rows.append(("felt now", f"{felt}{moving}; blend {blend:.2f}, gain "
                                 f"{s.get('gain', 0):.2f}"))
    else:
        rows.append(("felt now", "hidden (blinded)"))
    hx, hy = (s.get("handle_m") or [float("nan")] * 2)[:2]
    fx, fy = (s.get("force_n") or [0.0, 0.0])[:2]
    rows.append(("handle", f"x {hx:.3f} m, y {hy:.3f} m (robot frame); force "
                           f"{(fx * fx + fy * fy) ** 0.5:.2f} N ({fx:+.2f}, {fy:+.2f})"))
    latched = s.get("latched_faults") or []
    rows.append(("faults", (", ".join(latched) + " latched" if latched else "none latched")
                 + f"; {s.get('faults_logged', 0)} logged"))
    for f in s.get("faults_now") or []:
        rows.append((f"  {f['name']}", f"{f['what']} ({f['message']}, t = {f['t_s']:.2f} s). "
                                      f"{f['todo']}"))
    refused = s.get("rearm_refused_because") or []
    if s.get("mode") != "ARMED":
        rows.append(("re-arm", "would be refused: " + "; ".join(refused) if refused
                     else "would be accepted ('fieldbank haptic arm')"))
    if s.get("paused"):
        rows.append(("paused", "the running A/B/X block or training waits for a re-arm; no "
                               "answer is taken meanwhile"))
    loop = s.get("loop_last_10s") or {}
    pe = loop.get("period_error_us") or {}
    if pe:
        tt = loop.get("tick_total_us") or {}
        rows.append(("loop, 10 s", f"period error p50 {pe.get('p50', 0):.1f} µs, p99 "
                                   f"{pe.get('p99', 0):.1f} µs, max {pe.get('max', 0):.1f} µs; "
                                   f"overruns {loop.get('overruns', 0)}; tick p99 "
                                   f"{tt.get('p99', 0):.1f} µs"))
    rt = loop.get("realtime_scheduling")
    grant = loop.get("realtime") or {}
    if grant:
        rows.append(("scheduling", Grant.from_dict(grant).text()))
    elif rt is not None:
        rows.append(("scheduling", "SCHED_FIFO" if rt else "normal (SCHED_FIFO refused)"))
    abx = s.get("abx_trial")
    rows.append(("A/B/X", "none running" if abx is None else f"trial {abx + 1} running"))
    tr = s.get("training")
    if isinstance(tr, dict):
        if tr.get("done"):
            a = ((tr.get("result") or {}).get("summary") or {}).get("accuracy") or {}
            text = f"done: {a.get('correct', 0)} of {a.get('n', 0)} correct"
        elif tr.get("trial"):
            text = (f"{tr.get('phase')} trial {tr['trial']} of {tr.get('n_trials')}"
                    + (" (waiting for the answer)" if tr.get("awaiting_answer") else ""))
        else:
            text = f"started, {tr.get('n_trials')} trials"
        rows.append(("training", f"{text} · {tr.get('instruction')}"))
    else:
        rows.append(("training", "none"))
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


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
@socket_option
@json_option
def abx_start(trials: int, seed: int | None, socket_path: Path | None,
              as_json: bool) -> None:
    """Start a block of A/B/X trials (as many as --trials): A is before, B after; X is one of
    them, hidden."""
    seed = seed if seed is not None else int.from_bytes(os.urandom(4), "little")
    r = _request(socket_path, "abx", action="start", n_trials=trials, seed=seed)
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
    if r.get("flagged"):
        msg = (f"answer recorded but flagged, not counted ({'; '.join(r['flags'])}); next "
               f"trial {r['trial'] + 1}")
    if r.get("done"):
        res = r["result"]
        msg = (f"block done: {res['correct']} of {res['counted']} counted answers correct"
               + (f"; {res['flagged']} flagged (fault or no force) and left out"
                  if res.get("flagged") else ""))
    emit(r, as_json, msg)


@abx.command("stop")
@socket_option
@json_option
def abx_stop(socket_path: Path | None, as_json: bool) -> None:
    """End the running A/B/X block early; the answers so far are kept and scored."""
    r = _request(socket_path, "abx", action="stop")
    res = r["result"]
    emit(r, as_json, f"block stopped after {res['answered']} of {res['n_trials']} trials: "
                     f"{res['correct']} of {res['counted']} counted answers correct")
