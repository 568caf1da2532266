"""The figures of a what-if case, as vector graphics (:mod:`fieldbank.figures`,
:mod:`fieldbank.figures.fields`): the report's, ``whatif --plot``'s - one set of figures.

Each function takes already computed values and returns a
:class:`~fieldbank.figures.scene.Scene`;
what the plan changes comes first:

* :func:`stretch_figure` - the clinic's joint stretches (Tardieu-style): torque resisting the
  slow (5°/s) and the fast (180°/s) stretch over the joint angle, before and after, per joint
  and direction, the catch (R1) and the slow stop (R2) marked, the treated groups' stretches
  named; where the what-if has intervals, the 95% band of the fast stretch after;
* :func:`moving_field_figure` - the field with the hand moving in the direction that lengthens
  the treated groups (where the stretch reflex acts), before, after and the change;
* :func:`static_field_figure` - the passive (postural) field over the potential U, and ΔU on a
  diverging map; :func:`ellipse_figure` - static stiffness;
* :func:`severity_figure` - passive and dynamic grade per muscle group, before → after;
* :func:`probes_figure` - force felt along the seed's probing motions;
* :func:`timecourse_figure` - botulinum effect and fast-stretch torque week by week;
* :func:`validation_figure` - predicted against measured change, where maps measured after the
  plan exist;
* cohort figures of a batch: :func:`cohort_change_figure`, :func:`cohort_validation_figure`.

Before is drawn in blue, after in vermillion, changes in near black; units on every axis and
key; every curve and arrow set carries ``data-*`` attributes naming what it shows.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from fieldbank.evaluate.compare import Comparison, standard_grid
from fieldbank.evaluate.probing import (
    JointStretch,
    ProbeProfile,
    StretchProfile,
    lengthening_direction,
)
from fieldbank.evaluate.severity import GRADED_STRETCH, LEVELS, MUSCLE_GROUP_NAMES, GroupSeverity
from fieldbank.figures import fields
from fieldbank.figures.panel import Panel
from fieldbank.figures.scene import Scene
from fieldbank.figures.style import (
    AFTER,
    BEFORE,
    CHANGE,
    FONT,
    FONT_SMALL,
    FONT_TITLE,
    GREY,
    SERIES,
    TEXT,
    limits,
    nice_ticks,
    text_width,
)
from fieldbank.interventions.course import StretchCourse
from fieldbank.interventions.plan import Plan
from fieldbank.interventions.validate import CHANGE_TOLERANCE, PlanValidation
from fieldbank.model import Arm, FloatArray
from fieldbank.params import GROUPS

WIDTH = 1080.0
#: Colour of a check that held.
ACCENT_OK = "#009E73"
#: Hand speed of the moving-field figure (the metrics' moving speed), m/s.
MOVING_SPEED_M_PER_S = 0.3
#: Torque axes never span less than this (a flat line is not blown up to noise), N·m.
MIN_TORQUE_SPAN_N_M = 1.0
#: Force axes never span less than this, N.
MIN_FORCE_SPAN_N = 1.0


def pct(before: float, after: float) -> str:
    """Relative change as text ('−24%'); '' when the value before is 0."""
    if abs(before) < 1e-12:
        return "" if abs(after) < 1e-12 else "new"
    v = 100.0 * (after - before) / before
    return ("±0%" if abs(v) < 0.05 else f"{v:+.0f}%" if abs(v) >= 9.5 else f"{v:+.1f}%"
            ).replace("-", "−")


def _angle(deg: float | None) -> str:
    if deg is None:
        return "—"
    text = f"{deg:.0f}"
    return f"{'0' if text == '-0' else text}°"


@dataclass(frozen=True)
class StretchPair:
    """One joint stretch before and after: read-outs and profiles; ``band``: 95% interval
    (low, high) of the fast-stretch torque after, N·m, per sample of the profile, if any."""

    before: JointStretch
    after: JointStretch
    profile_before: StretchProfile
    profile_after: StretchProfile
    band: tuple[FloatArray, FloatArray] | None = None
    band_before: tuple[FloatArray, FloatArray] | None = None


def stretch_figure(pairs: Sequence[StretchPair], treated: Sequence[str] = ()) -> Scene:
    """Torque resisting the slow and the fast stretch over the joint angle, per joint and
    direction (2 × 2 panels), before and after; catches marked; treated stretches named."""
    ncol = 2
    block_w = WIDTH / ncol
    left, pw, ph, head, foot = 84.0, block_w - 84.0 - 36.0, 170.0, 50.0, 52.0
    nrow = math.ceil(len(pairs) / ncol)
    legend_h = 48.0
    scene = Scene(WIDTH, nrow * (head + ph + foot) + legend_h,
                  "joint stretches: resisting torque over the joint angle, before and after")
    scene.data["figure"] = "stretches"
    any_band = False
    for k, sp in enumerate(pairs):
        b, a, pb, pa = sp.before, sp.after, sp.profile_before, sp.profile_after
        col, row = k % ncol, k // ncol
        x0, y0 = col * block_w + left, row * (head + ph + foot) + head
        deg = np.degrees(pb.angles_rad)
        curves = {"slow before": pb.slow_n_m, "slow after": pa.slow_n_m,
                  "fast before": pb.fast_n_m, "fast after": pa.fast_n_m}
        extra = [sp.band[1]] if sp.band is not None else []
        extra += [sp.band_before[1]] if sp.band_before is not None else []
        top = max(float(np.max(np.concatenate([*curves.values(), *extra]))),
                  b.catch_threshold_n_m, MIN_TORQUE_SPAN_N_M)
        panel = Panel.at(scene, (x0, y0, pw, ph), (float(deg.min()), float(deg.max())),
                         (0.0, top * 1.08))
        name = b.name
        hit = [g for g in b.stretched if g in treated]
        panel.frame("", "joint angle (°)", "resisting torque (N·m)",
                    xticks=nice_ticks(float(deg.min()), float(deg.max()), 6))
        title = f"{name[0].upper()}{name[1:]}: stretches {', '.join(b.stretched)}"
        scene.text(x0, y0 - 30, title, FONT_TITLE, bold=True)
        if hit:
            scene.text(x0 + text_width(title, FONT_TITLE) + 14, y0 - 30,
                       f"treated: {', '.join(hit)}", FONT_TITLE, colour=AFTER, bold=True)
        scene.text(x0, y0 - 11,
                   f"fast peak {b.peak_torque_n_m:.2f} → {a.peak_torque_n_m:.2f} N·m "
                   f"({pct(b.peak_torque_n_m, a.peak_torque_n_m)}), slow "
                   f"{b.slow_torque_n_m:.2f} → {a.slow_torque_n_m:.2f} N·m, R1 "
                   f"{_angle(b.catch_angle_deg)} → {_angle(a.catch_angle_deg)}", FONT_SMALL)
        if sp.band_before is not None:
            panel.band(deg, *sp.band_before, BEFORE, 0.15,
                       data={"stretch": name, "band": "fast before"})
            any_band = True
        if sp.band is not None:
            panel.band(deg, *sp.band, AFTER, 0.2, data={"stretch": name, "band": "fast after"})
            any_band = True
        panel.hline(b.catch_threshold_n_m, GREY, 1.0, (2, 3))
        scene.text(x0 + pw - 4, float(panel.ty(b.catch_threshold_n_m)) - 4, "catch threshold",
                   FONT_SMALL, "end", colour=GREY)
        # before wide and light under after: where the plan changes nothing both show
        for label, colour, width, dash, opacity in (
                ("slow before", BEFORE, 3.2, (7, 4), 0.45),
                ("fast before", BEFORE, 4.6, None, 0.45),
                ("slow after", AFTER, 1.5, (7, 4), 1.0), ("fast after", AFTER, 2.0, None, 1.0)):
            panel.line(deg, curves[label], colour, width, dash, opacity=opacity,
                       data={"stretch": name, "curve": label})
        for js, colour in ((b, BEFORE), (a, AFTER)):
            if js.catch_angle_deg is not None:
                panel.markers([js.catch_angle_deg], [js.catch_threshold_n_m], "triangle",
                              colour, 6.0, {"stretch": name, "mark": "R1"})
            if js.slow_stop_angle_deg is not None:
                panel.markers([js.slow_stop_angle_deg], [js.catch_threshold_n_m], "square",
                              colour, 6.0, {"stretch": name, "mark": "R2"})
        travel = "travel →" if deg[-1] > deg[0] else "← travel"
        scene.text(x0 + (pw - 6 if deg[-1] > deg[0] else 6), y0 + ph - 8, travel, FONT_SMALL,
                   "end" if deg[-1] > deg[0] else "start", colour=GREY)
    entries: list[tuple[str, dict[str, object]]] = [
        (f"fast {pairs[0].before.speed_deg_s:.0f}°/s before",
         {"stroke": BEFORE, "width": 4.6, "opacity": 0.45}),
        ("fast after", {"stroke": AFTER, "width": 2.0}),
        (f"slow {pairs[0].before.slow_speed_deg_s:.0f}°/s before",
         {"stroke": BEFORE, "width": 3.2, "dash": (7, 4), "opacity": 0.45}),
        ("slow after", {"stroke": AFTER, "width": 1.5, "dash": (7, 4)}),
        ("R1 catch (fast)", {"marker": "triangle"}), ("R2 stop (slow)", {"marker": "square"}),
    ]
    if any_band:
        entries.append(("95% interval (fit samples)", {"fill": "#f3c7a8"}))
    scene.legend(left, scene.height - legend_h + 14, entries, max_width=WIDTH - left - 10)
    return scene


def direction_label(v: FloatArray) -> str:
    """A hand direction in words and degrees from +x (counter-clockwise)."""
    deg = math.degrees(math.atan2(float(v[1]), float(v[0]))) % 360.0
    names = ("right", "forward-right", "forward", "forward-left", "left", "back-left",
             "toward the body", "back-right")
    return f"{names[int(((deg + 22.5) % 360) // 45)]} ({deg:.0f}° from +x)"


def moving_field_figure(arm_b: Arm, arm_a: Arm, grid_m: FloatArray, direction: FloatArray,
                        why: str, speed_m_per_s: float = MOVING_SPEED_M_PER_S) -> Scene:
    """The field with the hand moving at ``speed_m_per_s`` in ``direction`` (unit, shoulder
    frame): before, after, and the change (arrows over Δ|F| on a diverging map)."""
    v = np.tile(np.asarray(direction, dtype=float) * speed_m_per_s, (len(grid_m), 1))
    fb, fa = arm_b.endpoint_force(grid_m, v), arm_a.endpoint_force(grid_m, v)
    rest = arm_b.rest_position()
    h = fields.row_height(grid_m, rest)
    scene = Scene(WIDTH, h + 58, "moving field before, after and the change")
    scene.data["figure"] = "moving-field"
    scene.text(62, 16, f"Hand moving {speed_m_per_s:g} m/s {direction_label(direction)}: "
               f"{why}", FONT_TITLE, bold=True)
    info = fields.field_row(scene, 30, grid_m, fb, fa, "moving field", rest_m=rest,
                               data="moving-")
    scene.data["change-max-n"] = f"{info.diff_max_n:.6g}"
    _arrow_legend(scene, h + 40, "cells: change of |F| (N), blue weaker, red stronger")
    return scene


def static_field_figure(arm_b: Arm, arm_a: Arm, grid_m: FloatArray) -> Scene:
    """The static (postural, passive) field over the potential U before and after, and the
    change with ΔU on a diverging map."""
    fb, fa = arm_b.endpoint_force(grid_m), arm_a.endpoint_force(grid_m)
    rest = arm_b.rest_position()
    h = fields.row_height(grid_m, rest)
    scene = Scene(WIDTH, h + 58, "static field before, after and the change")
    scene.data["figure"] = "static-field"
    scene.text(62, 16, "Static (passive, position-dependent) field over the passive "
               "potential U", FONT_TITLE, bold=True)
    info = fields.field_row(scene, 30, grid_m, fb, fa, "static field",
                               potential_before_j=arm_b.potential(grid_m),
                               potential_after_j=arm_a.potential(grid_m), rest_m=rest,
                               data="static-")
    scene.data["change-max-n"] = f"{info.diff_max_n:.6g}"
    _arrow_legend(scene, h + 40, "cells: U (J); ΔU (J) blue lower, red higher")
    return scene


def _arrow_legend(scene: Scene, y: float, cells: str) -> None:
    scene.legend(62, y, [("before", {"stroke": BEFORE, "width": 2}),
                         ("after", {"stroke": AFTER, "width": 2}),
                         ("after − before", {"stroke": CHANGE, "width": 2}),
                         *fields.MARKER_LEGEND, (cells, {"fill": "#f4a582"})])


def ellipse_figure(arm_b: Arm, grid_m: FloatArray, k_before: FloatArray,
                   k_after: FloatArray) -> Scene:
    """Static stiffness ellipses before and after on one scale, and the ratio of the larger
    stiffness after / before."""
    rest = arm_b.rest_position()
    h = fields.row_height(grid_m, rest)
    scene = Scene(WIDTH, h + 58, "static endpoint stiffness before and after")
    scene.data["figure"] = "stiffness"
    scene.text(62, 16, "Static endpoint stiffness (symmetric part of K)", FONT_TITLE,
               bold=True)
    fields.ellipse_row(scene, 30, grid_m, k_before, k_after, "stiffness", rest)
    scene.legend(62, h + 40, [("before", {"stroke": BEFORE, "width": 1.5}),
                              ("after", {"stroke": AFTER, "width": 1.5}),
                              ("dashed: a negative eigenvalue",
                               {"stroke": TEXT, "dash": (3, 2)}), *fields.MARKER_LEGEND])
    return scene


def severity_figure(rows: Sequence[tuple[str, GroupSeverity, GroupSeverity]]) -> Scene:
    """Passive and dynamic grade per muscle group, before (ring) → after (dot), on the
    scale's levels; ``*`` marks a grade resting on an unidentified parameter."""
    label_w, pw, gap = 250.0, 330.0, 60.0
    row_h = 24.0
    top = 52.0
    ph = row_h * len(rows)
    scene = Scene(WIDTH, top + ph + 92, "severity per muscle group before and after")
    scene.data["figure"] = "severity"
    scene.text(10, 18, "Severity per muscle group: passive (position-dependent: contracture) "
               "and dynamic (velocity-dependent: spasticity)", FONT_TITLE, bold=True)
    levels = list(LEVELS)
    flagged = False
    for k, comp in enumerate(("passive", "dynamic")):
        x0 = label_w + k * (pw + gap)
        panel = Panel.at(scene, (x0, top, pw, ph), (-0.3, 4.6), (0.0, len(rows)))
        ticks = list(range(len(levels)))
        panel.frame("", "", "", xticks=[float(t) for t in ticks],
                    xtick_labels=[lv.replace("very mild", "v. mild") for lv in levels],
                    yticks=[], grid=False)
        scene.text(x0, top - 8, f"{comp} grade", FONT, bold=True)
        for t in ticks:
            panel.vline(float(t), "#e6e6e6", 1.0, None)
        marks_b: list[tuple[float, float]] = []
        marks_a: list[tuple[float, float]] = []
        for i, (g, sb, sa) in enumerate(rows):
            y = len(rows) - i - 0.5
            cb, ca = sb.component(comp), sa.component(comp)
            xb, xa = min(cb.score, 4.5), min(ca.score, 4.5)
            if abs(xa - xb) > 0.02:
                panel.line([xb, xa], [y, y], GREY, 2.0)
            marks_b.append((xb, y))
            marks_a.append((xa, y))
            scene.data[f"{g}-{comp}"] = f"{cb.score:.3f} {ca.score:.3f}"
            flagged = flagged or bool(cb.unidentified or ca.unidentified)
            if k == 0:
                star = "*" if (sb.passive.unidentified or sb.dynamic.unidentified) else ""
                scene.text(label_w - 12, float(panel.ty(y)),
                           f"{MUSCLE_GROUP_NAMES[g]} ({g}){star}", FONT, "end", "middle")
        if marks_b:
            xy_b, xy_a = np.array(marks_b), np.array(marks_a)
            panel.markers(xy_b[:, 0], xy_b[:, 1], "ring", BEFORE, 8.0)
            panel.markers(xy_a[:, 0], xy_a[:, 1], "circle", AFTER, 6.0)
    ynote = top + ph + 48
    scene.legend(label_w, ynote, [("before", {"marker": "ring", "colour": BEFORE}),
                                  ("after", {"marker": "circle", "colour": AFTER})])
    scene.text(label_w, ynote + 24, "Scores beyond severe are drawn at the right edge; "
               "grades and their parameters in the table below"
               + (" (* rests on a parameter the fit did not identify)." if flagged else "."),
               FONT_SMALL, colour=GREY)
    return scene


def probes_figure(rows: Sequence[tuple[str, ProbeProfile, ProbeProfile]]) -> Scene:
    """|force| along each probing motion over time, before and after, one force axis."""
    n = len(rows)
    block = WIDTH / max(n, 1)
    left, ph = 72.0, 150.0
    pw = block - left - 30
    scene = Scene(WIDTH, ph + 140, "force felt along the probing motions")
    scene.data["figure"] = "probes"
    mags = [(np.hypot(*b.force_n.T), np.hypot(*a.force_n.T)) for _, b, a in rows]
    _, hi = limits(*[m for pair in mags for m in pair], include_zero=True,
                   floor_span=MIN_FORCE_SPAN_N)
    for k, ((name, b, a), (mb, ma)) in enumerate(zip(rows, mags, strict=True)):
        x0 = k * block + left
        t = b.motion.times_s
        panel = Panel.at(scene, (x0, 58, pw, ph), (float(t[0]), float(t[-1])), (0.0, hi))
        panel.frame("", "time (s)", "|force| (N)")
        scene.text(x0, 24, f"Probing {name}: peak {b.peak_force_n:.2f} → "
                   f"{a.peak_force_n:.2f} N ({pct(b.peak_force_n, a.peak_force_n)})",
                   FONT_TITLE, bold=True)
        scene.text(x0, 44, b.motion.description, FONT_SMALL)
        panel.line(t, mb, BEFORE, 2.0, data={"probe": name, "curve": "before"})
        panel.line(t, ma, AFTER, 2.0, (6, 3), data={"probe": name, "curve": "after"})
    scene.legend(left, ph + 120, [("before", {"stroke": BEFORE, "width": 2}),
                                  ("after", {"stroke": AFTER, "width": 2, "dash": (6, 3)})])
    return scene


def timecourse_figure(weeks: FloatArray, plan_week: float, effect: Mapping[str, FloatArray],
                      fast_peak_n_m: Mapping[str, FloatArray], stretches: Sequence[str]
                      ) -> Scene:
    """Botulinum effect per injected group (%), and the fast-stretch peak torque of the
    stretches that lengthen the injected groups, week by week; the plan's week marked."""
    block = WIDTH / 2
    left, ph = 76.0, 160.0
    pw = block - left - 40
    scene = Scene(WIDTH, ph + 140, "botulinum time course")
    scene.data["figure"] = "timecourse"
    w = np.asarray(weeks, dtype=float)
    p1 = Panel.at(scene, (left, 50, pw, ph), (float(w[0]), float(w[-1])), (0.0, 100.0))
    p1.frame("", "weeks since the most recent injection", "drop of α (%)")
    scene.text(left, 24, "Botulinum effect per injected group", FONT_TITLE, bold=True)
    entries: list[tuple[str, dict[str, object]]] = []
    for i, (g, e) in enumerate(effect.items()):
        colour = SERIES[(i + 2) % len(SERIES)]
        p1.line(w, 100.0 * np.asarray(e), colour, 2.0, data={"group": g})
        entries.append((f"effect {g}", {"stroke": colour, "width": 2}))
    p1.vline(plan_week, TEXT, 1.0, (3, 3))
    series = {n: np.asarray(fast_peak_n_m[n]) for n in stretches}
    _, hi = limits(*series.values(), include_zero=True, floor_span=MIN_TORQUE_SPAN_N_M)
    p2 = Panel.at(scene, (block + left, 50, pw, ph), (float(w[0]), float(w[-1])), (0.0, hi))
    p2.frame("", "weeks since the most recent injection", "fast-stretch torque (N·m)")
    scene.text(block + left, 24, "Fast-stretch peak torque of the treated stretches",
               FONT_TITLE, bold=True)
    for i, (n, y) in enumerate(series.items()):
        colour = SERIES[(i + 4) % len(SERIES)]
        p2.line(w, y, colour, 2.0, data={"stretch": n})
        entries.append((n, {"stroke": colour, "width": 2}))
    p2.vline(plan_week, TEXT, 1.0, (3, 3))
    entries.append((f"the plan's week ({plan_week:g})", {"stroke": TEXT, "dash": (3, 3)}))
    scene.legend(left, ph + 120, entries, max_width=WIDTH - left)
    return scene


# --- cohort -------------------------------------------------------------------------------
@dataclass(frozen=True)
class CohortPoint:
    """One treated group of one case: the change of its graded stretch, %."""

    label: str  # "botulinum · ef"
    case: str  # patient and plan, for the tooltip
    fast_pct: float
    slow_pct: float


def cohort_change_figure(points: Sequence[CohortPoint]) -> Scene:
    """Per intervention kind and treated muscle group: the change of the peak torque
    resisting the fast stretch (velocity-dependent) and the slow stretch (position-
    dependent) of the stretch the group is graded on, one dot per case, median marked."""
    labels = sorted({p.label for p in points})
    row_h = 26.0
    label_w, pw, gap = 210.0, 360.0, 60.0
    ph = row_h * max(len(labels), 1)
    scene = Scene(WIDTH, ph + 104, "change per intervention kind and muscle group")
    scene.data["figure"] = "cohort-change"
    scene.text(10, 20, "Change per intervention kind and treated muscle group (one dot per "
               "case; bar: median)", FONT_TITLE, bold=True)
    for k, (attr, title) in enumerate((("fast_pct", "change of the fast-stretch peak (%)"),
                                       ("slow_pct", "change of the slow-stretch peak (%)"))):
        vals = [getattr(p, attr) for p in points]
        lo, hi = limits(vals, [0.0], floor_span=20.0)
        x0 = label_w + k * (pw + gap)
        panel = Panel.at(scene, (x0, 56, pw, ph), (lo, hi), (0.0, float(len(labels))))
        panel.frame("", title, "", yticks=[], grid=False)
        panel.vline(0.0, GREY, 1.0, None)
        scene.text(x0, 46, "velocity-dependent (spasticity)" if k == 0 else
                   "position-dependent (contracture)", FONT, bold=True)
        for i, lab in enumerate(labels):
            y = len(labels) - i - 0.5
            mine = [p for p in points if p.label == lab]
            if k == 0:
                scene.text(label_w - 12, float(panel.ty(y)), f"{lab} (n={len(mine)})", FONT,
                           "end", "middle")
            ys = y + (np.arange(len(mine)) - (len(mine) - 1) / 2) * min(0.5 / max(len(mine), 1),
                                                                         0.12)
            for p, yy in zip(mine, ys, strict=True):
                panel.markers([getattr(p, attr)], [yy], "circle", AFTER, 4.0,
                              {"case": p.case, "group": lab,
                               "value": f"{getattr(p, attr):.4g}"})
            med = float(np.median([getattr(p, attr) for p in mine]))
            px = float(panel.tx(med))
            py = float(panel.ty(y))
            scene.line([[px, py - 10], [px, py + 10]], TEXT, 2.5)
    return scene


@dataclass(frozen=True)
class CheckPoint:
    """One map measured after a plan: RMS of the predicted and of the measured change (N or
    N/m), the realised fraction f (measured along predicted) with its SE, and the verdict of
    the map against the prediction."""

    case: str
    label: str
    unit: str
    predicted_rms: float
    measured_rms: float
    fraction: float | None
    fraction_se: float | None
    verdict: str


def check_points(v: PlanValidation, case: str) -> list[CheckPoint]:
    """The maps of every later session of a checked plan."""
    out = []
    for s in v.sessions:
        for m in s.maps:
            moving = "moving" if any(m.velocity_m_per_s) else "static"
            out.append(CheckPoint(case, f"{case}: {s.session} map {m.map_id} ({m.kind}, "
                                  f"{moving})", m.unit, m.predicted_change_rms,
                                  m.measured_change_rms, m.realised_fraction, m.realised_se,
                                  m.prediction.verdict))
    return out


def validation_figure(points: Sequence[CheckPoint], title: str,
                      tolerance: float = CHANGE_TOLERANCE) -> Scene:
    """Measured against predicted change per map (RMS over the map's values) on the identity
    line, one panel per unit (N: postural maps, N/m: stiffness maps), and the realised
    fraction per map (measured change along the predicted one, ±1 SE) against the tolerance
    of :mod:`fieldbank.interventions.validate`."""
    units = sorted({p.unit for p in points})
    npanel = len(units) + 1
    block = WIDTH / npanel
    left, ps = 78.0, min(230.0, block - 110.0)
    scene = Scene(WIDTH, ps + 150, title)
    scene.data["figure"] = "validation"
    scene.text(10, 20, title, FONT_TITLE, bold=True)
    colour_of = {"good": ACCENT_OK, "poor": AFTER}
    for k, unit in enumerate(units):
        mine = [p for p in points if p.unit == unit]
        top = 1.1 * max([p.predicted_rms for p in mine] + [p.measured_rms for p in mine]
                        + [1e-9])
        x0 = k * block + left
        panel = Panel.at(scene, (x0, 50, ps, ps), (0.0, top), (0.0, top))
        panel.frame("", f"predicted change, RMS ({unit})", f"measured change, RMS ({unit})")
        panel.line([0, top], [0, top], GREY, 1.0, (4, 3))
        for verdict in sorted({p.verdict for p in mine}):
            sel = [p for p in mine if p.verdict == verdict]
            panel.markers([p.predicted_rms for p in sel], [p.measured_rms for p in sel],
                          "circle", colour_of.get(verdict, TEXT), 5.0,
                          {"verdict": verdict, "unit": unit, "maps": str(len(sel))})
    frac = [p for p in points if p.fraction is not None]
    x0 = len(units) * block + left + 40
    pw = block - left - 60
    if frac:
        vals = [p.fraction for p in frac if p.fraction is not None]
        ses = [p.fraction_se or 0.0 for p in frac]
        lo, hi = limits(vals, [v - e for v, e in zip(vals, ses, strict=True)],
                        [v + e for v, e in zip(vals, ses, strict=True)],
                        [1.0 - tolerance, 1.0 + tolerance, 0.0])
        panel = Panel.at(scene, (x0, 50, pw, ps), (lo, hi), (0.0, float(len(frac))))
        panel.frame("", "measured ÷ predicted change", "", yticks=[], grid=False)
        panel.band([1.0 - tolerance, 1.0 + tolerance], [0.0, 0.0],
                   [float(len(frac))] * 2, ACCENT_OK, 0.12)
        panel.vline(1.0, ACCENT_OK, 1.0, None)
        panel.vline(0.0, GREY, 1.0, (4, 3))
        for i, p in enumerate(frac):
            y = len(frac) - i - 0.5
            f, e = float(p.fraction or 0.0), float(p.fraction_se or 0.0)
            colour = colour_of.get(p.verdict, TEXT)
            panel.line([f - e, f + e], [y, y], colour, 1.5)
            panel.markers([f], [y], "circle", colour, 4.5, {"map": p.label})
        scene.text(x0, 42, "realised fraction per map (±1 SE)", FONT_SMALL, bold=True)
    scene.legend(left, ps + 128, [
        ("map agrees with the prediction", {"marker": "circle", "colour": ACCENT_OK}),
        ("map poor against the prediction", {"marker": "circle", "colour": AFTER}),
        ("identity (measured = predicted)", {"stroke": GREY, "dash": (4, 3)}),
        (f"tolerance 1 ± {tolerance:g}", {"fill": "#d4eee6"})])
    return scene


# --- one case: the figures, in order ---------------------------------------------------------
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
                         bands.get("after", {}).get(n), bands.get("before", {}).get(n))
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
