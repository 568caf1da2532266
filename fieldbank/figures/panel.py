"""Panels: a box of a scene showing a data range, with its frame, ticks and labels; colour bars.

A :class:`Panel` maps data coordinates (y up) into a box of a :class:`~fieldbank.figures.scene.
Scene` (y down) and draws in data coordinates: lines, bands, markers, bars; :meth:`Panel.frame`
draws the frame, ticks (:func:`fieldbank.figures.style.nice_ticks`), tick labels, axis labels
and the title.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from fieldbank.figures.scene import Scene, marker_at
from fieldbank.figures.style import (
    FONT,
    FONT_SMALL,
    FONT_TITLE,
    GREY,
    TEXT,
    FloatArray,
    nice_ticks,
    text_width,
    tick_label,
)


@dataclass(eq=False)
class Panel:
    """A box of a scene (``x``, ``y``, ``w``, ``h`` px: the plotting area) showing the data
    range [x0, x1] × [y0, y1]; y up. ``clip`` clips what is drawn to the box."""

    scene: Scene
    x: float
    y: float
    w: float
    h: float
    x0: float
    x1: float
    y0: float
    y1: float
    clip: int | None = None

    @classmethod
    def at(cls, scene: Scene, box: tuple[float, float, float, float],
           xlim: tuple[float, float], ylim: tuple[float, float], equal: bool = False,
           clip: bool = True) -> Panel:
        """A panel in ``box``; ``equal``: one metre is as long on both axes (the limits
        grow about their centre to fill the box)."""
        x, y, w, h = box
        (x0, x1), (y0, y1) = xlim, ylim
        if x1 <= x0:
            x0, x1 = x0 - 0.5, x0 + 0.5
        if y1 <= y0:
            y0, y1 = y0 - 0.5, y0 + 0.5
        if equal:
            s = max((x1 - x0) / w, (y1 - y0) / h)
            cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
            x0, x1 = cx - 0.5 * s * w, cx + 0.5 * s * w
            y0, y1 = cy - 0.5 * s * h, cy + 0.5 * s * h
        c = scene.clip_rect(x, y, w, h) if clip else None
        return cls(scene, x, y, w, h, x0, x1, y0, y1, c)

    @property
    def px_per_x(self) -> float:
        return self.w / (self.x1 - self.x0)

    @property
    def px_per_y(self) -> float:
        return self.h / (self.y1 - self.y0)

    def tx(self, v: ArrayLike) -> FloatArray:
        return self.x + (np.asarray(v, dtype=float) - self.x0) * self.px_per_x

    def ty(self, v: ArrayLike) -> FloatArray:
        return self.y + self.h - (np.asarray(v, dtype=float) - self.y0) * self.px_per_y

    def pts(self, x: ArrayLike, y: ArrayLike) -> FloatArray:
        return np.stack([self.tx(x).reshape(-1), self.ty(y).reshape(-1)], axis=1)

    def xy(self, points: ArrayLike) -> FloatArray:
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        return self.pts(p[:, 0], p[:, 1])

    # drawing in data coordinates
    def line(self, x: ArrayLike, y: ArrayLike, colour: str = TEXT, width: float = 1.5,
             dash: tuple[float, ...] | None = None, opacity: float = 1.0,
             data: Mapping[str, str] | None = None) -> None:
        self.scene.lines([self.pts(x, y)], colour, width, dash=dash, opacity=opacity,
                         clip=self.clip, data=data)

    def band(self, x: ArrayLike, lo: ArrayLike, hi: ArrayLike, colour: str,
             opacity: float = 0.2, data: Mapping[str, str] | None = None) -> None:
        top = self.pts(x, hi)
        bottom = self.pts(x, lo)[::-1]
        self.scene.lines([np.vstack([top, bottom])], None, fill=colour, opacity=opacity,
                         closed=True, clip=self.clip, data=data)

    def hline(self, y: float, colour: str = GREY, width: float = 1.0,
              dash: tuple[float, ...] | None = (4, 3)) -> None:
        py = float(self.ty(y))
        self.scene.line([[self.x, py], [self.x + self.w, py]], colour, width, dash=dash,
                        clip=self.clip)

    def vline(self, x: float, colour: str = GREY, width: float = 1.0,
              dash: tuple[float, ...] | None = (4, 3)) -> None:
        px = float(self.tx(x))
        self.scene.line([[px, self.y], [px, self.y + self.h]], colour, width, dash=dash,
                        clip=self.clip)

    def markers(self, x: ArrayLike, y: ArrayLike, marker: str = "circle",
                colour: str = TEXT, size: float = 5.0,
                data: Mapping[str, str] | None = None) -> None:
        marker_at(self.scene, self.pts(x, y), marker, colour, size, data)

    def note(self, text: str, size: float = FONT) -> None:
        """A message in the middle of the panel (e.g. 'no change')."""
        self.scene.text(self.x + self.w / 2, self.y + self.h / 2, text, size, "middle",
                        "middle", GREY)

    def frame(self, title: str = "", xlabel: str = "", ylabel: str = "",
              xticks: Sequence[float] | None = None, yticks: Sequence[float] | None = None,
              xtick_labels: Sequence[str] | None = None,
              ytick_labels: Sequence[str] | None = None, grid: bool = True,
              title_size: float = FONT_TITLE, title_colour: str = TEXT) -> None:
        """Frame, ticks (default :func:`nice_ticks`), tick labels, axis labels and title."""
        s = self.scene
        xt = list(nice_ticks(self.x0, self.x1, max(3, int(self.w // 70))) if xticks is None
                  else xticks)
        yt = list(nice_ticks(self.y0, self.y1, max(3, int(self.h // 45))) if yticks is None
                  else yticks)
        xl = list(xtick_labels) if xtick_labels is not None else [tick_label(v, xt) for v in xt]
        yl = list(ytick_labels) if ytick_labels is not None else [tick_label(v, yt) for v in yt]
        bottom = self.y + self.h
        if grid:
            s.lines([[[self.x, float(self.ty(v))], [self.x + self.w, float(self.ty(v))]]
                     for v in yt], "#ececec", 1.0)
        s.lines([[[float(self.tx(v)), bottom], [float(self.tx(v)), bottom + 4]] for v in xt]
                + [[[self.x - 4, float(self.ty(v))], [self.x, float(self.ty(v))]]
                   for v in yt], TEXT, 1.0)
        for v, lab in zip(xt, xl, strict=True):
            s.text(float(self.tx(v)), bottom + 6, lab, FONT_SMALL, "middle", "hanging")
        for v, lab in zip(yt, yl, strict=True):
            s.text(self.x - 6, float(self.ty(v)), lab, FONT_SMALL, "end", "middle")
        s.lines([[[self.x, self.y], [self.x + self.w, self.y], [self.x + self.w, bottom],
                  [self.x, bottom]]], "#555555", 1.0, closed=True)
        if xlabel:
            s.text(self.x + self.w / 2, bottom + 22, xlabel, FONT, "middle", "hanging")
        if ylabel:
            widest = max((text_width(t, FONT_SMALL) for t in yl), default=0.0)
            s.text(self.x - 12 - widest, self.y + self.h / 2, ylabel, FONT, "middle",
                   "alphabetic", rotate=90.0)
        if title:
            s.text(self.x, self.y - 8, title, title_size, "start", "alphabetic",
                   title_colour, bold=True)


def colour_bar(scene: Scene, box: tuple[float, float, float, float], lo: float, hi: float,
               colours: Sequence[str], label: str, ticks: Sequence[float] | None = None,
               labels: Callable[[float], str] | None = None) -> None:
    """A vertical colour bar in ``box`` for values lo … hi drawn with ``colours`` (bottom to
    top), tick labels on its right (``labels`` writes them; default :func:`tick_label`) and
    the label (with its unit) above."""
    x, y, w, h = box
    n = len(colours)
    step = h / n
    scene.rects([[x, y + h - (i + 1) * step, w, step + 0.3] for i in range(n)], colours)
    scene.lines([[[x, y], [x + w, y], [x + w, y + h], [x, y + h]]], "#555555", 0.8,
                closed=True)
    t = list(nice_ticks(lo, hi, 5) if ticks is None else ticks)
    for v in t:
        py = y + h - (v - lo) / (hi - lo) * h if hi > lo else y + h / 2
        scene.line([[x + w, py], [x + w + 3, py]], TEXT, 1.0)
        scene.text(x + w + 5, py, labels(v) if labels else tick_label(v, t), FONT_SMALL,
                   "start", "middle")
    scene.text(x, y - 8, label, FONT_SMALL, "start", "alphabetic")

