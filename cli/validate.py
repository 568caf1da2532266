"""``fieldbank validate``: predictions checked against what was measured.

Without ``--loo``: every stored plan that was carried out (``whatif --save --given-on``),
against the maps its patient had measured after it
(:func:`fieldbank.interventions.validate.validate_plans`); the verdict's rules and numbers are
printed under the check (:class:`fieldbank.interventions.realised.Rules`). Exit status 1 when a
plan's prediction is contradicted (failed, stronger than predicted, or a partial effect),
else 0.

With ``--loo``: each map of a patient's latest fit (or ``--model``'s) left out in turn and
predicted by the others (:func:`fieldbank.fitting.crossval.cross_validate`): a check of the fit,
not of a plan, with its own words. Exit status 1 when the fit does not generalise to a map the
others should predict.
"""

from __future__ import annotations

import math
import textwrap
from typing import TYPE_CHECKING

import click

from fieldbank.cli.options import (
    MODEL_ID,
    PLAN_ID,
    db_option,
    emit_json,
    json_option,
    open_db,
    say,
    scheduler_option,
)
from fieldbank.interventions.whatifchoices import CHANGE_TOLERANCE, MAX_CHANGE_SE

if TYPE_CHECKING:  # typing only: the checks load when the command runs ('--help' at once)
    from fieldbank.fitting.crossval import CrossValidation
    from fieldbank.interventions.validate import PlanValidation, SessionCheck, ValidationReport
    from fieldbank.scheduler import SchedulerFlags

#: Text output is wrapped to this width.
WIDTH = 100


def _f(v: float | None, fmt: str) -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, fmt)


def _wrap(text: str, indent: str) -> list[str]:
    return textwrap.wrap(text, WIDTH, initial_indent=indent,
                         subsequent_indent=indent + "  ", break_on_hyphens=False)


def plans_text(rep: ValidationReport) -> str:
    """The check as text: per plan and later session, the maps, the realised fraction and the
    verdict with its reasons; then the rules with their numbers, then one overall verdict."""
    lines: list[str] = []
    for p in rep.plans:
        lines += _plan_lines(p)
        lines.append("")
    lines.append("How the verdicts are read:")
    for rule in rep.rules.lines():
        lines += _wrap(rule.strip(), "    " if rule.startswith("  ") else "  ")
    lines.append("")
    lines += _wrap(overall(rep), "")
    return "\n".join(lines)


_SHORT = {"prediction confirmed": "confirmed", "partial effect": "partial",
          "prediction failed": "failed", "stronger than predicted": "stronger"}


def overall(rep: ValidationReport) -> str:
    """The one overall line: the verdict, the plans contradicted, the count of the others."""
    from fieldbank.interventions.realised import CONTRADICTED

    bad = [f"plan {p.plan_id} ({p.patient or 'no patient'}) {_SHORT[p.verdict]}"
           for p in rep.contradicted]
    rest = [f"{n} {_SHORT.get(v, v)}" for v, n in rep.counts.items()
            if n and v not in CONTRADICTED]
    return f"Overall: {rep.verdict}" + "".join(f" - {x}" for x in ("; ".join(bad),
                                                                  ", ".join(rest)) if x)


def _plan_lines(p: PlanValidation) -> list[str]:
    head = (f"Plan {p.plan_id} ({p.patient or 'no patient'}) - {p.verdict}: {p.label}; model "
            f"before {p.before_model_id}" + (f" (fit {p.fit_id})" if p.fit_id is not None else ""))
    if p.given_on:
        head += f"; given {p.given_on}"
    lines = _wrap(head, "")
    if p.not_checked is not None:
        lines += _wrap(p.not_checked, "  ")
        return lines
    for s in p.sessions:
        lines += _session_lines(s)
    return lines


def _session_lines(s: SessionCheck) -> list[str]:
    from fieldbank.interventions.realised import CONTRADICTED

    timing = "botulinum re-timed" if s.retimed else "as stored"
    verdict = s.verdict.upper() if s.verdict in CONTRADICTED else s.verdict
    lines = _wrap(f"{s.session} ({s.session_date}, {s.weeks_after:.1f} weeks after, {timing}): "
                  f"{verdict}", "  ")
    lines.append(f"    {'map':>5} {'kind':<9} {'m/s':>5} {'R²':>6} {'RMS error':>12} "
                 f"{'χ²/n':>6} {'check':<5} {'Δ pred':>8} {'Δ meas':>8} {'Δ/sd':>6} "
                 f"{'realised':>10}")
    for m in s.maps:
        pr = m.prediction
        speed = math.hypot(*m.velocity_m_per_s)
        if m.duplicate_of is not None:
            lines.append(f"    {m.map_id:>5} {m.kind:<9} {speed:>5.2f}  (repeats map "
                         f"{m.duplicate_of}: counted once)")
            continue
        realised = ("-" if m.realised_fraction is None else
                    f"{m.realised_fraction:.2f}±{_f(m.realised_se, '.2f')}")
        lines.append(
            f"    {m.map_id:>5} {m.kind:<9} {speed:>5.2f} {_f(pr.r2, '.3f'):>6} "
            f"{_f(pr.rms_residual, '.3g'):>7} {m.unit:<4} {_f(pr.chi2_per_value, '.2f'):>6} "
            f"{pr.verdict:<5} {_f(m.predicted_change_rms, '.3g'):>8} "
            f"{_f(m.measured_change_rms, '.3g'):>8} {m.sensitivity_sd:>6.1f} {realised:>10}")
    lines.append("    (Δ pred, Δ meas: RMS of the predicted and the measured change; Δ/sd: how far "
                 "the predicted")
    lines.append("    change moves the map, in sd; check: the map against the prediction, fit "
                 "uncertainty allowed for)")
    lines += [x for r in s.reasons for x in _wrap(r, "    ")]
    if s.fit_uncertainty and s.fit_se is None and s.noise_se is not None:
        lines += _wrap(f"fit uncertainty: {s.fit_uncertainty}", "    ")
    return lines


def loo_text(cv: CrossValidation) -> str:
    """Leave-one-map-out as text: what it tests, per map the figures and why, one verdict."""
    from fieldbank.fitting.crossval import EXPLANATION

    lines = [f"Leave-one-map-out of model {cv.model_id} (patient {cv.patient})"]
    lines += _wrap(EXPLANATION, "  ")
    lines.append(f"    {'map':>5} {'kind':<10} {'moving':<6} {'R²':>7} {'RMS error':>12} "
                 f"{'χ²/n':>6} {'limit':>6}  verdict")
    for m in cv.maps:
        f = m.fit
        lines.append(f"    {m.map_id!s:>5} {f.kind:<10} {'yes' if m.moving else 'no':<6} "
                     f"{_f(f.r2, '.3f'):>7} {_f(f.rms_residual, '.3g'):>7} {f.unit:<4} "
                     f"{_f(f.chi2_per_value, '.2f'):>6} {f.chi2_limit:>6.2f}  {m.outcome}")
        if m.note:
            lines += _wrap(f"why: {m.note}", "          ")
    worst = "; ".join(f"map {m.map_id} {m.outcome}" for m in cv.maps if m.outcome != "predicted")
    lines += _wrap(f"Overall (leave-one-out, a check of the fit, not of a plan): {cv.verdict}"
                   + (f" - {worst}" if worst else ""), "")
    return "\n".join(lines)


@click.command("validate")
@click.argument("patients", nargs=-1)
@click.option("--plan", "plan_ids", multiple=True, type=PLAN_ID, metavar="ID",
              help="Only this stored plan (repeatable).")
@click.option("--loo", is_flag=True,
              help="Instead: does the fit generalise? Leave each map out of the patient's "
                   "latest fit (or --model's) and predict it from the others.")
@click.option("--model", "model_id", type=MODEL_ID, default=None,
              help="With --loo: the fitted model to cross-validate.")
@click.option("--change-tolerance", type=click.FloatRange(0.0, 10.0, min_open=True),
              default=CHANGE_TOLERANCE, show_default=True,
              help="'As predicted' means within this fraction of the predicted change.")
@click.option("--max-change-se", type=click.FloatRange(0.0, 10.0, min_open=True),
              default=MAX_CHANGE_SE, show_default=True,
              help="The realised fraction decides a verdict only when its SE is at most this.")
@scheduler_option
@db_option
@json_option
@click.pass_context
def validate(ctx: click.Context, patients: tuple[str, ...], plan_ids: tuple[int, ...],
             loo: bool, model_id: int | None, change_tolerance: float, max_change_se: float,
             scheduler: SchedulerFlags | None, db_url: str | None, as_json: bool) -> None:
    """Check given plans against maps measured after them; --loo: does the fit generalise.

    Exit status 1 when a plan's prediction is contradicted (failed, stronger than predicted or
    partial effect), or with --loo when the fit does not generalise to a map the others should
    predict; with
    --scheduler, also when a task failed (its plans were not checked).
    """
    # the checks and their numerics: when the command runs
    from fieldbank.engine import progress_bar
    from fieldbank.fitting.crossval import NOT_GENERALISED, cross_validate, latest_fitted_model
    from fieldbank.fitting.dbstore import DatabaseFitStore
    from fieldbank.interventions.validate import validate_plans
    from fieldbank.interventions.validate_batch import validate_on_cluster
    from fieldbank.scheduler import resolve_scheduler

    if loo:
        if plan_ids:
            raise click.UsageError("--loo cross-validates a fit; it takes no --plan.")
        if (model_id is None) == (len(patients) != 1):
            raise click.UsageError("--loo needs one PATIENT (its latest fit) or --model ID.")
        with open_db(db_url) as db:
            store = DatabaseFitStore(db)
            if patients:  # an unknown patient: the one "not found" message
                db.get_patient(patients[0])
            mid = model_id if model_id is not None else latest_fitted_model(store, patients[0])
            cv = cross_validate(store, mid, progress=lambda msg: click.echo(msg, err=True))
        if as_json:
            emit_json(cv.to_dict())
        else:
            click.echo(loo_text(cv))
        if cv.verdict == NOT_GENERALISED:
            ctx.exit(1)
        return
    if model_id is not None:
        raise click.UsageError("--model goes with --loo.")
    address = resolve_scheduler(scheduler)
    lost: tuple[str, ...] = ()
    with open_db(db_url) as db:
        if address:
            rep, lost = validate_on_cluster(db, address, patients, plan_ids,
                                            tolerance=change_tolerance, max_se=max_change_se,
                                            progress=progress_bar("validate"), say=say)
        else:
            rep = validate_plans(db, patients, plan_ids, tolerance=change_tolerance,
                                 max_se=max_change_se)
    if as_json:
        emit_json(rep.to_dict())
    else:
        click.echo(plans_text(rep))
    for line in lost:
        click.echo(f"not checked (task failed): {line}", err=True)
    if rep.contradicted or lost:
        ctx.exit(1)
