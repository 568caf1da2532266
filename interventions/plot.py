"""Before / after / difference plots of two models' fields (matplotlib, Agg backend).

Three rows: the static (postural) field with stiffness ellipses, the field at a moving speed
(mean over the standard directions is not a field; the plot shows the pull direction, -y,
where the probing pull runs), and the seed's probing motions with the force felt along them.
Columns: before, after, after - before. PNG or SVG by the file suffix.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fieldbank.errors import FieldbankError
from fieldbank.evaluate.compare import Conditions
from fieldbank.evaluate.probing import profile
from fieldbank.maps import ellipse
from fieldbank.model import Arm

PLOT_SPEED_M_PER_S = 0.3


def plot_comparison(arm_b: Arm, arm_a: Arm, path: str | Path, title: str = "") -> Path:
    """Write the figure; returns the path. Refuses suffixes other than .png and .svg."""
    out = Path(path)
    if out.suffix.lower() not in (".png", ".svg"):
        raise FieldbankError(f"{out}: plots are written as .png or .svg; got {out.suffix!r}.")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Ellipse as EllipsePatch

    cond = Conditions.standard(arm_b, grid_n=11)
    x = cond.grid_m
    v = np.array([0.0, -PLOT_SPEED_M_PER_S])
    rows = []
    for vel in (None, v):
        fb, kb, _ = arm_b.field(x, vel)
        fa, ka, _ = arm_a.field(x, vel)
        rows.append(((fb, kb), (fa, ka), (fa - fb, ka - kb)))
    fig, axes = plt.subplots(3, 3, figsize=(13, 12), squeeze=False)
    # Arrow scales from the 90th percentile, so a few near-singular edge postures do not shrink
    # every other arrow to a dot; the difference column has its own scale, shown by its key.
    spacing = float(np.min(np.ptp(x, axis=0))) / 10.0

    def arrow_scale(f: np.ndarray) -> float:
        mag = np.hypot(f[:, 0], f[:, 1])
        return max(float(np.percentile(mag, 90)), 1e-9) / (0.8 * spacing)

    e0 = ellipse(rows[0][0][1])
    kscale = max(float(np.percentile(e0.major_n_per_m, 90)), 1e-9) / (0.4 * spacing)
    heads = ("before", "after", "after − before")
    for r, row in enumerate(rows):
        label = "static" if r == 0 else f"moving {PLOT_SPEED_M_PER_S:g} m/s toward the body"
        for col, (f, k) in enumerate(row):
            ax = axes[r][col]
            sc = arrow_scale(f if col == 2 else np.vstack([row[0][0], row[1][0]]))
            q = ax.quiver(x[:, 0], x[:, 1], f[:, 0], f[:, 1], angles="xy", scale_units="xy",
                          scale=sc, width=0.004, color="C3" if col == 2 else "C0")
            key_n = float(f"{sc * 0.8 * spacing:.2g}")
            ax.quiverkey(q, 0.85, 1.02, key_n, f"{key_n:g} N", labelpos="E",
                         fontproperties={"size": 7})
            if r == 0 and col < 2:
                e = ellipse(k)
                for i in range(x.shape[0]):
                    if e.minor_n_per_m[i] <= 0:
                        continue
                    ax.add_patch(EllipsePatch(
                        (x[i, 0], x[i, 1]), 2 * e.major_n_per_m[i] / kscale,
                        2 * e.minor_n_per_m[i] / kscale,
                        angle=float(np.degrees(e.orientation_rad[i])), fill=False,
                        color="0.4", lw=0.6))
            ax.plot(*arm_b.rest_position(), "k+", ms=10)
            ax.set_aspect("equal")
            ax.set_title(f"{heads[col]} — {label}", fontsize=9)
            ax.set_xlabel("x (m)")
            ax.set_ylabel("y (m)")
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
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return out
