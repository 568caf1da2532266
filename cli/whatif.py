"""``fieldbank whatif``: apply an intervention plan to a model and compare before with after.

Options → :func:`fieldbank.interventions.whatif.run_whatif` → tables on stdout (or one JSON
document with ``--json``). The model is a stored patient's latest fitted model (``--db URL``),
``--params FILE`` or ``--severity TARGET=LEVEL`` (:mod:`fieldbank.modelsource`); the plan comes
from ``--plan FILE`` and the intervention options (:mod:`fieldbank.interventions.spec`).
``--render`` pushes before and after to a running renderer.
"""

from __future__ import annotations

from datetime import date
from typing import Any

import click

from fieldbank.cli.options import (
    GIVEN_DATE,
    SESSION_LABEL,
    db_option,
    emit_json,
    figure_path,
    from_top,
    json_option,
    open_db,
)
from fieldbank.cli.whatif_report import render_text
from fieldbank.haptic.client import push_models
from fieldbank.interventions.defaults import DOSE_UNIT, value
from fieldbank.interventions.whatifchoices import DEFAULT_INTERVAL_SAMPLES


@click.command("whatif")
@click.argument("patient", required=False)
@click.option("--params", "params_file", type=click.Path(dir_okay=False),
              help="Model to start from: an ArmParams JSON file.")
@click.option("--severity", multiple=True, metavar="TARGET=LEVEL",
              help="Start from a synthetic arm, e.g. elbow=severe or "
                   "elbow-flexors:dynamic=moderate (repeatable).")
@click.option("--plan", "plan_file", type=click.Path(dir_okay=False),
              help="Intervention plan JSON file (steps applied first).")
@click.option("--botox", multiple=True, metavar="GROUP=UNITS",
              help=f"Botulinum toxin A in {DOSE_UNIT}, e.g. ef=200U,ee=100U (one injection "
                   "session).")
@click.option("--session-limit", "session_limit", type=float,
              default=value("botulinum.session_warning_units"), show_default=True,
              help=f"Warn when a botulinum session exceeds this many {DOSE_UNIT} (adult "
                   f"upper-limb label maximum {value('botulinum.session_warning_units'):g}).")
@click.option("--weeks", type=float, default=None,
              help=f"Weeks since the injection (default {value('botulinum.weeks_since'):g}, "
                   "the peak).")
@click.option("--lengthen", multiple=True, metavar="GROUP=LENGTH",
              help="Lengthening surgery, e.g. bf=1cm (the unit is required: cm, mm or m).")
@click.option("--tenotomy", multiple=True, metavar="GROUP", help="Tenotomy / release.")
@click.option("--cast", multiple=True, metavar="GROUP[=LENGTH]",
              help=f"Serial casting (default +{value('casting.delta_m') * 1000:g} mm).")
@click.option("--rhizotomy", metavar="GROUPS[:FACTOR]",
              help="Selective dorsal rhizotomy: 'all' or e.g. ef,ee:0.4 (β × factor).")
@click.option("--baclofen", metavar="GROUPS[:FACTOR]",
              help="Intrathecal baclofen: 'all' or e.g. ef,ee:0.5 (β × factor).")
@click.option("--timecourse", is_flag=True, help="Also show the metrics week by week (0-24).")
@click.option("--detail", is_flag=True,
              help="Every table: field change, probing motions, 95% intervals, grade scores, "
                   "the weeks (--timecourse); the default is the summary and the main tables.")
@click.option("--optimize", is_flag=True,
              help="Search the botulinum split closest to unimpaired (model result).")
@click.option("--total-units", type=float, default=None,
              help=f"Dose limit for --optimize, {DOSE_UNIT}.")
@click.option("--groups", "opt_groups", default=None, metavar="G1,G2",
              help="Groups --optimize may inject (default all six).")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False),
              callback=figure_path,
              help="Write the figures (joint stretches, fields, grades) to this .svg, .png or "
                   ".pdf.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False),
              help="Write plan.json, after.json and lineage.json into this directory.")
@click.option("--save", is_flag=True,
              help="Store the after model and the plan, with lineage, in the database.")
@click.option("--given-on", type=GIVEN_DATE, default=None,
              help="With --save: the plan was carried out on this day ('fieldbank validate' "
                   "checks it against maps measured later).")
@click.option("--accept-poor-fit", is_flag=True,
              help="Run on a model from a poor fit anyway (recorded in the output).")
@click.option("--interval-samples", type=click.IntRange(min=0), default=None,
              help="Fit samples carried through the plan for 95% intervals (default "
                   f"{DEFAULT_INTERVAL_SAMPLES}; 0: none).")
@click.option("--session", "session", type=SESSION_LABEL, default=None,
              help="With PATIENT: start from the model fitted to this session's maps (default: "
                   "the latest measured session's; the output names it).")
@db_option
@click.option("--render", is_flag=True,
              help="Push before and after to a running 'fieldbank haptic serve' (A = before, "
                   "B = after) to feel them side by side; with --save the plan is stored once "
                   "the renderer has accepted the pair, never before.")
@click.option("--socket", "control_path", default=from_top("--socket"), metavar="SOCKET",
              help="Control socket of the renderer for --render (default: the one "
                   "'fieldbank haptic serve' uses).")
@json_option
def whatif(patient: str | None, params_file: str | None, severity: tuple[str, ...],
           plan_file: str | None, botox: tuple[str, ...], session_limit: float,
           weeks: float | None,
           lengthen: tuple[str, ...], tenotomy: tuple[str, ...], cast: tuple[str, ...],
           rhizotomy: str | None, baclofen: str | None, timecourse: bool, detail: bool,
           optimize: bool,
           total_units: float | None, opt_groups: str | None, plot_path: str | None,
           out_dir: str | None, save: bool, given_on: date | None, accept_poor_fit: bool,
           interval_samples: int | None, session: str | None, db_url: str | None,
           render: bool, control_path: str | None, as_json: bool) -> None:
    """Apply clinical interventions to a model and compare the fields before and after.

    The model: PATIENT (the model fitted to the patient's latest measured session, or to
    --session's), --params FILE or --severity; the output's first lines name it, the session
    and date it was fitted on and any plan the patient was given before.
    Muscle groups: sf = shoulder flexors, se = shoulder extensors, ef = elbow flexors,
    ee = elbow extensors, bf = bi-articular flexors (biceps short head), be = bi-articular
    extensors (triceps long head). The text opens with a three-line summary; --detail prints
    every table, --json everything. Terms (R1, R2, catch, χ²/n, under-determined, ...):
    docs/glossary.md.

    Results are model predictions, not treatment advice.
    """
    from fieldbank import modelsource
    from fieldbank.haptic.modelinfo import ModelInfo
    from fieldbank.interventions.defaults import value
    from fieldbank.interventions.spec import build_plan
    from fieldbank.interventions.whatif import DoseSearch, plan_label, run_whatif, store_whatif

    if sum(bool(x) for x in (patient, params_file, severity)) != 1:
        raise click.UsageError(
            "Give exactly one model: PATIENT, --params FILE or --severity TARGET=LEVEL.")
    if session is not None and patient is None:
        raise click.UsageError("--session chooses among a patient's fitted models: give "
                               "PATIENT.")
    # every argument is checked before the database opens or a model loads
    plan = build_plan(plan_file=plan_file, botox=botox, weeks=weeks, lengthen=lengthen,
                      tenotomy=tenotomy, cast=cast, rhizotomy=rhizotomy, baclofen=baclofen)
    if plan is None and not optimize:
        raise click.UsageError(
            "No intervention given: use --botox, --lengthen, --tenotomy, --cast, "
            "--rhizotomy, --baclofen, --plan or --optimize.")
    search = None
    if optimize:
        if total_units is None:
            raise click.UsageError("--optimize needs --total-units N.")
        search = DoseSearch(
            total_units, None if opt_groups is None else
            tuple(g.strip() for g in opt_groups.split(",")),
            value("botulinum.weeks_since") if weeks is None else weeks)
    if given_on is not None and not save:
        raise click.UsageError("--given-on records the day a stored plan was given: it needs "
                               "--save.")
    source = modelsource.resolve(params_file=params_file, severity=severity,
                                 patient=patient, session=session,
                                 open_db=lambda: open_db(db_url))
    # with --render, nothing is stored until the renderer has accepted the pair
    res = run_whatif(source, plan, search=search, timecourse=timecourse,
                     plot_path=plot_path, out_dir=out_dir,
                     save_to=(lambda: open_db(db_url)) if save and not render else None,
                     session_limit_units=session_limit,
                     accept_poor_fit=accept_poor_fit,
                     interval_samples=(DEFAULT_INTERVAL_SAMPLES if interval_samples is None
                                       else interval_samples),
                     given_on=None if render else given_on)
    rendered = None
    if render:
        plan_text = plan_label(res.plan)
        info = {"A": ModelInfo.describe(source.description, source.model_id,
                                        source.patient_code),
                "B": ModelInfo.describe(f"what-if result on {source.description}", None,
                                        source.patient_code, plan_text, None)}
        rendered = push_models(res.before, res.after, control_path,
                               model_ids=(source.model_id, None), model_info=info)
        if save:
            with open_db(db_url) as db:
                res = store_whatif(db, res, given_on)
    doc: dict[str, Any] = res.to_dict()
    if rendered is not None:
        doc["rendered"] = rendered
    if as_json:
        emit_json(doc)
        return
    click.echo(render_text(res, detail=detail or timecourse))
    if res.guesses is not None:
        if res.guesses.warnings:
            click.echo(f"warning: {len(res.guesses.warnings)} warning(s) in the output: the "
                       "prediction rests on parameters the fit did not identify, or on a poor "
                       "fit.", err=True)
    if plot_path:
        click.echo(f"plot written to {plot_path}", err=True)
    if out_dir:
        click.echo(f"plan, after model and lineage written to {out_dir}", err=True)
    if render:
        click.echo("pushed to the renderer: A = before, B = after "
                   "(switch with 'fieldbank haptic switch')", err=True)
    if res.saved:
        click.echo(f"stored: after model {res.saved.result_model_id} (parent "
                   f"{res.saved.base_model_id}), plan {res.saved.plan_id}"
                   + (f", given on {given_on.isoformat()}" if given_on else ""), err=True)
    elif render:
        click.echo("stored: nothing (--save stores the plan and its after model)", err=True)
