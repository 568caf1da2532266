"""One case of a report: metrics, time course, probing profiles and figures of a stored plan.

:func:`compute_case` is a pure function of a
:class:`~fieldbank.interventions.report.select.CaseSpec`, so batches can run it in worker
processes; it returns a picklable :class:`CaseResult`. Each case compiles its two models once
and shares them with its time course (:class:`fieldbank.evaluate.ArmCache`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.compare import Comparison, Conditions, compare
from fieldbank.evaluate.probing import STRETCHES
from fieldbank.files import json_finite
from fieldbank.interventions.catalogue import Botulinum
from fieldbank.interventions.course import time_course
from fieldbank.interventions.plan import dose_warnings
from fieldbank.interventions.report import figures
from fieldbank.interventions.report.select import CaseSpec
from fieldbank.interventions.report.trust import case_trust
from fieldbank.params import GROUPS
from fieldbank.severity import COMPONENTS, LEVELS, GroupSeverity, summary

#: Weeks after the most recent injection at which the time course is evaluated.
TIMECOURSE_WEEKS: tuple[float, ...] = tuple(float(w) for w in range(0, 25))
#: Grid of the field figures (``workspace_grid`` n; denser grids only crowd the arrows).
FIGURE_GRID_N = 11
#: Hand speed of the moving-field row (the metrics' moving speed), m/s toward the body.
FIGURE_SPEED_M_PER_S = 0.3


#: Columns of the metrics table (CSV header and HTML table), in order, with their headings.
COLUMNS: tuple[tuple[str, str], ...] = (
    ("patient", "patient"),
    ("plan_id", "plan"),
    ("plan_label", "plan label"),
    ("kinds", "kinds"),
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
)
#: Every column of metrics.csv / metrics.json; the HTML overview shows :data:`COLUMNS`.
ALL_COLUMNS: tuple[tuple[str, str], ...] = COLUMNS + CLINICAL_COLUMNS


@dataclass(frozen=True)
class Figure:
    key: str
    caption: str
    png: bytes


@dataclass(frozen=True)
class CaseResult:
    """Computed case: ``row`` (metrics table row), ``detail`` (JSON), ``figures``."""

    spec: CaseSpec
    row: dict[str, Any]
    detail: dict[str, Any]
    figures: tuple[Figure, ...]


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
    return out


def _levels(sev: dict[str, GroupSeverity]) -> str:
    return summary(sev)


def compute_case(spec: CaseSpec) -> CaseResult:
    """Metrics and figures of one stored plan (before = base model, after = result model)."""
    arms = ArmCache()
    arm_b, arm_a = arms(spec.before), arms(spec.after)
    cond = Conditions.standard(arm_b)
    c = compare(arm_b, arm_a, cond)
    plan = spec.plan
    course = None
    if plan is not None and any(isinstance(s, Botulinum) for s in plan.steps):
        course = time_course(arm_b, plan, TIMECOURSE_WEEKS, conditions=cond, arms=arms)

    static, moving = c.fields[0], c.fields[min(1, len(c.fields) - 1)]
    probes = {n: (b, a) for n, b, a in c.probe_rows()}
    sev_b, sev_a = c.before.severity, c.after.severity
    warnings = dose_warnings(plan) if plan is not None else []
    row: dict[str, Any] = {
        "patient": spec.patient_code or "",
        "plan_id": spec.plan_id,
        "plan_label": spec.plan_label,
        "kinds": " ".join(spec.kinds),
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
        "warnings": "; ".join(warnings),
        **_clinical(c),
    }
    detail: dict[str, Any] = {
        "plan_id": spec.plan_id,
        "patient": spec.patient,
        "plan_label": spec.plan_label,
        "plan": spec.plan_doc,
        "kinds": list(spec.kinds),
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
    trust_row, trust_detail = case_trust(spec, cond, arms)
    row.update(trust_row)
    detail.update(trust_detail)
    # what the prediction rests on first, then the plan's own warnings (dose above the limit)
    every = list(trust_detail.get("warnings", ())) + list(warnings)
    detail["warnings"] = every
    row["warnings"] = " | ".join(every)

    grid = Conditions.standard(arm_b, grid_n=FIGURE_GRID_N).grid_m
    _, kb, _ = arm_b.field(grid)
    _, ka, _ = arm_a.field(grid)
    figs = [
        Figure("fields", "Endpoint force field before, after and the difference: static "
               "(postural) over contours of the passive potential U, and with the hand moving "
               f"at {FIGURE_SPEED_M_PER_S:g} m/s (where the stretch reflex acts) in the "
               "direction, of 8 (angle from +x), where the field changes most; + marks the "
               "rest hand position.",
               figures.fields_figure(arm_b, arm_a, grid, FIGURE_SPEED_M_PER_S)),
        Figure("ellipses", "Static endpoint stiffness ellipses before and after "
               "(symmetric part of K, one scale).",
               figures.ellipses_figure(grid, kb, ka)),
        Figure("severity", "Severity per muscle group before and after: passive "
               "(position-dependent: contracture) and dynamic (velocity-dependent: "
               "spasticity, the stretch reflex) grades, 0 unimpaired … 4 severe.",
               figures.severity_figure(
                   list(sev_b),
                   {k: [min(s.component(k).score, 4.5) for s in sev_b.values()]
                    for k in COMPONENTS},
                   {k: [min(s.component(k).score, 4.5) for s in sev_a.values()]
                    for k in COMPONENTS}, LEVELS)),
        Figure("probes", "Force felt along the probing motions (seed Fig. 3b, 3c), before "
               "and after.",
               figures.probes_figure([
                   (n, b.motion.times_s, np.hypot(*b.force_n.T), np.hypot(*a.force_n.T))
                   for n, b, a in c.probe_rows()])),
    ]
    if course is not None:
        figs.append(Figure(
            "timecourse", "Botulinum time course: effect per injected group and probing peak "
            "force, weeks after the most recent injection.",
            figures.timecourse_figure(course.weeks, course.effect, course.probe_peak_n)))
    return CaseResult(spec, json_finite(row), json_finite(detail), tuple(figs))
