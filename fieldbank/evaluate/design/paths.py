"""Paths: the parametrised probe families the search explores.

Two families of parametrised paths are searched (:data:`FAMILIES`):

* **stroke** - a short stroke from the equilibrium, the seed's preferred probe (circles are
  long and reflexes habituate with repetition)::

      p(t) = p0 + L·s(t)·u(θ) + b·L·sin(π s(t))·n(θ),   s(t) minimum jerk over the duration T

  u the direction of travel θ, n its left normal, L the length, b the bulge (fraction of L,
  positive to the left of the direction of travel). b = 0 is a straight pull (the seed's pull is
  θ = −90°, L = 15 cm, T = 0.3 s); b ≈ ±0.5 a half-ellipse like the seed's semi-ellipse.
* **circle** - one circle around the equilibrium (radius r, duration T, either sense), starting
  nearest the body: the seed's Fig. 3a, where the min-max paradigm reads its locations.

Every path the search keeps stays inside :class:`ProbeLimits` (:mod:`.config`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from fieldbank.evaluate.design.config import ProbeLimits
from fieldbank.evaluate.probing import PROBE_SAMPLES, ProbeMotion, min_jerk
from fieldbank.model import FloatArray

_SIDE_WORDS = {"right": ("outward", "inward"), "left": ("inward", "outward")}


def direction_words(direction_deg: float, side: str = "right") -> str:
    """A direction in the shoulder frame in clinic words ("toward the body and outward")."""
    a = math.radians(direction_deg)
    dx, dy = math.cos(a), math.sin(a)
    plus_x, minus_x = _SIDE_WORDS.get(side, _SIDE_WORDS["right"])
    fwd = "away from the body" if dy > 0 else "toward the body"
    lat = plus_x if dx > 0 else minus_x
    if abs(dy) >= math.cos(math.radians(22.5)):
        return fwd
    if abs(dx) >= math.cos(math.radians(22.5)):
        return lat
    return f"{fwd} and {lat}"


def _stroke_batch(start: FloatArray, v: FloatArray, samples: int
                  ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Positions (S, K, 2), velocities (S, K, 2), times (S, K) of S strokes (rows of v:
    direction deg, length m, duration s, bulge)."""
    tau = np.linspace(0.0, 1.0, samples)
    s, ds = min_jerk(tau)
    th = np.radians(v[:, 0])
    length, dur, bulge = v[:, 1], v[:, 2], v[:, 3]
    u = np.stack([np.cos(th), np.sin(th)], axis=1)[:, None, :]
    n = np.stack([-np.sin(th), np.cos(th)], axis=1)[:, None, :]
    lat = (bulge * length)[:, None]
    dsdt = ds[None, :] / dur[:, None]
    along = length[:, None] * s[None, :]
    side = lat * np.sin(np.pi * s)[None, :]
    pos = start + along[..., None] * u + side[..., None] * n
    vel = (length[:, None] * dsdt)[..., None] * u \
        + (lat * np.pi * np.cos(np.pi * s)[None, :] * dsdt)[..., None] * n
    return pos, vel, tau[None, :] * dur[:, None]


def _circle_batch(centre: FloatArray, v: FloatArray, samples: int
                  ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """One circle per row of v (radius m, duration s, sense +1 counter-clockwise / -1),
    starting nearest the body, minimum-jerk phase."""
    tau = np.linspace(0.0, 1.0, samples)
    s, ds = min_jerk(tau)
    r, dur, sense = v[:, 0][:, None], v[:, 1][:, None], np.sign(v[:, 2])[:, None]
    phi = -0.5 * np.pi + sense * 2.0 * np.pi * s[None, :]
    dphi = sense * 2.0 * np.pi * ds[None, :] / dur
    pos = centre + np.stack([r * np.cos(phi), r * np.sin(phi)], axis=-1)
    vel = np.stack([-r * np.sin(phi) * dphi, r * np.cos(phi) * dphi], axis=-1)
    return pos, vel, tau[None, :] * dur


@dataclass(frozen=True)
class Stroke:
    """A short stroke from ``start_m`` (see the module docstring); shoulder frame, SI."""

    start_m: tuple[float, float]
    direction_deg: float
    length_m: float
    duration_s: float
    bulge: float = 0.0

    family = "stroke"

    @property
    def values(self) -> tuple[float, ...]:
        return (self.direction_deg, self.length_m, self.duration_s, self.bulge)

    def motion(self, samples: int = PROBE_SAMPLES, name: str = "stroke",
               side: str = "right") -> ProbeMotion:
        pos, vel, t = _stroke_batch(np.asarray(self.start_m), np.array([self.values]), samples)
        return ProbeMotion(name, t[0], pos[0], vel[0], self.describe(side))

    def describe(self, side: str = "right") -> str:
        d = ((self.direction_deg + 180.0) % 360.0) - 180.0
        text = (f"stroke {self.length_m * 100:.0f} cm {direction_words(d, side)} "
                f"({d:.0f}° from +x) in {self.duration_s:.2f} s")
        if abs(self.bulge) * self.length_m >= 0.005:
            a = math.radians(d + (90.0 if self.bulge > 0 else -90.0))
            text += (f", bulging {abs(self.bulge) * self.length_m * 100:.0f} cm "
                     f"{direction_words(math.degrees(a), side)}")
        return text

    def to_dict(self) -> dict[str, object]:
        return {"family": self.family, "start_m": list(self.start_m),
                "direction_deg": self.direction_deg, "length_m": self.length_m,
                "duration_s": self.duration_s, "bulge": self.bulge}


@dataclass(frozen=True)
class Circle:
    """One circle around ``centre_m``, starting nearest the body; shoulder frame, SI."""

    centre_m: tuple[float, float]
    radius_m: float
    duration_s: float
    sense: float = 1.0

    family = "circle"

    @property
    def values(self) -> tuple[float, ...]:
        return (self.radius_m, self.duration_s, self.sense)

    def motion(self, samples: int = PROBE_SAMPLES, name: str = "circle",
               side: str = "right") -> ProbeMotion:
        pos, vel, t = _circle_batch(np.asarray(self.centre_m), np.array([self.values]), samples)
        return ProbeMotion(name, t[0], pos[0], vel[0], self.describe(side))

    def describe(self, side: str = "right") -> str:
        turn = "counter-clockwise" if self.sense > 0 else "clockwise"
        return (f"circle of radius {self.radius_m * 100:.0f} cm around the rest position, "
                f"{turn} from the point nearest the body, in {self.duration_s:.2f} s")

    def to_dict(self) -> dict[str, object]:
        return {"family": self.family, "centre_m": list(self.centre_m),
                "radius_m": self.radius_m, "duration_s": self.duration_s, "sense": self.sense}


Path = Stroke | Circle


@dataclass(frozen=True)
class Family:
    name: str
    make: Callable[[FloatArray, FloatArray, int], tuple[FloatArray, FloatArray, FloatArray]]
    grid: Callable[[ProbeLimits], FloatArray]
    bounds: Callable[[ProbeLimits], tuple[FloatArray, FloatArray]]
    build: Callable[[FloatArray, FloatArray], Path]
    #: parameters the local polish moves (the others, e.g. a circle's sense, stay)
    polish: tuple[int, ...]
    closed: bool


def _stroke_grid(lim: ProbeLimits) -> FloatArray:
    rows = []
    for d in np.arange(-180.0, 180.0, 15.0):
        for length in (0.08, 0.15):
            length = min(max(length, lim.min_length_m), lim.max_length_m)
            for speed in (0.35, 1.0):
                # the peak speed of a straight minimum-jerk stroke is 1.875 L / T
                dur = min(max(1.875 * length / min(speed, lim.max_speed_m_per_s),
                              lim.min_duration_s), lim.max_duration_s)
                for b in (-0.5, 0.0, 0.5):
                    rows.append((d, length, dur, max(-lim.max_bulge, min(b, lim.max_bulge))))
    return np.array(rows)


def _circle_grid(lim: ProbeLimits) -> FloatArray:
    rows = []
    for r in np.linspace(lim.min_radius_m, lim.max_radius_m, 4):
        for dur in (1.5, 3.0):
            dur = min(max(dur, lim.min_duration_s, 1.0), max(lim.max_duration_s, 1.0))
            for sense in (1.0, -1.0):
                rows.append((r, dur, sense))
    return np.array(rows)


FAMILIES: dict[str, Family] = {
    "stroke": Family(
        "stroke", _stroke_batch, _stroke_grid,
        lambda lim: (np.array([-540.0, lim.min_length_m, lim.min_duration_s, -lim.max_bulge]),
                     np.array([540.0, lim.max_length_m, lim.max_duration_s, lim.max_bulge])),
        lambda start, v: Stroke((float(start[0]), float(start[1])), float(v[0]), float(v[1]),
                                float(v[2]), float(v[3])),
        (0, 1, 2, 3), False),
    "circle": Family(
        "circle", _circle_batch, _circle_grid,
        lambda lim: (np.array([lim.min_radius_m, max(lim.min_duration_s, 1.0), -1.0]),
                     np.array([lim.max_radius_m, max(lim.max_duration_s, 1.0, 4.0), 1.0])),
        lambda start, v: Circle((float(start[0]), float(start[1])), float(v[0]), float(v[1]),
                                1.0 if v[2] >= 0 else -1.0),
        (0, 1), True),
}

def circles(start_m: Sequence[float] | FloatArray, radii_m: Sequence[float] = (0.04, 0.06, 0.08),
            duration_s: float = 2.0, side: str = "right") -> list[ProbeMotion]:
    """Counter-clockwise circles of the given radii around ``start_m`` (seed Fig. 3a)."""
    c = (float(start_m[0]), float(start_m[1]))
    return [Circle(c, r, duration_s, 1.0).motion(PROBE_SAMPLES, f"circle {r * 100:.0f} cm", side)
            for r in radii_m]
