"""Figures of a batch and of predictions checked later: :func:`cohort_change_figure` (the
change per intervention kind and treated group across cases) and :func:`validation_figure`
(predicted against measured change, for one case or across patients)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fieldbank.figures.panel import Panel
from fieldbank.figures.scene import Scene
from fieldbank.figures.style import (
    AFTER,
    FONT,
    FONT_SMALL,
    FONT_TITLE,
    GREY,
    TEXT,
    limits,
    text_width,
)
from fieldbank.interventions.report.figures.common import ACCENT_OK, WIDTH
from fieldbank.interventions.validate import PlanValidation
from fieldbank.interventions.whatifchoices import CHANGE_TOLERANCE


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
    counts = {lab: sum(p.label == lab for p in points) for lab in labels}
    # the row labels' column as wide as its longest label: none is cut at the figure's edge
    label_w = max([text_width(f"{lab} (n={counts[lab]})", FONT) for lab in labels]
                  + [120.0]) + 24.0
    gap = 60.0
    pw = min(360.0, (WIDTH - label_w - gap - 20.0) / 2)
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


#: How a map measured after a plan stands against the prediction, as the figures mark it
#: (marker, colour): it saw the predicted change and agrees; it agrees only because the change
#: predicted for it is within its noise (it could not have seen it); it disagrees.
AGREES, WITHIN_NOISE, DISAGREES = "agrees", "within noise", "poor"
MARKS = {AGREES: ("circle", ACCENT_OK), WITHIN_NOISE: ("ring", GREY),
         DISAGREES: ("triangle", AFTER)}


@dataclass(frozen=True)
class CheckPoint:
    """One map measured after a plan: RMS of the predicted and of the measured change (N or
    N/m), the realised fraction f (measured along predicted) with its SE, the verdict of the
    map against the prediction, and whether the predicted change moves the map beyond its
    noise (``seen``: by the check's minimum, 4 sd)."""

    case: str
    label: str
    unit: str
    predicted_rms: float
    measured_rms: float
    fraction: float | None
    fraction_se: float | None
    verdict: str
    seen: bool = True
    #: The row's name in a figure: 'SYN-001 plan 1 · post-BoNT map 12'.
    short: str = ""

    @property
    def standing(self) -> str:
        """:data:`AGREES`, :data:`WITHIN_NOISE` or :data:`DISAGREES`."""
        if self.verdict != "good":
            return DISAGREES
        return AGREES if self.seen else WITHIN_NOISE


def check_points(v: PlanValidation, case: str) -> list[CheckPoint]:
    """The maps of every later session of a checked plan."""
    out = []
    for s in v.sessions:
        for m in s.maps:
            moving = "moving" if any(m.velocity_m_per_s) else "static"
            out.append(CheckPoint(case, f"{case}: {s.session} map {m.map_id} ({m.kind}, "
                                  f"{moving})", m.unit, m.predicted_change_rms,
                                  m.measured_change_rms, m.realised_fraction, m.realised_se,
                                  m.prediction.verdict,
                                  m.sensitivity_sd >= s.rules.min_sensitivity,
                                  f"{case} · {s.session} map {m.map_id}"))
    return out


def validation_figure(points: Sequence[CheckPoint], title: str,
                      tolerance: float = CHANGE_TOLERANCE) -> Scene:
    """Measured against predicted change per map (RMS over the map's values) on the identity
    line, one panel per unit (N: postural maps, N/m: stiffness maps), and the realised
    fraction per map (measured change along the predicted one, ±1 SE) against the tolerance
    of :mod:`fieldbank.interventions.validate`."""
    units = sorted({p.unit for p in points})
    frac = [p for p in points if p.fraction is not None]
    names = [p.short or p.label for p in frac]
    label_w = max([text_width(n, FONT_SMALL) for n in names] + [0.0]) + 10.0
    frac_w = 250.0 + label_w if frac else 0.0
    block = (WIDTH - frac_w) / max(len(units), 1)
    left, ps = 78.0, min(230.0, block - 110.0)
    scene = Scene(WIDTH, ps + 170, title)  # room for a legend of two rows
    scene.data["figure"] = "validation"
    scene.text(10, 20, title, FONT_TITLE, bold=True)
    for k, unit in enumerate(units):
        mine = [p for p in points if p.unit == unit]
        top = 1.1 * max([p.predicted_rms for p in mine] + [p.measured_rms for p in mine]
                        + [1e-9])
        x0 = k * block + left
        panel = Panel.at(scene, (x0, 50, ps, ps), (0.0, top), (0.0, top))
        panel.frame("", f"predicted change, RMS ({unit})", f"measured change, RMS ({unit})")
        panel.line([0, top], [0, top], GREY, 1.0, (4, 3))
        for standing, (marker, colour) in MARKS.items():
            sel = [p for p in mine if p.standing == standing]
            if sel:
                panel.markers([p.predicted_rms for p in sel], [p.measured_rms for p in sel],
                              marker, colour, 5.0,
                              {"standing": standing, "verdict": sel[0].verdict, "unit": unit,
                               "maps": str(len(sel))})
    x0 = len(units) * block + label_w + 20
    pw = WIDTH - x0 - 20
    if frac:
        vals = [p.fraction for p in frac if p.fraction is not None]
        ses = [p.fraction_se or 0.0 for p in frac]
        lo, hi = limits(vals, [v - e for v, e in zip(vals, ses, strict=True)],
                        [v + e for v, e in zip(vals, ses, strict=True)],
                        [1.0 - tolerance, 1.0 + tolerance, 0.0])
        panel = Panel.at(scene, (x0, 50, pw, ps), (lo, hi), (0.0, float(len(frac))))
        panel.frame("", "measured ÷ predicted change", "", yticks=[], grid=False)
        # what the axis's two marks mean, on a line of its own: the panel is narrow
        scene.text(x0 + pw / 2, 50 + ps + 42, "1: as predicted · 0: no change", FONT_SMALL,
                   "middle", "hanging", colour=GREY)
        panel.band([1.0 - tolerance, 1.0 + tolerance], [0.0, 0.0],
                   [float(len(frac))] * 2, ACCENT_OK, 0.12)
        panel.vline(1.0, ACCENT_OK, 1.0, None)
        panel.vline(0.0, GREY, 1.0, (4, 3))
        for i, (p, name) in enumerate(zip(frac, names, strict=True)):
            y = len(frac) - i - 0.5
            f, e = float(p.fraction or 0.0), float(p.fraction_se or 0.0)
            marker, colour = MARKS[p.standing]
            panel.line([f - e, f + e], [y, y], colour, 1.5)
            panel.markers([f], [y], marker, colour, 4.5, {"map": p.label})
            scene.text(x0 - 6, float(panel.ty(y)), name, FONT_SMALL, "end", "middle")
        scene.text(x0 - label_w, 42, "realised fraction per map (±1 SE)", FONT_SMALL,
                   bold=True)
    scene.legend(left, ps + 128, [
        ("map saw the predicted change and agrees", {"marker": "circle", "colour": ACCENT_OK}),
        ("agrees within noise: the change predicted for it is too small to see",
         {"marker": "ring", "colour": GREY}),
        ("map disagrees with the prediction", {"marker": "triangle", "colour": AFTER}),
        ("identity (measured = predicted)", {"stroke": GREY, "dash": (4, 3)}),
        (f"tolerance 1 ± {tolerance:g}", {"fill": "#d4eee6"})], max_width=WIDTH - left - 10)
    return scene
