"""The clinic's joint stretches (Tardieu-style), before and after: :func:`stretch_figure`
(torque resisting the slow and the fast stretch over the joint angle, catches marked, the
treated groups' stretches named, the 95% band of the fast stretch after where the what-if has
intervals), and the botulinum time course week by week (:func:`timecourse_figure`)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from fieldbank.evaluate.probing import (
    JointStretch,
    StretchProfile,
)
from fieldbank.figures.panel import Panel
from fieldbank.figures.scene import Scene
from fieldbank.figures.style import (
    AFTER,
    BEFORE,
    FONT_SMALL,
    FONT_TITLE,
    GREY,
    SERIES,
    TEXT,
    limits,
    nice_ticks,
    text_width,
)
from fieldbank.interventions.report.figures.common import WIDTH, angle_text, pct
from fieldbank.model import FloatArray

#: Torque axes never span less than this (a flat line is not blown up to noise), N·m.
MIN_TORQUE_SPAN_N_M = 1.0

#: A band wider than what the maps identified by this factor rests on a guess (as
#: :data:`fieldbank.interventions.guesses.GUESS_WIDENING` for an interval).
GUESS_WIDENING = 1.25
#: A band resting on a guess that reaches beyond this multiple of the rest of a panel is
#: cut at the panel's top (and its top said in words) instead of squashing the curves.
GUESS_AXIS_FACTOR = 1.5

Band = tuple[FloatArray, FloatArray]


@dataclass(frozen=True)
class StretchPair:
    """One joint stretch before and after: read-outs and profiles; ``band``: 95% interval
    (low, high) of the fast-stretch torque after, N·m, per sample of the profile, if any;
    ``band_identified``: the same of what the maps identified (the guessed parameters at
    their held value), given where the fit guessed parameters."""

    before: JointStretch
    after: JointStretch
    profile_before: StretchProfile
    profile_after: StretchProfile
    band: Band | None = None
    band_before: Band | None = None
    band_identified: Band | None = None
    band_before_identified: Band | None = None


def _split(drawn: Band | None, identified: Band | None) -> tuple[Band | None, Band | None]:
    """(the band of what the maps identified, the band with the guesses drawn when it is
    wider than that: it rests on a guess)."""
    if identified is None:
        return drawn, None
    if drawn is None:
        return identified, None
    wide = float(np.max(drawn[1] - drawn[0]))
    if wide > GUESS_WIDENING * float(np.max(identified[1] - identified[0])) + 1e-9:
        return identified, drawn
    return identified, None


def stretch_figure(pairs: Sequence[StretchPair], treated: Sequence[str] = ()) -> Scene:
    """Torque resisting the slow and the fast stretch over the joint angle, per joint and
    direction (2 × 2 panels), before and after; catches marked; treated stretches named."""
    ncol = 2
    block_w = WIDTH / ncol
    left, pw, ph, head, foot = 84.0, block_w - 84.0 - 36.0, 170.0, 64.0, 52.0
    nrow = math.ceil(len(pairs) / ncol)
    legend_h = 48.0
    scene = Scene(WIDTH, nrow * (head + ph + foot) + legend_h,
                  "joint stretches: resisting torque over the joint angle, before and after")
    scene.data["figure"] = "stretches"
    any_band = any_guess = False
    for k, sp in enumerate(pairs):
        b, a, pb, pa = sp.before, sp.after, sp.profile_before, sp.profile_after
        col, row = k % ncol, k // ncol
        x0, y0 = col * block_w + left, row * (head + ph + foot) + head
        deg = np.degrees(pb.angles_rad)
        curves = {"slow before": pb.slow_n_m, "slow after": pa.slow_n_m,
                  "fast before": pb.fast_n_m, "fast after": pa.fast_n_m}
        after_id, after_guess = _split(sp.band, sp.band_identified)
        before_id, before_guess = _split(sp.band_before, sp.band_before_identified)
        extra = [bd[1] for bd in (after_id, before_id) if bd is not None]
        top = max(float(np.max(np.concatenate([*curves.values(), *extra]))),
                  b.catch_threshold_n_m, MIN_TORQUE_SPAN_N_M)
        guess_top = max([float(np.max(g[1])) for g in (after_guess, before_guess)
                         if g is not None] + [0.0])
        cut = guess_top > GUESS_AXIS_FACTOR * top
        if not cut:
            top = max(top, guess_top)
        panel = Panel.at(scene, (x0, y0, pw, ph), (float(deg.min()), float(deg.max())),
                         (0.0, top * 1.08))
        name = b.name
        hit = [g for g in b.stretched if g in treated]
        panel.frame("", "joint angle (°)", "resisting torque (N·m)",
                    xticks=nice_ticks(float(deg.min()), float(deg.max()), 6))
        guessed = after_guess is not None or before_guess is not None
        title = (f"{name[0].upper()}{name[1:]}: stretches {', '.join(b.stretched)}"
                 + (" *" if guessed else ""))
        scene.text(x0, y0 - 44, title, FONT_TITLE, bold=True)
        if hit:
            scene.text(x0 + text_width(title, FONT_TITLE) + 14, y0 - 44,
                       f"treated: {', '.join(hit)}", FONT_TITLE, colour=AFTER, bold=True)
        scene.text(x0, y0 - 25,
                   f"fast peak {b.peak_torque_n_m:.2f} → {a.peak_torque_n_m:.2f} N·m "
                   f"({pct(b.peak_torque_n_m, a.peak_torque_n_m)}), slow "
                   f"{b.slow_torque_n_m:.2f} → {a.slow_torque_n_m:.2f} N·m, R1 "
                   f"{angle_text(b.catch_angle_deg)} → {angle_text(a.catch_angle_deg)}", FONT_SMALL)
        # the band of what the maps identified filled; the band resting on a guess apart, its
        # edges dotted and nothing filled, cut at the panel's top when it would dwarf the rest
        for ident, guess, colour, opacity, when in (
                (before_id, before_guess, BEFORE, 0.15, "before"),
                (after_id, after_guess, AFTER, 0.2, "after")):
            if ident is not None:
                panel.band(deg, *ident, colour, opacity,
                           data={"stretch": name, "band": f"fast {when}"})
                any_band = True
            if guess is not None:
                for edge in guess:
                    panel.line(deg, edge, colour, 1.2, (1.5, 2.5), opacity=0.8,
                               data={"stretch": name, "band": f"fast {when}, with guesses"})
                any_guess = True
        if cut:
            scene.text(x0, y0 - 8, f"* with the guesses drawn the band reaches "
                       f"{guess_top:.1f} N·m, above the axis", FONT_SMALL, colour=GREY)
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
        entries.append(("95% interval of what the maps identified", {"fill": "#f3c7a8"}))
    if any_guess:
        entries.append(("* 95% interval with the guessed parameters drawn from their range",
                        {"stroke": AFTER, "width": 1.2, "dash": (1.5, 2.5)}))
    scene.legend(left, scene.height - legend_h + 14, entries, max_width=WIDTH - left - 10)
    return scene

def _layered(i: int, n: int) -> tuple[float, float, tuple[float, ...] | None]:
    """(width, opacity, dash) of the ``i``-th of ``n`` curves of a panel whose curves may
    coincide (two groups given the same dose): the first wide and light under the next,
    narrower and dashed, so each stays visible where they lie on one another; a lone curve
    plain."""
    if n == 1:
        return 2.0, 1.0, None
    widths = (5.0, 2.6, 1.6, 1.2)
    dashes: tuple[tuple[float, ...], ...] = ((6.0, 3.0), (2.0, 2.0), (8.0, 2.0, 2.0, 2.0))
    return (widths[min(i, len(widths) - 1)], 0.45 if i == 0 else 1.0,
            None if i == 0 else dashes[(i - 1) % 3])


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
        width, opacity, dash = _layered(i, len(effect))
        p1.line(w, 100.0 * np.asarray(e), colour, width, dash, opacity, data={"group": g})
        entries.append((f"effect {g}", {"stroke": colour, "width": width, "dash": dash,
                                        "opacity": opacity}))
    p1.vline(plan_week, TEXT, 1.0, (3, 3))
    series = {n: np.asarray(fast_peak_n_m[n]) for n in stretches}
    _, hi = limits(*series.values(), include_zero=True, floor_span=MIN_TORQUE_SPAN_N_M)
    p2 = Panel.at(scene, (block + left, 50, pw, ph), (float(w[0]), float(w[-1])), (0.0, hi))
    p2.frame("", "weeks since the most recent injection", "fast-stretch torque (N·m)")
    scene.text(block + left, 24, "Fast-stretch peak torque of the treated stretches",
               FONT_TITLE, bold=True)
    for i, (n, y) in enumerate(series.items()):
        colour = SERIES[(i + 4) % len(SERIES)]
        width, opacity, dash = _layered(i, len(series))
        p2.line(w, y, colour, width, dash, opacity, data={"stretch": n})
        entries.append((n, {"stroke": colour, "width": width, "dash": dash,
                            "opacity": opacity}))
    p2.vline(plan_week, TEXT, 1.0, (3, 3))
    entries.append((f"the plan's week ({plan_week:g})", {"stroke": TEXT, "dash": (3, 3)}))
    scene.legend(left, ph + 120, entries, max_width=WIDTH - left)
    return scene
