"""Measured against fitted fields: one panel per map.

Postural maps: measured forces (black) and fitted forces (red) as arrows at each position.
Stiffness maps: the symmetric part of K as an ellipse (axes ∝ eigenvalues, along the
eigenvectors), measured black, fitted red; an axis with a negative eigenvalue is drawn dashed.
Rendered with matplotlib's Agg backend to PNG or SVG (by the file's extension).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.patches import Ellipse as EllipsePatch

from fieldbank.errors import FitError
from fieldbank.maps import FieldMap, ellipse

FORMATS = (".png", ".svg")


def _spacing(pos: np.ndarray) -> float:
    if pos.shape[0] < 2:
        return 0.05
    d = np.sqrt(((pos[:, None, :] - pos[None, :, :]) ** 2).sum(-1))
    d[d == 0] = np.inf
    return float(np.median(d.min(axis=1)))


def _quivers(ax: Axes, measured: FieldMap, fitted: FieldMap) -> None:
    pos = measured.positions_m
    mags = np.hypot(measured.values[:, 0], measured.values[:, 1])
    top = max(float(np.percentile(mags, 90)), 1e-12)
    scale = top / (0.8 * _spacing(pos))  # a 90th-percentile arrow spans 0.8 of the spacing
    for m, colour, label in ((measured, "black", "measured"), (fitted, "tab:red", "fitted")):
        ax.quiver(pos[:, 0], pos[:, 1], m.values[:, 0], m.values[:, 1], color=colour,
                  angles="xy", scale_units="xy", scale=scale, width=0.004, label=label)
    ax.set_title(f"postural, n={measured.n} (arrow {top:.3g} N = {top / scale * 100:.1f} cm)")


def _ellipses(ax: Axes, measured: FieldMap, fitted: FieldMap) -> None:
    pos = measured.positions_m
    em, ef = ellipse(measured.values), ellipse(fitted.values)
    axes_n = np.maximum(np.abs(em.major_n_per_m), np.abs(em.minor_n_per_m))
    top = max(float(np.percentile(axes_n, 90)), 1e-12)  # outliers may overlap their neighbours
    size = 0.9 * _spacing(pos) / top
    for e, colour, label, lw in ((em, "black", "measured", 2.0), (ef, "tab:red", "fitted", 1.0)):
        for i in range(pos.shape[0]):
            neg = e.minor_n_per_m[i] < 0 or e.major_n_per_m[i] < 0
            ax.add_patch(EllipsePatch(
                (pos[i, 0], pos[i, 1]), width=abs(e.major_n_per_m[i]) * size,
                height=abs(e.minor_n_per_m[i]) * size,
                angle=math.degrees(e.orientation_rad[i]), fill=False, edgecolor=colour,
                linestyle="--" if neg else "-", linewidth=lw,
                label=label if i == 0 else None))
    ax.plot(pos[:, 0], pos[:, 1], ".", color="grey", markersize=2)
    vx, vy = measured.velocity_m_per_s
    ax.set_title(f"stiffness at v=({vx:.2g}, {vy:.2g}) m/s, n={measured.n} "
                 f"(axis {top:.3g} N/m = {top * size * 100:.1f} cm)")


def plot_fit(
    measured: Sequence[FieldMap],
    fitted: Sequence[FieldMap],
    path: str | Path,
    r2: Sequence[float] | None = None,
    title: str = "",
) -> Path:
    """Draw measured against fitted maps to ``path`` (.png or .svg); returns the path."""
    out = Path(path)
    if out.suffix.lower() not in FORMATS:
        raise FitError(f"{out}: plot format must be one of {', '.join(FORMATS)}; "
                       f"got {out.suffix or 'no extension'!r}.")
    if len(measured) != len(fitted) or not measured:
        raise FitError("plot_fit needs one fitted map per measured map, and at least one.")
    n = len(measured)
    cols = min(n, 2)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(6.0 * cols, 5.0 * rows), squeeze=False)
    try:
        for k, (m, f) in enumerate(zip(measured, fitted, strict=True)):
            ax = axes[k // cols][k % cols]
            m = m.as_arm_on_handle()
            if m.kind == "postural":
                _quivers(ax, m, f)
            else:
                _ellipses(ax, m, f)
            if r2 is not None:
                ax.text(0.02, 0.02, f"R² = {r2[k]:.3f}", transform=ax.transAxes)
            ax.set_aspect("equal")
            ax.autoscale_view()
            ax.plot([0.0], [0.0], "k+", markersize=10)  # the shoulder
            ax.set_xlabel("x (m)")
            ax.set_ylabel("y (m)")
            ax.legend(loc="upper right", fontsize=8)
        for k in range(n, rows * cols):
            axes[k // cols][k % cols].set_visible(False)
        if title:
            fig.suptitle(title)
        fig.tight_layout()
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(out.name + ".part")
        fig.savefig(tmp, format=out.suffix.lower()[1:])
        tmp.replace(out)
    finally:
        plt.close(fig)
    return out
