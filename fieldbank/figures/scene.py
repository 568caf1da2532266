"""A figure as a scene of primitives in pixels (y down, the SVG convention).

A :class:`Scene` is a description: polylines, polygons, rectangles, ellipses, circles and text,
in drawing order, clip rectangles, and small ``data`` pairs saying what the figure shows (for
readers and tests). It knows nothing of its writers: :mod:`fieldbank.figures.svg` writes it as
SVG text, :mod:`fieldbank.figures.raster` draws it as PNG or PDF, and
:func:`fieldbank.figures.save` picks one by the file's name. What this keeps small on purpose:
no layout engine (callers place panels, :mod:`fieldbank.figures.panel`), no text measurement
(widths are estimated, :func:`fieldbank.figures.style.text_width`).

Markers shared by every figure (:func:`marker_at`): ● the shoulder, ◎ the rest hand position,
▲ a catch.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from fieldbank.figures.style import FONT, FONT_SMALL, TEXT, Anchor, Baseline, FloatArray, text_width


@dataclass(eq=False)
class Lines:
    """Polylines (one SVG path): each a (K, 2) px array; ``closed`` ones are polygons."""

    paths: list[FloatArray]
    stroke: str | None = TEXT
    width: float = 1.0
    fill: str | None = None
    dash: tuple[float, ...] | None = None
    opacity: float = 1.0
    closed: bool = False
    clip: int | None = None
    attrs: dict[str, str] = field(default_factory=dict)


@dataclass(eq=False)
class Rects:
    """Axis-aligned rectangles (N, 4) px (x, y, w, h), each with its fill colour."""

    boxes: FloatArray
    fills: list[str]
    stroke: str | None = None
    width: float = 0.5
    clip: int | None = None
    attrs: dict[str, str] = field(default_factory=dict)


@dataclass(eq=False)
class Ellipses:
    """Ellipse outlines: centres (N, 2) px, full axis lengths (N, 2) px, angles (N,) degrees
    (counter-clockwise on the page), dashed where ``dashed``."""

    centres: FloatArray
    axes: FloatArray
    angles_deg: FloatArray
    stroke: str
    width: float = 1.0
    dashed: FloatArray | None = None
    clip: int | None = None
    attrs: dict[str, str] = field(default_factory=dict)


@dataclass(eq=False)
class Circles:
    """Circles (markers): centres (N, 2) px, radius px."""

    centres: FloatArray
    radius: float
    fill: str | None = TEXT
    stroke: str | None = None
    width: float = 1.0
    clip: int | None = None
    attrs: dict[str, str] = field(default_factory=dict)


@dataclass(eq=False)
class Text:
    x: float
    y: float
    text: str
    size: float = FONT
    anchor: Anchor = "start"
    baseline: Baseline = "alphabetic"
    colour: str = TEXT
    bold: bool = False
    rotate: float = 0.0  # degrees, counter-clockwise on the page


Item = Lines | Rects | Ellipses | Circles | Text


class Scene:
    """A figure: ``width`` × ``height`` px and its primitives, in drawing order.

    ``data`` are small key/value pairs written as ``data-*`` attributes of the root element
    (what a figure shows, for readers and tests).
    """

    def __init__(self, width: float, height: float, label: str = "") -> None:
        self.width = float(width)
        self.height = float(height)
        self.label = label
        self.items: list[Item] = []
        self.clips: list[tuple[float, float, float, float]] = []
        self.data: dict[str, str] = {}

    # primitives
    def clip_rect(self, x: float, y: float, w: float, h: float) -> int:
        self.clips.append((x, y, w, h))
        return len(self.clips) - 1

    def lines(self, paths: Iterable[ArrayLike], stroke: str | None = TEXT, width: float = 1.0,
              *, fill: str | None = None, dash: tuple[float, ...] | None = None,
              opacity: float = 1.0, closed: bool = False, clip: int | None = None,
              data: Mapping[str, str] | None = None) -> None:
        ps = [np.asarray(p, dtype=float).reshape(-1, 2) for p in paths]
        ps = [p for p in ps if len(p) >= 1 and np.all(np.isfinite(p))]
        if ps:
            self.items.append(Lines(ps, stroke, width, fill, dash, opacity, closed, clip,
                                    _attrs(data)))

    def line(self, xy: ArrayLike, stroke: str = TEXT, width: float = 1.0, *,
             dash: tuple[float, ...] | None = None, opacity: float = 1.0,
             clip: int | None = None, data: Mapping[str, str] | None = None) -> None:
        self.lines([xy], stroke, width, dash=dash, opacity=opacity, clip=clip, data=data)

    def polygon(self, xy: ArrayLike, fill: str, stroke: str | None = None, width: float = 1.0,
                data: Mapping[str, str] | None = None) -> None:
        self.lines([xy], stroke, width, fill=fill, closed=True, data=data)

    def rects(self, boxes: ArrayLike, fills: Sequence[str], stroke: str | None = None,
              width: float = 0.5, clip: int | None = None,
              data: Mapping[str, str] | None = None) -> None:
        b = np.asarray(boxes, dtype=float).reshape(-1, 4)
        if len(b):
            self.items.append(Rects(b, list(fills), stroke, width, clip, _attrs(data)))

    def rect(self, x: float, y: float, w: float, h: float, fill: str,
             stroke: str | None = None, width: float = 0.5) -> None:
        self.rects([[x, y, w, h]], [fill], stroke, width)

    def ellipses(self, centres: ArrayLike, axes: ArrayLike, angles_deg: ArrayLike, stroke: str,
                 width: float = 1.0, dashed: ArrayLike | None = None, clip: int | None = None,
                 data: Mapping[str, str] | None = None) -> None:
        c = np.asarray(centres, dtype=float).reshape(-1, 2)
        if len(c):
            self.items.append(Ellipses(
                c, np.asarray(axes, dtype=float).reshape(-1, 2),
                np.asarray(angles_deg, dtype=float).reshape(-1), stroke, width,
                None if dashed is None else np.asarray(dashed, dtype=bool).reshape(-1), clip,
                _attrs(data)))

    def circles(self, centres: ArrayLike, radius: float, fill: str | None = TEXT,
                stroke: str | None = None, width: float = 1.0, clip: int | None = None,
                data: Mapping[str, str] | None = None) -> None:
        c = np.asarray(centres, dtype=float).reshape(-1, 2)
        if len(c):
            self.items.append(Circles(c, radius, fill, stroke, width, clip, _attrs(data)))

    def text(self, x: float, y: float, text: str, size: float = FONT, anchor: Anchor = "start",
             baseline: Baseline = "alphabetic", colour: str = TEXT, bold: bool = False,
             rotate: float = 0.0) -> None:
        if text:
            self.items.append(Text(float(x), float(y), text, size, anchor, baseline, colour,
                                   bold, rotate))

    def legend(self, x: float, y: float, entries: Sequence[tuple[str, dict[str, Any]]],
               size: float = FONT_SMALL, gap: float = 18.0, max_width: float | None = None
               ) -> float:
        """Entries (label, style) in a row from (x, y) (y: the row's middle), wrapping at
        ``max_width``; style keys: ``stroke``, ``width``, ``dash`` (a line sample),
        ``fill`` (a square), ``marker`` ('circle', 'ring', 'triangle'); returns the y below."""
        cx, cy = x, y
        right = x + (max_width if max_width is not None else self.width - x)
        for label, style in entries:
            w = 26.0 + text_width(label, size)
            if cx > x and cx + w > right:
                cx, cy = x, cy + size + 6
            sample(self, cx, cy, style)
            self.text(cx + 24, cy, label, size, baseline="middle")
            cx += w + gap
        return cy + size

    def place(self, other: Scene, dx: float, dy: float) -> None:
        """Draw ``other`` into this scene, its origin at (dx, dy)."""
        base = len(self.clips)
        self.clips += [(x + dx, y + dy, w, h) for x, y, w, h in other.clips]
        off = np.array([dx, dy])
        for it in other.items:
            clip = getattr(it, "clip", None)
            clip = None if clip is None else clip + base
            if isinstance(it, Lines):
                self.items.append(Lines([p + off for p in it.paths], it.stroke, it.width,
                                        it.fill, it.dash, it.opacity, it.closed, clip,
                                        it.attrs))
            elif isinstance(it, Rects):
                b = it.boxes.copy()
                b[:, :2] += off
                self.items.append(Rects(b, it.fills, it.stroke, it.width, clip, it.attrs))
            elif isinstance(it, Ellipses):
                self.items.append(Ellipses(it.centres + off, it.axes, it.angles_deg, it.stroke,
                                           it.width, it.dashed, clip, it.attrs))
            elif isinstance(it, Circles):
                self.items.append(Circles(it.centres + off, it.radius, it.fill, it.stroke,
                                          it.width, clip, it.attrs))
            else:
                self.items.append(Text(it.x + dx, it.y + dy, it.text, it.size, it.anchor,
                                       it.baseline, it.colour, it.bold, it.rotate))

    @classmethod
    def stack(cls, scenes: Sequence[Scene], gap: float = 16.0, label: str = "") -> Scene:
        """Scenes one below the other, left-aligned; each part's ``data`` are kept, named
        after its ``figure`` entry."""
        width = max((s.width for s in scenes), default=0.0)
        height = sum(s.height for s in scenes) + gap * max(len(scenes) - 1, 0)
        out = cls(width, height, label)
        y = 0.0
        for s in scenes:
            out.place(s, 0.0, y)
            y += s.height + gap
            # a part's data keep their meaning under the part's name
            name = s.data.get("figure", "")
            out.data.update({f"{name}-{k}" if name else k: v for k, v in s.data.items()
                             if k != "figure"})
        return out


def _attrs(data: Mapping[str, str] | None) -> dict[str, str]:
    return {k.replace("_", "-"): str(v) for k, v in (data or {}).items()}



def sample(scene: Scene, x: float, y: float, style: dict[str, Any]) -> None:
    """A legend sample at (x, y) (left, middle), 20 px wide."""
    if "fill" in style:
        scene.rect(x + 4, y - 6, 12, 12, style["fill"], style.get("stroke"))
    if "stroke" in style:
        scene.line([[x, y], [x + 20, y]], style["stroke"], style.get("width", 1.5),
                   dash=style.get("dash"), opacity=style.get("opacity", 1.0))
    marker = style.get("marker")
    if marker:
        marker_at(scene, np.array([[x + 10, y]]), marker, style.get("colour", TEXT))


def marker_at(scene: Scene, xy: ArrayLike, marker: str, colour: str = TEXT, size: float = 5.0,
              data: Mapping[str, str] | None = None) -> None:
    """Markers at px positions: 'circle' (filled), 'ring' (open, with a centre dot: the rest
    hand position), 'triangle' (filled, pointing up: a catch), 'square', 'shoulder'."""
    p = np.asarray(xy, dtype=float).reshape(-1, 2)
    if marker == "circle":
        scene.circles(p, size * 0.8, colour, data=data)
    elif marker == "shoulder":
        scene.circles(p, size * 0.9, colour, "#ffffff", 1.0, data=data)
    elif marker == "ring":
        scene.circles(p, size, "#ffffff", colour, 1.6, data=data)
        scene.circles(p, 1.4, colour)
    elif marker in ("triangle", "square"):
        s = size
        shape = (np.array([[0, -s], [s * 0.95, s * 0.7], [-s * 0.95, s * 0.7]])
                 if marker == "triangle" else
                 np.array([[-s, -s], [s, -s], [s, s], [-s, s]]) * 0.75)
        for q in p:
            scene.polygon(q + shape, colour, "#ffffff", 0.8, data=data)
    else:
        raise ValueError(f"unknown marker {marker!r}")

