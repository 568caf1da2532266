"""Probe design's sourced defaults and assumptions (those the command line shows are in
:mod:`fieldbank.probechoices`), and its three frozen configurations,
each with one bounds table: :class:`Perception` (what a hand tells apart), :class:`NoiseModel`
(force noise of a recording, motion noise of the operator) and :class:`ProbeLimits` (where and
how fast a probe may go).

:class:`ProbeLimits` keeps every path inside the renderer's speed limit and force saturation,
the workspace box and, for every candidate, the range of motion with a margin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from fieldbank.errors import ParameterError
from fieldbank.evaluate.probing import PROBE_SAMPLES
from fieldbank.probechoices import (
    CORRELATION_S,
    DIRECTION_JND_DEG,
    DIRECTION_SD_DEG,
    FORCE_JND,
    FORCE_LIMIT_N,
    FORCE_SD_N,
    LENGTH_SD,
    MAX_SPEED_M_PER_S,
    SPEED_SD,
)
from fieldbank.validation import Interval, check_fields, check_tuple

#: Stiffness Weber fraction for free exploration (seed: up to 67 %, 0.6 chosen for the scale).
FREE_EXPLORATION_JND = 0.60
#: Weber fraction of a distance felt by moving the arm, ≈ 11 % for 25-35 cm (van Beek,
#: Bergmann Tiest & Kappers 2014): places along a path closer than this fraction of its length
#: are not told apart (min-max paradigm).
LOCATION_JND = 0.11
#: Forces below this are not judged by direction and compare in magnitude as if this large, N
#: (assumption).
FELT_FLOOR_N = 1.0

#: The smooth wander of the hand off the path, m (assumption).
WANDER_M = 0.005

#: Distance every posture keeps from the edges of each candidate's range of motion, degrees.
ROM_MARGIN_DEG = 10.0

#: Samples per path during the search; reports use :data:`PROBE_SAMPLES`.
DESIGN_SAMPLES = 16
#: Samples per path at which the limits of a path the search keeps are checked: every point of
#: the delivered polyline (:data:`PROBE_SAMPLES`) and of the search's samples, and three more
#: between neighbouring points of the polyline - so that no execution of the drawn path leaves
#: the workspace, the range of motion or the speed limit between the points scored.
LIMIT_SAMPLES = 4 * math.lcm(DESIGN_SAMPLES - 1, PROBE_SAMPLES - 1) + 1
#: Grid points polished with nlopt, and the evaluations each polish may take.
POLISH_STARTS = 2
POLISH_EVALS = 30
#: A further path must raise the set's score by at least this much.
MIN_GAIN = 1e-3
#: Weight of the worst-pair tie-break in the score.
TIE_BREAK = 1e-3
#: Most combinations of executions kept when the D_KL of a set's paths add up.
MAX_COMBINATIONS = 49
#: Bayes error below which the information criterion calls a pair separated.
SEPARATED_ERROR = 0.05


PERCEPTION_BOUNDS: dict[str, Interval] = {
    "force_jnd": Interval(0.0, 5.0, "", low_closed=False),
    "direction_jnd_deg": Interval(0.0, 180.0, "deg", low_closed=False),
    "location_jnd": Interval(0.0, 1.0, "", low_closed=False),
    "floor_n": Interval(0.0, None, "N", low_closed=False),
}
NOISE_BOUNDS: dict[str, Interval] = {
    "force_sd_n": Interval(0.0, None, "N", low_closed=False),
    "correlation_s": Interval(0.0, 10.0, "s", low_closed=False),
    "direction_sd_deg": Interval(0.0, 90.0, "deg"),
    "length_sd": Interval(0.0, 0.9, ""),
    "speed_sd": Interval(0.0, 0.9, ""),
    "wander_m": Interval(0.0, 0.1, "m"),
}
LIMIT_BOUNDS: dict[str, Interval] = {
    "max_speed_m_per_s": Interval(0.0, 10.0, "m/s", low_closed=False),
    "force_limit_n": Interval(0.0, None, "N", low_closed=False),
    "rom_margin_deg": Interval(0.0, 45.0, "deg"),
    "min_length_m": Interval(0.0, 1.0, "m", low_closed=False),
    "max_length_m": Interval(0.0, 1.0, "m", low_closed=False),
    "min_duration_s": Interval(0.05, 30.0, "s"),
    "max_duration_s": Interval(0.05, 30.0, "s"),
    "max_bulge": Interval(0.0, 1.0, ""),
    "min_radius_m": Interval(0.0, 0.5, "m", low_closed=False),
    "max_radius_m": Interval(0.0, 0.5, "m", low_closed=False),
}


@dataclass(frozen=True)
class Perception:
    """What a hand tells apart; ranges in :data:`PERCEPTION_BOUNDS`.

    Attributes
    ----------
    force_jnd : float
        Weber fraction of force magnitude (0.10: Jones 1989; Pang, Tan & Durlach 1991).
    direction_jnd_deg : float, degrees
        Force-direction threshold (25.6°: Barbagli et al. 2006, haptics alone).
    location_jnd : float
        Fraction of a path's length two places must be apart to be told apart (0.11: van Beek
        et al. 2014).
    floor_n : float, N
        Forces below this are not judged by direction (assumption, 1 N).
    """

    force_jnd: float = FORCE_JND
    direction_jnd_deg: float = DIRECTION_JND_DEG
    location_jnd: float = LOCATION_JND
    floor_n: float = FELT_FLOOR_N

    def __post_init__(self) -> None:
        check_fields(self, PERCEPTION_BOUNDS, what="perception parameter")

    @classmethod
    def free_exploration(cls) -> Perception:
        """Magnitude judged with the seed's free-exploration Weber fraction 0.6."""
        return cls(force_jnd=FREE_EXPLORATION_JND)

    def to_dict(self) -> dict[str, float]:
        return {"force_jnd": self.force_jnd, "direction_jnd_deg": self.direction_jnd_deg,
                "location_jnd": self.location_jnd, "floor_n": self.floor_n}


@dataclass(frozen=True)
class NoiseModel:
    """Force noise of a recording and motion noise of the operator; ranges in
    :data:`NOISE_BOUNDS`. Every default is an assumption.

    Attributes
    ----------
    force_sd_n : float, N
        SD of the force noise per axis.
    correlation_s : float, s
        Time over which the force noise decorrelates (one independent sample per τ).
    direction_sd_deg, length_sd, speed_sd : float
        SD of the executed direction (degrees), of the executed length and of the executed speed
        (fractions) of a probe the operator performs.
    wander_m : float, m
        Smooth wander of the operator's hand off the path (the simulated operator).
    """

    force_sd_n: float = FORCE_SD_N
    correlation_s: float = CORRELATION_S
    direction_sd_deg: float = DIRECTION_SD_DEG
    length_sd: float = LENGTH_SD
    speed_sd: float = SPEED_SD
    wander_m: float = WANDER_M

    def __post_init__(self) -> None:
        check_fields(self, NOISE_BOUNDS, what="noise parameter")

    def to_dict(self) -> dict[str, float]:
        return {"force_sd_n": self.force_sd_n, "correlation_s": self.correlation_s,
                "direction_sd_deg": self.direction_sd_deg, "length_sd": self.length_sd,
                "speed_sd": self.speed_sd, "wander_m": self.wander_m}


@dataclass(frozen=True)
class ProbeLimits:
    """Where and how fast a probe may go; ranges in :data:`LIMIT_BOUNDS`.

    Attributes
    ----------
    max_speed_m_per_s : float, m/s
        Peak hand speed of every execution of the path.
    force_limit_n : float, N
        Saturation of the rendered force (predictions are saturated the same way).
    workspace_m : (xmin, xmax, ymin, ymax) in m, shoulder frame, or None
        Box every point must stay in (the robot's workspace).
    rom_margin_deg : float, degrees
        Margin from the edges of every candidate's range of motion.
    min_length_m, max_length_m, min_duration_s, max_duration_s, max_bulge : float
        Bounds of the stroke family (length m, duration s, |bulge| as a fraction of the length).
    min_radius_m, max_radius_m : float, m
        Bounds of the circle family (durations as for strokes, at least 1 s).
    """

    max_speed_m_per_s: float = MAX_SPEED_M_PER_S
    force_limit_n: float = FORCE_LIMIT_N
    workspace_m: tuple[float, float, float, float] | None = None
    rom_margin_deg: float = ROM_MARGIN_DEG
    min_length_m: float = 0.04
    max_length_m: float = 0.18
    min_duration_s: float = 0.2
    max_duration_s: float = 1.0
    max_bulge: float = 0.6
    min_radius_m: float = 0.03
    max_radius_m: float = 0.10

    def __post_init__(self) -> None:
        check_fields(self, LIMIT_BOUNDS, what="probe limit")
        if self.workspace_m is not None:
            x0, x1, y0, y1 = check_tuple("workspace_m", self.workspace_m, 4,
                                         Interval(None, None, "m"), what="probe limit")
            if not (x0 < x1 and y0 < y1):
                raise ParameterError("The 'workspace_m' probe limit must be (xmin, xmax, ymin, "
                                     f"ymax) with min < max; got {self.workspace_m!r} instead.")
        for lo, hi in (("min_length_m", "max_length_m"), ("min_duration_s", "max_duration_s"),
                       ("min_radius_m", "max_radius_m")):
            if getattr(self, lo) >= getattr(self, hi):
                raise ParameterError(f"The probe limits need {lo} < {hi}; got "
                                     f"{getattr(self, lo)!r} and {getattr(self, hi)!r}.")

    def to_dict(self) -> dict[str, object]:
        return {"max_speed_m_per_s": self.max_speed_m_per_s,
                "force_limit_n": self.force_limit_n,
                "workspace_m": None if self.workspace_m is None else list(self.workspace_m),
                "rom_margin_deg": self.rom_margin_deg}
