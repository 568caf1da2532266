"""Plots of force fields: quiver fields, stiffness ellipses and potential contours.

Drawn with matplotlib's Agg backend (no screen needed) into a given Axes, so callers compose
figures (before/after/difference, measured against fitted). :func:`save` writes PNG or SVG
deterministically (fixed metadata and SVG hash salt), so the same input gives the same bytes.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import EllipseCollection
from matplotlib.figure import Figure
from numpy.typing import ArrayLike

from fieldbank.maps import ellipse

FORMATS = ("png", "svg")


def new_figure(ncols: int = 1, size_in: tuple[float, float] = (5.5, 5.0)) -> tuple[Figure, Any]:
    fig, axes = plt.subplots(1, ncols, figsize=(size_in[0] * ncols, size_in[1]), squeeze=False)
    for ax in axes[0]:
        ax.set_aspect("equal")
        ax.set_xlabel("x (m, +right)")
        ax.set_ylabel("y (m, +forward)")
    return fig, axes[0]


def quiver(ax: Axes, positions_m: ArrayLike, force_n: ArrayLike, color: str = "C0",
           label: str | None = None, scale_n_per_m: float | None = None) -> float:
    """Force arrows at positions; returns the scale used (N per m of arrow length)."""
    pos = np.asarray(positions_m, dtype=float)
    f = np.asarray(force_n, dtype=float)
    if scale_n_per_m is None:
        span = float(np.ptp(pos, axis=0).max()) if len(pos) > 1 else 0.1
        fmax = float(np.abs(f).max()) or 1.0
        scale_n_per_m = fmax / (0.08 * max(span, 0.05))
    ax.quiver(pos[:, 0], pos[:, 1], f[:, 0], f[:, 1], color=color, angles="xy",
              scale_units="xy", scale=scale_n_per_m, width=0.004, label=label)
    return scale_n_per_m


def ellipses(ax: Axes, positions_m: ArrayLike, stiffness_n_per_m: ArrayLike, color: str = "C1",
             label: str | None = None, scale_n_per_m: float | None = None) -> float:
    """Stiffness ellipses (symmetric part of K) centred at the positions; returns the scale."""
    pos = np.asarray(positions_m, dtype=float)
    e = ellipse(stiffness_n_per_m)
    major = np.abs(e.major_n_per_m)
    minor = np.abs(e.minor_n_per_m)
    if scale_n_per_m is None:
        span = float(np.ptp(pos, axis=0).max()) if len(pos) > 1 else 0.1
        spacing = span / max(np.sqrt(len(pos)), 1.0)
        scale_n_per_m = (float(major.max()) or 1.0) / (0.9 * max(spacing, 0.01))
    coll = EllipseCollection(
        major / scale_n_per_m, minor / scale_n_per_m, np.degrees(e.orientation_rad),
        units="xy", offsets=pos, offset_transform=ax.transData, facecolors="none",
        edgecolors=color, linewidths=1.0, label=label,
    )
    ax.add_collection(coll)
    ax.autoscale_view()
    return scale_n_per_m


def contours(ax: Axes, positions_m: ArrayLike, values: ArrayLike, label: str = "U (J)") -> None:
    """Filled contours of a scalar over scattered positions (e.g. the passive potential)."""
    pos = np.asarray(positions_m, dtype=float)
    val = np.asarray(values, dtype=float)
    if len(pos) < 4:
        return
    cs = ax.tricontourf(pos[:, 0], pos[:, 1], val, levels=12, cmap="Greys", alpha=0.5)
    ax.figure.colorbar(cs, ax=ax, label=label, shrink=0.8)


def mark_shoulder(ax: Axes) -> None:
    ax.plot([0.0], [0.0], marker="o", color="k", markersize=6)
    ax.annotate("shoulder", (0.0, 0.0), textcoords="offset points", xytext=(5, -12), fontsize=8)


def save(fig: Figure, path: str | Path, fmt: str | None = None) -> Path:
    """Write the figure as PNG or SVG (format from ``fmt`` or the suffix), deterministic bytes."""
    p = Path(path)
    kind = (fmt or p.suffix.lstrip(".")).lower()
    if kind not in FORMATS:
        raise ValueError(f"plot format must be one of {', '.join(FORMATS)}; got {kind!r}.")
    with plt.rc_context({"svg.hashsalt": "fieldbank", "svg.fonttype": "path"}):
        metadata: dict[str, Any] = {"Software": None} if kind == "png" else {"Date": None}
        if kind == "svg":
            metadata["Creator"] = None
        fig.savefig(p, format=kind, metadata=metadata, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return p
