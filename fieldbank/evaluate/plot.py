"""Figures of probing motions: the paths with the force each candidate puts on the handle, the
force profiles along them, and a recorded trace against the candidates' predictions.

Drawn with :mod:`fieldbank.plotting` (matplotlib loads with the first figure). Candidates keep
one colour per impaired group (shoulder, elbow, bi-articular, unimpaired) and one line style per
severity, in every panel and figure, so a clinician reads "which group" by colour and "how
severe" by line.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from fieldbank import plotting
from fieldbank.evaluate.classify import Classification
from fieldbank.evaluate.design import Candidate, ProbeSetScore
from fieldbank.model import Arm

if TYPE_CHECKING:  # typing only: matplotlib loads with the first figure
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

GROUP_COLOURS = {"shoulder": "#1f77b4", "elbow": "#d62728", "biarticular": "#2ca02c",
                 "unimpaired": "#7f7f7f"}
OTHER_COLOURS = ("#9467bd", "#8c564b", "#e377c2", "#bcbd22", "#17becf", "#ff7f0e")
LEVEL_STYLES = {"severe": ("-", 2.2), "moderate": ("--", 1.8), "mild": ("-.", 1.5),
                "very mild": (":", 1.5), "unimpaired": ("-", 1.2)}
#: Arrows drawn along each path per candidate.
ARROWS_PER_PATH = 7


def _styles(candidates: Sequence[Candidate]) -> list[tuple[str, str, float]]:
    """(colour, line style, width) per candidate."""
    out = []
    others = iter(OTHER_COLOURS * 4)
    for c in candidates:
        colour = GROUP_COLOURS.get(c.label) or next(others)
        style, width = LEVEL_STYLES.get(c.level or "", ("-", 1.8))
        out.append((colour, style, width))
    return out


def draw_arm(ax: Axes, arm: Arm, q: Sequence[float] | None = None, colour: str = "0.75") -> None:
    """The upper arm and forearm at posture q (default: rest), shoulder at the origin."""
    qq = np.asarray(arm.q_rest if q is None else q, dtype=float)
    elbow = np.array([arm.l1 * math.cos(qq[0]), arm.l1 * math.sin(qq[0])])
    if arm.mirror:
        elbow[0] = -elbow[0]
    hand = arm.fk(qq)[0]
    ax.plot([0.0, elbow[0], hand[0]], [0.0, elbow[1], hand[1]], color=colour, lw=5,
            solid_capstyle="round", zorder=0)
    ax.plot([0.0, elbow[0]], [0.0, elbow[1]], "o", color=colour, ms=7, zorder=0)


def _panel_box(score: ProbeSetScore) -> tuple[np.ndarray, float]:
    """Centre and half-width (m) of a square view around every probe's path."""
    pts = np.vstack([p.motion.positions_m for p in score.probes])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    half = max(0.06, 0.5 * float((hi - lo).max()) + 0.04)
    return 0.5 * (lo + hi), half


def _path_panel(ax: Axes, score: ProbeSetScore, k: int, candidates: Sequence[Candidate],
                styles: Sequence[tuple[str, str, float]], scale_n_per_m: float,
                centre: np.ndarray, half: float) -> None:
    probe = score.probes[k]
    pos = probe.motion.positions_m
    draw_arm(ax, candidates[0].arm)
    ax.plot(pos[:, 0], pos[:, 1], color="k", lw=1.5)
    ax.plot(pos[0, 0], pos[0, 1], "o", color="k", ms=5)
    ax.annotate("", xy=pos[-1], xytext=pos[-4], arrowprops={"arrowstyle": "-|>", "color": "k"})
    idx = np.linspace(len(pos) // 8, len(pos) - 1, ARROWS_PER_PATH).astype(int)
    for i, (colour, _style, _w) in enumerate(styles):
        f = probe.force_n[i, idx]
        ax.quiver(pos[idx, 0], pos[idx, 1], f[:, 0], f[:, 1], color=colour, angles="xy",
                  scale_units="xy", scale=scale_n_per_m, width=0.007, alpha=0.85)
    key_n = float(f"{scale_n_per_m * 0.4 * half:.2g}")
    x0, y0 = centre[0] - 0.9 * half, centre[1] - 0.88 * half
    ax.quiver([x0], [y0], [key_n], [0.0], color="k", angles="xy", scale_units="xy",
              scale=scale_n_per_m, width=0.007)
    ax.annotate(f"{key_n:g} N", (x0 + key_n / scale_n_per_m + 0.005, y0 - 0.004), fontsize=7,
                va="center")
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    plotting.spatial_axes(ax, f"{probe.name}: path and force on the handle", 9.0)


def _directions(force_n: np.ndarray, floor_n: float) -> np.ndarray:
    """Directions in degrees, blank below ``floor_n`` and where they wrap round ±180°, so no
    line crosses the panel."""
    mag = np.hypot(force_n[:, 0], force_n[:, 1])
    ang = np.where(mag >= floor_n, np.degrees(np.arctan2(force_n[:, 1], force_n[:, 0])), np.nan)
    jump = np.r_[False, np.abs(np.diff(ang)) > 180.0]
    return np.where(jump, np.nan, ang)


def _profile_panels(ax_mag: Axes, ax_dir: Axes, times: np.ndarray, forces: np.ndarray,
                    styles: Sequence[tuple[str, str, float]], names: Sequence[str],
                    floor_n: float, recorded: np.ndarray | None = None,
                    recorded_times: np.ndarray | None = None) -> None:
    for f, (colour, style, width), name in zip(forces, styles, names, strict=True):
        mag = np.hypot(f[:, 0], f[:, 1])
        ax_mag.plot(times, mag, color=colour, ls=style, lw=width, label=name)
        ax_dir.plot(times, _directions(f, floor_n), color=colour, ls=style, lw=width)
    if recorded is not None and recorded_times is not None:
        mag = np.hypot(recorded[:, 0], recorded[:, 1])
        ax_mag.plot(recorded_times, mag, color="k", lw=0.8, alpha=0.6, label="recorded")
        ax_dir.plot(recorded_times, _directions(recorded, floor_n), color="k", lw=0.8,
                    alpha=0.6)
    ax_mag.set_ylabel("force magnitude (N)", fontsize=8)
    ax_dir.set_ylabel(f"force direction (° from +x;\nshown where ≥ {floor_n:g} N)", fontsize=8)
    ax_dir.set_xlabel("time (s)", fontsize=8)
    ax_dir.set_ylim(-180, 180)
    ax_dir.set_yticks([-180, -90, 0, 90, 180])
    for ax in (ax_mag, ax_dir):
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)


def probe_figure(score: ProbeSetScore, candidates: Sequence[Candidate],
                 title: str = "") -> Figure:
    """One column per probe: the path with each candidate's force along it (one arrow scale),
    the force magnitude and the force direction over time."""
    plt = plotting.pyplot()
    ncol = len(score.probes)
    fig, axes = plt.subplots(3, ncol, figsize=(4.6 * ncol, 11.0), squeeze=False,
                             gridspec_kw={"height_ratios": [1.5, 1.0, 1.0]})
    styles = _styles(candidates)
    centre, half = _panel_box(score)
    peak = max(float(np.hypot(p.force_n[..., 0], p.force_n[..., 1]).max())
               for p in score.probes)
    scale = max(peak, 1e-6) / (0.6 * half)  # the largest force spans 30 % of the view
    for k, probe in enumerate(score.probes):
        _path_panel(axes[0][k], score, k, candidates, styles, scale, centre, half)
        _profile_panels(axes[1][k], axes[2][k], probe.motion.times_s, probe.force_n, styles,
                        score.candidates, score.perception.floor_n)
        axes[1][k].set_title(_wrap_words(probe.motion.description, 60), fontsize=8)
    handles, labels = axes[1][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=min(6, len(labels)), fontsize=8,
               frameon=False)
    s = score.summary()
    head = title or "probing motions"
    fig.suptitle(f"{head}: {s['information_bits']:.2f} of {s['information_max_bits']:.2f} bits "
                 f"about the {score.target}; closest pair felt {s['worst_felt_jnd']:.1f} JND "
                 "apart", fontsize=10)
    fig.tight_layout(rect=(0.0, 0.05, 1.0, 0.96))
    return fig


def classification_figure(cl: Classification, top: int = 4) -> Figure:
    """Per observation the recorded force against the most probable candidates' predictions
    (magnitude and direction), and the posterior of every candidate."""
    plt = plotting.pyplot()
    nobs = len(cl.observations)
    fig, axes = plt.subplots(3, nobs + 1, figsize=(4.4 * (nobs + 1), 8.5), squeeze=False,
                             gridspec_kw={"height_ratios": [1.0, 1.0, 0.05]})
    order = np.argsort(-cl.posterior, kind="stable")[:top]
    cands = [cl.candidates[k] for k in order]
    styles = _styles(cands)
    names = [f"{c.name} (p = {cl.posterior[k]:.2g})" for c, k in zip(cands, order, strict=True)]
    floor = 1.0
    for j, (o, pred) in enumerate(zip(cl.observations, cl.predictions, strict=True)):
        # the recorded force only where the likelihood counts it (one model rendered alone)
        rec = o.force_n if o.counted is None else np.where(o.counted[:, None], o.force_n, np.nan)
        _profile_panels(axes[0][j], axes[1][j], o.times_s, pred[order], styles, names, floor,
                        rec, o.times_s)
        axes[0][j].set_title(f"{o.name}: recorded and predicted", fontsize=9)
        axes[2][j].axis("off")
    ax = axes[0][nobs]
    allc = np.argsort(-cl.posterior, kind="stable")
    colours = [s[0] for s in _styles([cl.candidates[k] for k in allc])]
    ax.barh(range(len(allc)), cl.posterior[allc], color=colours)
    ax.set_yticks(range(len(allc)), [cl.candidates[k].name for k in allc], fontsize=7)
    ax.invert_yaxis()
    ax.set_xlim(0, 1)
    ax.set_xlabel("posterior probability", fontsize=8)
    ax.set_title("which candidate", fontsize=9)
    ax.tick_params(labelsize=7)
    ax2 = axes[1][nobs]
    groups = cl.group_posterior
    gcol = [GROUP_COLOURS.get(g, "0.5") for g in groups]
    ax2.bar(range(len(groups)), list(groups.values()), color=gcol)
    ax2.set_xticks(range(len(groups)), list(groups), fontsize=8)
    ax2.set_ylim(0, 1)
    ax2.set_ylabel("probability", fontsize=8)
    ax2.set_title("which group", fontsize=9)
    ax2.tick_params(labelsize=7)
    axes[2][nobs].axis("off")
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=min(5, len(labels)), fontsize=8,
               frameon=False)
    fig.suptitle(_wrap_words(cl.verdict(), 110), fontsize=10)
    fig.tight_layout(rect=(0.0, 0.04, 1.0, 0.95))
    return fig


def _wrap_words(text: str, width: int) -> str:
    return "\n".join(textwrap.wrap(text, width))
