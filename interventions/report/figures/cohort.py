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
