"""Every figure of the product, one figure model: a scene of primitives, written as SVG or drawn
as PNG or PDF.

A figure is built as a :class:`~fieldbank.figures.scene.Scene` (pixels, primitives, ``data``
saying what it shows) with :class:`~fieldbank.figures.panel.Panel` boxes in data coordinates,
in the look of :mod:`fieldbank.figures.style`, and saved with :func:`save` - the format from the
file's name, one list of formats (:data:`FORMATS`) and one check (:func:`figure_format`)::

    scene = Scene(640, 420, "stiffness of P-001")
    panel = Panel.at(scene, (70, 40, 500, 320), (-0.3, 0.3), (0.2, 0.6), equal=True)
    panel.frame("stiffness", "x (m, right)", "y (m, forward)")
    ...
    save(scene, "out.pdf")          # .svg, .png or .pdf

Modules
-------
style    one palette (Okabe-Ito), type, colour maps (ColorBrewer), ticks
scene    the primitives and the scene; markers (shoulder, rest hand, catch) and legends
panel    a box of a scene in data coordinates: frame, ticks, labels; colour bars
svg      ``write(scene)``: SVG text (what the report's pages embed)
raster   ``render(scene, fmt)``: PNG or PDF through matplotlib - the one module that imports
         it, and only when asked
fields   force fields and stiffness on the workspace: arrows, ellipses, cells, keys, the
         before/after/change row, one map (``field --out``)
fit      measured against fitted maps (``fit --plot``)
probes   probing paths and force profiles, and a classification (``probe … --plot``)
"""

from __future__ import annotations

from pathlib import Path

from fieldbank.errors import Problem, ValidationError
from fieldbank.figures import raster, svg
from fieldbank.figures.scene import Scene
from fieldbank.files import write_atomic

#: The formats a figure is written in, by the file's suffix.
FORMATS = ("svg", "png", "pdf")


def figure_format(path: str | Path, fmt: str | None = None) -> str:
    """The format of a figure file: ``fmt``, else the suffix of ``path``, one of
    :data:`FORMATS`.

    Raises
    ------
    ValidationError
        Another format, named with the file.
    """
    kind = (fmt if fmt is not None else Path(path).suffix.lstrip(".")).lower()
    if kind not in FORMATS:
        got = f".{kind}" if kind else "no extension"
        raise ValidationError([Problem(str(path), "figures are written as .svg, .png or .pdf; "
                                                  f"got {got!r}")])
    return kind


def render(scene: Scene, fmt: str, scale: float = 2.0) -> bytes:
    """``scene`` as SVG (a file of its own), PNG (``scale`` × its pixels) or PDF bytes."""
    kind = figure_format(f"figure.{fmt}", fmt)
    if kind == "svg":
        return svg.write(scene, standalone=True).encode("utf-8")
    return raster.render(scene, kind, scale)


def save(scene: Scene, path: str | Path, fmt: str | None = None, scale: float = 2.0) -> Path:
    """Write ``scene`` to ``path`` as SVG, PNG or PDF (``fmt`` or the suffix): the same bytes
    for the same scene, all at once or not at all (:func:`fieldbank.files.write_atomic`)."""
    p = Path(path)
    write_atomic(p, render(scene, figure_format(p, fmt), scale))
    return p


__all__ = ["FORMATS", "Scene", "figure_format", "render", "save"]
