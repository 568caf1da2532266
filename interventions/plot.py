"""Before / after / difference plots of two compiled arms' fields (through
:mod:`fieldbank.plotting`).

Three rows: the static (postural) field with stiffness ellipses, the field at a moving speed
(mean over the standard directions is not a field; the plot shows the pull direction, -y,
where the probing pull runs), and the seed's probing motions with the force felt along them.
Columns: before, after, after - before. PNG or SVG by the file suffix.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fieldbank import plotting
from fieldbank.errors import FieldbankError
from fieldbank.evaluate.compare import Conditions
from fieldbank.evaluate.probing import profile
from fieldbank.model import Arm

PLOT_SPEED_M_PER_S = 0.3
#: Workspace grid of the figure (denser grids only crowd the arrows).
PLOT_GRID_N = 11


def plot_comparison(arm_b: Arm, arm_a: Arm, path: str | Path, title: str = "") -> Path:
    """Write the figure; returns the path. Refuses suffixes other than .png and .svg."""
    out = Path(path)
    if out.suffix.lower() not in (".png", ".svg"):
        raise FieldbankError(f"{out}: plots are written as .png or .svg; got {out.suffix!r}.")
    cond = Conditions.standard(arm_b, grid_n=PLOT_GRID_N)
    x = cond.grid_m
    rest = arm_b.rest_position()
    v = np.array([0.0, -PLOT_SPEED_M_PER_S])
    fig, axes = plotting.pyplot().subplots(3, 3, figsize=(13, 12), squeeze=False)
    (fb, kb, _), (fa, ka, _) = arm_b.field(x), arm_a.field(x)
    plotting.field_row(axes[0], x, fb, fa, "static", mark_m=rest, key_at=(0.85, 1.02))
    kscale = plotting.ellipse_scale(kb, plotting.grid_spacing(x))
    for ax, k in ((axes[0][0], kb), (axes[0][1], ka)):
        plotting.ellipses(ax, x, k, color="0.4", scale_n_per_m=kscale, linewidth=0.6)
    plotting.field_row(axes[1], x, arm_b.endpoint_force(x, v), arm_a.endpoint_force(x, v),
                       f"moving {PLOT_SPEED_M_PER_S:g} m/s toward the body", mark_m=rest,
                       key_at=(0.85, 1.02))
    for col, motion in enumerate(cond.probes):
        ax = axes[2][col]
        for arm, name, style in ((arm_b, "before", "C0-"), (arm_a, "after", "C1--")):
            p = profile(arm, motion)
            ax.plot(motion.times_s, np.hypot(*p.force_n.T), style, label=name)
        ax.set_title(f"probing: {motion.description}", fontsize=9)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("|force| (N)")
        ax.legend(fontsize=8)
    ax = axes[2][2]
    for motion in cond.probes:
        ax.plot(motion.positions_m[:, 0], motion.positions_m[:, 1], label=motion.name)
    ax.set_aspect("equal")
    ax.set_title("probing paths (shoulder frame)", fontsize=9)
    ax.legend(fontsize=8)
    if title:
        fig.suptitle(f"{title} (model predictions)")
    fig.tight_layout()
    return plotting.save(fig, out, dpi=100)
