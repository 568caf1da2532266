"""Scripted reference motions for the simulated operator's hand (robot frame, SI).

Each motion is a callable ``m(t_s) -> (x, y, vx, vy)``: where the operator wants the handle at
time t and how fast. The simulated operator does not impose this path: its hand is a
spring-damper that pulls the handle toward the reference (see :mod:`haptic.simrobot`), so the
arm's field pushes the handle off the path exactly as it would push a person's hand.

The seed's probing motions (Melendez-Calderon et al., Fig. 3):

- pull: from the arm's rest hand position straight along the mid-sagittal line toward the body
  (−y), minimum-jerk profile; "fast" (0.3 s) or "slow" (4 s) by default;
- ellipse: a semi-elliptical stroke from the rest position, out to the side (+x) and back to a
  point closer to the body;
- circle: circles through the rest position at a set frequency, speed ramped in;
- explore: free exploration, a seeded sum of slow sinusoids around the rest position;
- path: any probe given as a polyline of hand positions with times (a designed stroke, the
  seed's probes: :class:`fieldbank.probepath.ProbePath`), followed through a smooth
  cubic Hermite interpolation of its points.

Any motion can carry a seeded, smooth wander of the hand off the path (:func:`wander`): the
operator's motion noise, next to the scatter of how a probe is executed.

Pure ``math``, no numpy: the device process imports this module and steps it at 4 kHz.
"""

from __future__ import annotations

import bisect
import math
import random
from collections.abc import Callable, Sequence

from fieldbank.errors import ParameterError

MotionFn = Callable[[float], tuple[float, float, float, float]]

MOTIONS = ("hold", "pull", "fastpull", "ellipse", "circle", "explore", "path")
#: Time the operator holds still at the start before moving (s).
LEAD_IN_S = 0.2


def _min_jerk(tau: float) -> tuple[float, float]:
    """Minimum-jerk position s(τ) and ds/dτ for τ in [0, 1] (clamped outside)."""
    if tau <= 0.0:
        return 0.0, 0.0
    if tau >= 1.0:
        return 1.0, 0.0
    t3 = tau * tau * tau
    s = t3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)
    ds = 30.0 * tau * tau * (1.0 - tau) * (1.0 - tau)
    return s, ds


def hold(x0: float, y0: float) -> MotionFn:
    """Stay at (x0, y0)."""

    def m(t: float) -> tuple[float, float, float, float]:
        return x0, y0, 0.0, 0.0

    return m


def pull(x0: float, y0: float, distance_m: float = 0.12, duration_s: float = 4.0,
         direction: tuple[float, float] = (0.0, -1.0)) -> MotionFn:
    """Straight pull from (x0, y0) by ``distance_m`` along ``direction`` (default −y)."""
    n = math.hypot(*direction) or 1.0
    ux, uy = direction[0] / n, direction[1] / n

    def m(t: float) -> tuple[float, float, float, float]:
        s, ds = _min_jerk((t - LEAD_IN_S) / duration_s)
        d = distance_m * s
        v = distance_m * ds / duration_s
        return x0 + ux * d, y0 + uy * d, ux * v, uy * v

    return m


def ellipse(x0: float, y0: float, depth_m: float = 0.14, width_m: float = 0.08,
            duration_s: float = 1.0) -> MotionFn:
    """Semi-elliptical stroke from (x0, y0) to (x0, y0 − depth) bulging toward +x."""
    cy = y0 - depth_m / 2.0
    b = depth_m / 2.0

    def m(t: float) -> tuple[float, float, float, float]:
        s, ds = _min_jerk((t - LEAD_IN_S) / duration_s)
        th = math.pi * s
        thd = math.pi * ds / duration_s
        return (x0 + width_m * math.sin(th), cy + b * math.cos(th),
                width_m * math.cos(th) * thd, -b * math.sin(th) * thd)

    return m


def circle(x0: float, y0: float, radius_m: float = 0.06, frequency_hz: float = 0.5,
           ramp_s: float = 1.0) -> MotionFn:
    """Circles through (x0, y0), centre at (x0, y0 − radius), speed ramped in over ``ramp_s``."""
    w = 2.0 * math.pi * frequency_hz
    cx, cy = x0, y0 - radius_m

    def m(t: float) -> tuple[float, float, float, float]:
        tt = max(0.0, t - LEAD_IN_S)
        # phase with a smooth (quadratic) ramp of angular speed up to w
        if tt < ramp_s:
            ph = 0.5 * w * tt * tt / ramp_s
            phd = w * tt / ramp_s
        else:
            ph = 0.5 * w * ramp_s + w * (tt - ramp_s)
            phd = w
        return (cx + radius_m * math.sin(ph), cy + radius_m * math.cos(ph),
                radius_m * math.cos(ph) * phd, -radius_m * math.sin(ph) * phd)

    return m


def explore(x0: float, y0: float, amplitude_m: float = 0.06, seed: int = 0,
            components: int = 4) -> MotionFn:
    """Seeded smooth random motion: sums of sinusoids (0.15–0.8 Hz) around (x0, y0)."""
    rng = random.Random(seed)
    terms = [
        tuple((rng.uniform(0.15, 0.8), rng.uniform(0.0, 2.0 * math.pi)) for _ in range(2))
        for _ in range(components)
    ]
    a = amplitude_m / math.sqrt(components)

    def m(t: float) -> tuple[float, float, float, float]:
        tt = max(0.0, t - LEAD_IN_S)
        g, gd = _min_jerk(tt / 1.0)  # fade in over 1 s so the motion starts at rest
        x = y = vx = vy = 0.0
        for (fx, px), (fy, py) in terms:
            wx, wy = 2 * math.pi * fx, 2 * math.pi * fy
            x += math.sin(wx * tt + px) - math.sin(px)
            y += math.sin(wy * tt + py) - math.sin(py)
            vx += wx * math.cos(wx * tt + px)
            vy += wy * math.cos(wy * tt + py)
        return (x0 + a * g * x, y0 + a * g * y, a * (gd * x + g * vx), a * (gd * y + g * vy))

    return m


def format_path(points: Sequence[tuple[float, float, float]]) -> str:
    """A polyline of (t_s, x_m, y_m) as text for a ``sim://`` query: ``t:x:y;t:x:y;…``."""
    return ";".join(f"{t:.6g}:{x:.7g}:{y:.7g}" for t, x, y in points)


def parse_path(text: str) -> list[tuple[float, float, float]]:
    """The polyline of :func:`format_path`; ValueError names the bad point."""
    pts: list[tuple[float, float, float]] = []
    for k, item in enumerate(p for p in text.split(";") if p.strip()):
        parts = item.split(":")
        try:
            t, x, y = (float(v) for v in parts)
        except ValueError:
            raise ParameterError(f"path point {k + 1} {item!r} must read t:x:y (s, m, m)") from None
        if not all(math.isfinite(v) for v in (t, x, y)):
            raise ParameterError(f"path point {k + 1} {item!r} is not finite")
        if pts and t <= pts[-1][0]:
            raise ParameterError(f"path point {k + 1}: time {t:g} s does not follow "
                                 f"{pts[-1][0]:g} s")
        pts.append((t, x, y))
    if len(pts) < 2:
        raise ParameterError(f"a path needs at least 2 points; got {len(pts)}")
    return pts


def path(points: Sequence[tuple[float, float, float]]) -> MotionFn:
    """Follow a polyline of (t_s, x_m, y_m) from its first time (after :data:`LEAD_IN_S`),
    holding the first point before and the last after.

    Between points, a cubic Hermite segment whose tangents are the central differences of the
    neighbouring points (zero at both ends), so position and velocity are continuous.
    """
    pts = [(float(t), float(x), float(y)) for t, x, y in points]
    n = len(pts)
    t0 = pts[0][0]
    tangents = []
    for k in range(n):
        if k in (0, n - 1):
            tangents.append((0.0, 0.0))
        else:
            dt = pts[k + 1][0] - pts[k - 1][0]
            tangents.append(((pts[k + 1][1] - pts[k - 1][1]) / dt,
                             (pts[k + 1][2] - pts[k - 1][2]) / dt))
    times = [p[0] for p in pts]

    def m(t: float) -> tuple[float, float, float, float]:
        tt = t - LEAD_IN_S + t0
        if tt <= times[0]:
            return pts[0][1], pts[0][2], 0.0, 0.0
        if tt >= times[-1]:
            return pts[-1][1], pts[-1][2], 0.0, 0.0
        k = bisect.bisect_right(times, tt) - 1
        (ta, xa, ya), (tb, xb, yb) = pts[k], pts[k + 1]
        h = tb - ta
        u = (tt - ta) / h
        (mxa, mya), (mxb, myb) = tangents[k], tangents[k + 1]
        u2, u3 = u * u, u * u * u
        h00, h10, h01, h11 = 2 * u3 - 3 * u2 + 1, u3 - 2 * u2 + u, -2 * u3 + 3 * u2, u3 - u2
        d00, d10, d01, d11 = 6 * u2 - 6 * u, 3 * u2 - 4 * u + 1, -6 * u2 + 6 * u, 3 * u2 - 2 * u
        x = h00 * xa + h10 * h * mxa + h01 * xb + h11 * h * mxb
        y = h00 * ya + h10 * h * mya + h01 * yb + h11 * h * myb
        vx = (d00 * xa + d01 * xb) / h + d10 * mxa + d11 * mxb
        vy = (d00 * ya + d01 * yb) / h + d10 * mya + d11 * myb
        return x, y, vx, vy

    return m


def path_duration_s(points: Sequence[tuple[float, float, float]]) -> float:
    return points[-1][0] - points[0][0] if points else 0.0


def wander(motion: MotionFn, amplitude_m: float, seed: int = 0,
           components: int = 3) -> MotionFn:
    """``motion`` plus a seeded, smooth wander of the hand: per axis a sum of ``components``
    sinusoids of 0.5-2 Hz, RMS ``amplitude_m`` in the plane, zero at t = 0 and faded in over
    the lead-in (minimum jerk)."""
    if amplitude_m <= 0.0:
        return motion
    rng = random.Random(seed ^ 0x5EED)
    terms = [tuple((2.0 * math.pi * rng.uniform(0.5, 2.0), rng.uniform(0.0, 2.0 * math.pi))
                   for _ in range(2)) for _ in range(components)]
    a = amplitude_m / math.sqrt(components)  # each axis: RMS amplitude / √2

    def m(t: float) -> tuple[float, float, float, float]:
        x, y, vx, vy = motion(t)
        g, gd = _min_jerk(t / LEAD_IN_S)
        gd /= LEAD_IN_S
        wx = wy = dwx = dwy = 0.0
        for (ox, px), (oy, py) in terms:
            wx += math.sin(ox * t + px)
            wy += math.sin(oy * t + py)
            dwx += ox * math.cos(ox * t + px)
            dwy += oy * math.cos(oy * t + py)
        return (x + a * g * wx, y + a * g * wy, vx + a * (gd * wx + g * dwx),
                vy + a * (gd * wy + g * dwy))

    return m


def make_motion(kind: str, x0: float, y0: float, seed: int = 0,
                duration_s: float | None = None, distance_m: float | None = None,
                path_text: str = "") -> MotionFn:
    """Build a motion by name (:data:`MOTIONS`) starting at (x0, y0); ``path`` follows the
    polyline ``path_text`` (:func:`format_path`) instead."""
    if kind == "path":
        return path(parse_path(path_text))
    if kind == "hold":
        return hold(x0, y0)
    if kind in ("pull", "fastpull"):
        dur = duration_s if duration_s is not None else (4.0 if kind == "pull" else 0.3)
        return pull(x0, y0, distance_m if distance_m is not None else 0.12, dur)
    if kind == "ellipse":
        return ellipse(x0, y0, distance_m if distance_m is not None else 0.14,
                       duration_s=duration_s if duration_s is not None else 1.0)
    if kind == "circle":
        return circle(x0, y0, distance_m if distance_m is not None else 0.06)
    if kind == "explore":
        return explore(x0, y0, distance_m if distance_m is not None else 0.06, seed=seed)
    raise ParameterError(f"unknown motion {kind!r}; known: {', '.join(MOTIONS)}")


def motion_duration_s(kind: str, duration_s: float | None = None, path_text: str = "") -> float:
    """How long a motion takes including its lead-in and a short settle (s)."""
    if kind == "path":
        return LEAD_IN_S + (duration_s or path_duration_s(parse_path(path_text))) + 0.2
    if kind == "pull":
        return LEAD_IN_S + (duration_s or 4.0) + 0.3
    if kind == "fastpull":
        return LEAD_IN_S + (duration_s or 0.3) + 0.5
    if kind == "ellipse":
        return LEAD_IN_S + (duration_s or 1.0) + 0.5
    if kind == "circle":
        return LEAD_IN_S + (duration_s or 5.0)
    return LEAD_IN_S + (duration_s or 10.0)
