"""Every matplotlib helper: force arrows, stiffness ellipses, potential contours, the
before / after / difference field row, and deterministic PNG or SVG output.

matplotlib is loaded the first time a figure is made (:func:`pyplot`), with the Agg backend
(no screen needed), chosen there once; importing this module loads nothing, so commands and
worker processes that never draw never pay for it. Callers draw into Axes they lay out
themselves (the what-if figure, the report's figures, measured against fitted, a model's map)
and share two scaling rules, so every figure reads the same way:

* arrows - a high percentile of the force magnitudes spans :data:`ARROW_FILL` of the spacing
  between grid points, so a few near-singular edge postures do not shrink every other arrow
  to a dot (:func:`arrow_scale`);
* ellipses - the symmetric part of K, axes ∝ eigenvalues along the eigenvectors; a high
  percentile of the larger axis spans :data:`ELLIPSE_FILL` of the spacing; an axis with a
  negative eigenvalue is drawn at its absolute size with a dashed outline (:func:`ellipses`).

:func:`render` and :func:`save` give the same bytes for the same figure (fixed metadata, SVG
hash salt, no dates); :func:`save` writes through a temporary file, so a failed write leaves
nothing half-written.
"""

from __future__ import annotations

import functools
import io
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from fieldbank.files import write_atomic
from fieldbank.maps import ellipse

if TYPE_CHECKING:  # typing only: matplotlib loads with the first figure (pyplot())
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

FORMATS = ("png", "svg")
#: Fraction of the grid spacing the reference (percentile) arrow spans.
ARROW_FILL = 0.8
#: Fraction of the grid spacing the reference (percentile) ellipse axis spans.
ELLIPSE_FILL = 0.9
#: Percentile of magnitudes that sets a scale (outliers may overlap their neighbours).
SCALE_PERCENTILE = 90.0


@functools.cache
def pyplot() -> ModuleType:
    """``matplotlib.pyplot`` on the Agg backend (loaded and chosen on first use)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def new_figure(ncols: int = 1, size_in: tuple[float, float] = (5.5, 5.0)
               ) -> tuple[Figure, list[Axes]]:
    """A row of ``ncols`` equal-aspect panels in the shoulder frame; (figure, axes)."""
    fig, axes = pyplot().subplots(1, ncols, figsize=(size_in[0] * ncols, size_in[1]),
                                  squeeze=False)
    row: list[Axes] = list(axes[0])
    for ax in row:
        ax.set_aspect("equal")
        ax.set_xlabel("x (m, +right)")
        ax.set_ylabel("y (m, +forward)")
    return fig, row


def spatial_axes(ax: Axes, title: str, fontsize: float = 9.0) -> None:
    """Equal aspect, x/y in metres, a few ticks: a panel in the shoulder frame."""
    from matplotlib.ticker import MaxNLocator

    ax.set_aspect("equal")
    ax.set_title(title, fontsize=fontsize)
    ax.set_xlabel("x (m)", fontsize=fontsize - 1)
    ax.set_ylabel("y (m)", fontsize=fontsize - 1)
    ax.tick_params(labelsize=fontsize - 2)
    ax.xaxis.set_major_locator(MaxNLocator(5))
    ax.yaxis.set_major_locator(MaxNLocator(5))


# --- scales -------------------------------------------------------------------------------
def grid_spacing(positions_m: ArrayLike) -> float:
    """Median distance from each position to its nearest neighbour, m (0.05 for one point)."""
    pos = np.asarray(positions_m, dtype=float)
    if pos.shape[0] < 2:
        return 0.05
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


# --- drawing ------------------------------------------------------------------------------
def quiver(ax: Axes, positions_m: ArrayLike, force_n: ArrayLike, color: str = "C0",
           label: str | None = None, scale_n_per_m: float | None = None,
           width: float = 0.004) -> float:
    """Force arrows at positions; returns the scale used (N per m of arrow length)."""
    pos = np.asarray(positions_m, dtype=float)
    f = np.asarray(force_n, dtype=float)
    if scale_n_per_m is None:
        scale_n_per_m = arrow_scale(f, grid_spacing(pos))
    ax.quiver(pos[:, 0], pos[:, 1], f[:, 0], f[:, 1], color=color, angles="xy",
              scale_units="xy", scale=scale_n_per_m, width=width, label=label)
    return scale_n_per_m


def ellipses(ax: Axes, positions_m: ArrayLike, stiffness_n_per_m: ArrayLike, color: str = "C1",
             label: str | None = None, scale_n_per_m: float | None = None,
             linewidth: float = 1.0) -> float:
    """Stiffness ellipses centred at the positions; returns the scale (N/m per m of axis).

    The symmetric part of K: axes ∝ |eigenvalues| along the eigenvectors; an ellipse with a
    negative eigenvalue (the field pushes away along that axis) is drawn dashed.
    """
    from matplotlib.collections import EllipseCollection

    pos = np.asarray(positions_m, dtype=float)
    k = np.asarray(stiffness_n_per_m, dtype=float).reshape(-1, 2, 2)
    if scale_n_per_m is None:
        scale_n_per_m = ellipse_scale(k, grid_spacing(pos))
    e = ellipse(k)
    negative = (e.major_n_per_m < 0) | (e.minor_n_per_m < 0)
    coll = EllipseCollection(
        np.abs(e.major_n_per_m) / scale_n_per_m, np.abs(e.minor_n_per_m) / scale_n_per_m,
        np.degrees(e.orientation_rad), units="xy", offsets=pos, offset_transform=ax.transData,
        facecolors="none", edgecolors=color, linewidths=linewidth,
        linestyles=["--" if n else "-" for n in negative],
    )
    ax.add_collection(coll)
    if label is not None:  # legends have no handler for ellipse collections: a line stands in
        ax.plot([], [], color=color, linewidth=linewidth, label=label)
    ax.autoscale_view()
    return scale_n_per_m


def contours(ax: Axes, positions_m: ArrayLike, values: ArrayLike, label: str = "U (J)",
             levels: int = 12, alpha: float = 0.5, fontsize: float | None = None) -> None:
    """Filled contours of a scalar over scattered positions (e.g. the passive potential), with
    a colour bar; nothing for fewer than 4 points or a constant."""
    pos = np.asarray(positions_m, dtype=float)
    val = np.asarray(values, dtype=float)
    if len(pos) < 4 or float(np.ptp(val)) <= 1e-9:
        return
    cs = ax.tricontourf(pos[:, 0], pos[:, 1], val, levels=levels, cmap="Greys", alpha=alpha)
    if fontsize is None:
        ax.figure.colorbar(cs, ax=ax, label=label, shrink=0.8)
        return
    cb = ax.figure.colorbar(cs, ax=ax, shrink=0.8, pad=0.02, fraction=0.05)
    cb.ax.tick_params(labelsize=fontsize - 1)
    cb.set_label(label, fontsize=fontsize)


def mark_shoulder(ax: Axes) -> None:
    ax.plot([0.0], [0.0], marker="o", color="k", markersize=6)
    ax.annotate("shoulder", (0.0, 0.0), textcoords="offset points", xytext=(5, -12), fontsize=8)


def field_row(axes: Sequence[Axes], grid_m: ArrayLike, before_n: ArrayLike, after_n: ArrayLike,
              label: str, *, potential_before_j: ArrayLike | None = None,
              potential_after_j: ArrayLike | None = None, mark_m: ArrayLike | None = None,
              spacing_m: float | None = None, fontsize: float = 9.0,
              key_at: tuple[float, float] = (0.82, -0.2)) -> None:
    """Three panels: the field before, after (one arrow scale) and after − before (its own
    scale, from a higher percentile, shown by its key), over the potential when given.

    Parameters
    ----------
    axes : three Axes
    grid_m : array_like, shape (N, 2), m
    before_n, after_n : array_like, shape (N, 2), N
    label : what the row shows, in each panel's title
    potential_before_j, potential_after_j : array_like, shape (N,), J, optional
        Contours of U (ΔU in the difference panel).
    mark_m : array_like, shape (2,), m, optional
        A point marked '+' in every panel (the rest hand position).
    spacing_m : float, optional
        Grid spacing for the arrow scale (default :func:`grid_spacing`).
    """
    grid = np.asarray(grid_m, dtype=float)
    fb, fa = np.asarray(before_n, dtype=float), np.asarray(after_n, dtype=float)
    spacing = grid_spacing(grid) if spacing_m is None else spacing_m
    ub = None if potential_before_j is None else np.asarray(potential_before_j, dtype=float)
    ua = None if potential_after_j is None else np.asarray(potential_after_j, dtype=float)
    d = fa - fb
    scale = arrow_scale(np.vstack([fb, fa]), spacing)
    panels = ((fb, ub, scale, f"before: {label}", "C0", "U (J)"),
              (fa, ua, scale, f"after: {label}", "C0", "U (J)"),
              (d, None if ub is None or ua is None else ua - ub, arrow_scale(d, spacing, 98.0),
               f"after − before: {label}", "C3", "ΔU (J)"))
    for ax, (f, u, sc, title, color, ulabel) in zip(axes, panels, strict=True):
        if u is not None:
            contours(ax, grid, u, ulabel, levels=10, alpha=0.55, fontsize=fontsize - 2)
        if float(np.abs(f).max()) < 1e-9:
            ax.text(0.5, 0.5, "no change", transform=ax.transAxes, ha="center",
                    fontsize=fontsize + 1)
            ax.set_xlim(float(grid[:, 0].min()), float(grid[:, 0].max()))
            ax.set_ylim(float(grid[:, 1].min()), float(grid[:, 1].max()))
        else:
            q = ax.quiver(grid[:, 0], grid[:, 1], f[:, 0], f[:, 1], angles="xy",
                          scale_units="xy", scale=sc, width=0.005, color=color)
            key_n = float(f"{sc * ARROW_FILL * spacing:.2g}")
            ax.quiverkey(q, key_at[0], key_at[1], key_n, f"{key_n:g} N", labelpos="E",
                         fontproperties={"size": fontsize - 2})
        if mark_m is not None:
            ax.plot(*np.asarray(mark_m, dtype=float), "k+", ms=8)
        spatial_axes(ax, title, fontsize)


# --- output -------------------------------------------------------------------------------
def render(fig: Figure, fmt: str = "png", dpi: float = 110, tight: bool = True) -> bytes:
    """The figure as PNG or SVG bytes, deterministic (no software tag, date or random ids);
    the figure is closed."""
    plt = pyplot()
    kind = fmt.lower()
    if kind not in FORMATS:
        raise ValueError(f"plot format must be one of {', '.join(FORMATS)}; got {kind!r}.")
    metadata: dict[str, Any] = {"Software": None} if kind == "png" else {"Date": None,
                                                                        "Creator": None}
    buf = io.BytesIO()
    try:
        with plt.rc_context({"svg.hashsalt": "fieldbank", "svg.fonttype": "path"}):
            fig.savefig(buf, format=kind, metadata=metadata, dpi=dpi,
                        bbox_inches="tight" if tight else None)
    finally:
        plt.close(fig)
    return buf.getvalue()


def save(fig: Figure, path: str | Path, fmt: str | None = None, dpi: float = 110) -> Path:
    """Write the figure as PNG or SVG (format from ``fmt`` or the suffix), deterministic bytes,
    through a temporary file; returns the path."""
    p = Path(path)
    write_atomic(p, render(fig, fmt or p.suffix.lstrip("."), dpi))
    return p
