"""The SVG writer's path data: every polyline of a figure rounded, thinned and differenced in
one pass is the same text as each polyline written on its own by the plain algorithm (below,
written out as the reference)."""

from __future__ import annotations

import numpy as np
import pytest

from fieldbank.figures import svg
from fieldbank.figures.scene import Scene


def _thin_one(q: np.ndarray) -> np.ndarray:
    """The reference: one polyline (0.1 px units), repeated points dropped, then up to
    THIN_PASSES passes each dropping every other point of a run of points within the
    tolerance of the line of their neighbours and between them."""
    if len(q) > 1:
        q = q[np.concatenate([[True], np.any(np.diff(q, axis=0) != 0, axis=1)])]
    for _ in range(svg.THIN_PASSES):
        if len(q) <= 2:
            break
        drop = [False] * (len(q) - 2)
        run = 0
        for j in range(1, len(q) - 1):
            a, b, c = q[j - 1], q[j], q[j + 1]
            cross = abs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
            length = float(np.hypot(c[0] - a[0], c[1] - a[1]))
            cand = (cross <= svg.THIN_TOLERANCE * max(length, 1e-9)
                    and float(np.dot(b - a, c - a)) > 0)
            drop[j - 1] = cand and run % 2 == 0
            run = run + 1 if cand else 0
        if not any(drop):
            break
        q = q[np.concatenate([[True], ~np.array(drop), [True]])]
    return q


def _text(k: int) -> str:
    whole, frac = divmod(abs(k), 10)
    t = (str(whole) if whole else "") + (f".{frac}" if frac else "")
    return ("-" if k < 0 else "") + (t or "0")


def _path_one(p: np.ndarray, closed: bool) -> str:
    q = np.round(np.asarray(p, dtype=float) * 10.0)
    if len(q) > 3:
        q = _thin_one(q)
    pts = q.astype(int).tolist()
    x0, y0 = pts[0]
    out = f"M{_text(x0)} {_text(y0)}"
    steps = []
    for x, y in pts[1:]:
        steps.append(f"{_text(x - x0)} {_text(y - y0)}")
        x0, y0 = x, y
    if steps:
        out += "l" + " ".join(steps)
    return out + ("Z" if closed else "")


def _polylines(rng: np.random.Generator) -> list[np.ndarray]:
    out = []
    for _ in range(40):
        kind = rng.integers(5)
        n = int(rng.integers(1, 4)) if kind == 0 else int(rng.integers(4, 200))
        if kind == 1:  # a smooth curve: most points on the line of their neighbours
            t = np.linspace(0, 1, n)
            p = np.stack([300 * t, 80 * np.sin(3 * t) + 40], axis=1)
        elif kind == 2:  # straight runs with repeated points
            p = np.repeat(np.stack([np.linspace(5, 400, n // 2 + 2), np.full(n // 2 + 2, 7.0)],
                                   axis=1), 2, axis=0)
        elif kind == 3:  # a zigzag: nothing to drop
            p = np.stack([np.arange(n) * 3.0, (np.arange(n) % 2) * 9.0], axis=1)
        else:  # noise on the 0.1 px grid and below it, negative coordinates too
            p = np.cumsum(rng.normal(0, 0.4, (n, 2)), axis=0) - 20
        out.append(p)
    return out


@pytest.mark.parametrize("seed", range(6))
def test_the_path_data_of_all_polylines_at_once_is_each_written_on_its_own(seed: int) -> None:
    rng = np.random.default_rng(seed)
    paths = _polylines(rng)
    cuts = sorted(rng.choice(np.arange(1, len(paths)), 6, replace=False).tolist())
    groups = [paths[a:b] for a, b in zip([0, *cuts], [*cuts, len(paths)], strict=True)]
    closed = [bool(c) for c in rng.integers(0, 2, len(groups))]
    got = svg._path_data(groups, closed)
    want = ["".join(_path_one(p, shut) for p in g) for g, shut in zip(groups, closed,
                                                                        strict=True)]
    assert got == want
    # and a polyline of exactly three points is never thinned, one of four is
    assert svg._path_data([[np.array([[0, 0], [1, 0], [2, 0]])]], [False]) == ["M0 0l1 0 1 0"]
    assert svg._path_data([[np.array([[0, 0], [1, 0], [2, 0], [3, 0]])]], [True]) == [
        "M0 0l3 0Z"]


def test_a_scene_writes_the_same_bytes_whatever_else_it_holds() -> None:
    """A polyline's text does not depend on the other polylines written with it."""
    rng = np.random.default_rng(3)
    paths = _polylines(rng)
    alone = []
    for p in paths:
        s = Scene(400, 300)
        s.line(p)
        alone.append(svg.write(s).split('d="')[1].split('"')[0])
    s = Scene(400, 300)
    for p in paths:
        s.line(p)
    together = [part.split('"')[0] for part in svg.write(s).split('d="')[1:]]
    assert together == alone
