"""Measured against fitted fields: one panel per map (through :mod:`fieldbank.plotting`).

Postural maps: measured forces (black) and fitted forces (red) as arrows at each position.
Stiffness maps: the symmetric part of K as an ellipse (axes ∝ eigenvalues, along the
eigenvectors), measured black, fitted red; an axis with a negative eigenvalue is drawn dashed.
Written as PNG or SVG (by the file's extension).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from fieldbank import plotting
from fieldbank.errors import FitError
from fieldbank.maps import FieldMap

if TYPE_CHECKING:  # typing only: matplotlib loads with the first figure
    from matplotlib.axes import Axes

FORMATS = (".png", ".svg")


def _quivers(ax: Axes, measured: FieldMap, fitted: FieldMap) -> None:
    pos = measured.positions_m
    spacing = plotting.grid_spacing(pos)
    scale = plotting.arrow_scale(measured.values, spacing)
    for m, colour, label in ((measured, "black", "measured"), (fitted, "tab:red", "fitted")):
        plotting.quiver(ax, pos, m.values, color=colour, label=label, scale_n_per_m=scale)
    arrow_m = plotting.ARROW_FILL * spacing
    ax.set_title(f"postural, n={measured.n} (arrow {scale * arrow_m:.3g} N = "
                 f"{arrow_m * 100:.1f} cm)")


def _ellipses(ax: Axes, measured: FieldMap, fitted: FieldMap) -> None:
    pos = measured.positions_m
    spacing = plotting.grid_spacing(pos)
    scale = plotting.ellipse_scale(measured.values, spacing)
    for m, colour, label, lw in ((measured, "black", "measured", 2.0),
                                 (fitted, "tab:red", "fitted", 1.0)):
        plotting.ellipses(ax, pos, m.values, color=colour, label=label, scale_n_per_m=scale,
                          linewidth=lw)
    ax.plot(pos[:, 0], pos[:, 1], ".", color="grey", markersize=2)
    vx, vy = measured.velocity_m_per_s
    axis_m = plotting.ELLIPSE_FILL * spacing
    ax.set_title(f"stiffness at v=({vx:.2g}, {vy:.2g}) m/s, n={measured.n} "
                 f"(axis {scale * axis_m:.3g} N/m = {axis_m * 100:.1f} cm)")


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
    plt = plotting.pyplot()
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
            # the shoulder, marked as in every field figure (fieldbank.fieldplot): a dot
            ax.plot([0.0], [0.0], "o", color="#222222", markeredgecolor="white",
                    markersize=7, label="shoulder")
            ax.set_xlabel("x (m)")
            ax.set_ylabel("y (m)")
            ax.legend(loc="upper right", fontsize=8)
        for k in range(n, rows * cols):
            axes[k // cols][k % cols].set_visible(False)
        if title:
            fig.suptitle(title)
        fig.tight_layout()
    except BaseException:
        plt.close(fig)
        raise
    return plotting.save(fig, out, dpi=100)
