"""One case of a report: metrics, time course, clinical read-outs and figures of a stored plan.

:func:`compute_case` is a pure function of a
:class:`~fieldbank.interventions.report.select.CaseSpec`, so batches can run it in worker
processes; it returns a picklable :class:`CaseResult`. Each case compiles its two models once
and shares them with its time course (:class:`fieldbank.evaluate.ArmCache`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.compare import Comparison, Conditions, compare
from fieldbank.evaluate.probing import STRETCHES
from fieldbank.evaluate.severity import COMPONENTS, GroupSeverity, summary
from fieldbank.evaluate.tone import GRADED_STRETCH
from fieldbank.figures import svg
from fieldbank.files import json_finite
from fieldbank.interventions.catalogue import Botulinum
from fieldbank.interventions.course import stretch_course
from fieldbank.interventions.guesses import IntervalSet
from fieldbank.interventions.plan import dose_warnings
from fieldbank.interventions.report.figures.case import case_figures, treated_groups
from fieldbank.interventions.report.figures.cohort import CheckPoint, check_points
from fieldbank.interventions.report.select import CaseSpec
from fieldbank.interventions.report.trust import basis_of, case_trust
from fieldbank.params import GROUPS

#: Weeks after the most recent injection at which the time course is evaluated.
TIMECOURSE_WEEKS: tuple[float, ...] = tuple(float(w) for w in range(0, 25))


#: Columns of the metrics table (CSV header and HTML table), in order, with their headings.
COLUMNS: tuple[tuple[str, str], ...] = (
    ("patient", "patient"),
    ("plan_id", "plan"),
    ("plan_label", "plan label"),
    ("kinds", "kinds"),
    ("treated_groups", "treated groups"),
    ("sessions", "sessions"),
    ("case_date", "date"),
    ("base_model_id", "before model"),
    ("result_model_id", "after model"),
    ("static_force_rms_before_n", "static |F| RMS before (N)"),
    ("static_force_rms_after_n", "static |F| RMS after (N)"),
    ("static_diff_rms_n", "static ΔF RMS (N)"),
    ("moving_diff_rms_n", "moving ΔF RMS (N)"),
    ("moving_diff_max_n", "moving ΔF max (N)"),
    ("stiffness_area_ratio_median", "ellipse area ratio"),
    ("orientation_change_deg", "axis change (°)"),
    ("potential_rms_change_j", "ΔU RMS (J)"),
    ("pull_peak_before_n", "pull peak before (N)"),
    ("pull_peak_after_n", "pull peak after (N)"),
    ("semi_ellipse_peak_before_n", "semi-ellipse peak before (N)"),
    ("semi_ellipse_peak_after_n", "semi-ellipse peak after (N)"),
    ("severity_before", "severity before"),
    ("severity_after", "severity after"),
    ("warnings", "warnings"),
)
#: The joint-stretch read-outs per joint and direction (:class:`JointStretch` attribute,
#: column stem, heading); each gets a before and an after column.
STRETCH_READOUTS: tuple[tuple[str, str, str], ...] = (
    ("slow_torque_n_m", "slow_n_m", "slow-stretch torque (N·m)"),
    ("peak_torque_n_m", "fast_n_m", "fast-stretch torque (N·m)"),
    ("reflex_torque_n_m", "velocity_dependent_n_m", "velocity-dependent torque (N·m)"),
    ("catch_angle_deg", "catch_r1_deg", "catch R1 (°)"),
    ("slow_stop_angle_deg", "slow_r2_deg", "slow stop R2 (°)"),
    ("dynamic_range_deg", "r2_minus_r1_deg", "R2 − R1 (°)"),
)
#: Columns of the clinical read-outs: every joint stretch and every muscle group's grades.
CLINICAL_COLUMNS: tuple[tuple[str, str], ...] = tuple(
    (f"{j}_{d}_{stem}_{when}", f"{j} {d} {head} {when}")
    for j, d in STRETCHES for _, stem, head in STRETCH_READOUTS
    for when in ("before", "after")
) + tuple(
    (f"severity_{g}_{c}_{when}", f"{g} {c} {when}")
    for g in GROUPS for c in COMPONENTS for when in ("before", "after")
) + tuple(
    (f"severity_{g}_{c}_score_{when}", f"{g} {c} score {when}")
    for g in GROUPS for c in COMPONENTS for when in ("before", "after")
)
#: Every column of metrics.csv / metrics.json; the HTML overview shows :data:`COLUMNS`.
ALL_COLUMNS: tuple[tuple[str, str], ...] = COLUMNS + CLINICAL_COLUMNS


@dataclass(frozen=True)
class Figure:
    """A case's figure: key, caption and its SVG (empty: the caption says why there is no
    figure, e.g. a field the plan does not change)."""

    key: str
    caption: str
    svg: str


@dataclass(frozen=True)
class CaseResult:
    """Computed case: ``row`` (metrics table row), ``detail`` (JSON), ``figures``,
    ``checks``."""

    spec: CaseSpec
    row: dict[str, Any]
    detail: dict[str, Any]
    figures: tuple[Figure, ...]
    #: The plan checked against maps measured after it, per map (cohort figure).
    checks: tuple[CheckPoint, ...] = ()
    #: The prediction intervals computed for this case (None: read from the fit's kept
    #: documents, or none to compute), to keep with the fit.
    intervals: IntervalSet | None = None


def _clinical(c: Comparison) -> dict[str, Any]:
    """The :data:`CLINICAL_COLUMNS` of one comparison."""
    out: dict[str, Any] = {}
    for name, b, a in c.stretch_rows():
        key = name.replace(" ", "_")
        for attr, stem, _ in STRETCH_READOUTS:
            out[f"{key}_{stem}_before"] = getattr(b, attr)
            out[f"{key}_{stem}_after"] = getattr(a, attr)
    for g, sb, sa in c.severity_rows():
        for comp in COMPONENTS:
            out[f"severity_{g}_{comp}_before"] = sb.component(comp).text()
            out[f"severity_{g}_{comp}_after"] = sa.component(comp).text()
            out[f"severity_{g}_{comp}_score_before"] = sb.component(comp).score
            out[f"severity_{g}_{comp}_score_after"] = sa.component(comp).score
    return out


def _levels(sev: dict[str, GroupSeverity]) -> str:
    return summary(sev)


def compute_case(spec: CaseSpec) -> CaseResult:
    """Metrics and figures of one stored plan (before = base model, after = result model)."""
    arms = ArmCache()
    arm_b, arm_a = arms(spec.before), arms(spec.after)
    cond = Conditions.standard(arm_b)
    basis = basis_of(spec)
    # grades resting on a parameter the fit did not identify say so (the '*')
    c = compare(arm_b, arm_a, cond, [n for n, _ in basis.unidentified] if basis else ())
    plan = spec.plan
    course = None
    if plan is not None and any(isinstance(s, Botulinum) for s in plan.steps):
        course = stretch_course(arm_b, plan, TIMECOURSE_WEEKS, arms=arms)

    static, moving = c.fields[0], c.fields[min(1, len(c.fields) - 1)]
    probes = {n: (b, a) for n, b, a in c.probe_rows()}
    sev_b, sev_a = c.before.severity, c.after.severity
    trust = case_trust(spec, cond, arms)
    # what the prediction rests on first, then the plan's own warnings (dose above the limit)
    warnings = (list(trust.detail.get("warnings", ()))
                + (dose_warnings(plan) if plan is not None else []))
    treated = treated_groups(plan)
    row: dict[str, Any] = {
        "patient": spec.patient_code or "",
        "plan_id": spec.plan_id,
        "plan_label": spec.plan_label,
        "kinds": " ".join(spec.kinds),
        "treated_groups": " ".join(treated),
        "sessions": " ".join(label for label, _ in spec.sessions),
        "case_date": spec.case_date,
        "base_model_id": spec.base_model_id,
        "result_model_id": spec.result_model_id,
        "static_force_rms_before_n": static.force_rms_before_n,
        "static_force_rms_after_n": static.force_rms_after_n,
        "static_diff_rms_n": static.diff_rms_n,
        "moving_diff_rms_n": moving.diff_rms_n,
        "moving_diff_max_n": moving.diff_max_n,
        "stiffness_area_ratio_median": static.area_ratio_median,
        "orientation_change_deg": static.orientation_change_deg_mean,
        "potential_rms_change_j": c.potential.rms_j,
        "pull_peak_before_n": probes["pull"][0].peak_force_n,
        "pull_peak_after_n": probes["pull"][1].peak_force_n,
        "semi_ellipse_peak_before_n": probes["semi-ellipse"][0].peak_force_n,
        "semi_ellipse_peak_after_n": probes["semi-ellipse"][1].peak_force_n,
        "severity_before": _levels(sev_b),
        "severity_after": _levels(sev_a),
        "warnings": " | ".join(warnings),
        **_clinical(c),
    }
    detail: dict[str, Any] = {
        "plan_id": spec.plan_id,
        "patient": spec.patient,
        "plan_label": spec.plan_label,
        "plan": spec.plan_doc,
        "kinds": list(spec.kinds),
        "treated_groups": list(treated),
        "graded_stretches": {g: " ".join(GRADED_STRETCH[g]) for g in treated},
        "sessions": [{"label": lb, "date": d} for lb, d in spec.sessions],
        "case_date": spec.case_date,
        "fit_id": spec.fit_id,
        "before_model": {"id": spec.base_model_id, "origin": spec.base_origin,
                         "label": spec.base_label},
        "after_model": {"id": spec.result_model_id},
        "comparison": c.to_dict(),
        "steps": plan.describe() if plan is not None else [],
        "timecourse": course.to_dict() if course is not None else None,
        "warnings": warnings,
    }
    row.update(trust.row)
    detail.update({k: v for k, v in trust.detail.items() if k != "warnings"})
    who = f"{spec.patient_code or '-'} plan {spec.plan_id}"
    checks = (tuple(check_points(trust.validation, who)) if trust.validation is not None
              else ())
    bands = trust.guesses.bands if trust.guesses is not None else None
    # clip-path ids must be unique in the page: plan id and figure number
    figs = tuple(
        Figure(f.key, f.caption,
               "" if f.scene is None else svg.write(f.scene, f"p{spec.plan_id}f{k}"))
        for k, f in enumerate(case_figures(arm_b, arm_a, c, plan, course, bands, checks)))
    g = trust.guesses
    fresh = (IntervalSet(g.intervals, g.interval_note, g.n_samples, g.bands)
             if g is not None and spec.intervals is None and g.n_samples > 0 else None)
    return CaseResult(spec, json_finite(row), json_finite(detail), figs, checks, fresh)
