"""One case's figures, in order (:func:`case_figures`), what the plan changes first, each
with its caption; a figure the plan leaves unchanged is a caption saying so."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from fieldbank.evaluate.compare import Comparison, standard_grid
from fieldbank.evaluate.probing import lengthening_direction
from fieldbank.evaluate.tone import GRADED_STRETCH
from fieldbank.figures import fields
from fieldbank.figures.scene import Scene
from fieldbank.interventions.course import StretchCourse
from fieldbank.interventions.plan import Plan
from fieldbank.interventions.report.figures.cohort import CheckPoint, validation_figure
from fieldbank.interventions.report.figures.grades import probes_figure, severity_figure
from fieldbank.interventions.report.figures.stretches import (
    StretchPair,
    stretch_figure,
    timecourse_figure,
)
from fieldbank.interventions.report.figures.workspace import (
    MOVING_SPEED_M_PER_S,
    direction_label,
    ellipse_figure,
    moving_field_figure,
    static_field_figure,
)
from fieldbank.model import Arm, FloatArray
from fieldbank.params import GROUPS

#: Grid of the field figures (``workspace_grid`` n; denser grids only crowd the arrows).
FIGURE_GRID_N = 11


@dataclass(frozen=True)
class CaseFigure:
    """One figure of a case: key, caption, and the scene (None: ``caption`` says why there is
    no figure, e.g. the static field did not change)."""

    key: str
    caption: str
    scene: Scene | None


def treated_groups(plan: Plan | None) -> tuple[str, ...]:
    """The muscle groups the plan's steps act on, in the model's order."""
    if plan is None:
        return ()
    found = {g for s in plan.steps for g in s.targets()}
    return tuple(g for g in GROUPS if g in found)


def moving_direction(arm_b: Arm, arm_a: Arm, grid_m: FloatArray, treated: Sequence[str],
                     speed_m_per_s: float = MOVING_SPEED_M_PER_S) -> tuple[FloatArray, str]:
    """The hand direction of the moving-field figure and why: for each treated group the
    direction that lengthens it fastest at the rest posture (its stretch reflex acts there),
    the one of them where the field changes most; without treated groups, the one of 8
    directions where it changes most."""
    if treated:
        cands = [(lengthening_direction(arm_b, g), g) for g in treated]
    else:
        cands = [(np.array([math.cos(t), math.sin(t)]), "")
                 for t in 2 * np.pi * np.arange(8) / 8]
    best: tuple[float, FloatArray, str] | None = None
    for d, g in cands:
        v = np.tile(d * speed_m_per_s, (len(grid_m), 1))
        diff = arm_a.endpoint_force(grid_m, v) - arm_b.endpoint_force(grid_m, v)
        rms = float(np.sqrt(np.mean(diff * diff)))
        if best is None or rms > best[0] + 1e-12:
            best = (rms, d, g)
    assert best is not None
    _, d, g = best
    if g:
        stretched = [h for h in treated if np.dot(lengthening_direction(arm_b, h), d) > 0.2]
        why = (f"lengthens the treated {', '.join(stretched)} (fastest for {g}), so their "
               "stretch reflex acts")
    else:
        why = "the direction, of 8, where the field changes most"
    return d, why


def case_figures(arm_b: Arm, arm_a: Arm, c: Comparison, plan: Plan | None,
                 course: StretchCourse | None = None,
                 bands: Mapping[str, Mapping[str, tuple[FloatArray, FloatArray]]]
                 | None = None,
                 checks: Sequence[CheckPoint] = ()) -> list[CaseFigure]:
    """Every figure of one what-if case, what the plan changes first (module docstring).

    ``bands``: 95% intervals of the fast-stretch torque curves, ``{"before"|"after":
    {stretch name: (low, high)}}``; ``checks``: the plan checked against later maps.
    """
    treated = treated_groups(plan)
    prof_b, prof_a = c.before.profiles, c.after.profiles
    assert prof_b is not None and prof_a is not None
    bands = bands or {}
    pairs = [StretchPair(b, a, prof_b[(b.joint, b.direction)], prof_a[(a.joint, a.direction)],
                         bands.get("after", {}).get(n), bands.get("before", {}).get(n),
                         bands.get("after identified", {}).get(n),
                         bands.get("before identified", {}).get(n))
             for n, b, a in c.stretch_rows()]
    b0 = pairs[0].before
    out = [CaseFigure(
        "stretches",
        f"Joint stretches (Tardieu-style): torque resisting a slow ({b0.slow_speed_deg_s:.0f}°/s,"
        f" dashed) and a fast ({b0.speed_deg_s:.0f}°/s, solid) stretch of one joint through its "
        "range, the other at rest, before (blue) and after (vermillion). The gap between the "
        "fast and the slow curve is the velocity-dependent part (spasticity: the stretch "
        "reflex); the slow curve is position-dependent (contracture). ▲ R1: where the fast "
        "stretch meets the catch threshold (twice the unimpaired arm's largest slow-stretch "
        "torque); ■ R2: where the slow one does. Angles: elbow 0° straight, shoulder from +x, "
        "flexion positive.",
        stretch_figure(pairs, treated))]
    grid = standard_grid(arm_b, FIGURE_GRID_N)
    d, why = moving_direction(arm_b, arm_a, grid, treated)
    out.append(CaseFigure(
        "moving-field",
        f"Endpoint force with the hand moving at {MOVING_SPEED_M_PER_S:g} m/s "
        f"{direction_label(d)} at every grid point: the direction {why}. Arrows: the force of "
        "the arm on the handle (before and after on one scale; the change on its own, see the "
        "keys); cells: the change of its magnitude.",
        moving_field_figure(arm_b, arm_a, grid, d, why)))
    static = c.fields[0]
    if static.diff_max_n < fields.NO_CHANGE and c.potential.max_abs_j < fields.NO_CHANGE:
        out.append(CaseFigure(
            "static-field",
            "Static (passive, position-dependent) field, potential and stiffness: no change "
            f"(largest |ΔF| {static.diff_max_n:.2g} N, |ΔU| {c.potential.max_abs_j:.2g} J): the "
            "plan acts on the velocity-dependent (reflex) forces only.", None))
    else:
        _, kb, _ = arm_b.field(grid)
        _, ka, _ = arm_a.field(grid)
        out.append(CaseFigure(
            "static-field",
            "Static (postural, passive) field before and after over the passive potential U "
            "(one arrow scale, one colour scale), and the change: arrows ΔF over ΔU on a "
            "diverging map centred on zero.",
            static_field_figure(arm_b, arm_a, grid)))
        out.append(CaseFigure(
            "stiffness",
            "Static endpoint stiffness ellipses (symmetric part of K; axes ∝ eigenvalues, one "
            "scale, the largest cut and drawn thick) before and after, and the ratio of the "
            "larger stiffness after ÷ before.",
            ellipse_figure(arm_b, grid, kb, ka)))
    out.append(CaseFigure(
        "severity",
        "Severity per muscle group before (ring) and after (dot): passive grade "
        "(position-dependent, contracture) and dynamic grade (velocity-dependent, spasticity), "
        "on the seed's levels (Weber fraction 0.6 below a MAS-4 boundary of 10× unimpaired).",
        severity_figure(c.severity_rows())))
    probe_rows = c.probe_rows()
    probe_diff = max((float(np.max(np.abs(a.force_n - b.force_n))) for _, b, a in probe_rows),
                     default=0.0)
    if probe_diff < fields.NO_CHANGE:
        # the same curve twice would read as "the plan does nothing"; say what these motions
        # miss instead (the stretches above show what changes)
        out.append(CaseFigure(
            "probes",
            "Force felt along the seed's probing motions ("
            + ", ".join(n for n, _, _ in probe_rows)
            + f"): no change (largest |ΔF| {probe_diff:.2g} N): these motions do not engage "
            "what the plan changes; the joint stretches above show it.",
            None))
    else:
        out.append(CaseFigure(
            "probes", "Force felt along the seed's probing motions (Fig. 3b, 3c), before and "
            "after, one force axis.", probes_figure(probe_rows)))
    if course is not None:
        names = [f"{j} {dd}" for (j, dd) in {GRADED_STRETCH[g] for g in course.effect}]
        names = [n for n, _, _ in c.stretch_rows() if n in names]
        out.append(CaseFigure(
            "timecourse",
            f"Botulinum time course: effect per injected group (drop of α) and the peak "
            f"torque resisting the fast stretch of the stretches that lengthen them, weeks "
            f"after the most recent injection; dashed: the plan's week ({course.plan_week:g}).",
            timecourse_figure(course.weeks, course.plan_week, course.effect,
                              course.fast_peak_n_m, names)))
    if checks:
        out.append(CaseFigure(
            "validation",
            "The prediction against maps measured after the plan: per map, the RMS of the "
            "measured change (later map − model before) against the RMS of the predicted "
            "change (model after − model before) at the same points; on the dashed identity "
            "line the change came as predicted. Right: the measured change along the "
            "predicted one (1: as predicted, 0: none), ±1 SE, and the tolerance of the check.",
            validation_figure(checks, "The prediction against maps measured after the "
                                      "plan")))
    return out
