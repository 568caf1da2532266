"""Measured against fitted maps (``fieldbank fit --plot``): one panel per map.

Postural maps: the measured force (near black, thick) and the fitted force (vermillion, thin,
on top) as arrows at each position, on the measured map's arrow scale. Stiffness maps: the
symmetric part of K as an ellipse (full axes ∝ |eigenvalues| along the eigenvectors, dashed
where one is negative), measured thick, fitted thin, on the measured map's scale. Each panel
says its map, the number of positions, R² of the fit and its key; the shoulder is marked as in
every field figure. The rules of :mod:`fieldbank.figures.fields` (scales, cut arrows, keys).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from fieldbank.errors import FitError
from fieldbank.figures.fields import (
    ARROW_CLIP,
    ELLIPSE_CLIP,
    arrow_key,
    arrow_scale_px,
    arrows,
    ellipse_key,
    ellipse_scale_px,
    ellipses,
    grid_spacing,
    mark_points,
    round_value,
    spatial_height,
    spatial_panel,
)
from fieldbank.figures.scene import Scene
from fieldbank.figures.style import AFTER, FONT, FONT_TITLE, MODEL, TEXT, fmt_value
from fieldbank.maps import FieldMap

#: Plotting-area width of one map's panel, px.
PANEL_PX = 440.0
#: Left margin (tick labels, axis label) and the space between columns, px.
LEFT_PX, GAP_PX = 74.0, 56.0
#: Panels per row.
COLUMNS = 2


def fit_figure(measured: Sequence[FieldMap], fitted: Sequence[FieldMap],
               r2: Sequence[float] | None = None, title: str = "") -> Scene:
    """Measured against fitted maps, one panel per map (at most :data:`COLUMNS` a row)."""
    if len(measured) != len(fitted) or not measured:
        raise FitError("a fit figure needs one fitted map per measured map, and at least one.")
    n = len(measured)
    cols = min(n, COLUMNS)
    rows = math.ceil(n / cols)
    maps = [m.as_arm_on_handle() for m in measured]
    extra = np.zeros((1, 2))  # the shoulder is always in view
    each = [spatial_height(m.positions_m, PANEL_PX, extra) for m in maps]
    heights = [max(each[r * cols:(r + 1) * cols]) for r in range(rows)]
    head = 44.0 if title else 12.0
    row_extra = 34.0 + 84.0  # title above; tick labels, axis label and key below
    width = LEFT_PX + cols * PANEL_PX + (cols - 1) * GAP_PX + 96.0
    legend_y = head + sum(heights) + rows * row_extra + 8.0
    scene = Scene(width, legend_y + 26.0, title or "measured and fitted maps")
    if title:
        scene.text(LEFT_PX, 26.0, title, FONT_TITLE + 1, bold=True)
    scene.data.update({"figure": "fit", "maps": str(n),
                       "kinds": " ".join(m.kind for m in maps)})
    if r2 is not None:
        scene.data["r2"] = " ".join(f"{v:.4f}" for v in r2)
    top = head
    for k, (m, f) in enumerate(zip(maps, fitted, strict=True)):
        r, c = divmod(k, cols)
        if c == 0 and r:
            top += heights[r - 1] + row_extra
        box = (LEFT_PX + c * (PANEL_PX + GAP_PX), top + 34.0, PANEL_PX, heights[r])
        _map_panel(scene, box, m, f, None if r2 is None else r2[k], k)
    scene.legend(LEFT_PX, legend_y, [
        ("measured", {"stroke": MODEL, "width": 2.4}),
        ("fitted", {"stroke": AFTER, "width": 1.2}),
        ("shoulder", {"marker": "shoulder"}),
        *([("dashed: a negative eigenvalue", {"stroke": TEXT, "dash": (3, 2)})]
          if any(m.kind == "stiffness" for m in maps) else [])])
    return scene


def _map_panel(scene: Scene, box: tuple[float, float, float, float], m: FieldMap,
               f: FieldMap, r2: float | None, k: int) -> None:
    pos = m.positions_m
    if m.kind == "postural":
        title = f"postural map, n = {m.n}"
    else:
        vx, vy = m.velocity_m_per_s
        title = f"stiffness at v = ({fmt_value(vx, 2)}, {fmt_value(vy, 2)}) m/s, n = {m.n}"
    panel = spatial_panel(scene, box, pos, title, np.zeros((1, 2)))
    spacing = grid_spacing(pos)
    key_y = box[1] + box[3] + 62.0
    tag = {"map": str(k)}
    if m.kind == "postural":
        scale = arrow_scale_px(panel, m.values, spacing)
        max_px = ARROW_CLIP * spacing * panel.px_per_x
        cut = arrows(panel, pos, m.values, scale, MODEL, max_px, 2.4,
                     data={"field": "measured", **tag})
        cut += arrows(panel, pos, f.values, scale, AFTER, max_px, 1.2,
                      data={"field": "fitted", **tag})
        arrow_key(scene, panel.x, key_y, round_value(0.8 * spacing * panel.px_per_x * scale),
                  scale, MODEL, cut, max_px * scale)
    else:
        per = ellipse_scale_px(panel, m.values, spacing)
        max_px = ELLIPSE_CLIP * spacing * panel.px_per_x
        cut = ellipses(panel, pos, m.values, per, MODEL, max_px, 2.2,
                       data={"field": "measured", **tag})
        cut += ellipses(panel, pos, f.values, per, AFTER, max_px, 1.1,
                        data={"field": "fitted", **tag})
        panel.markers(pos[:, 0], pos[:, 1], "circle", "#999999", 1.6)
        ellipse_key(scene, panel.x, key_y, round_value(0.9 * spacing * panel.px_per_x * per),
                    per, MODEL, cut, max_px * per)
    mark_points(panel)
    if r2 is not None:
        scene.text(panel.x + 8, panel.y + panel.h - 8, f"R² = {r2:.3f}", FONT, bold=True)
