"""Report figures as PNG bytes (drawn through :mod:`fieldbank.plotting`; deterministic).

Each function draws one figure from already computed arrays and returns the PNG bytes:
postural fields before / after / difference over the passive potential, stiffness ellipses
before and after, severity per muscle group (passive and dynamic), probing force profiles and
the botulinum time course. Sizes are small (the report holds several per case) and every scale
is shared between the before and after panels, so they can be compared by eye.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from fieldbank import plotting
from fieldbank.model import Arm, FloatArray

if TYPE_CHECKING:  # typing only: matplotlib loads with the first figure
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

DPI = 72
PANEL_IN = (3.6, 3.2)


def png_bytes(fig: Figure) -> bytes:
    """The figure as PNG bytes at the report's resolution, with its fixed margins."""
    return plotting.render(fig, "png", dpi=DPI, tight=False)


def _panels(n: int, size_in: tuple[float, float] = PANEL_IN,
            left_in: float = 0.5) -> tuple[Figure, list[Axes]]:
    fig = plotting.pyplot().figure(figsize=(size_in[0] * n, size_in[1]))
    # Fixed margins instead of a layout engine: constrained layout doubled the drawing time.
    fig.subplots_adjust(left=left_in / (size_in[0] * n), right=1 - 0.15 / (size_in[0] * n),
                        bottom=0.55 / size_in[1], top=1 - 0.35 / size_in[1],
                        wspace=0.35 if n > 1 else 0.2)
    axes = list(fig.subplots(1, n, squeeze=False)[0])
    return fig, axes


def fields_figure(arm_b: Arm, arm_a: Arm, grid_m: FloatArray, speed_m_per_s: float,
                  n_directions: int = 8) -> bytes:
    """Endpoint force field before, after and after − before; two rows.

    Row 1: static (postural) field over contours of the passive potential U (ΔU in the
    difference panel). Row 2: the field with the hand moving at ``speed_m_per_s``, where the
    stretch reflex acts, in the one of ``n_directions`` evenly spread directions where the
    field changes most (the reflex acts on lengthening muscles only, so a flexor injection
    shows when the elbow extends and an extensor injection when it flexes).
    """
    fig = plotting.pyplot().figure(figsize=(PANEL_IN[0] * 3, PANEL_IN[1] * 2))
    fig.subplots_adjust(left=0.05, right=0.98, bottom=0.09, top=0.95, wspace=0.3, hspace=0.4)
    axes = fig.subplots(2, 3, squeeze=False)
    rest = arm_b.rest_position()
    plotting.field_row(axes[0], grid_m, arm_b.endpoint_force(grid_m),
                       arm_a.endpoint_force(grid_m), "static F, U",
                       potential_before_j=arm_b.potential(grid_m),
                       potential_after_j=arm_a.potential(grid_m), mark_m=rest)
    best: tuple[float, int, FloatArray, FloatArray] | None = None
    for k in range(n_directions):
        th = 2.0 * np.pi * k / n_directions
        v = np.tile([speed_m_per_s * np.cos(th), speed_m_per_s * np.sin(th)],
                    (grid_m.shape[0], 1))
        fb, fa = arm_b.endpoint_force(grid_m, v), arm_a.endpoint_force(grid_m, v)
        rms = float(np.sqrt(np.mean((fa - fb) ** 2)))
        if best is None or rms > best[0] + 1e-12:
            best = (rms, k, fb, fa)
    assert best is not None
    deg = 360.0 * best[1] / n_directions
    plotting.field_row(axes[1], grid_m, best[2], best[3],
                       f"F moving {speed_m_per_s:g} m/s at {deg:g}°", mark_m=rest)
    return png_bytes(fig)


def ellipses_figure(grid_m: FloatArray, k_before: FloatArray, k_after: FloatArray) -> bytes:
    """Static stiffness ellipses before and after, on one scale."""
    fig, axes = _panels(2)
    scale = plotting.ellipse_scale(np.concatenate([k_before, k_after]),
                                   plotting.grid_spacing(grid_m))
    for ax, k, title, color in ((axes[0], k_before, "stiffness before", "C0"),
                                (axes[1], k_after, "stiffness after", "C1")):
        plotting.ellipses(ax, grid_m, k, color=color, scale_n_per_m=scale)
        ax.plot(grid_m[:, 0], grid_m[:, 1], ".", color="0.7", ms=2)
        plotting.spatial_axes(ax, f"{title} (axis ∝ N/m)")
    return png_bytes(fig)


def severity_figure(groups: Sequence[str], before: Mapping[str, Sequence[float]],
                    after: Mapping[str, Sequence[float]], levels: Sequence[str]) -> bytes:
    """Severity score per muscle group before and after (0 unimpaired … 4 severe), passive
    (solid) and dynamic (hatched); ``before`` and ``after`` map a component to the scores."""
    fig, axes = _panels(1, (7.2, 2.9), left_in=0.9)
    ax = axes[0]
    x = np.arange(len(groups))
    width = 0.2
    bars = (("passive", "before", "C0", ""), ("passive", "after", "C1", ""),
            ("dynamic", "before", "C0", "///"), ("dynamic", "after", "C1", "///"))
    top = 0.0
    for k, (comp, when, color, hatch) in enumerate(bars):
        values = (before if when == "before" else after)[comp]
        top = max(top, float(max(values, default=0.0)))
        ax.bar(x + (k - 1.5) * width, values, width, color=color, hatch=hatch,
               edgecolor="white" if not hatch else "0.2", linewidth=0.4,
               label=f"{comp} {when}")
    ax.set_xticks(x, list(groups), fontsize=8)
    ax.set_yticks(range(len(levels)), list(levels), fontsize=7)
    # headroom above "severe" for the legend
    ax.set_ylim(0, max(len(levels) + 0.4, top + 1.2))
    ax.set_title("severity per muscle group: passive (solid), dynamic (hatched)", fontsize=9)
    ax.legend(fontsize=6, loc="upper center", ncol=4, frameon=False)
    return png_bytes(fig)


def probes_figure(profiles: Sequence[tuple[str, FloatArray, FloatArray, FloatArray]]) -> bytes:
    """|force| along each probing motion: (name, times s, |F| before N, |F| after N)."""
    fig, axes = _panels(len(profiles), (3.6, 2.8))
    for ax, (name, t, fb, fa) in zip(axes, profiles, strict=True):
        ax.plot(t, fb, "C0-", label="before")
        ax.plot(t, fa, "C1--", label="after")
        ax.set_title(f"probing: {name}", fontsize=9)
        ax.set_xlabel("time (s)", fontsize=8)
        ax.set_ylabel("|force| (N)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=7)
    return png_bytes(fig)


def timecourse_figure(weeks: FloatArray, effect: Mapping[str, FloatArray],
                      probe_peak_n: Mapping[str, FloatArray]) -> bytes:
    """Botulinum effect per injected group and probing peak force, week by week."""
    fig, axes = _panels(2, (3.8, 2.8))
    for g in sorted(effect):
        axes[0].plot(weeks, 100.0 * np.asarray(effect[g]), label=g)
    axes[0].set_title("botulinum effect (drop of α)", fontsize=9)
    axes[0].set_ylabel("%", fontsize=8)
    for name in sorted(probe_peak_n):
        axes[1].plot(weeks, probe_peak_n[name], label=name)
    axes[1].set_title("probing peak force after", fontsize=9)
    axes[1].set_ylabel("N", fontsize=8)
    for ax in axes:
        ax.set_xlabel("weeks since injection", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=7)
    return png_bytes(fig)
