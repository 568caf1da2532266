"""``fieldbank validate``: predictions checked against what was measured.

Without ``--loo``: every stored plan that was carried out (``whatif --save --given-on``),
against the maps its patient had measured after it
(:func:`fieldbank.interventions.validate.validate_plans`). With ``--loo``: each map of a
patient's latest fit (or ``--model``'s) left out in turn and predicted by the others
(:func:`fieldbank.fitting.crossval.cross_validate`). Exit status 1 when a prediction failed.
"""

from __future__ import annotations

import math

import click

from fieldbank.cli.options import (
    db_option,
    emit_json,
    json_option,
    open_db,
    say,
    scheduler_option,
)
from fieldbank.engine import progress_bar, resolve_scheduler
from fieldbank.fitting.crossval import CrossValidation, cross_validate, latest_fitted_model
from fieldbank.fitting.dbstore import DatabaseFitStore
from fieldbank.interventions.validate import (
    CHANGE_TOLERANCE,
    FAILED,
    MAX_CHANGE_SE,
    PlanValidation,
    ValidationReport,
    validate_plans,
)
from fieldbank.interventions.validate_batch import validate_on_cluster


def _f(v: float | None, fmt: str) -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, fmt)


def plans_text(rep: ValidationReport) -> str:
    lines: list[str] = []
    for p in rep.plans:
        lines += _plan_lines(p)
        lines.append("")
    failed = ", ".join(f"plan {p.plan_id} ({p.patient})" for p in rep.failed)
    lines.append(f"Overall: {rep.verdict}" + (f": {failed}" if failed else ""))
    return "\n".join(lines)


def _plan_lines(p: PlanValidation) -> list[str]:
    head = (f"Plan {p.plan_id} ({p.patient or 'no patient'}): {p.label}; model before "
            f"{p.before_model_id}" + (f" (fit {p.fit_id})" if p.fit_id is not None else ""))
    if p.given_on:
        head += f"; given on {p.given_on}"
    lines = [head]
    if p.not_checked is not None:
        lines.append(f"  not checked: {p.not_checked}")
        return lines
    for s in p.sessions:
        timing = "botulinum effect re-timed to the session" if s.retimed else "as stored"
        lines.append(f"  session {s.session} ({s.session_date}, {s.weeks_after:.1f} weeks after;"
                     f" {timing}): {s.verdict.upper() if s.verdict == FAILED else s.verdict}")
        lines.append(f"    {'map':>5} {'kind':<10}{'speed':>6} {'values':>6} {'R²':>7} "
                     f"{'RMS error':>15} {'χ²/n':>7}  {'verdict':<8}{'Δ predicted':>13}"
                     f"{'Δ measured':>12}{'realised':>10}")
        for m in s.maps:
            pr = m.prediction
            speed = math.hypot(*m.velocity_m_per_s)
            lines.append(
                f"    {m.map_id:>5} {m.kind:<10}{speed:>6.2f} {pr.n_values:>6} "
                f"{_f(pr.r2, '.3f'):>7} {_f(pr.rms_residual, '.3g'):>9} {m.unit:<5} "
                f"{_f(pr.chi2_per_value, '.2f'):>7}  {pr.verdict:<8}"
                f"{_f(m.predicted_change_rms, '.3g'):>13}{_f(m.measured_change_rms, '.3g'):>12}"
                f"{_f(m.realised_fraction, '.2f'):>10}")
        lines.append(f"    measured change / predicted change (pooled): "
                     f"{_f(s.realised_fraction, '.2f')} ± {_f(s.realised_se, '.2f')}")
        lines += [f"    {r}" for r in s.reasons]
    return lines


def loo_text(cv: CrossValidation) -> str:
    lines = [f"Leave-one-map-out of model {cv.model_id} (patient {cv.patient}): each map "
             "predicted by a fit of the others",
             f"  {'map':>5} {'kind':<10}{'moving':>7} {'values':>6} {'R²':>7} "
             f"{'RMS error':>15} {'χ²/n':>7}  verdict"]
    for m in cv.maps:
        f = m.fit
        lines.append(f"  {m.map_id!s:>5} {f.kind:<10}{'yes' if m.moving else 'no':>7} "
                     f"{f.n_values:>6} {_f(f.r2, '.3f'):>7} {_f(f.rms_residual, '.3g'):>9} "
                     f"{f.unit:<5} {_f(f.chi2_per_value, '.2f'):>7}  {f.verdict}")
        lines += [f"      {r}" for r in f.reasons]
        if m.note:
            lines.append(f"      {m.note}")
    lines.append(f"Overall: {cv.verdict}")
    return "\n".join(lines)


@click.command("validate")
@click.argument("patients", nargs=-1)
@click.option("--plan", "plan_ids", multiple=True, type=int, metavar="ID",
              help="Only this stored plan (repeatable).")
@click.option("--loo", is_flag=True,
              help="Instead: leave each map out of the patient's latest fit (or --model's) "
                   "and predict it from the others.")
@click.option("--model", "model_id", type=int, default=None,
              help="With --loo: the fitted model to cross-validate.")
@click.option("--change-tolerance", type=click.FloatRange(0.0, 10.0, min_open=True),
              default=CHANGE_TOLERANCE, show_default=True,
              help="A measured change within this fraction of the predicted one counts as "
                   "predicted.")
@click.option("--max-change-se", type=click.FloatRange(0.0, 10.0, min_open=True),
              default=MAX_CHANGE_SE, show_default=True,
              help="The change is checked only when its realised fraction is known to this SE.")
@scheduler_option
@db_option
@json_option
@click.pass_context
def validate(ctx: click.Context, patients: tuple[str, ...], plan_ids: tuple[int, ...],
             loo: bool, model_id: int | None, change_tolerance: float, max_change_se: float,
             scheduler: str | None, db_url: str | None, as_json: bool) -> None:
    """Check predictions against maps measured after the plan; --loo: leave maps out of a fit."""
    if loo:
        if plan_ids:
            raise click.UsageError("--loo cross-validates a fit; it takes no --plan.")
        if (model_id is None) == (len(patients) != 1):
            raise click.UsageError("--loo needs one PATIENT (its latest fit) or --model ID.")
        with open_db(db_url) as db:
            store = DatabaseFitStore(db)
            mid = model_id if model_id is not None else latest_fitted_model(store, patients[0])
            cv = cross_validate(store, mid, progress=lambda msg: click.echo(msg, err=True))
        if as_json:
            emit_json(cv.to_dict())
        else:
            click.echo(loo_text(cv))
        if cv.verdict == FAILED:
            click.echo("prediction failed: a map left out is not predicted by the others",
                       err=True)
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
    if rep.failed:
        click.echo("prediction failed: " + ", ".join(
            f"plan {p.plan_id} ({p.patient})" for p in rep.failed), err=True)
    if rep.failed or lost:
        ctx.exit(1)
