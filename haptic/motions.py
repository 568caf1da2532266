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
- explore: free exploration, a seeded sum of slow sinusoids around the rest position.

Pure ``math``, no numpy: the device process imports this module and steps it at 4 kHz.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable

MotionFn = Callable[[float], tuple[float, float, float, float]]

MOTIONS = ("hold", "pull", "fastpull", "ellipse", "circle", "explore")
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


def make_motion(kind: str, x0: float, y0: float, seed: int = 0,
                duration_s: float | None = None, distance_m: float | None = None) -> MotionFn:
    """Build a motion by name (:data:`MOTIONS`) starting at (x0, y0)."""
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
    raise ValueError(f"unknown motion {kind!r}; known: {', '.join(MOTIONS)}")


def motion_duration_s(kind: str, duration_s: float | None = None) -> float:
    """How long a motion takes including its lead-in and a short settle (s)."""
    if kind == "pull":
        return LEAD_IN_S + (duration_s or 4.0) + 0.3
    if kind == "fastpull":
        return LEAD_IN_S + (duration_s or 0.3) + 0.5
    if kind == "ellipse":
        return LEAD_IN_S + (duration_s or 1.0) + 0.5
    if kind == "circle":
        return LEAD_IN_S + (duration_s or 5.0)
    return LEAD_IN_S + (duration_s or 10.0)
