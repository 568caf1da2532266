"""``fieldbank haptic train simulate`` and ``results``: the heavy part of the training group
(the loop and the simulated trainee; the database)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from fieldbank.cli.haptic_train import probe_choice, probes_option
from fieldbank.cli.options import (
    SESSION_ID,
    db_option,
    emit,
    json_option,
    open_db,
    output_file,
    say,
)
from fieldbank.files import write_atomic

# The loop, the trainee and the database load inside the commands: '--help' starts at once.


@click.command("simulate")
@click.option("--instructed/--non-instructed", default=True, show_default=True,
              help="Follow the drawn probing paths, or explore freely.")
@probes_option
@click.option("--short", is_flag=True, help="1 familiarisation round, 1 repetition (16 trials).")
@click.option("--familiarisation-rounds", type=click.IntRange(0, 50), default=None)
@click.option("--repetitions", type=click.IntRange(0, 50), default=None)
@click.option("--noise-deg", type=click.FloatRange(0, 180), default=0.0, show_default=True,
              help="Error of each perceived force direction, degrees (sd).")
@click.option("--size-noise", type=click.FloatRange(0, 2), default=0.0, show_default=True,
              help="Error of each perceived force size (sd of its log): the severity judgement.")
@click.option("--seed", type=click.IntRange(0, 2**31), default=0, show_default=True)
@click.option("--link-delay-ms", type=click.FloatRange(0, 2000), default=None,
              help="Feel every arm through a simulated remote link with this one-way delay "
                   "(docs/remote.md).")
@click.option("--link-loss", type=click.FloatRange(0, 0.5), default=0.0, show_default=True,
              help="The simulated link's loss probability (with --link-delay-ms).")
@click.option("--link-jitter-ms", type=click.FloatRange(0, 500), default=0.0,
              show_default=True, help="The simulated link's jitter (with --link-delay-ms).")
@click.option("--html", "html_out", type=click.Path(dir_okay=False, path_type=Path),
              callback=output_file,
              help="Write the results as a small HTML page.")
@db_option
@click.option("--no-db", is_flag=True, help="Do not record the session in the database.")
@json_option
def simulate(instructed: bool, probes_file: Path | None, seed_probes: bool, short: bool,
             familiarisation_rounds: int | None, repetitions: int | None, noise_deg: float,
             size_noise: float, seed: int, link_delay_ms: float | None, link_loss: float,
             link_jitter_ms: float, html_out: Path | None, db_url: str | None, no_db: bool,
             as_json: bool) -> None:
    """Run the protocol with a simulated trainee on the simulated robot."""
    from fieldbank.haptic import trainee
    from fieldbank.haptic.dbsink import DatabaseTraceSink
    from fieldbank.haptic.remote.channel import Impairment
    from fieldbank.haptic.remote.config import SiteConfig
    from fieldbank.haptic.remote.simulate import linked_environment
    from fieldbank.haptic.safety import SafetyConfig
    from fieldbank.haptic.session import trace_name_now
    from fieldbank.haptic.training import TrainingProtocol
    from fieldbank.haptic.trainingresults import accuracy_text, results_html, results_page

    kw: dict[str, Any] = {"instruction": "instructed" if instructed else "non-instructed",
                          "seed": seed}
    if probes_file is not None and not instructed:
        raise click.UsageError("--probes draws probes to follow; it needs --instructed")
    kw.update(probe_choice(probes_file, seed_probes))
    if short:
        kw.update(familiarisation_rounds=1, assessment_repetitions=1)
    if familiarisation_rounds is not None:
        kw["familiarisation_rounds"] = familiarisation_rounds
    if repetitions is not None:
        kw["assessment_repetitions"] = repetitions
    protocol = TrainingProtocol.from_dict(kw)
    rule = trainee.DirectionRule(noise_deg, seed, size_noise)
    if link_delay_ms is None:
        if link_loss or link_jitter_ms:
            raise click.UsageError("--link-loss and --link-jitter-ms need --link-delay-ms")
        res = trainee.simulate(protocol, rule, say=say)
    else:
        env, chains = linked_environment(SiteConfig(lockstep=True, impairment=Impairment(
            link_delay_ms / 1000, link_jitter_ms / 1000, link_loss, seed)))
        try:
            res = trainee.simulate(protocol, rule, say=say, environment=env,
                                   safety=SafetyConfig(passivity=False))
        finally:
            for c in chains:
                c.close()
    out: dict[str, Any] = {"simulated_s": res.simulated_s, **res.result,
                           "severity_judgements": res.severities}
    if link_delay_ms is not None:
        out["link"] = {"delay_ms": link_delay_ms, "loss": link_loss,
                       "jitter_ms": link_jitter_ms}
    if not no_db:
        with open_db(db_url) as db:
            out["database"] = DatabaseTraceSink(db).write_trace(res.trace,
                                                                "train-sim-" + trace_name_now())
    if html_out is not None:
        write_atomic(html_out, results_page([results_html(
            res.summary, f"Simulated trainee, {protocol.instruction}",
            note="Simulated trainee: answers by the direction of the peak force along each "
                 "probe, nearest to what it felt in familiarisation.")]))
    lines = [f"simulated {res.simulated_s:.0f} s of training ({protocol.n_trials} trials, "
             f"{protocol.instruction})"
             + (f" through a link of {link_delay_ms:g} ms one-way" if link_delay_ms is not None
                else ""), *accuracy_text(res.summary)]
    if res.severities:
        right = sum(1 for r in res.severities if r["answered_severity"] == r["severity"])
        lines.append(f"severity judged right in {right} of {len(res.severities)} assessment "
                     "trials (the trainee's own judgement; the protocol asks the group)")
    if "database" in out:
        lines.append(f"database: {out['database']}")
    if html_out is not None:
        lines.append(f"html: {html_out}")
    emit(out, as_json, "\n".join(lines))


@click.command("results")
@click.argument("sessions", nargs=-1, type=SESSION_ID)
@click.option("--patient", help="Only sessions of this patient.")
@click.option("--html", "html_out", type=click.Path(dir_okay=False, path_type=Path),
              callback=output_file,
              help="Write the results as a small HTML page.")
@db_option
@json_option
def results(sessions: tuple[int, ...], patient: str | None, html_out: Path | None,
            db_url: str | None, as_json: bool) -> None:
    """Confusion matrix and accuracy per severity of stored training sessions.

    SESSIONS are haptic session ids (default: every session with training trials).
    """
    from fieldbank.haptic.training import summarise
    from fieldbank.haptic.trainingresults import (
        accuracy_text,
        results_html,
        results_page,
        trainee_note,
    )

    with open_db(db_url) as db:
        if patient is not None:  # an unknown patient: the one "not found" message
            db.get_patient(patient)
        listed = db.list_haptic_sessions(patient)
        chosen = {s.id for s in listed}
        # sessions a simulated trainee answered (haptic train simulate records it)
        by_trainee = {s.id for s in listed
                      if "simulated_trainee" in ((s.stats or {}).get("metadata") or {})}
        if sessions:
            missing = sorted(set(sessions) - chosen)
            if missing:
                raise click.BadParameter(f"no haptic session {', '.join(map(str, missing))}"
                                         + (f" of patient {patient}" if patient else ""))
            chosen = set(sessions)
        trials = [t for t in db.list_haptic_trials(kind="training")
                  if t.haptic_session_id in chosen]
    records = [t.to_dict() for t in trials]
    used = sorted({t.haptic_session_id for t in trials})
    if not used:
        raise click.ClickException("no stored training trials"
                                   + (f" in session(s) {', '.join(map(str, sessions))}"
                                      if sessions else ""))
    summary = summarise(records)
    simulated = [i for i in used if i in by_trainee]
    who = trainee_note(simulated, [i for i in used if i not in by_trainee])
    doc = {"sessions": used, "simulated_trainee_sessions": simulated, "summary": summary}
    if html_out is not None:
        write_atomic(html_out, results_page([results_html(
            summary, f"Training results, session(s) {', '.join(map(str, used))}", who=who)]))
    emit(doc, as_json, "\n".join([f"sessions: {', '.join(map(str, used))}", who,
                                  *accuracy_text(summary)]
                                 + ([f"html: {html_out}"] if html_out else [])))
