"""``fieldbank whatif``: apply an intervention plan to a model and compare before with after.

The model comes from ``--params FILE`` (an ArmParams JSON document), ``--severity
GROUP=LEVEL`` (a synthetic arm on the severity scale) or, once the database layer is present,
a stored patient's latest fitted model (:func:`load_patient_model`, ``--db URL``).
``--save`` stores the after model (origin 'intervention', its parent the model before) and
the plan with its lineage (:func:`save_result`). The plan comes from ``--plan
FILE`` and/or the intervention options, applied in this order: plan file steps, lengthening,
tenotomy, serial casting, rhizotomy, baclofen, botulinum.

Human-readable tables go to stdout, or one JSON document with ``--json``.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path
from typing import Any

import click

from fieldbank import modelsource
from fieldbank.cli.options import db_option, emit_json, json_option, open_db
from fieldbank.errors import FieldbankError
from fieldbank.files import to_json, write_atomic
from fieldbank.interventions.catalogue import (
    Baclofen,
    Botulinum,
    Intervention,
    Lengthening,
    Rhizotomy,
    SerialCasting,
    Tenotomy,
)
from fieldbank.interventions.defaults import value
from fieldbank.interventions.errors import InterventionError
from fieldbank.interventions.plan import Plan, params_sha256
from fieldbank.params import GROUPS, ArmParams

_NUM = r"([-+]?[0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)"
_LENGTH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}


def _split_items(items: tuple[str, ...]) -> list[str]:
    return [p.strip() for item in items for p in item.split(",") if p.strip()]


def parse_units(items: tuple[str, ...]) -> dict[str, float]:
    """``('ef=200U', 'ee=100')`` → {'ef': 200.0, 'ee': 100.0}."""
    out: dict[str, float] = {}
    for part in _split_items(items):
        m = re.fullmatch(rf"(\w+)\s*=\s*{_NUM}\s*(?:U|u|units?)?", part)
        if not m:
            raise InterventionError(
                f"--botox {part!r}: expected GROUP=DOSE in units, e.g. ef=200U "
                f"(groups: {', '.join(GROUPS)}).")
        if m.group(1) in out:
            raise InterventionError(f"--botox: muscle group {m.group(1)!r} given twice.")
        out[m.group(1)] = float(m.group(2))
    return out


def parse_length(text: str, option: str) -> float:
    """'1cm', '10 mm', '0.01m', '0.01' (m) → metres."""
    m = re.fullmatch(rf"{_NUM}\s*(m|cm|mm)?", text.strip())
    if not m:
        raise InterventionError(
            f"{option} {text!r}: expected a length such as 1cm, 10mm or 0.01m.")
    return float(m.group(1)) * _LENGTH_UNITS[m.group(2) or "m"]


def parse_group_lengths(items: tuple[str, ...], option: str,
                        default_m: float | None = None) -> list[tuple[str, float]]:
    out = []
    for part in _split_items(items):
        if "=" in part:
            g, length = part.split("=", 1)
            out.append((g.strip(), parse_length(length, option)))
        elif default_m is not None:
            out.append((part, default_m))
        else:
            raise InterventionError(f"{option} {part!r}: expected GROUP=LENGTH, e.g. bf=1cm.")
    return out


def parse_reflex(text: str, option: str) -> tuple[tuple[str, ...], float | None]:
    """'all', 'ef,ee', 'all:0.4' → (groups, factor or None)."""
    groups_text, _, factor_text = text.partition(":")
    groups = GROUPS if groups_text.strip() in ("", "all") else tuple(
        g.strip() for g in groups_text.split(",") if g.strip())
    factor = None
    if factor_text:
        try:
            factor = float(factor_text)
        except ValueError:
            raise InterventionError(
                f"{option} {text!r}: the factor after ':' must be a number.") from None
    return groups, factor


def build_plan(plan_file: str | None, botox: tuple[str, ...], weeks: float | None,
               lengthen: tuple[str, ...], tenotomy: tuple[str, ...], cast: tuple[str, ...],
               rhizotomy: str | None, baclofen: str | None) -> Plan | None:
    steps: list[Intervention] = []
    label = ""
    if plan_file:
        plan = Plan.from_file(plan_file)
        steps.extend(plan.steps)
        label = plan.label
    for g, d in parse_group_lengths(lengthen, "--lengthen"):
        steps.append(Lengthening(group=g, delta_m=d))
    for g in _split_items(tenotomy):
        steps.append(Tenotomy(group=g))
    for g, d in parse_group_lengths(cast, "--cast", default_m=value("casting.delta_m")):
        steps.append(SerialCasting(group=g, delta_m=d))
    for text, cls in ((rhizotomy, Rhizotomy), (baclofen, Baclofen)):
        if text is not None:
            groups, factor = parse_reflex(text, f"--{cls.kind}")
            steps.append(cls(groups=groups) if factor is None else cls(groups=groups,
                                                                      factor=factor))
    if botox:
        kw: dict[str, Any] = {} if weeks is None else {"weeks_since": weeks}
        steps.append(Botulinum(parse_units(botox), **kw))
    elif weeks is not None and not any(isinstance(s, Botulinum) for s in steps):
        raise InterventionError("--weeks needs a botulinum injection (--botox or --plan).")
    elif weeks is not None:
        steps = list(Plan(tuple(steps)).at_week(weeks).steps)
    return Plan(tuple(steps), label) if steps else None


def save_result(db_url: str | None, patient_code: str | None, base_model_id: int | None,
                before: ArmParams, after: ArmParams, source: str, plan: Plan,
                lineage_doc: dict[str, Any]) -> dict[str, int]:
    """Store the after model (origin 'intervention', parent = the before model) and the plan.

    A before model that is not in the database yet (--params, --severity) is stored first as
    a synthetic model, so the lineage always has both ends.
    """
    label = plan.label or "; ".join(s.describe() for s in plan.steps)
    with open_db(db_url) as db:
        base_id, child, rec = db.add_plan_result(
            after, lineage_doc, label, patient_code=patient_code, base_model_id=base_model_id,
            before=before if base_model_id is None else None, before_label=source)
    return {"base_model_id": int(base_id), "result_model_id": int(child.id),
            "plan_id": int(rec.id)}


@click.command("whatif")
@click.argument("patient", required=False)
@click.option("--params", "params_file", type=click.Path(dir_okay=False),
              help="Model to start from: an ArmParams JSON file.")
@click.option("--severity", multiple=True, metavar="GROUP=LEVEL",
              help="Start from a synthetic arm, e.g. elbow=severe (repeatable).")
@click.option("--plan", "plan_file", type=click.Path(dir_okay=False),
              help="Intervention plan JSON file (steps applied first).")
@click.option("--botox", multiple=True, metavar="GROUP=UNITS",
              help="Botulinum toxin A, e.g. ef=200U,ee=100U (one injection session).")
@click.option("--weeks", type=float, default=None,
              help=f"Weeks since the injection (default {value('botulinum.weeks_since'):g}, "
                   "the peak).")
@click.option("--lengthen", multiple=True, metavar="GROUP=LENGTH",
              help="Lengthening surgery, e.g. bf=1cm.")
@click.option("--tenotomy", multiple=True, metavar="GROUP", help="Tenotomy / release.")
@click.option("--cast", multiple=True, metavar="GROUP[=LENGTH]",
              help=f"Serial casting (default +{value('casting.delta_m') * 1000:g} mm).")
@click.option("--rhizotomy", metavar="GROUPS[:FACTOR]",
              help="Selective dorsal rhizotomy: 'all' or e.g. ef,ee:0.4 (β × factor).")
@click.option("--baclofen", metavar="GROUPS[:FACTOR]",
              help="Intrathecal baclofen: 'all' or e.g. ef,ee:0.5 (β × factor).")
@click.option("--timecourse", is_flag=True, help="Also show the metrics week by week (0-24).")
@click.option("--optimize", is_flag=True,
              help="Search the botulinum split closest to unimpaired (model result).")
@click.option("--total-units", type=float, default=None, help="Dose limit for --optimize, U.")
@click.option("--groups", "opt_groups", default=None, metavar="G1,G2",
              help="Groups --optimize may inject (default all six).")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False),
              help="Write before/after/difference fields to this PNG or SVG.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False),
              help="Write plan.json, after.json and lineage.json into this directory.")
@click.option("--save", is_flag=True,
              help="Store the after model and the plan, with lineage, in the database.")
@db_option
@click.option("--render", is_flag=True,
              help="Push before and after to a running 'fieldbank haptic serve' (A = before, "
                   "B = after) to feel them side by side.")
@click.option("--socket", "control_path", default=None, metavar="SOCKET",
              help="Control socket of the renderer for --render (default: the one "
                   "'fieldbank haptic serve' uses).")
@json_option
def whatif(patient: str | None, params_file: str | None, severity: tuple[str, ...],
           plan_file: str | None, botox: tuple[str, ...], weeks: float | None,
           lengthen: tuple[str, ...], tenotomy: tuple[str, ...], cast: tuple[str, ...],
           rhizotomy: str | None, baclofen: str | None, timecourse: bool, optimize: bool,
           total_units: float | None, opt_groups: str | None, plot_path: str | None,
           out_dir: str | None, save: bool, db_url: str | None, render: bool,
           control_path: str | None, as_json: bool) -> None:
    """Apply clinical interventions to a model and compare the fields before and after.

    Results are model predictions, not treatment advice.
    """
    from fieldbank.cli.whatif_report import render_text
    from fieldbank.evaluate import ArmCache, Conditions, compare
    from fieldbank.interventions.course import time_course
    from fieldbank.interventions.inverse import optimise_botulinum

    try:
        if sum(bool(x) for x in (patient, params_file, severity)) != 1:
            raise click.UsageError(
                "Give exactly one model: PATIENT, --params FILE or --severity GROUP=LEVEL.")
        src = modelsource.resolve(params_file=params_file, severity=severity, patient=patient,
                                  open_db=lambda: open_db(db_url))
        before, source, base_model_id = src.params, src.description, src.model_id
        plan = build_plan(plan_file, botox, weeks, lengthen, tenotomy, cast, rhizotomy,
                          baclofen)
        if plan is None and not optimize:
            raise click.UsageError(
                "No intervention given: use --botox, --lengthen, --tenotomy, --cast, "
                "--rhizotomy, --baclofen, --plan or --optimize.")
        arms = ArmCache()
        arm_b = arms(before)
        cond = Conditions.standard(arm_b)
        doc: dict[str, Any] = {"model": {"source": source, "sha256": params_sha256(before)}}
        inverse = None
        if optimize:
            if total_units is None:
                raise click.UsageError("--optimize needs --total-units N.")
            gs = None if opt_groups is None else [g.strip() for g in opt_groups.split(",")]
            inverse = optimise_botulinum(
                arm_b, total_units, gs, conditions=cond, arms=arms,
                weeks_since=value("botulinum.weeks_since") if weeks is None else weeks)
            doc["inverse"] = inverse.to_dict()
            if plan is None:
                plan = inverse.plan
        assert plan is not None
        after, lineage = plan.derive(before)
        arm_a = arms(after)
        comparison = compare(arm_b, arm_a, cond)
        doc["plan"] = plan.to_dict()
        doc["plan_steps"] = plan.describe()
        doc["lineage"] = lineage.to_dict()
        doc["comparison"] = comparison.to_dict()
        course = None
        if timecourse:
            course = time_course(arm_b, plan, conditions=cond, arms=arms)
            doc["timecourse"] = course.to_dict()
        if plot_path:
            from fieldbank.interventions.plot import plot_comparison

            plot_comparison(arm_b, arm_a, plot_path, title=source)
            doc["plot"] = plot_path
        if out_dir:
            d = Path(out_dir)
            write_atomic(d / "plan.json", plan.to_json() + "\n")
            write_atomic(d / "after.json", after.to_json() + "\n")
            write_atomic(d / "lineage.json", to_json(lineage) + "\n")
            doc["out"] = str(d)
        if save:
            doc["saved"] = save_result(db_url, patient, base_model_id, before, after, source,
                                       plan, lineage.to_dict())
        if render:
            from fieldbank.haptic.control import push_models

            ids = doc.get("saved")
            model_ids = ((ids["base_model_id"], ids["result_model_id"]) if ids else
                         (base_model_id, None))
            doc["rendered"] = push_models(before, after, control_path, model_ids=model_ids)
    except FieldbankError as exc:
        raise click.ClickException(str(exc)) from None
    if as_json:
        emit_json(doc)
    else:
        click.echo(render_text(source, plan, comparison, course, inverse))
        if plot_path:
            click.echo(f"plot written to {plot_path}", err=True)
        if out_dir:
            click.echo(f"plan, after model and lineage written to {out_dir}", err=True)
        if render:
            click.echo("pushed to the renderer: A = before, B = after "
                       "(switch with 'fieldbank haptic switch')", err=True)
        if save:
            ids = doc["saved"]
            click.echo(f"stored: after model {ids['result_model_id']} (parent "
                       f"{ids['base_model_id']}), plan {ids['plan_id']}", err=True)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(whatif())
