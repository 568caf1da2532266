"""Figures of probing motions (``fieldbank probe design|paths --plot``) and of a classification
(``fieldbank probe classify --plot``).

:func:`probe_figure`: one column per probe - the path in the shoulder frame over the arm at
rest, with the force each candidate puts on the handle along it (one arrow scale for every
path, with its key), then the force magnitude and the force direction over time.
:func:`classification_figure`: per recorded probe the recorded force against the most probable
candidates' predictions, and the posterior of every candidate and of every group.

Candidates keep one colour per impaired group (shoulder, elbow, bi-articular, unimpaired) and
one line per severity (:data:`fieldbank.figures.style.GROUP_COLOURS`, ``LEVEL_STROKES``) in
every panel and figure, so a clinician reads "which group" by colour and "how severe" by the
line. The shoulder is marked as in every field figure.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence
from typing import Any

import numpy as np

from fieldbank.evaluate.classify import Classification
from fieldbank.evaluate.design import Candidate, ProbeSetScore
from fieldbank.figures.fields import arrow_key, arrows, round_value
from fieldbank.figures.panel import Panel
from fieldbank.figures.scene import Scene
from fieldbank.figures.style import (
    FONT,
    FONT_SMALL,
    FONT_TITLE,
    GREY,
    GROUP_COLOURS,
    LEVEL_STROKES,
    LIGHT,
    MODEL,
    OTHER_COLOURS,
    TEXT,
    limits,
    nice_ticks,
    text_width,
)
from fieldbank.model import Arm, FloatArray

#: Arrows drawn along each path per candidate.
ARROWS_PER_PATH = 7
#: Plotting-area width of a column, px; left margin and gap between columns, px.
COLUMN_PX, LEFT_PX, GAP_PX = 330.0, 84.0, 74.0
#: Heights of the force-over-time panels, px.
PROFILE_PX = 150.0
#: The largest force of any candidate on any path spans this fraction of a path panel's width.
ARROW_SPAN = 0.3

#: (colour, dash, width) of a candidate's lines.
Stroke = tuple[str, tuple[float, ...] | None, float]


def candidate_strokes(candidates: Sequence[Candidate]) -> list[Stroke]:
    """One colour per impaired group, one line per severity; other candidates take the
    further colours of the palette in turn."""
    out = []
    others = iter(OTHER_COLOURS * (len(candidates) // len(OTHER_COLOURS) + 1))
    for c in candidates:
        colour = GROUP_COLOURS.get(c.group or "") or (GROUP_COLOURS["unimpaired"]
                                                       if c.level == "unimpaired"
                                                       else next(others))
        dash, width = LEVEL_STROKES.get(c.level or "", (None, 2.0))
        out.append((colour, dash, width))
    return out


def arm_points(arm: Arm, q: Sequence[float] | None = None) -> FloatArray:
    """Shoulder, elbow and hand at posture q (default: rest), m, shoulder frame."""
    qq = np.asarray(arm.q_rest if q is None else q, dtype=float)
    elbow = np.array([arm.l1 * math.cos(qq[0]), arm.l1 * math.sin(qq[0])])
    if arm.mirror:
        elbow[0] = -elbow[0]
    return np.vstack([[0.0, 0.0], elbow, arm.fk(qq)[0]])


def draw_arm(panel: Panel, arm: Arm, q: Sequence[float] | None = None,
             width: float = 7.0) -> None:
    """The upper arm and forearm at posture q (default: rest) in light grey, the shoulder
    (marked as in every figure) and the elbow where they are in view."""
    pts = arm_points(arm, q)
    panel.line(pts[:, 0], pts[:, 1], LIGHT, width, data={"kind": "arm"})
    for (x, y), marker, colour, size in ((pts[1], "circle", "#bdbdbd", 0.7 * width),
                                         (pts[0], "shoulder", TEXT, 5.0)):
        if panel.x0 <= x <= panel.x1 and panel.y0 <= y <= panel.y1:
            panel.markers([x], [y], marker, colour, size)


def _segments(panel: Panel, x: FloatArray, y: FloatArray) -> list[FloatArray]:
    """The finite runs of a curve, in px (a gap where a value is NaN)."""
    ok = np.isfinite(x) & np.isfinite(y)
    edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(int), 0]))
    return [panel.pts(x[a:b], y[a:b]) for a, b in zip(edges[::2], edges[1::2], strict=True)
            if b - a >= 2]


def _curve(panel: Panel, x: FloatArray, y: FloatArray, stroke: Stroke,
           data: dict[str, str], opacity: float = 1.0) -> None:
    colour, dash, width = stroke
    panel.scene.lines(_segments(panel, np.asarray(x, float), np.asarray(y, float)), colour,
                      width, dash=dash, opacity=opacity, clip=panel.clip, data=data)


def directions_deg(force_n: FloatArray, floor_n: float) -> FloatArray:
    """Directions in degrees from +x, blank below ``floor_n`` and where they wrap round ±180°,
    so no line crosses the panel."""
    mag = np.hypot(force_n[:, 0], force_n[:, 1])
    ang = np.where(mag >= floor_n, np.degrees(np.arctan2(force_n[:, 1], force_n[:, 0])), np.nan)
    jump = np.r_[False, np.abs(np.diff(ang)) > 180.0]
    return np.where(jump, np.nan, ang)


def _profiles(scene: Scene, x: float, top: float, times: FloatArray, forces: FloatArray,
              strokes: Sequence[Stroke], names: Sequence[str], floor_n: float, probe: str,
              recorded: FloatArray | None = None, recorded_times: FloatArray | None = None,
              title: str = "") -> float:
    """Force magnitude and direction over time, two panels one above the other from ``top``;
    returns the y below them."""
    mags = [np.hypot(f[:, 0], f[:, 1]) for f in forces]
    rec_mag = None if recorded is None else np.hypot(recorded[:, 0], recorded[:, 1])
    t_all = [times] + ([] if recorded_times is None else [recorded_times])
    tlim = limits(*t_all, pad=0.0)
    mlim = limits(*mags, *([] if rec_mag is None else [rec_mag]), include_zero=True,
                  floor_span=1.0)
    mag = Panel.at(scene, (x, top, COLUMN_PX, PROFILE_PX), tlim, mlim)
    xt = nice_ticks(tlim[0], tlim[1], max(3, int(COLUMN_PX // 70)))
    mag.frame(title, "", "force magnitude (N)", xticks=xt, xtick_labels=[""] * len(xt),
              title_size=FONT)  # one time axis: labelled below the direction panel
    dirs = Panel.at(scene, (x, top + PROFILE_PX + 26.0, COLUMN_PX, PROFILE_PX), tlim,
                    (-180.0, 180.0))
    dirs.frame("", "time (s)", "direction (° from +x)", yticks=[-180, -90, 0, 90, 180])
    for f, m, stroke, name in zip(forces, mags, strokes, names, strict=True):
        tag = {"probe": probe, "candidate": name}
        _curve(mag, times, m, stroke, {**tag, "curve": "magnitude"})
        _curve(dirs, times, directions_deg(f, floor_n), stroke, {**tag, "curve": "direction"})
    if recorded is not None and recorded_times is not None and rec_mag is not None:
        rec: Stroke = (MODEL, None, 1.0)
        tag = {"probe": probe, "candidate": "recorded"}
        _curve(mag, recorded_times, rec_mag, rec, {**tag, "curve": "magnitude"}, 0.75)
        _curve(dirs, recorded_times, directions_deg(recorded, floor_n), rec,
               {**tag, "curve": "direction"}, 0.75)
    scene.text(x + COLUMN_PX, top + 2 * PROFILE_PX + 26.0 + 56.0,
               f"direction shown where the force is ≥ {floor_n:g} N", FONT_SMALL, "end",
               colour=GREY)
    return top + 2 * PROFILE_PX + 26.0 + 64.0


def _wrap(scene: Scene, x: float, y: float, text: str, width_px: float, size: float = FONT,
          bold: bool = False, colour: str = TEXT) -> float:
    """``text`` wrapped to ``width_px`` from (x, y) (first baseline); returns the y below."""
    chars = max(20, int(width_px / (0.58 * size)))
    for line in textwrap.wrap(text, chars):
        scene.text(x, y, line, size, bold=bold, colour=colour)
        y += size + 5.0
    return y


def _view(score: ProbeSetScore) -> tuple[FloatArray, float]:
    """Centre and half-width (m) of a square view around every probe's path."""
    pts = np.vstack([p.motion.positions_m for p in score.probes])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    half = max(0.06, 0.5 * float((hi - lo).max()) + 0.04)
    return 0.5 * (lo + hi), half


def probe_figure(score: ProbeSetScore, candidates: Sequence[Candidate],
                 title: str = "") -> Scene:
    """One column per probe: the path with each candidate's force along it (one arrow scale),
    the force magnitude and the force direction over time."""
    ncol = len(score.probes)
    strokes = candidate_strokes(candidates)
    s = score.summary()
    head = title or "probing motions"
    heading = (f"{head}: {s['information_bits']:.2f} of {s['information_max_bits']:.2f} bits "
               f"about the {score.target}; closest pair felt {s['worst_felt_jnd']:.1f} JND "
               "apart")
    width = LEFT_PX + ncol * COLUMN_PX + (ncol - 1) * GAP_PX + 30.0
    probe_names = [p.name for p in score.probes]
    desc_lines = max(len(textwrap.wrap(p.motion.description,
                                       int(COLUMN_PX / (0.58 * FONT_SMALL))))
                     for p in score.probes)
    title_lines = len(textwrap.wrap(heading, int((width - 20) / (0.58 * (FONT_TITLE + 1)))))
    path_top = 18.0 + title_lines * (FONT_TITLE + 6) + 30.0
    prof_top = path_top + COLUMN_PX + 90.0 + desc_lines * (FONT_SMALL + 5)
    legend_y = prof_top + 2 * PROFILE_PX + 26.0 + 92.0
    scene = Scene(width, legend_y + 60.0, heading)
    scene.data.update({"figure": "probes", "probes": "|".join(probe_names),
                       "candidates": "|".join(score.candidates), "target": score.target,
                       "information-bits": f"{s['information_bits']:.4f}",
                       "worst-felt-jnd": f"{s['worst_felt_jnd']:.4f}"})
    _wrap(scene, 10.0, 26.0, heading, width - 20, FONT_TITLE + 1, bold=True)
    centre, half = _view(score)
    peak = max(float(np.hypot(p.force_n[..., 0], p.force_n[..., 1]).max())
               for p in score.probes)
    for k, probe in enumerate(score.probes):
        x = LEFT_PX + k * (COLUMN_PX + GAP_PX)
        panel = Panel.at(scene, (x, path_top, COLUMN_PX, COLUMN_PX),
                         (centre[0] - half, centre[0] + half),
                         (centre[1] - half, centre[1] + half), equal=True)
        panel.frame(f"{probe.name}: path and force on the handle", "x (m, right)",
                    "y (m, forward)", grid=False, title_size=FONT)
        n_per_px = max(peak, 1e-6) / (ARROW_SPAN * COLUMN_PX)
        _path(panel, probe.name, probe.motion.positions_m, probe.force_n, score.candidates,
              candidates[0].arm, strokes, n_per_px)
        key_y = path_top + COLUMN_PX + 56.0
        arrow_key(scene, x, key_y, round_value(0.2 * COLUMN_PX * n_per_px), n_per_px, MODEL)
        _wrap(scene, x, key_y + 30.0, probe.motion.description, COLUMN_PX, FONT_SMALL,
              colour=TEXT)
        _profiles(scene, x, prof_top, probe.motion.times_s, probe.force_n, strokes,
                  score.candidates, score.perception.floor_n, probe.name)
    _legend(scene, legend_y, score.candidates, strokes,
            [("arm at rest", {"stroke": LIGHT, "width": 6.0}),
             ("shoulder", {"marker": "shoulder"}),
             ("the view (dashed, in the inset)", {"stroke": GREY, "dash": (3, 2)})])
    return scene


def _path(panel: Panel, name: str, pos: FloatArray, force_n: FloatArray,
          names: Sequence[str], arm: Arm, strokes: Sequence[Stroke], n_per_px: float) -> None:
    draw_arm(panel, arm)
    panel.line(pos[:, 0], pos[:, 1], TEXT, 1.8, data={"probe": name, "kind": "path"})
    panel.markers([pos[0, 0]], [pos[0, 1]], "circle", TEXT, 4.0)
    tip = panel.xy(pos[-1])[0]
    back = panel.xy(pos[max(0, len(pos) - 4)])[0]
    d = tip - back
    n = float(np.hypot(*d))
    if n > 0:  # an arrowhead at the end: the direction of travel
        u = d / n
        side = np.array([-u[1], u[0]])
        panel.scene.polygon(np.array([tip, tip - 9 * u + 4.5 * side, tip - 9 * u - 4.5 * side]),
                            TEXT)
    idx = np.linspace(len(pos) // 8, len(pos) - 1, ARROWS_PER_PATH).astype(int)
    for i, (colour, _dash, _w) in enumerate(strokes):
        arrows(panel, pos[idx], force_n[i, idx], n_per_px, colour, None, 1.7,
               data={"probe": name, "candidate": names[i]})
    _where(panel, arm, pos)


#: Side of the inset that shows where a path panel's view lies on the arm, px.
INSET_PX = 92.0


def _where(panel: Panel, arm: Arm, pos: FloatArray) -> None:
    """An inset in the corner of ``panel`` farthest from the path: the whole arm at rest,
    the shoulder, the path and the panel's view (dashed)."""
    corners = {(0, 0): (panel.x0, panel.y1), (1, 0): (panel.x1, panel.y1),
               (0, 1): (panel.x0, panel.y0), (1, 1): (panel.x1, panel.y0)}
    cx, cy = max(corners, key=lambda k: float(np.hypot(*(pos - corners[k]).T).min()))
    x = panel.x + 6 if cx == 0 else panel.x + panel.w - INSET_PX - 6
    y = panel.y + 6 if cy == 0 else panel.y + panel.h - INSET_PX - 6
    view = np.array([[panel.x0, panel.y0], [panel.x1, panel.y0], [panel.x1, panel.y1],
                     [panel.x0, panel.y1]])
    pts = np.vstack([arm_points(arm), view])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.06 * float((hi - lo).max())
    panel.scene.rect(x, y, INSET_PX, INSET_PX, "#ffffff", "#999999", 0.8)
    inset = Panel.at(panel.scene, (x + 4, y + 4, INSET_PX - 8, INSET_PX - 8),
                     (lo[0] - pad, hi[0] + pad), (lo[1] - pad, hi[1] + pad), equal=True)
    draw_arm(inset, arm, width=3.0)
    inset.scene.lines([inset.xy(view)], GREY, 0.8, dash=(3, 2), closed=True, clip=inset.clip)
    inset.line(pos[:, 0], pos[:, 1], TEXT, 1.0)


def _legend(scene: Scene, y: float, names: Sequence[str], strokes: Sequence[Stroke],
            extra: Sequence[tuple[str, dict[str, Any]]] = ()) -> None:
    entries: list[tuple[str, dict[str, Any]]] = [
        (n, {"stroke": c, "dash": d, "width": w}) for n, (c, d, w) in zip(names, strokes,
                                                                          strict=True)]
    entries += extra
    scene.legend(LEFT_PX, y, entries, max_width=scene.width - LEFT_PX - 10)


def classification_figure(cl: Classification, top: int = 4) -> Scene:
    """Per observation the recorded force against the ``top`` most probable candidates'
    predictions (magnitude and direction), and the posterior of every candidate and group."""
    nobs = len(cl.observations)
    order = np.argsort(-cl.posterior, kind="stable")[:top]
    cands = [cl.candidates[k] for k in order]
    strokes = candidate_strokes(cands)
    names = [f"{c.name} (p = {cl.posterior[k]:.2g})" for c, k in zip(cands, order, strict=True)]
    allc = np.argsort(-cl.posterior, kind="stable")
    label_px = max(text_width(c.name, FONT_SMALL) for c in cl.candidates) + 16.0
    bars_x = LEFT_PX + nobs * (COLUMN_PX + GAP_PX) + label_px - 40.0
    width = bars_x + 260.0 + 40.0
    verdict = cl.verdict()
    title_lines = len(textwrap.wrap(verdict, int((width - 20) / (0.58 * (FONT_TITLE + 1)))))
    top_y = 18.0 + title_lines * (FONT_TITLE + 6) + 30.0
    legend_y = top_y + 2 * PROFILE_PX + 26.0 + 92.0
    scene = Scene(width, legend_y + 60.0, verdict)
    best = cl.best
    scene.data.update({
        "figure": "classification", "best": best.name, "probability": f"{cl.probability:.4f}",
        "observations": "|".join(o.name for o in cl.observations),
        "posterior": "|".join(f"{c.name}={p:.4g}" for c, p in zip(cl.candidates, cl.posterior,
                                                                  strict=True))})
    _wrap(scene, 10.0, 26.0, verdict, width - 20, FONT_TITLE + 1, bold=True)
    for j, (o, pred) in enumerate(zip(cl.observations, cl.predictions, strict=True)):
        # the recorded force only where the likelihood counts it (one model rendered alone)
        rec = o.force_n if o.counted is None else np.where(o.counted[:, None], o.force_n, np.nan)
        x = LEFT_PX + j * (COLUMN_PX + GAP_PX)
        _profiles(scene, x, top_y, o.times_s, pred[order], strokes, names, 1.0, o.name, rec,
                  o.times_s, f"{o.name}: recorded and predicted")
    _posterior_bars(scene, bars_x, top_y, cl, allc)
    _legend(scene, legend_y, names, strokes, [("recorded", {"stroke": MODEL, "width": 1.0})])
    return scene


def _posterior_bars(scene: Scene, x: float, top: float, cl: Classification,
                    order: np.ndarray) -> None:
    colours = [s[0] for s in candidate_strokes([cl.candidates[k] for k in order])]
    n = len(order)
    panel = Panel(scene, x, top, 240.0, PROFILE_PX, 0.0, 1.0, -0.5, n - 0.5)  # best on top
    panel.frame("which candidate", "posterior probability", "",
                yticks=[n - 1 - r for r in range(n)],
                ytick_labels=[cl.candidates[int(k)].name for k in order], grid=False,
                title_size=FONT)
    for rank, (k, colour) in enumerate(zip(order, colours, strict=True)):
        c = cl.candidates[int(k)]
        y = n - 1 - rank
        p = float(cl.posterior[int(k)])
        px = panel.pts([0.0, p], [y - 0.35, y + 0.35])
        scene.rects([[px[0, 0], px[1, 1], px[1, 0] - px[0, 0], px[0, 1] - px[1, 1]]], [colour],
                    data={"candidate": c.name, "posterior": f"{p:.4g}"})
    groups = cl.group_posterior
    gp = Panel.at(scene, (x, top + PROFILE_PX + 80.0, 240.0, PROFILE_PX - 30.0),
                  (-0.5, max(len(groups), 1) - 0.5), (0.0, 1.0), clip=False)
    gp.frame("which group", "", "probability", xticks=list(range(len(groups))),
             xtick_labels=list(groups), grid=True, title_size=FONT)
    for i, (g, p) in enumerate(groups.items()):
        px = gp.pts([i - 0.35, i + 0.35], [0.0, p])
        scene.rects([[px[0, 0], px[1, 1], px[1, 0] - px[0, 0], px[0, 1] - px[1, 1]]],
                    [GROUP_COLOURS.get(g, GREY)], data={"group": g, "posterior": f"{p:.4g}"})
