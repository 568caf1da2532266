"""The accuracy-vs-delay figure: how well the simulated trainee names the impaired group and
the severity through a link with growing one-way delay (``benchmarks/bench_remote_perception.py``
draws it; docs/remote.md shows it), on the product's one figure system
(:mod:`fieldbank.figures`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from fieldbank.figures.panel import Panel
from fieldbank.figures.scene import Scene
from fieldbank.figures.style import GREY, SERIES

#: The delays a perception figure is drawn on a log-like axis from (0 ms sits at its left end).
ZERO_AT_MS = 1.0


def _x(ms: float) -> float:
    return float(np.log10(max(ms, ZERO_AT_MS)))


def accuracy_vs_delay(rows: Sequence[Mapping[str, Any]], direct: Mapping[str, Any] | None,
                      title: str, noticed_ms: Sequence[tuple[float, str]] = ()) -> Scene:
    """Group and severity accuracy (with their binomial 95 % intervals) against the one-way
    delay; the accuracy without any link as dashed lines; chance; the delays people notice
    (``noticed_ms``: (ms, label)) as vertical marks.

    Each row: ``delay_ms``, ``group_accuracy``, ``group_ci``, ``severity_accuracy``,
    ``severity_ci`` (the intervals as (low, high)), ``n``.
    """
    scene = Scene(760, 450, title)
    xs = [_x(r["delay_ms"]) for r in rows]
    panel = Panel.at(scene, (70, 46, 600, 310), (min(xs) - 0.15, max(xs) + 0.15), (0.0, 1.05))
    ticks = [r["delay_ms"] for r in rows]
    panel.frame(title, "one-way delay of the link (ms; 0 drawn at 1)", "share of trials right",
                xticks=[_x(t) for t in ticks], xtick_labels=[f"{t:g}" for t in ticks],
                yticks=[0, 0.25, 1 / 3, 0.5, 0.75, 1.0],
                ytick_labels=["0", "0.25", "chance", "0.5", "0.75", "1"])
    panel.hline(1 / 3, GREY, 1.0, dash=(3, 3))
    for k, (ms, label) in enumerate(noticed_ms):   # staggered: marks may stand close together
        panel.vline(_x(ms), GREY, 1.0, dash=(2, 4))
        scene.text(float(panel.tx(_x(ms))) + 3, panel.y + 12 + 13 * k, label, 10, "start",
                   "middle", GREY)
    series = [("group", "impaired group", SERIES[0]), ("severity", "severity", SERIES[1])]
    legend = []
    for key, label, colour in series:
        acc = [r[f"{key}_accuracy"] for r in rows]
        lo = [r[f"{key}_ci"][0] for r in rows]
        hi = [r[f"{key}_ci"][1] for r in rows]
        panel.band(xs, lo, hi, colour, opacity=0.15)
        panel.line(xs, acc, colour, 2.0)
        panel.markers(xs, acc, "circle", colour, 4.5)
        legend.append((f"{label} (95 % interval shaded)", {"stroke": colour, "width": 2.0}))
        if direct is not None:
            panel.hline(direct[f"{key}_accuracy"], colour, 1.0, dash=(6, 4))
            legend.append((f"{label}, no link", {"stroke": colour, "width": 1.0,
                                                 "dash": (6, 4)}))
    below = scene.legend(panel.x + 8, panel.y + panel.h + 44, legend,
                         max_width=panel.w - 8)
    n = rows[0].get("n") if rows else None
    if n:
        scene.text(panel.x + 8, below + 12, f"{n} assessment trials per delay; dotted: the "
                   "delay people notice in each kind of environment (Rank et al. 2010)", 10,
                   "start", "middle", GREY)
    return scene
