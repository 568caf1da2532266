"""The look every figure shares: one palette, type, colour maps and ticks.

* sizes in CSS pixels; type at least :data:`FONT_SMALL` px (legible at 100% zoom), one family
  (:data:`FONT_FAMILY`, DejaVu Sans where the page or the raster has it);
* colours from the Okabe-Ito colour-blind safe palette (Okabe & Ito 2008): :data:`BEFORE`
  (blue) and :data:`AFTER` (vermillion), :data:`CHANGE` (near black) for differences,
  :data:`MODEL` for a single model or a measurement, :data:`SERIES` for several series,
  :data:`GROUP_COLOURS` for the impaired groups of probing figures (one colour per group, one
  dash per severity, :data:`LEVEL_STROKES`);
* diverging maps centred on zero from ColorBrewer's RdBu, sequential maps from its Blues
  (Brewer 2003, colorbrewer2.org), in :data:`MAP_STEPS` steps;
* ticks from the 1-2-2.5-5 ladder (:func:`nice_ticks`), as many decimals as the step needs,
  '−' as the minus sign.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Sequence
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

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


#: One colour per impaired group of a probing figure (Okabe & Ito), and for other candidates.
GROUP_COLOURS = {"shoulder": "#0072B2", "elbow": "#D55E00", "biarticular": "#009E73",
                 "unimpaired": GREY}
OTHER_COLOURS = ("#CC79A7", "#E69F00", "#56B4E9", "#000000", "#F0E442")
#: Line of a candidate per severity: (dash pattern px or None, width px).
LEVEL_STROKES: dict[str, tuple[tuple[float, ...] | None, float]] = {
    "severe": (None, 2.4), "moderate": ((7.0, 3.5), 2.0), "mild": ((7.0, 2.5, 1.5, 2.5), 1.8),
    "very mild": ((1.5, 2.5), 1.8), "unimpaired": (None, 1.3)}

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


@functools.lru_cache(maxsize=256)
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

