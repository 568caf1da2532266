"""SVG text of a scene (:func:`write`): compact, and the same bytes for the same scene.

Coordinates are rounded to 0.1 px; a polyline is one path, its first point absolute and then
relative steps on the 0.1 px grid (so the steps add up exactly), points on the line of their
neighbours dropped (:func:`thin`: the drawing is unchanged at any zoom a page is read at);
cells of one colour share a path; a run of texts of one style shares a group. The ``data`` of
the scene become ``data-*`` attributes of the root element, those of an item attributes of its
element, so a reader (or a test) finds what a figure shows without decoding its geometry.
Every polyline of a figure is rounded, thinned and differenced in one numpy pass over all of
them (a figure's curves are dozens of items of one polyline each; numpy's cost per call, not
per point, was most of the writing), and the text of each 0.1 px number is made once per
process; the bytes are those of each polyline written on its own.

Why write SVG directly: a report draws about ten figures per case, and matplotlib spends
≈ 190 ms on one three-panel quiver figure (building artists, laying out, rendering), where
writing the same figure's SVG from numpy arrays takes ≈ 1 ms (an SVG builder with one object per
path command, drawsvg, ≈ 10 ms); ``benchmarks/bench_report.py`` measures the per-case cost.
"""

from __future__ import annotations

from html import escape

import numpy as np
from numpy.typing import NDArray

from fieldbank.figures.scene import Circles, Ellipses, Item, Lines, Rects, Scene, Text
from fieldbank.figures.style import FONT_FAMILY, TEXT, FloatArray


def write(scene: Scene, id_prefix: str = "f", standalone: bool = False,
          css_class: str = "fig") -> str:
    """``scene`` as SVG text; ``id_prefix`` makes clip ids unique within a page;
    ``standalone`` adds the XML declaration and a white background for a file of its own."""
    w, h = _n(scene.width), _n(scene.height)
    head = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {w} {h}" width="{w}" '
            f'height="{h}" class="{css_class}" font-family="{FONT_FAMILY}" role="img"']
    if scene.label:
        head.append(f' aria-label="{escape(scene.label)}"')
    for k, v in scene.data.items():
        head.append(f' data-{k}="{escape(v)}"')
    out = ["".join(head) + ">"]
    if standalone:
        out.insert(0, '<?xml version="1.0" encoding="UTF-8"?>\n')
        out.append(f'<rect width="{w}" height="{h}" fill="#ffffff"/>')
    if scene.clips:
        out.append("<defs>")
        out += [f'<clipPath id="{id_prefix}c{i}"><rect x="{_n(x)}" y="{_n(y)}" '
                f'width="{_n(cw)}" height="{_n(ch)}"/></clipPath>'
                for i, (x, y, cw, ch) in enumerate(scene.clips)]
        out.append("</defs>")
    items = scene.items
    lines = [it for it in items if isinstance(it, Lines)]
    data = dict(zip(map(id, lines), _path_data([it.paths for it in lines],
                                               [it.closed for it in lines]), strict=True))
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
        out.append(_svg_item(it, id_prefix, data.get(id(it))))
        i += 1
    out.append("</svg>")
    return "".join(out)


def _n(v: float) -> str:
    """A coordinate, 0.1 px, no trailing zero."""
    s = f"{v:.1f}"
    if s.endswith(".0"):
        s = s[:-2]
    return "0" if s == "-0" else s


#: The path text of each integer number of 0.1 px met so far (:func:`_tenths`): a process
#: writes the same few thousand coordinates in every figure.
_TENTHS: dict[int, str] = {}


def _tenths(k: int) -> str:
    """An integer number of 0.1 px as compact path text: '12', '1.5', '.5', '-.5'."""
    text = _TENTHS.get(k)
    if text is None:
        whole, frac = divmod(abs(k), 10)
        text = (str(whole) if whole else "") + (f".{frac}" if frac else "")
        text = _TENTHS[k] = ("-" if k < 0 else "") + (text or "0")
    return text


def _c(v: float) -> str:
    """A compact path number: 0.1 px, no trailing zero, no leading zero ('.5', '-.5')."""
    return _tenths(round(v * 10.0))


#: Largest distance, 0.1 px units, of a dropped polyline point from the line of its kept
#: neighbours, per pass of :func:`thin` (at most :data:`THIN_PASSES` passes: 0.4 px in all).
THIN_TOLERANCE = 1.0
THIN_PASSES = 4


def thin(q: FloatArray) -> FloatArray:
    """Drop repeated points and points on the line of their neighbours (each pass drops no
    two neighbours, so every judgement is against points that stay)."""
    q = np.asarray(q, dtype=float).reshape(-1, 2)
    start = np.zeros(len(q), dtype=bool)
    start[:1] = True
    return _thin_runs(q, start, np.ones(len(q), dtype=bool))[0]


def _thin_runs(q: FloatArray, start: NDArray[np.bool_], thinnable: NDArray[np.bool_]
               ) -> tuple[FloatArray, NDArray[np.bool_]]:
    """:func:`thin` of every polyline of ``q`` (polylines end to end, each beginning where
    ``start``; only the points of ``thinnable`` ones may go) in one pass over all of them at a
    time: a polyline's ends never go, so no judgement reaches across two of them, and a
    polyline that loses nothing in a pass loses nothing in the next. Returns the points kept
    and where each polyline now begins."""
    if len(q) > 1:
        keep = start | ~thinnable
        keep[1:] |= np.any(np.diff(q, axis=0) != 0, axis=1)
        q, start, thinnable = q[keep], start[keep], thinnable[keep]
    end = np.append(start[1:], True)
    inner = (thinnable & ~start & ~end)[1:-1]
    for _ in range(THIN_PASSES):
        if len(q) <= 2:
            break
        a, b, c = q[:-2], q[1:-1], q[2:]
        cross = np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1])
                       - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
        length = np.hypot(c[:, 0] - a[:, 0], c[:, 1] - a[:, 1])
        between = np.einsum("ij,ij->i", b - a, c - a) > 0
        cand = (cross <= THIN_TOLERANCE * np.maximum(length, 1e-9)) & between & inner
        # every other point of a run of candidates: no two neighbours go in one pass
        k = np.arange(len(cand))
        pos = k - np.maximum.accumulate(np.where(~cand, k, -1)) - 1
        drop = cand & (pos % 2 == 0)
        if not drop.any():
            break
        keep = np.concatenate([[True], ~drop, [True]])
        q, start = q[keep], start[keep]
        inner = np.concatenate([[False], inner, [False]])[keep][1:-1]
    return q, start


def _path(p: FloatArray, closed: bool = False) -> str:
    """One polyline as compact SVG path data (:func:`_path_data`)."""
    return _path_data([[p]], [closed])[0]


def _path_data(groups: list[list[FloatArray]], closed: list[bool]) -> list[str]:
    """The path data of each group of polylines (a :class:`Lines` item's; ``closed``: its
    polylines are polygons): each polyline its first point absolute, then relative steps in
    0.1 px (rounded on the 0.1 px grid first, so steps add up exactly), thinned by
    :func:`thin` when longer than three points (the drawing is unchanged at any zoom a page is
    read at). Rounded once, thinned and differenced for every polyline of every group at once
    (a figure's curves are many items of one polyline each)."""
    paths = [np.asarray(p, dtype=float).reshape(-1, 2) for g in groups for p in g]
    if not paths:
        return ["" for _ in groups]
    lens = np.array([len(p) for p in paths])
    start = np.zeros(int(lens.sum()), dtype=bool)
    start[np.cumsum(lens)[:-1]] = True
    start[0] = True
    q, start = _thin_runs(np.round(np.concatenate(paths) * 10.0), start,
                          np.repeat(lens > 3, lens))
    qi = q.astype(np.int64)
    steps = qi.copy()
    steps[1:] -= qi[:-1]
    firsts = np.flatnonzero(start)
    steps[firsts] = qi[firsts]  # each polyline starts absolute
    get = _TENTHS.get
    text = [get(v) or _tenths(v) for v in steps.ravel().tolist()]
    bounds = [*firsts.tolist(), len(qi)]
    out = []
    k = 0
    for g, shut in zip(groups, closed, strict=True):
        tail = "Z" if shut else ""
        parts = []
        for lo, hi in zip(bounds[k:k + len(g)], bounds[k + 1:k + len(g) + 1], strict=True):
            parts.append(f"M{text[2 * lo]} {text[2 * lo + 1]}"
                         + ("l" + " ".join(text[2 * lo + 2:2 * hi]) if hi - lo > 1 else "")
                         + tail)
        out.append("".join(parts))
        k += len(g)
    return out


def _points(xy: FloatArray) -> str:
    return " ".join(f"{_n(x)},{_n(y)}" for x, y in xy)


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


def _svg_item(it: Item, prefix: str, d: str | None = None) -> str:
    """One item as SVG; ``d``: a :class:`Lines` item's path data, when written already."""
    if isinstance(it, Lines):
        if d is None:
            d = _path_data([it.paths], [it.closed])[0]
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

