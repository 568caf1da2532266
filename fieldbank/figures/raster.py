"""PNG and PDF of a scene (:func:`render`), drawn by matplotlib primitive by primitive.

The one module that imports matplotlib, and only when a PNG or PDF is asked for: importing it
loads nothing, so commands and worker processes that never rasterise never pay for it. The
canvas is the scene's size (``scale`` × its pixels for PNG), the Agg backend for PNG and
matplotlib's PDF backend for PDF, chosen per figure (no global backend); the bytes are the same
for the same scene (no software tag, no date).
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np

from fieldbank.figures.scene import Circles, Ellipses, Lines, Rects, Scene

_PT_PER_PX = 0.75  # CSS pixels are 1/96 in, points 1/72 in


#: What :func:`render` draws.
FORMATS = ("png", "pdf")


def render(scene: Scene, fmt: str, scale: float = 2.0) -> bytes:
    """``scene`` as PNG (``scale`` × its pixel size) or PDF bytes; deterministic (no software
    tag, no date)."""
    if fmt not in FORMATS:
        raise ValueError(f"the raster writer draws {' or '.join(FORMATS)}; got {fmt!r}")
    import matplotlib  # here only: loaded with the first raster figure

    with matplotlib.rc_context({"lines.scale_dashes": False}):  # dashes in px, as in SVG
        return _draw(scene, fmt, scale)


def _draw(scene: Scene, fmt: str, scale: float) -> bytes:
    # a Figure drawn by its own canvas: no pyplot, no global backend
    from matplotlib.backends.backend_agg import FigureCanvasAgg
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
    FigureCanvasAgg(fig)  # PDF is written by the PDF backend savefig picks for the format
    fig.savefig(buf, format=fmt, metadata=metadata, dpi=96.0 * scale)
    return buf.getvalue()
