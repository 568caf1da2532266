"""The most informative probing motions for a set of candidate arms, and the seed's min-max and
orientation paradigms as computations (seed, "Selection of specific probing motions" and
"A guided approach to manipulation"; the search for the most informative motion is the seed's
stated next step).

Candidates
----------
The arms a clinician hesitates between (:class:`Candidate`): synthetic severities per joint
group (:func:`severity_candidates`), stored fitted models, parameter files, each compiled once.
Their equilibrium is the mean of their rest hand positions; every path is in the shoulder frame.

Paths
-----
Two families of parametrised paths are searched (:data:`FAMILIES`):

* **stroke** - a short stroke from the equilibrium, the seed's preferred probe (circles are
  long and reflexes habituate with repetition)::

      p(t) = p0 + L·s(t)·u(θ) + b·L·sin(π s(t))·n(θ),   s(t) minimum jerk over the duration T

  u the direction of travel θ, n its left normal, L the length, b the bulge (fraction of L,
  positive to the left of the direction of travel). b = 0 is a straight pull (the seed's pull is
  θ = −90°, L = 15 cm, T = 0.3 s); b ≈ ±0.5 a half-ellipse like the seed's semi-ellipse.
* **circle** - one circle around the equilibrium (radius r, duration T, either sense), starting
  nearest the body: the seed's Fig. 3a, where the min-max paradigm reads its locations.

:class:`ProbeLimits` keeps every path inside the renderer's speed limit and force saturation,
the workspace box and, for every candidate, the range of motion with a margin.

Predicted force
---------------
The force a candidate puts on the handle along a path is what a hand moving the rigid arm along
it feels: the muscles' endpoint force at the path's positions and velocities
(:meth:`fieldbank.model.Arm.endpoint_force`: the reflex sees the velocity) plus the arm's
inertia, −J⁻ᵀ(H q̈ + C q̇) (:func:`fieldbank.dynamics.hand_inertial_force`), saturated at the
renderer's force limit. The inertia matters: on a stroke of 0.2 s it is as large as a severe
group's force, the same for every candidate, and hides their differences. The renderer's
virtual coupling (a spring and damper between handle and hand) is left out; the classifier
replays it (:mod:`fieldbank.evaluate.classify`).

What a hand feels (:class:`Perception`)
---------------------------------------
Two candidates feel different along a path where, at the same moment of the motion, their forces
differ by more than a just-noticeable difference (JND) in magnitude (Weber fraction 10 %:
7 % for matched forces, Jones 1989; 5–15 %, Pang, Tan & Durlach 1991) or in direction (25.6°
with haptics alone: Barbagli, Salisbury, Ho, Spence & Tan 2006). The two channels add as
independent cues, d = √(m² + a²) in JNDs, and a pair's separation is the largest d along the
path. Directions are judged only where both forces reach :data:`FELT_FLOOR_N` (assumption).
The operator never performs a path exactly: a pair counts as felt apart only if it stays apart
for every pair of executions within the motion noise (direction, length and speed each ±1 SD,
:class:`NoiseModel`), so a difference the clinician's own variability could produce does not
count. Free exploration uses the seed's stiffness Weber fraction 0.6 for magnitude instead
(:meth:`Perception.free_exploration`). The seed's paradigms are read the same way:
*orientation* - the directions at each candidate's peak force differ by ≥ 1 JND; *min-max* -
the places along the path of the largest or the smallest force differ by ≥ 11 % of the path's
length (distance Weber fraction of active arm movements, van Beek, Bergmann Tiest & Kappers 2014).

Statistically (:class:`NoiseModel`)
-----------------------------------
The recorded force is the prediction plus Gaussian noise of SD σ per axis whose samples
decorrelate over τ (assumption), so a path of duration T carries T/τ independent samples. Between
two candidates D_KL = Σ_k (Δt_k/τ)·|F_i − F_j|² / (2σ²) (averaged over the executions); a
set of paths adds. The information the path gives about which candidate it is, with prior p,
is bounded below by the pairwise-distance estimate of Kolchinsky & Tracey (2017, Entropy 19:361)
with the Bhattacharyya distance, D_KL/4 for equal covariances:
I ≥ −Σ_i p_i log₂ Σ_j p_j exp(−D_ij/4) bits (at most log₂ n). Pairwise, the Bayes error of
telling two candidates apart is Φ(−√(2 D_ij)/2).

Search
------
For one path: every point of a coarse grid of the family is scored on its nominal execution in
one vectorised evaluation per candidate; the best few distinct ones are polished with nlopt
(Sbplx, derivative-free) on the robust score. A set is built greedily: each next path maximises
the score of the set with it, until every pair is separated (felt apart by ≥ 1 JND, or a
Bayes error ≤ 5 % for the information criterion), the score stops improving, or n − 1 paths.
Scores saturate when every pair is far apart; a term 10⁻³·log(1 + worst pair) breaks the tie
toward the path that separates the closest pair most.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import nlopt
import numpy as np
from scipy.special import erf, ndtr

from fieldbank.dynamics import hand_inertial_force
from fieldbank.errors import ParameterError
from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.probing import PROBE_SAMPLES, ProbeMotion, min_jerk, pull, semi_ellipse
from fieldbank.model import Arm, FloatArray
from fieldbank.params import JOINT_GROUPS, ArmParams
from fieldbank.severity import group_name, level_name, synthesize
from fieldbank.validation import Interval, check_number, check_tuple

# --- what a hand feels: sourced defaults ------------------------------------------------------
#: Weber fraction of force magnitude: 7 % for matched forces (Jones 1989), 5-15 % for actively
#: felt forces (Pang, Tan & Durlach 1991); the upper end of 7-10 %.
FORCE_JND = 0.10
#: Stiffness Weber fraction for free exploration (seed: up to 67 %, 0.6 chosen for the scale).
FREE_EXPLORATION_JND = 0.60
#: Force-direction discrimination threshold with haptics alone, degrees (Barbagli et al. 2006;
#: 18.4° with congruent vision, 31.9° with incongruent vision).
DIRECTION_JND_DEG = 25.6
#: Weber fraction of a distance felt by moving the arm, ≈ 11 % for 25-35 cm (van Beek,
#: Bergmann Tiest & Kappers 2014): places along a path closer than this fraction of its length
#: are not told apart (min-max paradigm).
LOCATION_JND = 0.11
#: Forces below this are not judged by direction and compare in magnitude as if this large, N
#: (assumption).
FELT_FLOOR_N = 1.0

# --- noise model: assumptions -------------------------------------------------------------------
#: Force noise per axis, N: force sensing plus what the model leaves out (assumption).
FORCE_SD_N = 2.0
#: Time over which the force noise decorrelates, s: one independent sample per τ (assumption).
CORRELATION_S = 0.05
#: Scatter of the executed direction (deg), relative length and relative speed of a probe the
#: operator performs (assumptions), and the smooth wander of the hand off the path, m.
DIRECTION_SD_DEG = 10.0
LENGTH_SD = 0.15
SPEED_SD = 0.20
WANDER_M = 0.005

# --- limits: assumptions ------------------------------------------------------------------------
#: Peak hand speed of a probe, m/s: a fast clinical stretch (the seed's pull peaks at 0.94 m/s),
#: well below the renderer's 2.5 m/s speed limit.
MAX_SPEED_M_PER_S = 1.2
#: The renderer's default force saturation, N (haptic safety).
FORCE_LIMIT_N = 40.0
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

CRITERIA = ("feel", "information", "orientation", "minmax")
TARGETS = ("candidate", "group")

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


def _check(obj: object, bounds: Mapping[str, Interval], what: str) -> None:
    for name, interval in bounds.items():
        check_number(name, getattr(obj, name), interval, what=what)


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
        _check(self, PERCEPTION_BOUNDS, "perception parameter")

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
        _check(self, NOISE_BOUNDS, "noise parameter")

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
        _check(self, LIMIT_BOUNDS, "probe limit")
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


# --- candidates ---------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Candidate:
    """One arm a clinician hesitates about.

    Attributes
    ----------
    name : str
        Unique among the candidates ("elbow severe", "model 12").
    arm : Arm
        The compiled model.
    group, level : str or None
        The impaired joint group and its severity level when known ("unimpaired": no group).
    notes : tuple of str
        What the candidate's numbers rest on that its data did not identify.
    """

    name: str
    arm: Arm
    group: str | None = None
    level: str | None = None
    notes: tuple[str, ...] = ()

    @classmethod
    def from_severity(cls, group: str | None, level: str, base: ArmParams | None = None,
                      cache: ArmCache | None = None) -> Candidate:
        """A synthetic arm with ``group`` at ``level`` (:func:`fieldbank.severity.synthesize`)."""
        lvl = level_name(level)
        if lvl == "unimpaired" or group is None:
            params = synthesize({}, base)
            return cls("unimpaired", (cache or Arm.from_params)(params), None, "unimpaired")
        g = group_name(group)
        params = synthesize({g: lvl}, base)
        return cls(f"{g} {lvl}", (cache or Arm.from_params)(params), g, lvl)

    @property
    def label(self) -> str:
        """The group a classification names ("unimpaired" when no group is impaired)."""
        return self.group if self.group is not None else (self.level or self.name)


def severity_candidates(groups: Sequence[str] = tuple(JOINT_GROUPS),
                        levels: Sequence[str] = ("severe",), *, unimpaired: bool = False,
                        base: ArmParams | None = None,
                        cache: ArmCache | None = None) -> tuple[Candidate, ...]:
    """Every group at every level (groups × levels), optionally with the unimpaired arm."""
    cache = cache or ArmCache()
    out = [Candidate.from_severity(g, lvl, base, cache) for lvl in levels for g in groups]
    if unimpaired:
        out.append(Candidate.from_severity(None, "unimpaired", base, cache))
    return tuple(out)


def check_candidates(candidates: Sequence[Candidate], at_least: int = 2) -> tuple[Candidate, ...]:
    """The candidates as a tuple; refuses fewer than ``at_least`` or repeated names."""
    cands = tuple(candidates)
    if len(cands) < at_least:
        raise ParameterError(f"Give at least {at_least} candidate arms; got {len(cands)}.")
    names = [c.name for c in cands]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ParameterError(f"Candidate names must differ; repeated: {', '.join(dup)}.")
    return cands


def equilibrium(candidates: Sequence[Candidate]) -> FloatArray:
    """The candidates' mean rest hand position, shape (2,), m, shoulder frame."""
    return np.mean([c.arm.rest_position() for c in candidates], axis=0)


def check_prior(prior: Sequence[float] | FloatArray | None, n: int) -> FloatArray:
    """Prior probabilities of n candidates (uniform when None), normalised."""
    if prior is None:
        return np.full(n, 1.0 / n)
    p = np.asarray(prior, dtype=float)
    if p.shape != (n,) or not np.all(np.isfinite(p)) or np.any(p < 0) or p.sum() <= 0:
        raise ParameterError(f"The prior must be {n} non-negative numbers with a positive sum; "
                             f"got {np.asarray(prior).tolist()!r}.")
    return p / p.sum()


# --- paths --------------------------------------------------------------------------------------
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
class _Family:
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


FAMILIES: dict[str, _Family] = {
    "stroke": _Family(
        "stroke", _stroke_batch, _stroke_grid,
        lambda lim: (np.array([-540.0, lim.min_length_m, lim.min_duration_s, -lim.max_bulge]),
                     np.array([540.0, lim.max_length_m, lim.max_duration_s, lim.max_bulge])),
        lambda start, v: Stroke((float(start[0]), float(start[1])), float(v[0]), float(v[1]),
                                float(v[2]), float(v[3])),
        (0, 1, 2, 3), False),
    "circle": _Family(
        "circle", _circle_batch, _circle_grid,
        lambda lim: (np.array([lim.min_radius_m, max(lim.min_duration_s, 1.0), -1.0]),
                     np.array([lim.max_radius_m, max(lim.max_duration_s, 1.0, 4.0), 1.0])),
        lambda start, v: Circle((float(start[0]), float(start[1])), float(v[0]), float(v[1]),
                                1.0 if v[2] >= 0 else -1.0),
        (0, 1), True),
}


# --- executions, predictions, feasibility -----------------------------------------------------
def _execution_deltas(noise: NoiseModel) -> list[tuple[float, float, float]]:
    """(rotation deg, length scale, speed scale) of the nominal execution and ±1 SD of each."""
    out = [(0.0, 1.0, 1.0)]
    if noise.direction_sd_deg > 0:
        out += [(noise.direction_sd_deg, 1.0, 1.0), (-noise.direction_sd_deg, 1.0, 1.0)]
    if noise.length_sd > 0:
        out += [(0.0, 1.0 + noise.length_sd, 1.0), (0.0, 1.0 - noise.length_sd, 1.0)]
    if noise.speed_sd > 0:
        out += [(0.0, 1.0, 1.0 + noise.speed_sd), (0.0, 1.0, 1.0 - noise.speed_sd)]
    return out


def _execute(pos: FloatArray, vel: FloatArray, t: FloatArray,
             deltas: Sequence[tuple[float, float, float]], closed: bool = False
             ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Executions of S paths (S, K, ·) → (S, E, K, ·): each rotated about and scaled from its
    anchor - the first point of an open path (where the hand starts), the centre of a closed
    one (a circle around the equilibrium stays around it) - its speed scaled."""
    p0 = pos.mean(axis=1)[:, None, None, :] if closed else pos[:, None, :1, :]
    rel = pos[:, None, :, :] - p0
    pe, ve, te = [], [], []
    for rot, scale, speed in deltas:
        c, s = math.cos(math.radians(rot)), math.sin(math.radians(rot))
        r = np.array([[c, -s], [s, c]]) * scale
        pe.append(rel @ r.T)
        ve.append(vel[:, None] @ r.T * speed)
        te.append(t[:, None] / speed)
    return (p0 + np.concatenate(pe, axis=1), np.concatenate(ve, axis=1),
            np.concatenate(te, axis=1))


def executions(motion: ProbeMotion, noise: NoiseModel, closed: bool = False
               ) -> list[ProbeMotion]:
    """The nominal execution of ``motion`` and ±1 SD of each kind of motion noise."""
    deltas = _execution_deltas(noise)
    pos, vel, t = _execute(motion.positions_m[None], motion.velocities_m_per_s[None],
                           motion.times_s[None], deltas, closed)
    return [ProbeMotion(motion.name, t[0, e], pos[0, e], vel[0, e], motion.description)
            for e in range(len(deltas))]


def draw_execution(motion: ProbeMotion, noise: NoiseModel, rng: np.random.Generator,
                   closed: bool = False) -> ProbeMotion:
    """One execution of ``motion`` as an operator with ``noise`` performs it: direction, length
    and speed drawn from the noise model (truncated at ±2.5 SD, speed and length at ≥ 0.3)."""
    z = np.clip(rng.standard_normal(3), -2.5, 2.5)
    rot = float(z[0] * noise.direction_sd_deg)
    scale = max(0.3, 1.0 + float(z[1]) * noise.length_sd)
    speed = max(0.3, 1.0 + float(z[2]) * noise.speed_sd)
    pos, vel, t = _execute(motion.positions_m[None], motion.velocities_m_per_s[None],
                           motion.times_s[None], [(rot, scale, speed)], closed)
    return ProbeMotion(motion.name, t[0, 0], pos[0, 0], vel[0, 0],
                       f"{motion.description} (executed: {rot:+.0f}°, length ×{scale:.2f}, "
                       f"speed ×{speed:.2f})")


def saturate(force_n: FloatArray, limit_n: float) -> FloatArray:
    """Force vectors (..., 2) scaled down to a norm of at most ``limit_n``, as the renderer."""
    mag = np.hypot(force_n[..., 0], force_n[..., 1])
    k = np.where(mag > limit_n, limit_n / np.maximum(mag, 1e-300), 1.0)
    return force_n * k[..., None]


def path_accelerations(velocities_m_per_s: FloatArray, times_s: FloatArray) -> FloatArray:
    """Accelerations (..., K, 2), m/s², of evenly sampled paths: velocities (..., K, 2), times
    (..., K)."""
    dt = times_s[..., 1] - times_s[..., 0]
    acc = np.gradient(velocities_m_per_s, axis=-2, edge_order=2)
    return np.asarray(acc / dt[..., None, None], dtype=float)


def predict(candidates: Sequence[Candidate], positions_m: FloatArray,
            velocities_m_per_s: FloatArray, force_limit_n: float | None,
            accelerations_m_per_s2: FloatArray | None = None) -> FloatArray:
    """Force each candidate puts on the handle, shape (n, ..., 2), N: the muscles' endpoint
    force, plus the rigid arm's inertia when the accelerations are given."""
    shape = positions_m.shape
    x = positions_m.reshape(-1, 2)
    v = velocities_m_per_s.reshape(-1, 2)
    acc = None if accelerations_m_per_s2 is None else accelerations_m_per_s2.reshape(-1, 2)
    out = np.empty((len(candidates), *shape))
    inertial: dict[tuple[object, ...], FloatArray] = {}
    for i, c in enumerate(candidates):
        f = c.arm.endpoint_force(x, v)
        if acc is not None:
            key = _inertia_key(c.arm)
            if key not in inertial:
                inertial[key] = hand_inertial_force(c.arm, x, v, acc)
            f = f + inertial[key]
        f = f.reshape(shape)
        out[i] = f if force_limit_n is None else saturate(f, force_limit_n)
    return out


def _inertia_key(arm: Arm) -> tuple[object, ...]:
    p = arm.params
    return (arm.l1, arm.l2, arm.mirror, p.upper_arm_mass_kg, p.forearm_mass_kg,
            p.upper_arm_com_m, p.forearm_com_m, p.upper_arm_inertia_kg_m2,
            p.forearm_inertia_kg_m2)


def _geometry_key(arm: Arm) -> tuple[object, ...]:
    p = arm.params
    return (arm.l1, arm.l2, arm.mirror, p.shoulder_range_rad, p.elbow_range_rad)


def feasible(candidates: Sequence[Candidate], positions_m: FloatArray,
             velocities_m_per_s: FloatArray, limits: ProbeLimits) -> FloatArray:
    """Which of S paths (S, M, 2) respect the limits for every candidate: mask (S,)."""
    s_count = positions_m.shape[0]
    pts = positions_m.reshape(s_count, -1, 2)
    vel = velocities_m_per_s.reshape(s_count, -1, 2)
    ok = np.all(np.isfinite(pts), axis=(1, 2)) & np.all(np.isfinite(vel), axis=(1, 2))
    ok &= np.hypot(vel[..., 0], vel[..., 1]).max(axis=1) <= limits.max_speed_m_per_s * (1 + 1e-9)
    if limits.workspace_m is not None:
        x0, x1, y0, y1 = limits.workspace_m
        ok &= np.all((pts[..., 0] >= x0) & (pts[..., 0] <= x1) & (pts[..., 1] >= y0)
                     & (pts[..., 1] <= y1), axis=1)
    margin = math.radians(limits.rom_margin_deg)
    flat = pts.reshape(-1, 2)
    seen: set[tuple[object, ...]] = set()
    for c in candidates:
        key = _geometry_key(c.arm)
        if key in seen:
            continue
        seen.add(key)
        good = c.arm.reachable(flat)
        if margin > 0 and good.any():
            q = c.arm.ik(flat[good])
            p = c.arm.params
            (s0, s1), (e0, e1) = p.shoulder_range_rad, p.elbow_range_rad
            inside = ((q[:, 0] >= s0 + margin) & (q[:, 0] <= s1 - margin)
                      & (q[:, 1] >= e0 + margin) & (q[:, 1] <= e1 - margin))
            good[np.flatnonzero(good)] = inside
        ok &= good.reshape(s_count, -1).all(axis=1)
    return ok


# --- separations ----------------------------------------------------------------------------
def _pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    i, j = np.triu_indices(n, 1)
    return i, j


@dataclass(frozen=True)
class _Features:
    """Per candidate, path and execution: log magnitude, direction, felt mask, and the places
    of the peak and the trough (fractions of the path length) with the peak's direction."""

    logmag: FloatArray      # (n, S, E, K)
    angle: FloatArray       # (n, S, E, K) rad
    felt: np.ndarray        # (n, S, E, K) bool
    peak_angle: FloatArray  # (n, S, E)
    peak_felt: np.ndarray   # (n, S, E) bool
    at_max: FloatArray      # (n, S, E) fraction of the path
    at_min: FloatArray      # (n, S, E)


def _features(force: FloatArray, frac: FloatArray, perception: Perception) -> _Features:
    """``force`` (n, S, E, K, 2); ``frac`` (S, K) arc-length fraction of each sample."""
    mag = np.hypot(force[..., 0], force[..., 1])
    ang = np.arctan2(force[..., 1], force[..., 0])
    imax = np.argmax(mag, axis=-1)
    imin = np.argmin(mag, axis=-1)
    peak_mag = np.take_along_axis(mag, imax[..., None], -1)[..., 0]
    peak_ang = np.take_along_axis(ang, imax[..., None], -1)[..., 0]
    s_idx = np.arange(frac.shape[0])[None, :, None]
    return _Features(np.log(np.maximum(mag, perception.floor_n)), ang,
                     mag >= perception.floor_n, peak_ang, peak_mag >= perception.floor_n,
                     frac[s_idx, imax], frac[s_idx, imin])


def _wrap(a: FloatArray) -> FloatArray:
    return np.abs((a + np.pi) % (2.0 * np.pi) - np.pi)


def _separations(f: _Features, perception: Perception, closed: bool
                 ) -> dict[str, FloatArray]:
    """Robust felt, orientation and min-max separations in JNDs for every pair, shape (P, S):
    the smallest over every pair of executions (e of the first candidate, e' of the second)."""
    n = f.logmag.shape[0]
    i, j = _pairs(n)
    lm_i, lm_j = f.logmag[i][:, :, :, None], f.logmag[j][:, :, None, :]
    mag = np.abs(lm_i - lm_j) / math.log1p(perception.force_jnd)
    both = f.felt[i][:, :, :, None] & f.felt[j][:, :, None, :]
    dang = np.where(both, _wrap(f.angle[i][:, :, :, None] - f.angle[j][:, :, None, :]), 0.0)
    dang /= math.radians(perception.direction_jnd_deg)
    felt = np.sqrt(mag * mag + dang * dang).max(axis=-1).min(axis=(2, 3))
    pboth = f.peak_felt[i][:, :, :, None] & f.peak_felt[j][:, :, None, :]
    orient = np.where(pboth, _wrap(f.peak_angle[i][:, :, :, None]
                                   - f.peak_angle[j][:, :, None, :]), 0.0)
    orient = (orient / math.radians(perception.direction_jnd_deg)).min(axis=(2, 3))
    dmax = np.abs(f.at_max[i][:, :, :, None] - f.at_max[j][:, :, None, :])
    dmin = np.abs(f.at_min[i][:, :, :, None] - f.at_min[j][:, :, None, :])
    if closed:
        dmax = np.minimum(dmax, 1.0 - dmax)
        dmin = np.minimum(dmin, 1.0 - dmin)
    minmax = (np.maximum(dmax, dmin) / perception.location_jnd).min(axis=(2, 3))
    return {"feel": felt, "orientation": orient, "minmax": minmax}


def felt_jnd(force_a_n: FloatArray, force_b_n: FloatArray,
             perception: Perception | None = None) -> float:
    """How far apart two force profiles (K, 2) sampled at the same moments feel, in JNDs: the
    largest √(m² + a²) along them (magnitude and direction JNDs, module docstring)."""
    f = np.stack([np.asarray(force_a_n, dtype=float), np.asarray(force_b_n, dtype=float)])
    k = f.shape[1]
    feats = _features(f[:, None, None], np.linspace(0.0, 1.0, k)[None], perception or Perception())
    return float(_separations(feats, perception or Perception(), False)["feel"][0, 0])


def _kl(force: FloatArray, times_s: FloatArray, noise: NoiseModel) -> FloatArray:
    """D_KL between every pair for every execution (P, S, E); ``force`` (n, S, E, K, 2),
    ``times_s`` (S, E, K)."""
    dt = np.diff(times_s, axis=-1)
    w = np.zeros(times_s.shape)
    w[..., 1:] += 0.5 * dt
    w[..., :-1] += 0.5 * dt
    w /= noise.correlation_s
    i, j = _pairs(force.shape[0])
    d = force[i] - force[j]
    sq = (d * d).sum(axis=-1)
    return (sq * w[None]).sum(axis=-1) / (2.0 * noise.force_sd_n ** 2)


def _full(pairs: FloatArray, n: int) -> FloatArray:
    """(P, ...) pairwise values → (..., n, n) symmetric with a zero diagonal."""
    i, j = _pairs(n)
    out = np.zeros((*pairs.shape[1:], n, n))
    out[..., i, j] = np.moveaxis(pairs, 0, -1)
    out[..., j, i] = np.moveaxis(pairs, 0, -1)
    return out


def information_bits(kl_nats: FloatArray, prior: FloatArray,
                     labels: Sequence[str] | None = None) -> FloatArray:
    """Information (bits) a recording gives about which candidate it is - or, with ``labels``,
    about which label (group) - from the pairwise D_KL (..., n, n) under equal-covariance
    Gaussian noise.

    The pairwise-distance estimate of Kolchinsky & Tracey (2017) with the Bhattacharyya
    distance (D_KL / 4): for candidates, I ≥ −Σ_i p_i log₂ Σ_j p_j e^{−D_ij/4}, a lower bound;
    for labels, the estimate of H(Y) minus that of H(Y | label),
    Σ_i p_i log₂ [Σ_{j ~ i} p_j e^{−D_ij/4} / (p_label(i) Σ_j p_j e^{−D_ij/4})], which is 0
    when nothing is told apart and H(label) when the labels are.
    """
    k = prior * np.exp(-kl_nats / 4.0)
    total = k.sum(axis=-1)
    if labels is None:
        return -(prior * np.log2(total)).sum(axis=-1)
    lab = np.asarray(labels)
    same = lab[:, None] == lab[None, :]
    p_label = (prior[None, :] * same).sum(axis=-1)
    own = (k * same).sum(axis=-1)
    return (prior * np.log2(own / (p_label * total))).sum(axis=-1)


def entropy_bits(prior: FloatArray, labels: Sequence[str] | None = None) -> float:
    """H of the candidates (or of their labels) under ``prior``, bits: the most any recording
    can tell."""
    if labels is None:
        q = prior
    else:
        q = np.array([prior[[k for k, lab in enumerate(labels) if lab == u]].sum()
                      for u in dict.fromkeys(labels)])
    q = q[q > 0]
    return float(-(q * np.log2(q)).sum())


def pair_error(kl_nats: FloatArray) -> FloatArray:
    """Bayes error of telling two equal-covariance Gaussians apart with equal priors."""
    return ndtr(-np.sqrt(2.0 * np.maximum(kl_nats, 0.0)) / 2.0)


def _pair_mask(labels: Sequence[str], n: int) -> np.ndarray:
    """Pairs (i < j) that must be told apart: those with different labels."""
    i, j = _pairs(n)
    lab = np.asarray(labels)
    return np.asarray(lab[i] != lab[j])


def _pair_weights(prior: FloatArray, mask: np.ndarray) -> FloatArray:
    i, j = _pairs(len(prior))
    w = prior[i] * prior[j] * mask
    return w / w.sum() if w.sum() > 0 else mask / max(int(mask.sum()), 1)


def _score(criterion: str, sep: Mapping[str, FloatArray], kl: FloatArray, prior: FloatArray,
           labels: Sequence[str], tie_break: bool = True) -> FloatArray:
    """The criterion's score of each of S paths (or sets): ``sep`` (P, S), ``kl`` (P, S, E)
    → (S,).

    information: the information about the labels, bits, averaged over the executions E of the
    motion noise; the others: the prior-weighted mean
    over the pairs to tell apart of erf(d/2), the chance above guessing that a two-alternative
    comparison tells the pair apart for a separation of d JNDs (0 … 1). ``tie_break`` adds
    10⁻³·log(1 + the worst pair to tell apart).
    """
    mask = _pair_mask(labels, len(prior))
    named = None if len(set(labels)) == len(labels) else labels
    if criterion == "information":
        # information is concave in D: average it over the executions, not D
        out = information_bits(_full(kl, len(prior)), prior, named).mean(axis=-1)
        worst = kl.mean(axis=-1)[mask].min(axis=0)
    else:
        s = sep[criterion]
        out = (_pair_weights(prior, mask)[:, None] * erf(s / 2.0)).sum(axis=0)
        worst = s[mask].min(axis=0)
    return out + TIE_BREAK * np.log1p(worst) if tie_break else out


def _separated(criterion: str, sep: Mapping[str, FloatArray], kl: FloatArray,
               mask: np.ndarray) -> np.ndarray:
    """Per pair (P, S): separated by ``criterion``, or not one to tell apart (``mask`` False)."""
    if criterion == "information":
        ok = np.asarray(pair_error(kl.mean(axis=-1)) <= SEPARATED_ERROR)
    else:
        ok = np.asarray(sep[criterion] >= 1.0)
    return ok | ~mask.reshape((-1,) + (1,) * (ok.ndim - 1))


def _arc_fraction(pos: FloatArray) -> FloatArray:
    """Arc length from the start as a fraction of the path's length, (S, K, 2) → (S, K)."""
    seg = np.hypot(*np.moveaxis(np.diff(pos, axis=1), -1, 0))
    arc = np.concatenate([np.zeros((pos.shape[0], 1)), np.cumsum(seg, axis=1)], axis=1)
    total = np.maximum(arc[:, -1:], 1e-12)
    return arc / total


@dataclass
class _Context:
    candidates: tuple[Candidate, ...]
    prior: FloatArray
    criterion: str
    perception: Perception
    noise: NoiseModel
    limits: ProbeLimits
    deltas: list[tuple[float, float, float]]
    labels: tuple[str, ...]
    evaluations: int = 0

    def evaluate(self, pos: FloatArray, vel: FloatArray, t: FloatArray, closed: bool,
                 robust: bool) -> tuple[dict[str, FloatArray], FloatArray]:
        """Separations (P, S) and D_KL per execution (P, S, E) of S paths (S, K, ·)."""
        frac = _arc_fraction(pos)
        if robust:
            pe, ve, te = _execute(pos, vel, t, self.deltas, closed)
        else:
            pe, ve, te = pos[:, None], vel[:, None], t[:, None]
        force = predict(self.candidates, pe, ve, self.limits.force_limit_n,
                        path_accelerations(ve, te))
        self.evaluations += pos.shape[0]
        feats = _features(force, frac, self.perception)
        return _separations(feats, self.perception, closed), _kl(force, te, self.noise)


# --- scores of given probes ------------------------------------------------------------------
@dataclass(frozen=True)
class PathFeatures:
    """Where along a path one candidate's force is largest and smallest, and its direction
    (nominal execution; directions from +x in the shoulder frame, degrees)."""

    candidate: str
    max_force_n: float
    max_at_s: float
    max_at_m: tuple[float, float]
    max_at_fraction: float
    max_direction_deg: float
    min_force_n: float
    min_at_s: float
    min_at_m: tuple[float, float]
    min_at_fraction: float
    mean_direction_deg: float

    def to_dict(self) -> dict[str, object]:
        return {"candidate": self.candidate, "max_force_n": round(self.max_force_n, 4),
                "max_at_s": round(self.max_at_s, 4),
                "max_at_m": [round(v, 4) for v in self.max_at_m],
                "max_at_fraction": round(self.max_at_fraction, 4),
                "max_direction_deg": round(self.max_direction_deg, 2),
                "min_force_n": round(self.min_force_n, 4), "min_at_s": round(self.min_at_s, 4),
                "min_at_m": [round(v, 4) for v in self.min_at_m],
                "min_at_fraction": round(self.min_at_fraction, 4),
                "mean_direction_deg": round(self.mean_direction_deg, 2)}


def path_features(name: str, motion: ProbeMotion, force_n: FloatArray) -> PathFeatures:
    """:class:`PathFeatures` of one candidate's force (K, 2) along ``motion``."""
    mag = np.hypot(force_n[:, 0], force_n[:, 1])
    frac = _arc_fraction(motion.positions_m[None])[0]
    i, k = int(np.argmax(mag)), int(np.argmin(mag))
    mean = force_n.mean(axis=0)
    p = motion.positions_m
    return PathFeatures(
        name, float(mag[i]), float(motion.times_s[i]), (float(p[i, 0]), float(p[i, 1])),
        float(frac[i]), math.degrees(math.atan2(force_n[i, 1], force_n[i, 0])),
        float(mag[k]), float(motion.times_s[k]), (float(p[k, 0]), float(p[k, 1])),
        float(frac[k]), math.degrees(math.atan2(mean[1], mean[0])))


@dataclass(frozen=True, eq=False)
class ProbeScore:
    """How one probe separates the candidates.

    Attributes
    ----------
    motion : ProbeMotion
    path : Stroke, Circle or None
        The parametrised path when the probe was designed.
    candidates : tuple of str
    force_n : ndarray, shape (n, K, 2), N
        Each candidate's predicted force along the nominal motion.
    features : tuple of PathFeatures
        Where each candidate's force is largest and smallest, and its direction.
    separations : dict of ndarray (n, n)
        'feel', 'orientation', 'minmax' in JNDs (robust to the motion noise); 'kl' D_KL, nats,
        averaged over the executions.
    kl_executions : ndarray, shape (P, E), nats
        D_KL of every pair (i < j) for each execution (nominal, then ±1 SD of each noise).
    closed : bool
        The path returns to its start (locations compare around it).
    """

    motion: ProbeMotion
    path: Path | None
    candidates: tuple[str, ...]
    force_n: FloatArray
    features: tuple[PathFeatures, ...]
    separations: dict[str, FloatArray]
    kl_executions: FloatArray
    closed: bool = False

    @property
    def name(self) -> str:
        return self.motion.name


@dataclass(frozen=True, eq=False)
class ProbeSetScore:
    """How a set of probes separates the candidates: per pair the best probe's felt, orientation
    and min-max separation (JNDs), and the sum of the probes' D_KL.

    ``labels`` says what must be told apart: with target 'candidate' every candidate is its
    own label; with 'group' only candidates of different impaired groups need separating.
    """

    probes: tuple[ProbeScore, ...]
    candidates: tuple[str, ...]
    prior: FloatArray
    perception: Perception
    noise: NoiseModel
    labels: tuple[str, ...]
    target: str = "candidate"

    def matrix(self, what: str) -> FloatArray:
        """(n, n): 'feel', 'orientation', 'minmax' (max over probes) or 'kl' (sum)."""
        mats = [p.separations[what] for p in self.probes]
        if not mats:
            return np.zeros((len(self.candidates),) * 2)
        return np.sum(mats, axis=0) if what == "kl" else np.max(mats, axis=0)

    def _pair_values(self, what: str) -> FloatArray:
        i, j = _pairs(len(self.candidates))
        return self.matrix(what)[i, j]

    def _kl_combinations(self) -> FloatArray:
        """D_KL of every pair for combinations of the probes' executions, (P, C)."""
        out: tuple[dict[str, FloatArray], FloatArray] | None = None
        for p in self.probes:
            sep = {k: p.separations[k][_pairs(len(self.candidates))][:, None]
                   for k in ("feel", "orientation", "minmax")}
            s, kl = _combine(sep, p.kl_executions[:, None, :], out)
            out = ({k: v[:, 0] for k, v in s.items()}, kl[:, 0])
        return out[1] if out is not None else np.zeros((len(_pairs(len(self.candidates))[0]),
                                                         1))

    def _sep_kl(self) -> tuple[dict[str, FloatArray], FloatArray]:
        sep = {k: self._pair_values(k)[:, None] for k in ("feel", "orientation", "minmax")}
        return sep, self._kl_combinations()[:, None, :]

    @property
    def _named(self) -> tuple[str, ...] | None:
        return None if len(set(self.labels)) == len(self.labels) else self.labels

    @property
    def information_bits(self) -> float:
        """Information the set gives about the target (candidate or group), bits, averaged over
        the executions of its probes."""
        kl = self._kl_combinations()
        n = len(self.candidates)
        return float(information_bits(_full(kl, n), self.prior, self._named).mean())

    @property
    def information_max_bits(self) -> float:
        """The most any recording can tell about the target, bits."""
        return entropy_bits(self.prior, self._named)

    def score(self, criterion: str) -> float:
        """The criterion's score of the set (see the module docstring; no tie-break term)."""
        sep, kl = self._sep_kl()
        return float(_score(criterion, sep, kl, self.prior, self.labels, tie_break=False)[0])

    def separated(self, criterion: str = "feel") -> np.ndarray:
        """(n, n) bool: pairs the set separates by ``criterion`` (or need not separate)."""
        n = len(self.candidates)
        sep, kl = self._sep_kl()
        ok = _separated(criterion, sep, kl, _pair_mask(self.labels, n))[:, 0]
        out = np.eye(n, dtype=bool)
        i, j = _pairs(n)
        out[i, j] = ok
        out[j, i] = ok
        return out

    def unseparated(self, criterion: str = "feel") -> list[tuple[str, str]]:
        s = self.separated(criterion)
        i, j = _pairs(len(self.candidates))
        return [(self.candidates[a], self.candidates[b]) for a, b in zip(i, j, strict=True)
                if not s[a, b]]

    def separates_all(self, criterion: str = "feel") -> bool:
        return not self.unseparated(criterion)

    def pairs(self) -> list[dict[str, object]]:
        """Every pair with each measure (JNDs, nats, Bayes error) and the probe felt most."""
        out: list[dict[str, object]] = []
        i, j = _pairs(len(self.candidates))
        kl = self.matrix("kl")
        must = _pair_mask(self.labels, len(self.candidates))
        for k, (a, b) in enumerate(zip(i, j, strict=True)):
            felt = [float(p.separations["feel"][a, b]) for p in self.probes]
            best = int(np.argmax(felt)) if felt else -1
            out.append({
                "pair": [self.candidates[a], self.candidates[b]],
                "to_tell_apart": bool(must[k]),
                "felt_jnd": round(max(felt), 3) if felt else 0.0,
                "felt_best_probe": self.probes[best].name if felt else None,
                "orientation_jnd": round(float(self.matrix("orientation")[a, b]), 3),
                "minmax_jnd": round(float(self.matrix("minmax")[a, b]), 3),
                "kl_nats": round(float(kl[a, b]), 3),
                "error_probability": float(f"{float(pair_error(kl[a, b])):.3g}"),
                "felt_apart": bool(max(felt) >= 1.0) if felt else False,
            })
        return out

    def summary(self) -> dict[str, object]:
        """The headline figures: information, worst felt pair, what stays unseparated."""
        must = _pair_mask(self.labels, len(self.candidates))
        felt = self._pair_values("feel")[must]
        err = pair_error(self._pair_values("kl")[must])
        return {
            "probes": len(self.probes),
            "target": self.target,
            "information_bits": round(self.information_bits, 4),
            "information_max_bits": round(self.information_max_bits, 4),
            "feel_score": round(self.score("feel"), 4),
            "worst_felt_jnd": round(float(felt.min()), 3) if felt.size else 0.0,
            "worst_error_probability": float(f"{float(err.max()):.3g}") if err.size else 0.0,
            "separates_all_by_feel": self.separates_all("feel"),
            "separates_all_statistically": self.separates_all("information"),
            "unseparated_by_feel": [list(p) for p in self.unseparated("feel")],
        }

    def to_dict(self, shoulder_offset_m: tuple[float, float] = (0.0, 0.0)
                ) -> dict[str, object]:
        return {
            "candidates": list(self.candidates),
            "prior": [round(float(p), 6) for p in self.prior],
            "summary": self.summary(),
            "probes": [{
                "name": p.name, "description": p.motion.description,
                "path": None if p.path is None else p.path.to_dict(),
                "duration_s": round(float(p.motion.times_s[-1] - p.motion.times_s[0]), 4),
                "peak_speed_m_per_s": round(p.motion.peak_speed_m_per_s, 4),
                "drawing": p.motion.path(shoulder_offset_m).to_dict(),
                "features": [f.to_dict() for f in p.features],
            } for p in self.probes],
            "pairs": self.pairs(),
            "perception": self.perception.to_dict(),
            "noise": self.noise.to_dict(),
        }


def target_labels(candidates: Sequence[Candidate], target: str) -> tuple[str, ...]:
    """What must be told apart: each candidate ('candidate') or each impaired group ('group')."""
    if target not in TARGETS:
        raise ParameterError(f"Unknown target {target!r}; known: {', '.join(TARGETS)}.")
    labels = tuple(c.name if target == "candidate" else c.label for c in candidates)
    if len(set(labels)) < 2:
        raise ParameterError(f"Every candidate has the same {target} ({labels[0]!r}); there is "
                             "nothing to tell apart.")
    return labels


def score_probes(candidates: Sequence[Candidate], motions: Sequence[ProbeMotion], *,
                 paths: Sequence[Path | None] | None = None,
                 prior: Sequence[float] | FloatArray | None = None,
                 perception: Perception | None = None, noise: NoiseModel | None = None,
                 limits: ProbeLimits | None = None,
                 closed: Sequence[bool] | None = None,
                 target: str = "candidate") -> ProbeSetScore:
    """Score given probes (e.g. the seed's pull and semi-ellipse) on the candidates."""
    cands = check_candidates(candidates, 2)
    p = check_prior(prior, len(cands))
    labels = target_labels(cands, target)
    ctx = _Context(cands, p, "feel", perception or Perception(), noise or NoiseModel(),
                   limits or ProbeLimits(), _execution_deltas(noise or NoiseModel()), labels)
    out = []
    for k, m in enumerate(motions):
        path = paths[k] if paths is not None else None
        is_closed = closed[k] if closed is not None else isinstance(path, Circle)
        sep, kl = ctx.evaluate(m.positions_m[None], m.velocities_m_per_s[None],
                               m.times_s[None], is_closed, robust=True)
        force = predict(cands, m.positions_m, m.velocities_m_per_s, ctx.limits.force_limit_n,
                        m.accelerations_m_per_s2)
        n = len(cands)
        mats = {key: _full(v, n)[0] for key, v in sep.items()}
        mats["kl"] = _full(kl.mean(axis=-1), n)[0]
        feats = tuple(path_features(c.name, m, force[i]) for i, c in enumerate(cands))
        out.append(ProbeScore(m, path, tuple(c.name for c in cands), force, feats, mats,
                              kl[:, 0, :], is_closed))
    return ProbeSetScore(tuple(out), tuple(c.name for c in cands), p, ctx.perception, ctx.noise,
                         labels, target)


# --- the search -----------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ProbeDesign:
    """A designed set of probes and how it was found.

    Attributes
    ----------
    paths : tuple of Stroke or Circle
    score : ProbeSetScore
        The set scored at report resolution (robust to the motion noise).
    criterion, family : str
    search_s : float, s
        Wall time of the search.
    evaluations : int
        Paths evaluated (each on every candidate; robust ones once per execution).
    limits : ProbeLimits
    """

    paths: tuple[Path, ...]
    score: ProbeSetScore
    criterion: str
    family: str
    search_s: float
    evaluations: int
    limits: ProbeLimits

    @property
    def motions(self) -> tuple[ProbeMotion, ...]:
        return tuple(p.motion for p in self.score.probes)

    def to_dict(self, shoulder_offset_m: tuple[float, float] = (0.0, 0.0)
                ) -> dict[str, object]:
        return {"criterion": self.criterion, "family": self.family, "target": self.score.target,
                "search_s": round(self.search_s, 4), "evaluations": self.evaluations,
                "limits": self.limits.to_dict(), **self.score.to_dict(shoulder_offset_m)}


def _polish(ctx: _Context, fam: _Family, start: FloatArray, x0: FloatArray,
            prev: tuple[dict[str, FloatArray], FloatArray] | None,
            evals: int) -> tuple[FloatArray, float]:
    """nlopt Sbplx from ``x0`` on the robust score; returns the best point seen and its score."""
    lo, hi = fam.bounds(ctx.limits)
    if fam.name == "stroke":  # direction: a local window, the grid chose the neighbourhood
        lo, hi = lo.copy(), hi.copy()
        lo[0], hi[0] = x0[0] - 20.0, x0[0] + 20.0
    idx = list(fam.polish)
    best_x, best_val = x0.copy(), -np.inf

    def f(x: Sequence[float], grad: FloatArray) -> float:
        nonlocal best_x, best_val
        v = x0.copy()
        v[idx] = x
        val = float(_robust_score(ctx, fam, start, v[None], prev)[0])
        if val > best_val:
            best_x, best_val = v, val
        return val

    opt = nlopt.opt(nlopt.LN_SBPLX, len(idx))
    opt.set_lower_bounds(lo[idx].tolist())
    opt.set_upper_bounds(hi[idx].tolist())
    opt.set_max_objective(f)
    opt.set_maxeval(evals)
    opt.set_xtol_rel(1e-3)
    opt.set_initial_step(((hi[idx] - lo[idx]) / 8.0).tolist())
    x_start = np.clip(x0[idx], lo[idx], hi[idx])
    try:
        opt.optimize(x_start.tolist())
    except (nlopt.RoundoffLimited, ValueError, RuntimeError):
        pass  # the best point seen is kept
    return best_x, best_val


def _combine(sep: dict[str, FloatArray], kl: FloatArray,
             prev: tuple[dict[str, FloatArray], FloatArray] | None
             ) -> tuple[dict[str, FloatArray], FloatArray]:
    """A set so far (``prev``: separations (P,), D_KL per execution combination (P, C)) with
    each of S new paths (``sep`` (P, S), ``kl`` (P, S, E)): felt separations take the best
    path, D_KL adds over every combination of executions (at most :data:`MAX_COMBINATIONS`,
    a fixed stride through them beyond)."""
    if prev is None:
        return sep, kl
    psep, pkl = prev
    both = (pkl[:, None, :, None] + kl[:, :, None, :]).reshape(kl.shape[0], kl.shape[1], -1)
    if both.shape[-1] > MAX_COMBINATIONS:
        both = both[..., np.linspace(0, both.shape[-1] - 1, MAX_COMBINATIONS).astype(int)]
    return {k: np.maximum(psep[k][:, None], v) for k, v in sep.items()}, both


def _within_limits(ctx: _Context, fam: _Family, start: FloatArray, v: FloatArray,
                   samples: int = LIMIT_SAMPLES) -> np.ndarray:
    """Which of S paths (rows of v) keep every limit in every execution of the motion noise,
    sampled at ``samples`` points: mask (S,).

    At :data:`LIMIT_SAMPLES` the check holds for every point of the drawn polyline and of the
    search; at :data:`DESIGN_SAMPLES` (points among those) it is a cheap necessary condition.
    """
    pos, vel, t = fam.make(start, v, samples)
    pe, ve, _ = _execute(pos, vel, t, ctx.deltas, fam.closed)
    return feasible(ctx.candidates, pe, ve, ctx.limits)


def _robust_score(ctx: _Context, fam: _Family, start: FloatArray, v: FloatArray,
                  prev: tuple[dict[str, FloatArray], FloatArray] | None) -> FloatArray:
    """Score of S paths (rows of v) added to the set ``prev``; paths that break a limit score
    −1 (a feasible path scores ≥ 0)."""
    ok = _within_limits(ctx, fam, start, v)
    pos, vel, t = fam.make(start, v, DESIGN_SAMPLES)
    out = np.full(v.shape[0], -1.0)
    if ok.any():
        sep, kl = ctx.evaluate(pos[ok], vel[ok], t[ok], fam.closed, robust=True)
        sep, kl = _combine(sep, kl, prev)
        out[ok] = _score(ctx.criterion, sep, kl, ctx.prior, ctx.labels)
    return out


def _search_one(ctx: _Context, fam: _Family, start: FloatArray,
                prev: tuple[dict[str, FloatArray], FloatArray] | None,
                starts: int, evals: int) -> tuple[FloatArray | None, float]:
    grid = fam.grid(ctx.limits)
    pos, vel, t = fam.make(start, grid, DESIGN_SAMPLES)
    # the coarse check filters the grid; a start is checked at full resolution before polish
    ok = _within_limits(ctx, fam, start, grid, DESIGN_SAMPLES)
    if not ok.any():
        return None, -np.inf
    grid = grid[ok]
    sep, kl = ctx.evaluate(pos[ok], vel[ok], t[ok], fam.closed, robust=False)
    sep, kl = _combine(sep, kl, prev)
    order = np.argsort(-_score(ctx.criterion, sep, kl, ctx.prior, ctx.labels), kind="stable")
    chosen: list[FloatArray] = []
    for k in order:
        g = grid[k]
        if fam.name == "stroke" and any(
                abs(((g[0] - c[0]) + 180.0) % 360.0 - 180.0) < 30.0 for c in chosen):
            continue
        if not _within_limits(ctx, fam, start, g[None])[0]:
            continue
        chosen.append(g)
        if len(chosen) == starts:
            break
    best_v: FloatArray | None = None
    best = -np.inf
    for g in chosen:
        v, val = _polish(ctx, fam, start, g, prev, evals) if evals > 0 else \
            (g, float(_robust_score(ctx, fam, start, g[None], prev)[0]))
        if val > best:
            best_v, best = v, val
    if best < 0.0:  # no start kept every limit
        return None, -np.inf
    if best_v is not None and fam.name == "stroke":
        best_v = best_v.copy()
        best_v[0] = ((best_v[0] + 180.0) % 360.0) - 180.0
    return best_v, best


def design(candidates: Sequence[Candidate], *, criterion: str = "feel", family: str = "stroke",
           target: str = "candidate", max_probes: int | None = None,
           prior: Sequence[float] | FloatArray | None = None,
           perception: Perception | None = None, noise: NoiseModel | None = None,
           limits: ProbeLimits | None = None, start_m: Sequence[float] | None = None,
           stop_when_separated: bool = True, polish_starts: int = POLISH_STARTS,
           polish_evals: int = POLISH_EVALS, names: Sequence[str] | None = None) -> ProbeDesign:
    """The set of at most ``max_probes`` (default n − 1) paths that best separates the candidates.

    Parameters
    ----------
    candidates : sequence of Candidate
    criterion : {'feel', 'information', 'orientation', 'minmax'}
        What is maximised: felt separation (JNDs), information (bits), or one of the seed's
        paradigms alone.
    family : {'stroke', 'circle'}
    target : {'candidate', 'group'}
        Tell every candidate apart, or only candidates of different impaired groups.
    max_probes : int, optional
    prior : sequence of float, optional
        Prior probability of each candidate (uniform by default).
    start_m : (x, y), m, optional
        Where strokes start / circles are centred (default: the candidates' equilibrium).
    stop_when_separated : bool
        Stop adding paths once every pair is separated (else go on while the score improves).
    polish_starts, polish_evals : int
        Grid points polished with nlopt and the evaluations each may use.
    names : sequence of str, optional
        Names of the probes (default "stroke 1", "stroke 2", …).
    """
    t0 = time.perf_counter()
    cands = check_candidates(candidates, 2)
    if criterion not in CRITERIA:
        raise ParameterError(f"Unknown criterion {criterion!r}; known: {', '.join(CRITERIA)}.")
    if family not in FAMILIES:
        raise ParameterError(f"Unknown path family {family!r}; known: {', '.join(FAMILIES)}.")
    n = len(cands)
    limit = n - 1 if max_probes is None else int(max_probes)
    if limit < 1:
        raise ParameterError(f"max_probes must be at least 1; got {max_probes!r}.")
    fam = FAMILIES[family]
    noise = noise or NoiseModel()
    labels = target_labels(cands, target)
    ctx = _Context(cands, check_prior(prior, n), criterion, perception or Perception(), noise,
                   limits or ProbeLimits(), _execution_deltas(noise), labels)
    mask = _pair_mask(labels, n)
    start = equilibrium(cands) if start_m is None else np.asarray(start_m, dtype=float)
    chosen: list[FloatArray] = []
    prev: tuple[dict[str, FloatArray], FloatArray] | None = None
    last = -np.inf
    while len(chosen) < limit:
        v, val = _search_one(ctx, fam, start, prev, polish_starts, polish_evals)
        if v is None or (chosen and val < last + MIN_GAIN):
            break
        chosen.append(v)
        last = val
        pos, vel, t = fam.make(start, v[None], DESIGN_SAMPLES)
        sep, kl = ctx.evaluate(pos, vel, t, fam.closed, robust=True)
        sep, kl = _combine(sep, kl, prev)
        prev = ({k: s[:, 0] for k, s in sep.items()}, kl[:, 0])
        if stop_when_separated and _separated(
                criterion, {k: s[:, None] for k, s in prev[0].items()}, prev[1][:, None, :],
                mask).all():
            break
    if not chosen:
        raise ParameterError(
            f"No {family} within the limits (peak speed ≤ {ctx.limits.max_speed_m_per_s:g} m/s, "
            f"{ctx.limits.rom_margin_deg:g}° inside every candidate's range of motion"
            + ("" if ctx.limits.workspace_m is None else ", inside the workspace box")
            + ") starts at the equilibrium; relax the limits or check the candidates.")
    side = "left" if cands[0].arm.mirror else "right"
    paths = tuple(fam.build(start, v) for v in chosen)
    titles = list(names) if names is not None else [f"{family} {k + 1}" for k in range(len(paths))]
    motions = [p.motion(PROBE_SAMPLES, titles[k], side) for k, p in enumerate(paths)]
    score = score_probes(cands, motions, paths=paths, prior=ctx.prior,
                         perception=ctx.perception, noise=noise, limits=ctx.limits,
                         closed=[fam.closed] * len(paths), target=target)
    return ProbeDesign(paths, score, criterion, family, time.perf_counter() - t0,
                       ctx.evaluations, ctx.limits)


@dataclass(frozen=True)
class Paradigms:
    """The seed's two paradigms read on given paths: for every path, where each candidate's
    force is largest and smallest and its direction; which pairs each paradigm separates; and a
    greedy set of at most n − 1 of the paths that separates every pair, if one exists."""

    score: ProbeSetScore
    minmax_set: tuple[str, ...]
    orientation_set: tuple[str, ...]
    minmax_complete: bool
    orientation_complete: bool

    def to_dict(self) -> dict[str, object]:
        d = self.score.to_dict()
        d["minmax_set"] = {"paths": list(self.minmax_set), "separates_all": self.minmax_complete}
        d["orientation_set"] = {"paths": list(self.orientation_set),
                                "separates_all": self.orientation_complete}
        return d


def _greedy_cover(score: ProbeSetScore, what: str, limit: int) -> tuple[tuple[str, ...], bool]:
    """At most ``limit`` probes whose union separates the most pairs (≥ 1 JND), greedily."""
    n = len(score.candidates)
    i, j = _pairs(n)
    covers = [p.separations[what][i, j] >= 1.0 for p in score.probes]
    todo = np.ones(len(i), dtype=bool)
    chosen: list[str] = []
    while todo.any() and len(chosen) < limit:
        gains = [int((c & todo).sum()) for c in covers]
        k = int(np.argmax(gains)) if gains else 0
        if not gains or gains[k] == 0:
            break
        chosen.append(score.probes[k].name)
        todo &= ~covers[k]
    return tuple(chosen), not todo.any()


def paradigms(candidates: Sequence[Candidate], motions: Sequence[ProbeMotion], *,
              closed: Sequence[bool] | None = None, perception: Perception | None = None,
              noise: NoiseModel | None = None, limits: ProbeLimits | None = None) -> Paradigms:
    """Read the min-max and orientation paradigms on ``motions``; pick ≤ n − 1 of them."""
    score = score_probes(candidates, motions, perception=perception, noise=noise,
                         limits=limits, closed=closed)
    limit = len(score.candidates) - 1
    mm, mm_ok = _greedy_cover(score, "minmax", limit)
    orient, orient_ok = _greedy_cover(score, "orientation", limit)
    return Paradigms(score, mm, orient, mm_ok, orient_ok)


def seed_probes(candidates: Sequence[Candidate]) -> list[ProbeMotion]:
    """The seed's pull and semi-ellipse (:mod:`fieldbank.evaluate.probing`) from the
    candidates' equilibrium."""
    cands = check_candidates(candidates, 1)
    arm = cands[0].arm
    shift = equilibrium(cands) - arm.rest_position()
    return [ProbeMotion(m.name, m.times_s, m.positions_m + shift, m.velocities_m_per_s,
                        m.description) for m in (pull(arm), semi_ellipse(arm))]


@dataclass(frozen=True, eq=False)
class DesignReport:
    """A designed set of probes next to the seed's pull and semi-ellipse on the same
    candidates, measured the same way."""

    design: ProbeDesign
    seed: ProbeSetScore

    def to_dict(self, shoulder_offset_m: tuple[float, float] = (0.0, 0.0)
                ) -> dict[str, object]:
        return {**self.design.to_dict(shoulder_offset_m),
                "seed_probes": self.seed.to_dict(shoulder_offset_m)}


def design_report(candidates: Sequence[Candidate], **options: object) -> DesignReport:
    """:func:`design` with ``options``, and the seed's probes scored on the same candidates with
    the same perception, noise, limits, prior and target."""
    d = design(candidates, **options)  # type: ignore[arg-type]
    s = score_probes(candidates, seed_probes(candidates), prior=d.score.prior,
                     perception=d.score.perception, noise=d.score.noise, limits=d.limits,
                     target=d.score.target)
    return DesignReport(d, s)


def circles(start_m: Sequence[float] | FloatArray, radii_m: Sequence[float] = (0.04, 0.06, 0.08),
            duration_s: float = 2.0, side: str = "right") -> list[ProbeMotion]:
    """Counter-clockwise circles of the given radii around ``start_m`` (seed Fig. 3a)."""
    c = (float(start_m[0]), float(start_m[1]))
    return [Circle(c, r, duration_s, 1.0).motion(PROBE_SAMPLES, f"circle {r * 100:.0f} cm", side)
            for r in radii_m]


__all__ = [
    "CRITERIA",
    "FAMILIES",
    "TARGETS",
    "Candidate",
    "Circle",
    "DesignReport",
    "NoiseModel",
    "Paradigms",
    "PathFeatures",
    "Perception",
    "ProbeDesign",
    "ProbeLimits",
    "ProbeScore",
    "ProbeSetScore",
    "Stroke",
    "check_candidates",
    "check_prior",
    "circles",
    "design",
    "design_report",
    "direction_words",
    "draw_execution",
    "entropy_bits",
    "equilibrium",
    "executions",
    "feasible",
    "felt_jnd",
    "information_bits",
    "pair_error",
    "paradigms",
    "path_accelerations",
    "path_features",
    "predict",
    "saturate",
    "score_probes",
    "seed_probes",
    "severity_candidates",
    "target_labels",
]
