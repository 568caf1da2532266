"""Field figures on :mod:`fieldbank.figures.panel` panels: force arrows, stiffness ellipses and
scalar maps over the workspace, with their keys and markers, the before / after / difference
row, and the one-map figure of ``fieldbank field --out``.

The conventions every field figure shares (the report's, ``whatif --plot``'s and
``field --out``'s):

* panels in the shoulder frame, x to the patient's right and y forward, metres, one metre as
  long on both axes; before and after panels share their limits, arrow scale and colour scale;
* arrows: the force the arm exerts on the handle; the 90th percentile magnitude spans 80% of
  the grid spacing (:func:`arrow_scale`); arrows longer than
  :data:`ARROW_CLIP` spacings are cut there and drawn thicker; every arrow set has a key (a
  reference arrow of a round value, in N);
* ellipses: the symmetric part of K, full axes ∝ |eigenvalues| (dashed where one is negative),
  the 90th percentile larger axis spans 90% of the spacing
  (:func:`ellipse_scale`); axes longer than :data:`ELLIPSE_CLIP` spacings
  are cut and drawn thicker (so one near-singular posture does not hide the rest); every set
  has a key (a circle of a round stiffness, in N/m);
* scalar maps as one coloured cell per grid point (no interpolation): the passive potential U
  on a light sequential map, every difference (ΔU, Δ|F|) on a diverging map centred on zero;
  each with its colour bar and unit;
* markers: ● the shoulder, ◎ the rest hand position - the same in every figure, named in the
  legend; colours :data:`fieldbank.figures.style.BEFORE` / ``AFTER`` / ``CHANGE`` / ``MODEL``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar, cast

import numpy as np
from numpy.typing import ArrayLike

from fieldbank.figures.panel import Panel, colour_bar
from fieldbank.figures.scene import Scene, marker_at
from fieldbank.figures.style import (
    AFTER,
    BEFORE,
    CHANGE,
    FONT_SMALL,
    MODEL,
    TEXT,
    diverging,
    fmt_value,
    sequential,
)
from fieldbank.maps import FieldMap, ellipse
from fieldbank.model import Arm, FloatArray

T = TypeVar("T")

#: Fraction of the grid spacing the reference (percentile) arrow spans.
ARROW_FILL = 0.8
#: Fraction of the grid spacing the reference (percentile) ellipse axis spans.
ELLIPSE_FILL = 0.9
#: Percentile of magnitudes that sets a scale (outliers may overlap their neighbours).
SCALE_PERCENTILE = 90.0


#: Longest arrow drawn, in grid spacings; longer ones are cut and drawn thicker.
ARROW_CLIP = 1.6
#: Longest ellipse axis drawn, in grid spacings.
ELLIPSE_CLIP = 1.4
#: Percentile of the larger ellipse axes that spans 90% of the grid spacing: lower than the
#: arrows' (stiffness grows steeply toward the edges of the workspace, and the interior
#: ellipses would otherwise be needles; the largest are cut at ELLIPSE_CLIP).
ELLIPSE_PERCENTILE = 60.0
#: Below this a difference is "no change" (N, J).
NO_CHANGE = 1e-9
#: Plotting-area widths of the large (the change) and the small (before, after) panels of a
#: field row, px; the row is 1080 px wide.
BIG_WIDTH_PX = 560.0
SMALL_WIDTH_PX = 250.0


# --- scales -------------------------------------------------------------------------------
#: A figure asks for the spacing of one grid many times (each panel, layout and key): the
#: last grids' spacings, by the grid's bytes, kept for the process.
_SPACINGS: dict[tuple[str, bytes], Any] = {}
_SPACINGS_KEPT = 32


def _remembered(what: str, grid: FloatArray, compute: Callable[[], T]) -> T:
    """``compute()`` of ``grid`` the first time, the same value while it is kept."""
    key = (what, grid.tobytes() + str(grid.shape).encode())
    found = _SPACINGS.get(key)
    if found is None:
        if len(_SPACINGS) >= _SPACINGS_KEPT:
            del _SPACINGS[next(iter(_SPACINGS))]
        found = _SPACINGS[key] = compute()
    return cast(T, found)


def grid_spacing(positions_m: ArrayLike) -> float:
    """Median distance from each position to its nearest neighbour, m (0.05 for one point)."""
    pos = np.asarray(positions_m, dtype=float)
    if pos.shape[0] < 2:
        return 0.05
    return _remembered("spacing", pos, lambda: _grid_spacing(pos))


def _grid_spacing(pos: FloatArray) -> float:
    d = np.sqrt(((pos[:, None, :] - pos[None, :, :]) ** 2).sum(-1))
    d[d == 0] = np.inf
    return float(np.median(d.min(axis=1)))


def arrow_scale(force_n: ArrayLike, spacing_m: float, percentile: float = SCALE_PERCENTILE
                ) -> float:
    """N per m of arrow: the ``percentile`` magnitude spans :data:`ARROW_FILL` · spacing."""
    f = np.asarray(force_n, dtype=float).reshape(-1, 2)
    top = float(np.percentile(np.hypot(f[:, 0], f[:, 1]), percentile)) if len(f) else 0.0
    return max(top, 1e-9) / (ARROW_FILL * spacing_m)


def ellipse_scale(stiffness_n_per_m: ArrayLike, spacing_m: float,
                  percentile: float = SCALE_PERCENTILE) -> float:
    """N/m per m of ellipse axis: the ``percentile`` larger axis spans ELLIPSE_FILL · spacing."""
    e = ellipse(stiffness_n_per_m)
    axes_n = np.maximum(np.abs(e.major_n_per_m), np.abs(e.minor_n_per_m))
    top = float(np.percentile(axes_n, percentile)) if axes_n.size else 0.0
    return max(top, 1e-9) / (ELLIPSE_FILL * spacing_m)


def round_value(v: float) -> float:
    """The 1-2-2.5-5 × 10^k value nearest below ``v`` (> 0): a key's length."""
    if not (v > 0 and math.isfinite(v)):
        return 0.0
    mag = 10.0 ** math.floor(math.log10(v))
    return max(m * mag for m in (1.0, 2.0, 2.5, 5.0) if m * mag <= v * 1.0000001)


def spacing_xy(grid_m: ArrayLike) -> tuple[float, float]:
    """Grid steps in x and y, m (the smallest non-zero difference of the coordinates; the
    median nearest-neighbour distance when the points are scattered)."""
    g = np.asarray(grid_m, dtype=float).reshape(-1, 2)
    return _remembered("steps", g, lambda: _spacing_xy(g))


def _spacing_xy(g: FloatArray) -> tuple[float, float]:
    out = []
    for k in range(2):
        d = np.diff(np.unique(np.round(g[:, k], 9)))
        d = d[d > 1e-9]
        out.append(float(d.min()) if d.size else 0.0)
    s = grid_spacing(g)
    if not all(out) or min(out) < 0.3 * s:  # scattered positions, not a lattice
        return s, s
    return out[0], out[1]


@dataclass(frozen=True)
class ArrowSet:
    """What an arrow set was drawn with: N per px of arrow, arrows cut, key value (N)."""

    n_per_px: float
    clipped: int
    key_n: float


def arrow_scale_px(panel: Panel, force_n: ArrayLike, spacing_m: float,
                   percentile: float = SCALE_PERCENTILE) -> float:
    """N per px of arrow on ``panel`` (:func:`arrow_scale`)."""
    return arrow_scale(force_n, spacing_m, percentile) / panel.px_per_x


def arrows(panel: Panel, positions_m: ArrayLike, force_n: ArrayLike, n_per_px: float,
           colour: str = MODEL, max_px: float | None = None, width: float = 1.3,
           data: Mapping[str, str] | None = None) -> int:
    """Force arrows from the positions; returns how many were cut at ``max_px``."""
    p = panel.xy(positions_m)
    f = np.asarray(force_n, dtype=float).reshape(-1, 2)
    v = np.stack([f[:, 0], -f[:, 1]], axis=1) / max(n_per_px, 1e-300)
    length = np.hypot(v[:, 0], v[:, 1])
    cut = np.zeros(len(v), dtype=bool)
    if max_px is not None:
        cut = length > max_px
        v[cut] *= (max_px / length[cut])[:, None]
        length = np.minimum(length, max_px)
    for sel, w in ((~cut, width), (cut, width * 1.9)):
        # shorter than a line is wide: no direction to read; a head from 4 px on
        keep = sel & (length >= 1.5)
        p0, dv, n = p[keep], v[keep], length[keep]
        tip = p0 + dv
        with np.errstate(divide="ignore", invalid="ignore"):
            u = dv / n[:, None]
        head = np.minimum(0.38 * n, 6.5)
        back = tip - head[:, None] * u
        side = (0.45 * head)[:, None] * np.stack([-u[:, 1], u[:, 0]], axis=1)
        shafts = np.stack([p0, tip], axis=1)
        heads = np.stack([back + side, tip, back - side], axis=1)
        paths: list[FloatArray] = []
        for k, with_head in enumerate((n >= 4.0).tolist()):
            paths.append(shafts[k])
            if with_head:
                paths.append(heads[k])
        panel.scene.lines(paths, colour, w, clip=panel.clip, data=data)
    return int(cut.sum())


def arrow_key(scene: Scene, x: float, y: float, value_n: float, n_per_px: float,
              colour: str = MODEL, clipped: int = 0, max_n: float | None = None) -> float:
    """A reference arrow of ``value_n`` N at (x, y) (its left end, middle) with its label;
    returns the x after it."""
    n = value_n / n_per_px
    tip = x + n
    scene.lines([[[x, y], [tip, y]], [[tip - 6, y - 3], [tip, y], [tip - 6, y + 3]]], colour,
                1.3)
    label = f"= {fmt_value(value_n)} N"
    if clipped and max_n is not None:
        label += f"; {clipped} cut at {fmt_value(max_n)} N (thick)"
    scene.text(tip + 6, y, label, FONT_SMALL, "start", "middle")
    return tip + 6 + 0.58 * FONT_SMALL * len(label)


def ellipse_scale_px(panel: Panel, stiffness_n_per_m: ArrayLike, spacing_m: float,
                     percentile: float = ELLIPSE_PERCENTILE) -> float:
    """N/m per px of ellipse axis on ``panel`` (the rule of :func:`ellipse_scale`,
    at :data:`ELLIPSE_PERCENTILE`)."""
    return ellipse_scale(stiffness_n_per_m, spacing_m, percentile) / panel.px_per_x


def ellipses(panel: Panel, positions_m: ArrayLike, stiffness_n_per_m: ArrayLike,
             per_px: float, colour: str = MODEL, max_px: float | None = None,
             width: float = 1.1, data: Mapping[str, str] | None = None) -> int:
    """Stiffness ellipses (symmetric part of K) at the positions; returns how many were cut."""
    p = panel.xy(positions_m)
    e = ellipse(np.asarray(stiffness_n_per_m, dtype=float).reshape(-1, 2, 2))
    ax = np.stack([np.abs(e.major_n_per_m), np.abs(e.minor_n_per_m)], axis=1) / per_px
    # page angle: y up in data, so the data angle is the page's counter-clockwise angle, once
    # the panel's x and y scales are equal (spatial panels are)
    ang = np.degrees(e.orientation_rad)
    negative = (e.major_n_per_m < 0) | (e.minor_n_per_m < 0)
    cut = np.zeros(len(p), dtype=bool)
    if max_px is not None:
        big = ax.max(axis=1)
        cut = big > max_px
        ax[cut] *= (max_px / big[cut])[:, None]
    ax = np.maximum(ax, 0.6)
    for sel, w in ((~cut, width), (cut, width * 2.0)):
        if np.any(sel):
            panel.scene.ellipses(p[sel], ax[sel], ang[sel], colour, w, dashed=negative[sel],
                                 clip=panel.clip, data=data)
    return int(cut.sum())


def ellipse_key(scene: Scene, x: float, y: float, value_n_per_m: float, per_px: float,
                colour: str = MODEL, clipped: int = 0, max_n_per_m: float | None = None
                ) -> float:
    """A reference circle whose diameter is ``value_n_per_m``; returns the x after it."""
    d = value_n_per_m / per_px
    scene.ellipses([[x + d / 2, y]], [[d, d]], [0.0], colour, 1.1)
    label = f"diameter = {fmt_value(value_n_per_m)} N/m"
    if clipped and max_n_per_m is not None:
        label += f"; {clipped} cut at {fmt_value(max_n_per_m)} N/m (thick)"
    scene.text(x + d + 6, y, label, FONT_SMALL, "start", "middle")
    return x + d + 6 + 0.58 * FONT_SMALL * len(label)


def cells(panel: Panel, positions_m: ArrayLike, colours: Sequence[str],
          step_m: tuple[float, float], data: Mapping[str, str] | None = None) -> None:
    """One coloured cell per grid position (``step_m``: the grid steps in x and y, m)."""
    p = panel.xy(positions_m)
    w = step_m[0] * panel.px_per_x
    h = step_m[1] * panel.px_per_y
    boxes = np.column_stack([p[:, 0] - w / 2, p[:, 1] - h / 2, np.full(len(p), w + 0.4),
                             np.full(len(p), h + 0.4)])
    panel.scene.rects(boxes, colours, clip=panel.clip, data=data)


def spatial_limits(grid_m: ArrayLike, extra_m: ArrayLike | None = None
                   ) -> tuple[tuple[float, float], tuple[float, float]]:
    """x and y limits over the grid (one step of margin) and the ``extra_m`` points."""
    g = np.asarray(grid_m, dtype=float).reshape(-1, 2)
    sx, sy = spacing_xy(g)
    pts = g if extra_m is None else np.vstack([g, np.asarray(extra_m, float).reshape(-1, 2)])
    return ((float(pts[:, 0].min()) - sx, float(pts[:, 0].max()) + sx),
            (float(pts[:, 1].min()) - sy, float(pts[:, 1].max()) + sy))


def spatial_height(grid_m: ArrayLike, width_px: float, extra_m: ArrayLike | None = None,
                   max_ratio: float = 1.25) -> float:
    """Height of an equal-aspect panel ``width_px`` wide over the grid, px."""
    (x0, x1), (y0, y1) = spatial_limits(grid_m, extra_m)
    return float(min(width_px * (y1 - y0) / max(x1 - x0, 1e-9), width_px * max_ratio))


def spatial_panel(scene: Scene, box: tuple[float, float, float, float], grid_m: ArrayLike,
                  title: str, extra_m: ArrayLike | None = None,
                  title_colour: str = TEXT) -> Panel:
    """An equal-aspect panel over the grid (one step of margin) and ``extra_m`` points,
    with its frame, ticks and labels."""
    xlim, ylim = spatial_limits(grid_m, extra_m)
    panel = Panel.at(scene, box, xlim, ylim, equal=True)
    panel.frame(title, "x (m, right)", "y (m, forward)", grid=False, title_colour=title_colour)
    return panel


def mark_points(panel: Panel, rest_m: ArrayLike | None = None, shoulder: bool = True) -> None:
    """● the shoulder (origin) and ◎ the rest hand position."""
    if shoulder:
        marker_at(panel.scene, panel.pts([0.0], [0.0]), "shoulder", TEXT, 5.0)
    if rest_m is not None:
        r = np.asarray(rest_m, dtype=float).reshape(2)
        marker_at(panel.scene, panel.pts([r[0]], [r[1]]), "ring", TEXT, 5.5)


MARKER_LEGEND = [("shoulder", {"marker": "shoulder"}),
                 ("rest hand position", {"marker": "ring"})]


@dataclass(frozen=True)
class RowInfo:
    """What a field row drew: the arrow sets of (before and after, shared), and of the
    difference; the largest |ΔF| (N) and |Δ scalar|."""

    shared: ArrowSet
    change: ArrowSet
    diff_max_n: float
    scalar_diff_max: float


@dataclass(frozen=True)
class RowLayout:
    """Boxes of a before / after / change row, px: the change large on the left, before and
    after small on the right, one above the other (what the plan changes comes first)."""

    big: tuple[float, float, float, float]
    small: tuple[tuple[float, float, float, float], tuple[float, float, float, float]]
    big_key_y: float
    small_key_y: float
    height: float

    @classmethod
    def of(cls, grid_m: ArrayLike, rest_m: ArrayLike | None, top: float = 0.0) -> RowLayout:
        extra = _extra(rest_m)
        hb = spatial_height(grid_m, BIG_WIDTH_PX, extra)
        hs = spatial_height(grid_m, SMALL_WIDTH_PX, extra)
        x_small = 62.0 + BIG_WIDTH_PX + 146.0
        y1 = top + 28.0
        y2 = y1 + hs + 70.0
        big_h = 28.0 + hb + 62.0
        small_h = 28.0 + hs + 70.0 + hs + 62.0
        return cls((62.0, y1, BIG_WIDTH_PX, hb),
                   ((x_small, y1, SMALL_WIDTH_PX, hs), (x_small, y2, SMALL_WIDTH_PX, hs)),
                   y1 + hb + 48.0, y2 + hs + 48.0, max(big_h, small_h))


def _extra(rest_m: ArrayLike | None) -> FloatArray | None:
    return None if rest_m is None else np.vstack([[0.0, 0.0], np.asarray(rest_m, float)])


def field_row(scene: Scene, top: float, grid_m: ArrayLike, before_n: ArrayLike,
              after_n: ArrayLike, title: str, *, potential_before_j: ArrayLike | None = None,
              potential_after_j: ArrayLike | None = None, rest_m: ArrayLike | None = None,
              data: str = "") -> RowInfo:
    """A force field before and after and the change (:class:`RowLayout`, from y = ``top``):
    the change large - arrows ΔF over ΔU, or over the change of |F| when no potential is
    given, on a diverging map centred on zero, with its own arrow scale - and before and
    after small, on one arrow scale and one colour scale of U. Needs :func:`row_height` px."""
    g = np.asarray(grid_m, dtype=float).reshape(-1, 2)
    fb = np.asarray(before_n, dtype=float).reshape(-1, 2)
    fa = np.asarray(after_n, dtype=float).reshape(-1, 2)
    d = fa - fb
    step = spacing_xy(g)
    spacing = grid_spacing(g)
    lay = RowLayout.of(g, rest_m, top)
    extra = _extra(rest_m)
    big = spatial_panel(scene, lay.big, g, f"after − before: {title}", extra, AFTER)
    small = [spatial_panel(scene, box, g, f"{when}: {title}", extra)
             for box, when in zip(lay.small, ("before", "after"), strict=True)]
    has_u = potential_before_j is not None and potential_after_j is not None
    if has_u:
        ub = np.asarray(potential_before_j, dtype=float).reshape(-1)
        ua = np.asarray(potential_after_j, dtype=float).reshape(-1)
        scalar = ua - ub
        lo, hi = float(min(ub.min(), ua.min())), float(max(ub.max(), ua.max()))
        for panel, u in zip(small, (ub, ua), strict=True):
            cells(panel, g, sequential(u, lo, hi), step)
        slabel, sunit = "ΔU", "J"
    else:
        scalar = np.hypot(*fa.T) - np.hypot(*fb.T)
        slabel, sunit = "Δ|F|", "N"
    smax = float(np.abs(scalar).max()) if scalar.size else 0.0
    if smax > NO_CHANGE:
        cells(big, g, diverging(scalar, smax), step, data={"field": f"{data}scalar"})
    shared = arrow_scale_px(small[0], np.vstack([fb, fa]), spacing)
    max_small = ARROW_CLIP * spacing * small[0].px_per_x
    cut_b = arrows(small[0], g, fb, shared, BEFORE, max_small, 1.1, data={"field": f"{data}before"})
    cut_a = arrows(small[1], g, fa, shared, AFTER, max_small, 1.1, data={"field": f"{data}after"})
    dmax = float(np.hypot(*d.T).max()) if d.size else 0.0
    change = arrow_scale_px(big, d, spacing, 98.0)
    max_big = ARROW_CLIP * spacing * big.px_per_x
    cut_d = 0
    if dmax > NO_CHANGE:
        cut_d = arrows(big, g, d, change, CHANGE, max_big, 1.5, data={"field": f"{data}change"})
    else:
        big.note("no change")
    for panel in (big, *small):
        mark_points(panel, rest_m)
    key_shared = round_value(0.8 * spacing * small[0].px_per_x * shared)
    key_change = round_value(0.8 * spacing * big.px_per_x * change)
    x = arrow_key(scene, small[1].x, lay.small_key_y, key_shared, shared, BEFORE)
    arrow_key(scene, x + 8, lay.small_key_y, key_shared, shared, AFTER, cut_b + cut_a,
              max_small * shared)
    if dmax > NO_CHANGE:
        arrow_key(scene, big.x, lay.big_key_y, key_change, change, CHANGE, cut_d,
                  max_big * change)
    if has_u:
        colour_bar(scene, (small[0].x + small[0].w + 8, small[0].y + 16, 10,
                           small[1].y + small[1].h - small[0].y - 16), lo, hi,
                   sequential(np.linspace(lo, hi, 24), lo, hi), "U (J)")
    if smax > NO_CHANGE:
        colour_bar(scene, (big.x + big.w + 10, big.y + 20, 12, big.h - 20), -smax, smax,
                   diverging(np.linspace(-smax, smax, 24), smax), f"{slabel} ({sunit})")
    return RowInfo(ArrowSet(shared, cut_b + cut_a, key_shared),
                   ArrowSet(change, cut_d, key_change), dmax, smax)


def ellipse_row(scene: Scene, top: float, grid_m: ArrayLike, k_before: ArrayLike,
                k_after: ArrayLike, title: str, rest_m: ArrayLike | None = None) -> int:
    """Stiffness ellipses before (blue) and after (vermillion) overlaid on one scale, large,
    and small: the ratio of the larger |eigenvalue| after / before per position on a
    diverging map (log scale, 1 white). The layout of :func:`field_row`; returns how many
    ellipses were cut."""
    g = np.asarray(grid_m, dtype=float).reshape(-1, 2)
    kb = np.asarray(k_before, dtype=float).reshape(-1, 2, 2)
    ka = np.asarray(k_after, dtype=float).reshape(-1, 2, 2)
    spacing = grid_spacing(g)
    lay = RowLayout.of(g, rest_m, top)
    extra = _extra(rest_m)
    big = spatial_panel(scene, lay.big, g, f"before and after: {title}", extra, AFTER)
    ratio_panel = spatial_panel(scene, lay.small[0], g, "larger stiffness after ÷ before",
                                extra)
    per = ellipse_scale_px(big, np.concatenate([kb, ka]), spacing)
    max_px = ELLIPSE_CLIP * spacing * big.px_per_x
    cut = ellipses(big, g, kb, per, BEFORE, max_px, 1.6, data={"field": "before"})
    cut += ellipses(big, g, ka, per, AFTER, max_px, 1.1, data={"field": "after"})
    eb, ea = ellipse(kb), ellipse(ka)
    big_b = np.maximum(np.abs(eb.major_n_per_m), np.abs(eb.minor_n_per_m))
    big_a = np.maximum(np.abs(ea.major_n_per_m), np.abs(ea.minor_n_per_m))
    ok = big_b > 1e-9 * max(float(big_b.max(initial=0.0)), 1e-300)
    ratio = np.log2(np.where(ok, np.maximum(big_a, 1e-300) / np.where(ok, big_b, 1.0), 1.0))
    lim = max(float(np.abs(ratio).max(initial=0.0)), 0.05)
    if float(np.abs(ratio).max(initial=0.0)) > 1e-9:
        cells(ratio_panel, g, diverging(ratio, lim), spacing_xy(g), data={"field": "ratio"})
        colour_bar(scene, (ratio_panel.x + ratio_panel.w + 8, ratio_panel.y + 16, 10,
                           ratio_panel.h - 16), -lim, lim,
                   diverging(np.linspace(-lim, lim, 24), lim), "ratio",
                   labels=lambda v: f"×{fmt_value(2.0 ** v, 2)}")
    else:
        ratio_panel.note("no change")
    for panel in (big, ratio_panel):
        mark_points(panel, rest_m)
    ellipse_key(scene, big.x, lay.big_key_y,
                round_value(0.9 * spacing * big.px_per_x * per), per, TEXT, cut, max_px * per)
    return cut


def row_height(grid_m: ArrayLike, rest_m: ArrayLike | None = None) -> float:
    """Height of a :func:`field_row` or :func:`ellipse_row` over ``grid_m``, px."""
    return RowLayout.of(grid_m, rest_m).height


def map_figure(arm: Arm, m: FieldMap, title: str = "") -> Scene:
    """One map of one model (``fieldbank field --out``): the postural field over the passive
    potential U, or the stiffness ellipses, with the shoulder and the rest hand position."""
    pos = m.positions_m
    rest = arm.rest_position()
    extra = np.vstack([[0.0, 0.0], rest])
    size = 460.0
    height = spatial_height(pos, size, extra)
    scene = Scene(size + 170, height + 140, title or f"{m.kind} map")
    scene.data.update({"figure": "map", "kind": m.kind, "positions": str(len(pos))})
    panel_title = title or ("postural field: force of the arm on the handle"
                            if m.kind == "postural" else
                            "stiffness ellipses at v = "
                            f"({m.velocity_m_per_s[0]:g}, {m.velocity_m_per_s[1]:g}) m/s")
    panel = spatial_panel(scene, (70, 40, size, height), pos, panel_title, extra)
    spacing = grid_spacing(pos)
    key_y = 40 + height + 52
    if m.kind == "postural":
        u = arm.potential(pos)
        lo, hi = float(u.min()), float(u.max())
        if len(pos) > 1 and hi > lo:
            cells(panel, pos, sequential(u, lo, hi), spacing_xy(pos))
            colour_bar(scene, (panel.x + panel.w + 14, panel.y + 20, 12, panel.h - 20), lo, hi,
                       sequential(np.linspace(lo, hi, 24), lo, hi), "U (J)")
        scale = arrow_scale_px(panel, m.values, spacing)
        max_px = ARROW_CLIP * spacing * panel.px_per_x
        cut = arrows(panel, pos, m.values, scale, MODEL, max_px, data={"field": "model"})
        arrow_key(scene, panel.x, key_y, round_value(0.8 * spacing * panel.px_per_x * scale),
                      scale, MODEL, cut, max_px * scale)
    else:
        per = ellipse_scale_px(panel, m.values, spacing)
        max_px = ELLIPSE_CLIP * spacing * panel.px_per_x
        cut = ellipses(panel, pos, m.values, per, MODEL, max_px, data={"field": "model"})
        ellipse_key(scene, panel.x, key_y,
                        round_value(0.9 * spacing * panel.px_per_x * per), per, MODEL, cut,
                        max_px * per)
    mark_points(panel, rest)
    scene.legend(panel.x, key_y + 26, MARKER_LEGEND
                 + ([("dashed: a negative eigenvalue", {"stroke": MODEL, "dash": (3, 2)})]
                    if m.kind == "stiffness" else []))
    return scene
