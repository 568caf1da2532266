"""``fieldbank fit PATIENT``, ``fieldbank fit --all`` and ``fieldbank models list|show``.

Thin: the commands open a :class:`fieldbank.fitting.records.FitStore`, call
:func:`fieldbank.fitting.records.fit_patient` or the store, and print; ``fit --all`` calls
:func:`fieldbank.fitting.batch.fit_all` (a batch on local processes or a Dask cluster).
The store comes from ``ctx.obj['fit_store']`` when the caller provides one (a factory
``db_url -> FitStore``), else from :func:`fieldbank.fitting.dbstore.open_fit_store` on the
field database; without one, ``models list`` reads the database through its driver alone
(:func:`fieldbank.cli.options.read_db`).
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import click

from fieldbank.cli.options import (
    MODEL_ID,
    db_option,
    emit_json,
    figure_path,
    json_option,
    open_db,
    read_db,
    say,
    scheduler_option,
)
from fieldbank.cli.table import fit_lines, table, wrap
from fieldbank.fitchoices import (
    ALGORITHMS,
    DEFAULT_ALGORITHM,
    DEFAULT_PRIOR_WEIGHT,
    DEFAULT_REPLICATES,
    DEFAULT_UNCERTAINTY,
    FIT_KINDS,
    MODEL_VERSION,
    UNCERTAINTY_METHODS,
)
from fieldbank.params import GROUP_NAMES, GROUPS, ArmParams
from fieldbank.sanitize import printable

if TYPE_CHECKING:  # typing only: the library loads when a command runs
    from fieldbank.engine import BatchResult
    from fieldbank.fitting.records import FitOutcome, FitStore
    from fieldbank.scheduler import SchedulerFlags
    from fieldbank.stored.records import ListedModel

StoreFactory = Callable[[str | None], "FitStore"]


def _store(ctx: click.Context, db_url: str | None) -> FitStore:
    factory: StoreFactory | None = None
    if isinstance(ctx.obj, Mapping):
        factory = ctx.obj.get("fit_store")
    if factory is None:
        from fieldbank.fitting.dbstore import open_fit_store

        factory = open_fit_store
    return factory(db_url)


def _listed_models(ctx: click.Context, db_url: str | None,
                   patient: str | None) -> list[ListedModel]:
    """The models ``models list`` shows: from the caller's FitStore when it provides one, else
    read from the database through its driver alone (:func:`read_db`)."""
    if isinstance(ctx.obj, Mapping) and ctx.obj.get("fit_store") is not None:
        return list(_store(ctx, db_url).list_models(patient))
    with read_db(db_url) as db:
        if patient is not None:  # an unknown patient: the one "not found" message
            db.get_patient(patient)
        return list(db.list_models(patient))


def _plans_cell(m: ListedModel) -> str:
    """'plan 4' (the plan that made it) and '-> 5,6' (plans applied to it)."""
    parts = ([f"plan {m.plan_id}"] if m.plan_id is not None else []) + (
        ["->" + ",".join(map(str, m.plans_from))] if m.plans_from else [])
    return " ".join(parts) or "-"


def _num(v: object, fmt: str = ".3g") -> str:
    return format(v, fmt) if isinstance(v, (int, float)) else "-"


def fit_quality_lines(report: Mapping[str, Any]) -> list[str]:
    """Status, goodness of fit per map and the parameters with their 95% intervals, from a
    stored fit report (:meth:`fieldbank.fitting.ArmFitter.report`)."""
    from fieldbank.fitting.space import ParamSpace

    lines = [f"  status: {report.get('status')}"]
    gof = report.get("goodness_of_fit")
    if isinstance(gof, Mapping):
        lines.append(f"  goodness of fit: {gof.get('verdict')}: χ²/dof "
                     f"{_num(gof.get('chi2_per_dof'), '.2f')} (limit "
                     f"{_num(gof.get('chi2_limit'), '.2f')}), pooled R² "
                     f"{_num(gof.get('r2'), '.3f')}")
        ids = report.get("map_ids") or []
        lines.append(f"    {'map':>6} {'kind':<10} {'values':>6} {'R²':>7} {'χ²/n':>7} "
                     f"{'RMS residual':>15}  verdict")
        for m in gof.get("maps", []):
            k = int(m.get("index", 0))
            name = str(ids[k]) if k < len(ids) else str(k)
            lines.append(f"    {name:>6} {m.get('kind', ''):<10} {m.get('n_values', 0):>6} "
                         f"{_num(m.get('r2'), '.3f'):>7} {_num(m.get('chi2_per_value'), '.2f'):>7}"
                         f" {_num(m.get('rms_residual'), '.3g'):>9} {m.get('unit', ''):<5}  "
                         f"{m.get('verdict')}")
        lines += [f"    {r}" for r in gof.get("reasons", [])]
    method = report.get("uncertainty_method")
    if isinstance(method, Mapping):
        why = "; ".join(method.get("reasons", [])) or "the Gaussian approximation holds"
        lines.append(f"  uncertainty: {method.get('method')}, {method.get('replicates')} "
                     f"samples, residual scale {_num(method.get('residual_scale'), '.2f')} "
                     f"({why})")
    intervals = report.get("intervals")
    if isinstance(intervals, Mapping) and intervals:
        lines.append(f"  {'parameter':<16}{'value':>10}{'sd':>10}   {'95% interval':<23}basis")
        # stored documents sort their keys: show them in the fit's order (km, alpha, beta, ...)
        order = {n: k for k, n in enumerate(ParamSpace.build(ArmParams.from_anthropometry(),
                                                             FIT_KINDS).names)}
        for name, iv in sorted(intervals.items(), key=lambda kv: order.get(kv[0], 99)):
            span = f"{_num(iv.get('low'), '.4g')} … {_num(iv.get('high'), '.4g')}"
            lines.append(f"  {name:<16}{_num(iv.get('value'), '.4g'):>10}"
                         f"{_num(iv.get('sd'), '.3g'):>10}   {span:<23}{iv.get('basis')}")
    held = report.get("held_at_unimpaired") or []
    if held:
        lines.append("  held at the unimpaired value (a guess, not a measurement): "
                     + ", ".join(held))
    return lines


def _summary(out: FitOutcome) -> str:
    f = out.fitter
    report = out.record.report
    lines = [
        f"fit {out.saved.fit_id} -> model {out.saved.model_id} for patient "
        f"{out.record.patient!r}" + (f", session {out.record.session!r}" if out.record.session
                                     else ""),
        f"  {f.algorithm_} seed {f.seed_}: cost {f.cost_:.4g}, {f.n_evals_} evaluations, "
        f"{f.time_s_:.2f} s",
        *fit_quality_lines(report),
    ]
    if f.unidentified_:
        lines.append("  not identified by these maps:")
        lines += _unidentified_lines([(u.name, u.reason) for u in f.unidentified_], "    ")
    if f.severity_:
        lines += _severity_lines(f.severity_)
    return "\n".join(fit_lines(lines))


def _unidentified_lines(items: Sequence[tuple[str, str]], indent: str) -> list[str]:
    """One line per reason, naming every parameter it holds for (α and β of one group share
    theirs): 'alpha_sf, beta_sf: reflex gains β and α of sf not identifiable: …'."""
    by_reason: dict[str, list[str]] = {}
    for name, reason in items:
        by_reason.setdefault(reason, []).append(name)
    return [f"{indent}{', '.join(names)}: {reason}" for reason, names in by_reason.items()]


def _grade_text(grade: Mapping[str, object]) -> str:
    text = (f"{grade['level']}{'+' if grade.get('beyond_scale') else ''}"
            f"{'*' if grade.get('unidentified') else ''}")
    span = grade.get("level_range")
    if isinstance(span, list) and len(span) == 2 and span[0] != span[1]:
        text += f" ({span[0]} … {span[1]})"
    return text


def _severity_lines(severity: Mapping[str, Mapping[str, Mapping[str, object]]]) -> list[str]:
    """The fit report's severity as a table: one muscle group per line."""
    out = [f"  {'severity':<24} {'passive (contracture)':<36} dynamic (spasticity)",
           "  (+ beyond severe; * rests on a parameter these maps did not identify; (… …) the "
           "95% range over the fit's samples)"]
    for g, v in severity.items():
        out.append(f"  {v.get('name', g)!s:<24} {_grade_text(v['passive']):<36} "
                   f"{_grade_text(v['dynamic'])}")
    return out


@click.command("fit")
@click.argument("patient", required=False)
@click.option("--session", default=None, help="Fit the maps of this session only.")
@click.option("--all", "batch", is_flag=True,
              help="Fit every session with maps as a batch (of --patient, else of every "
                   "patient), on --scheduler's cluster or local worker processes; a fit "
                   "stored already with the same maps, options and model version is found, "
                   "not repeated.")
@click.option("--patient", "patients", multiple=True, metavar="CODE",
              help="With --all: only this patient's sessions (repeatable).")
@click.option("--older-than", "older_than", type=click.IntRange(min=1), default=None,
              metavar="VERSION",
              help="With --all: refit only the fits made under a model version below VERSION "
                   f"(this fieldbank's: {MODEL_VERSION}).")
@scheduler_option
@click.option("--jobs", type=click.IntRange(min=1), default=None,
              help="With --all and no scheduler: worker processes (default: the cores "
                   "available).")
@click.option("--algorithm", type=click.Choice(list(ALGORITHMS)), default=DEFAULT_ALGORITHM,
              show_default=True, help="nlopt global+local, or the dual annealing baseline.")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True)
@click.option("--fit", "fit_kinds", default="km,alpha,beta", show_default=True,
              help=f"Comma-separated parameter kinds to fit ({', '.join(FIT_KINDS)}).")
@click.option("--prior-weight", type=float, default=DEFAULT_PRIOR_WEIGHT, show_default=True)
@click.option("--max-evals", type=click.IntRange(min=10), default=None)
@click.option("--uncertainty", type=click.Choice(list(UNCERTAINTY_METHODS)),
              default=DEFAULT_UNCERTAINTY,
              show_default=True,
              help="Gauss-Newton where it holds else a parametric bootstrap ('auto'), or one "
                   "of the two always.")
@click.option("--replicates", type=click.IntRange(min=2), default=DEFAULT_REPLICATES,
              show_default=True, help="Bootstrap replicates (and parameter samples kept).")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None,
              callback=figure_path,
              help="Write measured against fitted fields to this .svg, .png or .pdf.")
@json_option
@db_option
@click.pass_context
def fit(ctx: click.Context, patient: str | None, session: str | None, batch: bool,
        patients: tuple[str, ...], older_than: int | None, scheduler: SchedulerFlags | None,
        jobs: int | None, algorithm: str, seed: int, fit_kinds: str, prior_weight: float,
        max_evals: int | None, uncertainty: str, replicates: int, plot_path: str | None,
        as_json: bool, db_url: str | None) -> None:
    """Fit PATIENT's arm model to the patient's measured maps and store it."""
    from fieldbank.figures import save
    from fieldbank.figures.fit import fit_figure
    from fieldbank.fitting import ArmFitter
    from fieldbank.fitting.records import fit_patient
    from fieldbank.modelsource import default_changes, patient_defaults

    kinds = tuple(k.strip() for k in fit_kinds.split(",") if k.strip())
    if batch:
        from fieldbank.engine import default_jobs, progress_bar
        from fieldbank.fitting.batch import fit_all
        from fieldbank.scheduler import resolve_scheduler

        if patient is not None or session is not None or plot_path is not None:
            raise click.UsageError("--all fits every session: name patients with --patient; "
                                   "it takes no PATIENT, --session or --plot.")
        options = {"algorithm": algorithm, "seed": seed, "fit": list(kinds),
                   "prior_weight": prior_weight, "max_evals": max_evals,
                   "uncertainty": uncertainty, "replicates": replicates}
        address = resolve_scheduler(scheduler)  # a bad address is refused before any work
        with open_db(db_url) as db:
            before = patient_defaults(db, patients or [p.code for p in db.list_patients()])
            res = fit_all(db, options, patients=patients, older_than=older_than,
                          scheduler=address, jobs=jobs or default_jobs(),
                          progress=progress_bar("fit"), say=say)
            changes = default_changes(db, before)
        _batch_output(res, as_json)
        for line in changes:  # a later fit changes what a patient's code stands for: said
            say(textwrap.fill(line, 100, subsequent_indent="  "))
        if res.failed:
            ctx.exit(1)
        return
    if patient is None:
        raise click.UsageError("give a PATIENT to fit, or --all for every session.")
    if patients or older_than is not None or scheduler is not None or jobs is not None:
        raise click.UsageError("--patient, --older-than, --jobs and the scheduler options go "
                               "with --all.")

    def progress(n: int, best: float) -> None:
        click.echo(f"  {n} evaluations, best cost {best:.6g}", err=True)

    fitter = ArmFitter(algorithm=algorithm, seed=seed, fit=kinds, prior_weight=prior_weight,
                       max_evals=max_evals, progress=progress, uncertainty=uncertainty,
                       replicates=replicates)
    store = _store(ctx, db_url)
    held = getattr(store, "db", None)  # a database store: say when the patient's model changes
    defaults = patient_defaults(held, [patient]) if held is not None else None
    out = fit_patient(store, patient, session, fitter,
                      progress=lambda msg: click.echo(msg, err=True))
    changes = (default_changes(held, defaults) if held is not None and defaults is not None
               else [])
    if not out.saved.created:
        click.echo(wrap(f"fit {out.saved.fit_id} (model {out.saved.model_id}) holds the same "
                        "maps with the same options under this model version: it is the fit "
                        "shown, and nothing new was stored."), err=True)
    if plot_path:
        f = out.fitter
        path = save(fit_figure(f.maps_, f.predict(f.maps_), f.r2_,
                               f"patient {patient}: measured and fitted maps"), plot_path)
        click.echo(f"plot written to {path}", err=True)
    if as_json:
        report = dict(out.record.report)
        report["fit_id"] = out.saved.fit_id
        report["model_id"] = out.saved.model_id
        emit_json(report)
    else:
        click.echo(_summary(out))
    if out.fitter.unidentified_:
        click.echo(wrap(f"warning: {len(out.fitter.unidentified_)} parameter(s) are not "
                        "identified by these maps and stay near the unimpaired prior (see 'not "
                        "identified' above)."), err=True)
    if out.fitter.status_ == "poor":
        click.echo(wrap("warning: poor fit (" + "; ".join(out.fitter.goodness_.reasons)
                        + "). It is stored, but what-ifs and reports refuse it unless given "
                        "--accept-poor-fit. A contracture needs its slack length fitted: "
                        "--fit km,alpha,beta,slack."), err=True)
    for line in changes:
        say(textwrap.fill(line, 100, subsequent_indent="  "))


def _batch_output(res: BatchResult, as_json: bool) -> None:
    """What a batch fit did: one line per task that failed, the totals; or the JSON."""
    if as_json:
        emit_json(res.to_dict())
    else:
        for o in res.outcomes:
            if o.state != "failed":
                click.echo(f"{o.state:<8} {printable(o.key)}: {printable(o.detail)}")
    run = res.run
    click.echo(f"run {run.id} ({res.engine}): {res.count('done')} fitted, "
               f"{res.count('skipped')} found fitted already, {res.count('failed')} failed"
               + (f", {run.left} left" if run.left else "") + "; 'fieldbank jobs "
               f"{run.id}' shows each", err=True)
    for o in res.failed:
        click.echo(f"failed: {printable(o.detail)}", err=True)


@click.group("models")
def models() -> None:
    """Stored arm models (fitted, synthetic, after interventions)."""


@models.command("list")
@click.option("--patient", default=None, help="Only this patient's models.")
@json_option
@db_option
@click.pass_context
def models_list(ctx: click.Context, patient: str | None, as_json: bool,
                db_url: str | None) -> None:
    """List models with their origin, parent and plans (the plan that made each, and the
    plans applied to it: 'fieldbank plans show ID')."""
    from fieldbank.stored.records import model_summary

    rows = _listed_models(ctx, db_url, patient)
    if as_json:
        emit_json([model_summary(m) for m in rows])
        return
    if not rows:
        click.echo("no models", err=True)
        return
    click.echo("\n".join(table(
        ("id", "patient", "origin", "parent", "plans", "label"),
        [(str(m.id), m.patient_code or "-", m.origin,
          "" if m.parent_id is None else str(m.parent_id), _plans_cell(m), printable(m.label))
         for m in rows], "><<><")))


@models.command("show")
@click.argument("model_id", type=MODEL_ID)
@json_option
@db_option
@click.pass_context
def models_show(ctx: click.Context, model_id: int, as_json: bool, db_url: str | None) -> None:
    """Show a model's parameters, lineage, plans and the fit that produced it."""
    detail = _store(ctx, db_url).get_model(model_id)
    if as_json:
        emit_json(detail.to_json_dict())
        return
    m = detail.model
    p = m.params
    lines = [f"model {m.id} ({m.origin}) patient {m.patient_code}: {printable(m.label)}",
             "  group                        Km N/m    alpha N    beta  slack mm"]
    lines += [f"  {g} {GROUP_NAMES[g]:<24}{p.km_n_per_m[i]:>10.1f} {p.alpha_n[i]:>10.1f} "
              f"{p.beta[i]:>7.3f} {1000 * p.slack_offset_m[i]:>+9.1f}"
              for i, g in enumerate(GROUPS)]
    q = [math.degrees(v) for v in p.q_rest_rad]
    lines.append(f"  rest posture: {q[0]:.1f}°, {q[1]:.1f}°")
    if detail.lineage:
        lines.append("  lineage: " + " <- ".join(f"{a.id} ({a.origin})" for a in detail.lineage))
    if m.plan_id is not None:
        lines.append(f"  made by plan {m.plan_id} ('fieldbank plans show {m.plan_id}')")
    if m.plans_from:
        lines.append("  plans applied to it: " + ", ".join(map(str, m.plans_from)))
    fit_report = detail.fit
    if fit_report:
        lines.append(f"  fit: {fit_report.get('algorithm')} seed {fit_report.get('seed')}, "
                     f"cost {fit_report.get('cost'):.4g}, status {fit_report.get('status')}, "
                     f"maps {fit_report.get('map_ids')}")
        lines += ["  " + line for line in fit_quality_lines(fit_report)]
        unidentified = [(str(u["name"]), str(u["reason"]))
                        for u in fit_report.get("unidentified", [])]
        if unidentified:
            lines.append("    not identified by these maps:")
            lines += _unidentified_lines(unidentified, "      ")
    click.echo("\n".join(fit_lines(lines)))
