"""matplotlib helpers (force arrows, stiffness ellipses, deterministic PNG or SVG output) and
the scaling rules every field figure shares.

The report, ``whatif --plot`` and ``field --out`` draw with :mod:`fieldbank.svgplot` and
:mod:`fieldbank.fieldplot` (vector graphics written directly; PNG and PDF through matplotlib
only when asked); the fit and probe figures (measured against fitted, probing paths) draw
with matplotlib through the helpers here. matplotlib is loaded the first time such a figure is
made (:func:`pyplot`), with the Agg backend (no screen needed), chosen there once; importing
this module loads nothing, so commands and worker processes that never draw never pay for it.
Both kinds share two scaling rules, so every figure reads the same way:

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
