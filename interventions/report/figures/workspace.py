"""Fields over the workspace, before, after and the change: the field with the hand moving in
the direction that lengthens the treated groups (:func:`moving_field_figure`, where the stretch
reflex acts), the static field over the passive potential (:func:`static_field_figure`) and
the static stiffness (:func:`ellipse_figure`), on the rows of :mod:`fieldbank.figures.fields`."""

from __future__ import annotations

import math

import numpy as np

from fieldbank.figures import fields
from fieldbank.figures.scene import Scene
from fieldbank.figures.style import (
    AFTER,
    BEFORE,
    CHANGE,
    FONT_TITLE,
    TEXT,
)
from fieldbank.interventions.report.figures.common import WIDTH
from fieldbank.model import Arm, FloatArray

#: Hand speed of the moving-field figure (the metrics' moving speed), m/s.
MOVING_SPEED_M_PER_S = 0.3

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
