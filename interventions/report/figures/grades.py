"""The grades and the force felt along the seed's probes, before and after:
:func:`severity_figure` (passive and dynamic grade per muscle group on the scale's levels) and
:func:`probes_figure` (force along the seed's probing motions, one force axis)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fieldbank.evaluate.probing import ProbeProfile
from fieldbank.evaluate.severity import LEVELS, MUSCLE_GROUP_NAMES, GroupSeverity
from fieldbank.figures.panel import Panel
from fieldbank.figures.scene import Scene
from fieldbank.figures.style import (
    AFTER,
    BEFORE,
    FONT,
    FONT_SMALL,
    FONT_TITLE,
    GREY,
    limits,
)
from fieldbank.interventions.report.figures.common import WIDTH, pct

#: Force axes never span less than this, N.
MIN_FORCE_SPAN_N = 1.0

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
