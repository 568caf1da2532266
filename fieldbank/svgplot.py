"""Figures as plain vector graphics: a scene of primitives in pixels, panels with data axes.

A :class:`Scene` is a figure description - polylines, polygons, rectangles, ellipses, circles
and text in pixel coordinates (y down, the SVG convention) - and a :class:`Panel` maps data
coordinates into a box of it and draws axes, ticks and labels. The scene is written as SVG
text directly (:meth:`Scene.to_svg`), or, when a user asks for PNG or PDF, drawn by matplotlib
primitive by primitive (:meth:`Scene.render`), so both look the same: one
description, two renderers.

Why not matplotlib for every figure: a report draws about ten figures per case, and matplotlib
spends ≈ 190 ms on one three-panel quiver figure (building artists, laying out, rendering),
where writing the same figure's SVG from numpy arrays takes ≈ 1 ms (and an SVG builder with
one object per path command, drawsvg, ≈ 10 ms); interactive chart libraries embed their
script in every page (plotly.min.js alone is 4.8 MB). ``benchmarks/bench_report.py`` measures
the whole per-case cost. What this module keeps small on purpose: no layout engine (callers
place panels), no text measurement (widths are estimated, :func:`text_width`), ticks from
the usual 1-2-2.5-5 ladder (:func:`nice_ticks`).

Conventions shared by every figure built on it (:mod:`fieldbank.fieldplot`, the report's and
the what-if's figures):

* sizes in CSS pixels; type at least :data:`FONT_SMALL` px (legible at 100% zoom);
* coordinates rounded to 0.1 px, so the text is compact and the same input gives the same
  bytes;
* colours: :data:`BEFORE` (blue) and :data:`AFTER` (vermillion) of the Okabe-Ito colour-blind
  safe palette (Okabe & Ito 2008), :data:`CHANGE` (near black) for differences,
  :data:`MODEL` for a single model; diverging maps centred on zero from ColorBrewer's RdBu,
  sequential maps from its Blues (Brewer 2003, colorbrewer2.org).
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from html import escape
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from fieldbank.files import write_atomic

FloatArray = np.ndarray

#: Colours (Okabe & Ito 2008 colour-blind safe palette, and greys).
BEFORE = "#0072B2"
AFTER = "#D55E00"
CHANGE = "#1a1a1a"
MODEL = "#1a1a1a"
ACCENT = "#009E73"
GREY = "#888888"
LIGHT = "#d9d9d9"
TEXT = "#222222"
#: Type sizes, px.
FONT_SMALL = 11.0
FONT = 12.0
FONT_TITLE = 13.0
FONT_FAMILY = "DejaVu Sans, Helvetica, Arial, sans-serif"
#: Ordinary categorical colours for several series (Okabe & Ito), after BEFORE/AFTER.
SERIES = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000")

# ColorBrewer RdBu (11 classes), from negative (blue) to positive (red).
_RDBU = ("#053061", "#2166ac", "#4393c3", "#92c5de", "#d1e5f0", "#f7f7f7", "#fddbc7",
         "#f4a582", "#d6604d", "#b2182b", "#67001f")
# ColorBrewer Blues (9 classes), light to dark.
_BLUES = ("#f7fbff", "#deebf7", "#c6dbef", "#9ecae1", "#6baed6", "#4292c6", "#2171b5",
          "#08519c", "#08306b")

Anchor = Literal["start", "middle", "end"]
Baseline = Literal["alphabetic", "middle", "hanging"]


def _rgb(hexcolour: str) -> tuple[int, int, int]:
    h = hexcolour.lstrip("#")
    return int(h[0:2], 16), int(h[2:4], 16), int(h[4:6], 16)


def _ramp(anchors: Sequence[str], t: ArrayLike) -> list[str]:
    """Colours at fractions t in [0, 1] along the anchors (linear in RGB)."""
    rgb = np.array([_rgb(a) for a in anchors], dtype=float)
    tt = np.clip(np.asarray(t, dtype=float).reshape(-1), 0.0, 1.0) * (len(anchors) - 1)
    i = np.minimum(tt.astype(int), len(anchors) - 2)
    f = (tt - i)[:, None]
    c = np.rint(rgb[i] * (1 - f) + rgb[i + 1] * f).astype(int)
    return [f"#{r:02x}{g:02x}{b:02x}" for r, g, b in c]


#: Colour steps of a map (24 between its ends; a diverging map gets one more, white at 0).
MAP_STEPS = 24


def _steps(t: FloatArray) -> FloatArray:
    return np.rint(np.clip(t, 0.0, 1.0) * MAP_STEPS) / MAP_STEPS


def diverging(values: ArrayLike, limit: float) -> list[str]:
    """Colours of a diverging map centred on zero: -limit blue, 0 white, +limit red (in
    :data:`MAP_STEPS` + 1 steps)."""
    v = np.asarray(values, dtype=float).reshape(-1)
    lim = limit if limit > 0 else 1.0
    return _ramp(_RDBU, _steps(0.5 + 0.5 * v / lim))


def sequential(values: ArrayLike, lo: float, hi: float, light: float = 0.0,
               dark: float = 0.6) -> list[str]:
    """Colours of a light sequential map (Blues from ``light`` to ``dark`` of its range), so
    arrows drawn over it stay readable."""
    v = np.asarray(values, dtype=float).reshape(-1)
    span = hi - lo if hi > lo else 1.0
    return _ramp(_BLUES, light + (dark - light) * _steps((v - lo) / span))


def nice_ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    """Round tick values within [lo, hi], steps 1, 2, 2.5 or 5 × 10^k: the finest step
    giving at most ``n`` + 1 ticks."""
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        return [lo] if math.isfinite(lo) else []
    mag = 10.0 ** math.floor(math.log10((hi - lo) / max(n, 1)))
    for step in (m * mag * f for f in (1.0, 10.0, 100.0) for m in (1.0, 2.0, 2.5, 5.0)):
        first = math.ceil(lo / step - 1e-9)
        last = math.floor(hi / step + 1e-9)
        if last - first + 1 <= n + 1:
            return [0.0 if k == 0 else round(k * step, 12) for k in range(first, last + 1)]
    return [lo, hi]


def _decimals(step: float) -> int:
    """Decimals that write every multiple of ``step`` exactly (0.25 -> 2, 5 -> 0)."""
    for d in range(7):
        v = abs(step) * 10**d
        if abs(v - round(v)) < 1e-6 * max(v, 1.0):
            return d
    return 6


def tick_label(v: float, ticks: Sequence[float]) -> str:
    """A tick's label with as many decimals as the tick step needs; '−' as minus sign."""
    if v == 0:
        return "0"
    step = min((abs(b - a) for a, b in itertools.pairwise(ticks)), default=1.0)
    text = f"{v:.{_decimals(step) if step > 0 else 0}f}"
    return text.replace("-", "−")


def fmt_value(v: float, digits: int = 3) -> str:
    """A value to ``digits`` significant digits, '−' as minus sign (labels, keys)."""
    if v == 0:
        return "0"
    text = f"{v:.{digits}g}"
    if "e" in text:
        mant, exp = text.split("e")
        text = f"{mant}×10^{int(exp)}"
    return text.replace("-", "−")


def text_width(text: str, size: float = FONT) -> float:
    """Estimated width of ``text`` in px (mean glyph ≈ 0.58 em for sans-serif)."""
    return 0.58 * size * len(text)


def _n(v: float) -> str:
    """A coordinate, 0.1 px, no trailing zero."""
    s = f"{v:.1f}"
    if s.endswith(".0"):
        s = s[:-2]
    return "0" if s == "-0" else s


@functools.lru_cache(maxsize=65536)
def _tenths(k: int) -> str:
    """An integer number of 0.1 px as compact path text: '12', '1.5', '.5', '-.5'."""
    whole, frac = divmod(abs(k), 10)
    text = (str(whole) if whole else "") + (f".{frac}" if frac else "")
    return ("-" if k < 0 else "") + (text or "0")


def _c(v: float) -> str:
    """A compact path number: 0.1 px, no trailing zero, no leading zero ('.5', '-.5')."""
    return _tenths(round(v * 10.0))


#: Largest distance, 0.1 px units, of a dropped polyline point from the line of its kept
#: neighbours, per pass of :func:`_thin` (at most :data:`THIN_PASSES` passes: 0.4 px in all).
THIN_TOLERANCE = 1.0
THIN_PASSES = 4


def _thin(q: FloatArray) -> FloatArray:
    """Drop repeated points and points on the line of their neighbours (each pass drops no
    two neighbours, so every judgement is against points that stay)."""
    if len(q) > 1:
        q = q[np.concatenate([[True], np.any(np.diff(q, axis=0) != 0, axis=1)])]
    for _ in range(THIN_PASSES):
        if len(q) <= 2:
            break
        a, b, c = q[:-2], q[1:-1], q[2:]
        cross = np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1])
                       - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
        length = np.hypot(c[:, 0] - a[:, 0], c[:, 1] - a[:, 1])
        between = np.einsum("ij,ij->i", b - a, c - a) > 0
        cand = (cross <= THIN_TOLERANCE * np.maximum(length, 1e-9)) & between
        # every other point of a run of candidates: no two neighbours go in one pass
        k = np.arange(len(cand))
        pos = k - np.maximum.accumulate(np.where(~cand, k, -1)) - 1
        drop = cand & (pos % 2 == 0)
        if not drop.any():
            break
        q = q[np.concatenate([[True], ~drop, [True]])]
    return q


def _path(p: FloatArray, closed: bool = False) -> str:
    """One polyline as compact SVG path data: the first point absolute, then relative steps
    in 0.1 px (rounded on the 0.1 px grid first, so steps add up exactly), thinned by
    :func:`_thin` when longer than three points (the drawing is unchanged at any zoom a page
    is read at)."""
    if len(p) <= 3:  # arrows, ticks, markers: plain Python is faster than numpy here
        q = [(round(x * 10.0), round(y * 10.0)) for x, y in p.tolist()]
    else:
        q = _thin(np.round(np.asarray(p, dtype=float) * 10.0)).astype(int).tolist()
    x0, y0 = q[0]
    out = [f"M{_tenths(x0)} {_tenths(y0)}"]
    if len(q) > 1:
        steps = []
        for x, y in q[1:]:
            steps.append(f"{_tenths(x - x0)} {_tenths(y - y0)}")
            x0, y0 = x, y
        out.append("l" + " ".join(steps))
    if closed:
        out.append("Z")
    return "".join(out)


def _points(xy: FloatArray) -> str:
    return " ".join(f"{_n(x)},{_n(y)}" for x, y in xy)


# --- the scene ----------------------------------------------------------------------------
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

    # output
    def to_svg(self, id_prefix: str = "f", standalone: bool = False,
               css_class: str = "fig") -> str:
        """The scene as SVG text; ``id_prefix`` makes clip ids unique within a page;
        ``standalone`` adds the XML namespace declaration for a file of its own."""
        w, h = _n(self.width), _n(self.height)
        head = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {w} {h}" width="{w}" '
                f'height="{h}" class="{css_class}" font-family="{FONT_FAMILY}" role="img"']
        if self.label:
            head.append(f' aria-label="{escape(self.label)}"')
        for k, v in self.data.items():
            head.append(f' data-{k}="{escape(v)}"')
        out = ["".join(head) + ">"]
        if standalone:
            out.insert(0, '<?xml version="1.0" encoding="UTF-8"?>\n')
            out.append(f'<rect width="{w}" height="{h}" fill="#ffffff"/>')
        if self.clips:
            out.append("<defs>")
            out += [f'<clipPath id="{id_prefix}c{i}"><rect x="{_n(x)}" y="{_n(y)}" '
                    f'width="{_n(cw)}" height="{_n(ch)}"/></clipPath>'
                    for i, (x, y, cw, ch) in enumerate(self.clips)]
            out.append("</defs>")
        items = self.items
        i = 0
        while i < len(items):
            it = items[i]
            if isinstance(it, Text) and not it.rotate:
                # a run of texts of one style (tick labels) shares a group with that style
                style = _text_style(it)
                run = [it]
                for nxt in items[i + 1:]:
                    if not (isinstance(nxt, Text) and not nxt.rotate
                            and _text_style(nxt) == style):
                        break
                    run.append(nxt)
                if len(run) > 1:
                    out.append(f"<g{style}>")
                    out += [_svg_text(t, style=False) for t in run]
                    out.append("</g>")
                    i += len(run)
                    continue
            out.append(_svg_item(it, id_prefix))
            i += 1
        out.append("</svg>")
        return "".join(out)

    def save(self, path: str | Path, fmt: str | None = None, scale: float = 2.0) -> Path:
        """Write as SVG, PNG or PDF (from ``fmt`` or the suffix), deterministic bytes, through
        a temporary file. PNG and PDF are drawn by matplotlib (:meth:`render`)."""
        p = Path(path)
        write_atomic(p, self.render(fmt or p.suffix.lstrip("."), scale))
        return p

    def render(self, fmt: str, scale: float = 2.0) -> bytes:
        """The scene as SVG, PNG (``scale`` × its pixel size) or PDF bytes."""
        kind = fmt.lower()
        if kind == "svg":
            return self.to_svg(standalone=True).encode("utf-8")
        if kind in ("png", "pdf"):
            return _render_matplotlib(self, kind, scale)
        raise ValueError(f"figure format must be svg, png or pdf; got {fmt!r}.")


FIGURE_FORMATS = ("svg", "png", "pdf")


def _attrs(data: Mapping[str, str] | None) -> dict[str, str]:
    return {k.replace("_", "-"): str(v) for k, v in (data or {}).items()}


def _common(stroke: str | None, width: float, fill: str | None,
            dash: tuple[float, ...] | None = None, opacity: float = 1.0,
            clip: int | None = None, prefix: str = "f", attrs: dict[str, str] | None = None
            ) -> str:
    parts = [f' fill="{fill or "none"}"']
    if stroke:
        parts.append(f' stroke="{stroke}"')
        if width != 1.0:
            parts.append(f' stroke-width="{_n(width)}"')
    if dash:
        parts.append(f' stroke-dasharray="{" ".join(_n(d) for d in dash)}"')
    if opacity != 1.0:
        parts.append(f' opacity="{opacity:g}"')
    if clip is not None:
        parts.append(f' clip-path="url(#{prefix}c{clip})"')
    for k, v in (attrs or {}).items():
        parts.append(f' data-{k}="{escape(v)}"')
    return "".join(parts)


def _svg_item(it: Item, prefix: str) -> str:
    if isinstance(it, Lines):
        d = "".join(_path(p, it.closed) for p in it.paths)
        join = ' stroke-linejoin="round" stroke-linecap="round"' if it.stroke else ""
        return (f'<path d="{d}"{join}'
                + _common(it.stroke, it.width, it.fill, it.dash, it.opacity, it.clip, prefix,
                          it.attrs) + "/>")
    if isinstance(it, Rects):
        g = "<g" + _common(it.stroke, it.width, None, clip=it.clip, prefix=prefix,
                           attrs=it.attrs) + ">"
        if len(it.boxes) <= 4:
            body = "".join(f'<rect x="{_n(x)}" y="{_n(y)}" width="{_n(w)}" height="{_n(h)}" '
                           f'fill="{c}"/>' for (x, y, w, h), c in zip(it.boxes, it.fills,
                                                                      strict=True))
            return g + body + "</g>"
        # many cells: one path per colour (cells of one colour map come in a few dozen
        # colours)
        by_fill: dict[str, list[str]] = {}
        for (x, y, w, h), c in zip(it.boxes, it.fills, strict=True):
            by_fill.setdefault(c, []).append(f"M{_c(x)} {_c(y)}h{_c(w)}v{_c(h)}h{_c(-w)}z")
        return g + "".join(f'<path fill="{c}" d="{"".join(ds)}"/>'
                           for c, ds in by_fill.items()) + "</g>"
    if isinstance(it, Ellipses):
        g = "<g" + _common(it.stroke, it.width, None, clip=it.clip, prefix=prefix,
                           attrs=it.attrs) + ">"
        parts: list[str] = []
        dashed = it.dashed if it.dashed is not None else np.zeros(len(it.centres), bool)
        for (cx, cy), (a, b), ang, dsh in zip(it.centres, it.axes, it.angles_deg, dashed,
                                              strict=True):
            rot = f' transform="rotate({_n(-ang)} {_n(cx)} {_n(cy)})"' if abs(ang) > 0.05 \
                else ""
            parts.append(f'<ellipse cx="{_n(cx)}" cy="{_n(cy)}" rx="{_n(a / 2)}" '
                         f'ry="{_n(b / 2)}"{rot}' + (' stroke-dasharray="3 2"' if dsh else "")
                         + "/>")
        return g + "".join(parts) + "</g>"
    if isinstance(it, Circles):
        g = "<g" + _common(it.stroke, it.width, it.fill, clip=it.clip, prefix=prefix,
                           attrs=it.attrs) + ">"
        r = _n(it.radius)
        return g + "".join(f'<circle cx="{_n(x)}" cy="{_n(y)}" r="{r}"/>'
                           for x, y in it.centres) + "</g>"
    return _svg_text(it)


def _text_style(it: Text) -> str:
    base = {"alphabetic": "", "middle": ' dominant-baseline="central"',
            "hanging": ' dominant-baseline="hanging"'}[it.baseline]
    anchor = "" if it.anchor == "start" else f' text-anchor="{it.anchor}"'
    return (f' font-size="{_n(it.size)}"{anchor}{base}'
            + (' font-weight="bold"' if it.bold else "")
            + (f' fill="{it.colour}"' if it.colour != TEXT else ""))


def _svg_text(it: Text, style: bool = True) -> str:
    rot = (f' transform="rotate({_n(-it.rotate)} {_n(it.x)} {_n(it.y)})"' if it.rotate
           else "")
    return (f'<text x="{_n(it.x)}" y="{_n(it.y)}"{_text_style(it) if style else ""}{rot}>'
            f"{escape(it.text, quote=False)}</text>")


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


# --- panels -------------------------------------------------------------------------------
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


def limits(*arrays: ArrayLike, pad: float = 0.05, include_zero: bool = False,
           floor_span: float = 0.0) -> tuple[float, float]:
    """Data limits over the finite values of the arrays, padded by ``pad`` of the span; a
    span below ``floor_span`` is widened to it (so a flat line is not blown up to noise)."""
    vals = np.concatenate([np.asarray(a, dtype=float).reshape(-1) for a in arrays] or
                          [np.zeros(0)])
    vals = vals[np.isfinite(vals)]
    if include_zero:
        vals = np.append(vals, 0.0)
    if vals.size == 0:
        return 0.0, 1.0
    lo, hi = float(vals.min()), float(vals.max())
    if hi - lo < floor_span:
        mid = 0.5 * (hi + lo) if not include_zero or lo < 0 else max(lo, 0.0)
        lo, hi = (mid - floor_span / 2, mid + floor_span / 2) if lo < 0 or not include_zero \
            else (lo, lo + floor_span)
    span = hi - lo if hi > lo else max(abs(hi), 1.0)
    lo2 = lo - pad * span if not (include_zero and lo == 0.0) else 0.0
    return lo2, hi + pad * span


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


# --- PNG and PDF through matplotlib -----------------------------------------------------------
_PT_PER_PX = 0.75  # CSS pixels are 1/96 in, points 1/72 in


def _render_matplotlib(scene: Scene, fmt: str, scale: float = 2.0) -> bytes:
    """Draw the scene's primitives with matplotlib (Agg for PNG, its PDF backend for PDF) on
    a canvas of the scene's size; deterministic bytes (no software tag, no date)."""
    import matplotlib

    matplotlib.use("Agg")
    with matplotlib.rc_context({"lines.scale_dashes": False}):  # dashes in px, as in SVG
        return _draw_matplotlib(scene, fmt, scale)


def _draw_matplotlib(scene: Scene, fmt: str, scale: float) -> bytes:
    import io

    from matplotlib.collections import EllipseCollection, PathCollection, PolyCollection
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle
    from matplotlib.path import Path as MplPath

    fig = Figure(figsize=(scene.width / 96.0, scene.height / 96.0), dpi=96.0 * scale)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_xlim(0.0, scene.width)
    ax.set_ylim(scene.height, 0.0)
    ax.set_axis_off()
    ax.add_patch(Rectangle((0.0, 0.0), scene.width, scene.height, facecolor="#ffffff",
                           edgecolor="none", zorder=0))
    clips = [Rectangle((x, y), w, h, transform=ax.transData, facecolor="none")
             for x, y, w, h in scene.clips]

    def add(artist: Any, clip: int | None) -> None:
        # after adding: the axes give an artist without a clip path their own, and a
        # rectangle becomes a clip box, which reads as "no clip path"
        ax.add_collection(artist)
        if clip is not None:
            artist.set_clip_path(clips[clip])

    def dashes(d: tuple[float, ...] | None) -> Any:
        return "solid" if not d else (0.0, tuple(v * _PT_PER_PX for v in d))

    z = 1
    for it in scene.items:
        z += 1
        if isinstance(it, Lines):
            verts, codes = [], []
            for p in it.paths:
                verts.append(p)
                c = [MplPath.MOVETO] + [MplPath.LINETO] * (len(p) - 1)
                if it.closed:
                    verts.append(p[:1])
                    c.append(MplPath.CLOSEPOLY)
                codes += c
            path = MplPath(np.vstack(verts), codes)
            coll: Any = PathCollection([path], facecolors=it.fill or "none",
                                  edgecolors=it.stroke or "none",
                                  linewidths=it.width * _PT_PER_PX, alpha=it.opacity,
                                  linestyles=dashes(it.dash), zorder=z)
            coll.set_capstyle("round")
            coll.set_joinstyle("round")
            add(coll, it.clip)
        elif isinstance(it, Rects):
            b = it.boxes
            polys = [[(x, y), (x + w, y), (x + w, y + h), (x, y + h)] for x, y, w, h in b]
            coll = PolyCollection(polys, facecolors=it.fills, edgecolors=it.stroke or "none",
                                  linewidths=it.width * _PT_PER_PX, zorder=z)
            add(coll, it.clip)
        elif isinstance(it, Ellipses):
            dashed = it.dashed if it.dashed is not None else np.zeros(len(it.centres), bool)
            for flag in (False, True):
                sel = dashed == flag
                if not np.any(sel):
                    continue
                # the axes are y-down: an angle counter-clockwise on the page is negative here
                coll = EllipseCollection(it.axes[sel, 0], it.axes[sel, 1],
                                         -it.angles_deg[sel], units="xy",
                                         offsets=it.centres[sel], offset_transform=ax.transData,
                                         facecolors="none", edgecolors=it.stroke,
                                         linewidths=it.width * _PT_PER_PX,
                                         linestyles=dashes((3, 2) if flag else None), zorder=z)
                add(coll, it.clip)
        elif isinstance(it, Circles):
            d = 2.0 * it.radius
            coll = EllipseCollection(np.full(len(it.centres), d), np.full(len(it.centres), d),
                                     np.zeros(len(it.centres)), units="xy", offsets=it.centres,
                                     offset_transform=ax.transData,
                                     facecolors=it.fill or "none",
                                     edgecolors=it.stroke or "none",
                                     linewidths=it.width * _PT_PER_PX, zorder=z)
            add(coll, it.clip)
        else:
            ax.text(it.x, it.y, it.text, fontsize=it.size * _PT_PER_PX, color=it.colour,
                    ha={"start": "left", "middle": "center", "end": "right"}[it.anchor],
                    va={"alphabetic": "baseline", "middle": "center_baseline",
                        "hanging": "top"}[it.baseline],
                    rotation=it.rotate, rotation_mode="anchor",
                    fontweight="bold" if it.bold else "normal", zorder=z,
                    family=["DejaVu Sans"])
    buf = io.BytesIO()
    metadata: dict[str, Any] = ({"Software": None} if fmt == "png" else
                                {"Creator": None, "Producer": None, "CreationDate": None})
    fig.savefig(buf, format=fmt, metadata=metadata, dpi=96.0 * scale)
    return buf.getvalue()
