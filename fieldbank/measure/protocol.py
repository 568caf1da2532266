"""The clinical measuring protocol as a plan: where the robot takes the hand, when, how fast.

Three parts, any of them (Mussa-Ivaldi, Hogan & Bizzi 1985 for the first two; BRIEF §16):

* **postural** — at each posture of a grid the robot holds the relaxed hand for
  ``postural_hold_s``; the force after the transient (``transient_s``) is the postural force.
* **stiffness** — at each posture the robot displaces the hand by ``displacement_m`` (5–8 mm in
  MIHB 1985) in ``directions`` directions evenly spread (8 in MIHB), each by a smooth move of
  ``move_s``, holds it ``hold_s``, returns and holds at the base again. The holds after their
  transient give ΔF = −K Δx (:mod:`fieldbank.measure.estimate`); the return holds give the
  postural force as well.
* **stretch** — the robot moves the hand through the postures of each column of the grid at
  ``stretch_speed_m_per_s`` (1.2 m/s: the seed's reflex fires only on a fast stretch; 180°/s at
  the elbow is ≈ 1.1 m/s at the hand), toward and away from the body, on the column and at
  ±``stretch_offset_m`` beside it; the velocity rises and falls as a raised cosine over
  ``ramp_s``, and the plateau covers every posture of the column with ``pass_margin_m`` to
  spare. Forces on the plateau near each posture give the stiffness map while moving, whose
  velocity-dependent part is the reflex.

Between postures the hand moves on minimum-jerk paths at ``transfer_speed_m_per_s`` (peak) and
settles for ``settle_s``. Every choice is a documented, overridable default; the robot time of a
plan is :attr:`ProtocolPlan.duration_s` (the driver adds nothing but the first approach); those the
command line shows are in :mod:`fieldbank.measurechoices`.

The grid is ``grid`` = (columns, rows) postures ``spacing_m`` apart, centred on ``centre_m``
(shoulder frame). By default both follow the patient's arm (:meth:`ProtocolConfig.resolved`):
the centre is the hand with the shoulder at 40° and the elbow at 80°
(:data:`DEFAULT_CENTRE_POSTURE_DEG`), the spacing 7 % of the arm's length (4.8 cm at 1.75 m),
and the passes run at 1.2 m/s - the protocol that, over bodies of 1.55-1.90 m, left and right,
stretches every group past its slack length at ≥ 4 postures and fires a mild reflex of every
group at ≥ 4 pass points (:mod:`fieldbank.measure.visibility`; the earlier fixed grid around
(0, 0.50) m at 1 m/s never fired the shoulder extensors' mild reflex, stretched the
bi-articular flexors at one posture, and on a 1.90 m arm left the elbow flexors slack
everywhere). :func:`plan` refuses a grid the patient's arm cannot reach, naming the posture; a
stretch stroke that would leave the reach (they run 10 cm past the grid to reach speed) leaves
out the far postures of that stroke, said in :attr:`ProtocolPlan.notes`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from fieldbank.errors import ParameterError
from fieldbank.measurechoices import (
    DIRECTIONS,
    DISPLACEMENT_M,
    HOLD_S,
    PARTS,
    STRETCH_SPEED_M_PER_S,
)
from fieldbank.model import Arm, FloatArray
from fieldbank.params import ArmParams
from fieldbank.validation import Interval, check_fields, check_tuple

#: The posture (shoulder, elbow), degrees, whose hand position centres the default grid.
DEFAULT_CENTRE_POSTURE_DEG = (40.0, 80.0)
#: The default spacing of the grid, as a fraction of the arm's length (upper arm + forearm).
DEFAULT_SPACING_FRACTION = 0.07

#: Allowed range of every numeric setting of :class:`ProtocolConfig`.
PROTOCOL_BOUNDS: dict[str, Interval] = {
    "spacing_m": Interval(0.005, 0.2, "m"),
    "displacement_m": Interval(0.002, 0.03, "m"),
    "directions": Interval(3, 64, ""),
    "hold_s": Interval(0.05, 10.0, "s"),
    "transient_s": Interval(0.0, 5.0, "s"),
    "move_s": Interval(0.05, 2.0, "s"),
    "postural_hold_s": Interval(0.05, 30.0, "s"),
    "transfer_speed_m_per_s": Interval(0.01, 1.0, "m/s"),
    "settle_s": Interval(0.0, 5.0, "s"),
    "stretch_speed_m_per_s": Interval(0.05, 2.0, "m/s"),
    "stretch_offset_m": Interval(0.0, 0.03, "m"),
    "ramp_s": Interval(0.05, 1.0, "s"),
    "pass_margin_m": Interval(0.0, 0.05, "m"),
}
#: Where the grid's centre may be, each coordinate (shoulder frame): within an arm's reach.
CENTRE_BOUNDS = Interval(-1.0, 1.0, "m")


@dataclass(frozen=True)
class ProtocolConfig:
    """What to measure and how (see the module docstring); SI units."""

    parts: tuple[str, ...] = PARTS
    grid: tuple[int, int] = (5, 5)
    #: None: 7 % of the patient's arm length (:meth:`resolved`)
    spacing_m: float | None = None
    #: None: the patient's hand at :data:`DEFAULT_CENTRE_POSTURE_DEG` (:meth:`resolved`)
    centre_m: tuple[float, float] | None = None
    displacement_m: float = DISPLACEMENT_M
    directions: int = DIRECTIONS
    hold_s: float = HOLD_S
    transient_s: float = 0.15
    move_s: float = 0.15
    postural_hold_s: float = 1.0
    transfer_speed_m_per_s: float = 0.2
    settle_s: float = 0.25
    stretch_speed_m_per_s: float = STRETCH_SPEED_M_PER_S
    stretch_offset_m: float = 0.008
    ramp_s: float = 0.2
    pass_margin_m: float = 0.015

    def __post_init__(self) -> None:
        bad = [p for p in self.parts if p not in PARTS]
        if bad or not self.parts:
            raise ParameterError(f"protocol parts must be among {', '.join(PARTS)}; got "
                                 f"{', '.join(self.parts) or 'none'}")
        nx, ny = self.grid
        if not (1 <= nx <= 15 and 1 <= ny <= 15):
            raise ParameterError(f"grid must be 1–15 by 1–15 postures; got {nx}×{ny}")
        check_fields(self, PROTOCOL_BOUNDS, what="protocol setting",
                     names=[n for n in PROTOCOL_BOUNDS if getattr(self, n) is not None])
        if self.centre_m is not None:
            check_tuple("centre_m", self.centre_m, 2, CENTRE_BOUNDS,
                        labels=("centre x", "centre y"), what="protocol setting")
        if self.transient_s >= min(self.hold_s, self.postural_hold_s):
            raise ParameterError(f"transient_s ({self.transient_s:g} s) must be shorter than "
                                 "the holds it is cut from")

    def resolved(self, arm: Arm | None = None) -> ProtocolConfig:
        """This configuration with the grid's centre and spacing set for ``arm`` where they
        are left to the default (the adult default arm when no arm is given): the hand at
        :data:`DEFAULT_CENTRE_POSTURE_DEG`, 7 % of the arm's length apart."""
        if self.centre_m is not None and self.spacing_m is not None:
            return self
        a = arm if arm is not None else Arm.from_params(ArmParams.from_anthropometry())
        hand = a.fk(np.radians(np.array([DEFAULT_CENTRE_POSTURE_DEG])))[0]
        centre = self.centre_m if self.centre_m is not None else (
            round(float(hand[0]), 3), round(float(hand[1]), 3))
        spacing = self.spacing_m if self.spacing_m is not None else round(
            DEFAULT_SPACING_FRACTION * (a.l1 + a.l2), 3)
        return replace(self, centre_m=centre, spacing_m=spacing)

    @property
    def centre(self) -> tuple[float, float]:
        """The grid's centre, m (a resolved configuration's; :meth:`resolved`)."""
        if self.centre_m is None:
            raise ParameterError("the protocol's grid centre follows the patient's arm: "
                                 "resolve it first (ProtocolConfig.resolved)")
        return self.centre_m

    @property
    def spacing(self) -> float:
        """The grid's spacing, m (a resolved configuration's; :meth:`resolved`)."""
        if self.spacing_m is None:
            raise ParameterError("the protocol's grid spacing follows the patient's arm: "
                                 "resolve it first (ProtocolConfig.resolved)")
        return self.spacing_m


@dataclass(frozen=True)
class Segment:
    """One stretch of the reference: a minimum-jerk move, a hold, or a pass (a stroke with
    raised-cosine ramps). Positions in the shoulder frame, m; times in s from the plan's start.

    ``trial`` is the index of the trial this segment is (holds and passes), else -1.
    """

    kind: str                      # 'move' | 'hold' | 'pass'
    t0_s: float
    duration_s: float
    start_m: tuple[float, float]
    end_m: tuple[float, float]
    speed_m_per_s: float = 0.0     # plateau speed of a pass
    ramp_s: float = 0.0
    trial: int = -1

    @property
    def t1_s(self) -> float:
        return self.t0_s + self.duration_s

    def reference(self, t_s: float) -> tuple[float, float, float, float]:
        """(x, y, vx, vy) of the reference at time ``t_s`` within the segment."""
        (x0, y0), (x1, y1) = self.start_m, self.end_m
        dx, dy = x1 - x0, y1 - y0
        if self.kind == "hold":
            return x0, y0, 0.0, 0.0
        tau = min(max(t_s - self.t0_s, 0.0), self.duration_s)
        if self.kind == "move":
            s = tau / self.duration_s
            p = s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)
            dp = 30.0 * s * s * (1.0 - s) ** 2 / self.duration_s
            return x0 + dx * p, y0 + dy * p, dx * dp, dy * dp
        length = math.hypot(dx, dy)
        ux, uy = dx / length, dy / length
        v, tr, total = self.speed_m_per_s, self.ramp_s, self.duration_s
        if tau < tr:
            d = 0.5 * v * (tau - tr / math.pi * math.sin(math.pi * tau / tr))
            sp = 0.5 * v * (1.0 - math.cos(math.pi * tau / tr))
        elif tau <= total - tr:
            d = 0.5 * v * tr + v * (tau - tr)
            sp = v
        else:
            r = total - tau
            d = length - 0.5 * v * (r - tr / math.pi * math.sin(math.pi * r / tr))
            sp = 0.5 * v * (1.0 - math.cos(math.pi * r / tr))
        return x0 + ux * d, y0 + uy * d, ux * sp, uy * sp


@dataclass(frozen=True)
class PlannedTrial:
    """A trial of the plan: role, posture (-1 for a pass), when, and what it reads."""

    index: int
    role: str
    posture: int
    start_s: float
    stop_s: float
    window_s: tuple[float, float]
    target_m: tuple[float, float]
    velocity_m_per_s: tuple[float, float] = (0.0, 0.0)
    label: str = ""


@dataclass(frozen=True)
class ProtocolPlan:
    """The whole protocol: segments in time order, trials, postures."""

    config: ProtocolConfig
    postures_m: FloatArray
    segments: tuple[Segment, ...]
    trials: tuple[PlannedTrial, ...]
    start_m: tuple[float, float] = field(default=(0.0, 0.0))
    notes: tuple[str, ...] = ()

    @property
    def duration_s(self) -> float:
        return self.segments[-1].t1_s if self.segments else 0.0

    def segment_at(self, t_s: float, hint: int = 0) -> int:
        """Index of the segment covering ``t_s`` (search forward from ``hint``)."""
        i = hint
        segs = self.segments
        while i < len(segs) - 1 and t_s >= segs[i].t1_s:
            i += 1
        return i


def grid_postures(config: ProtocolConfig) -> FloatArray:
    """Posture positions of the grid, shape (nx·ny, 2), m; row by row from the body outward."""
    c = config.resolved()
    nx, ny = c.grid
    cx, cy = c.centre
    xs = cx + c.spacing * (np.arange(nx) - (nx - 1) / 2)
    ys = cy + c.spacing * (np.arange(ny) - (ny - 1) / 2)
    return np.array([[x, y] for y in ys for x in xs], dtype=float)


class _Builder:
    def __init__(self, config: ProtocolConfig, start: tuple[float, float]) -> None:
        self.c = config
        self.t = 0.0
        self.at = start
        self.segments: list[Segment] = []
        self.trials: list[PlannedTrial] = []
        self.notes: list[str] = []

    def move(self, to: tuple[float, float], duration: float | None = None) -> None:
        d = math.hypot(to[0] - self.at[0], to[1] - self.at[1])
        if d < 1e-9:
            return
        # minimum-jerk peak speed is 1.875 d / T
        dur = duration if duration is not None else max(
            0.3, 1.875 * d / self.c.transfer_speed_m_per_s)
        self.segments.append(Segment("move", self.t, dur, self.at, to))
        self.t += dur
        self.at = to

    def hold(self, duration: float, trial: tuple[str, int, str] | None = None,
             transient: float = 0.0) -> None:
        idx = -1
        if trial is not None:
            role, posture, label = trial
            idx = len(self.trials)
            self.trials.append(PlannedTrial(idx, role, posture, self.t, self.t + duration,
                                            (self.t + transient, self.t + duration),
                                            self.at, label=label))
        self.segments.append(Segment("hold", self.t, duration, self.at, self.at, trial=idx))
        self.t += duration

    def stroke(self, start: tuple[float, float], end: tuple[float, float],
               plateau: tuple[float, float], label: str) -> None:
        c = self.c
        self.move(start)
        self.hold(c.settle_s)
        length = math.hypot(end[0] - start[0], end[1] - start[1])
        dur = 2 * c.ramp_s + (length - c.stretch_speed_m_per_s * c.ramp_s) / c.stretch_speed_m_per_s
        ux, uy = (end[0] - start[0]) / length, (end[1] - start[1]) / length
        v = (ux * c.stretch_speed_m_per_s, uy * c.stretch_speed_m_per_s)
        idx = len(self.trials)
        self.trials.append(PlannedTrial(idx, "pass", -1, self.t, self.t + dur,
                                        (self.t + plateau[0], self.t + plateau[1]), start, v,
                                        label))
        self.segments.append(Segment("pass", self.t, dur, start, end,
                                     c.stretch_speed_m_per_s, c.ramp_s, idx))
        self.t += dur
        self.at = end


def plan(config: ProtocolConfig, arm: Arm | None = None,
         start_m: Sequence[float] | None = None) -> ProtocolPlan:
    """The plan of ``config`` for a patient's ``arm`` (reachability checked when given; the
    grid's centre and spacing resolved for it, :meth:`ProtocolConfig.resolved`), starting with
    the hand at ``start_m`` (default: the first posture)."""
    c = config.resolved(arm)
    postures = grid_postures(c)
    if arm is not None:
        bad = np.flatnonzero(~arm.reachable(postures))
        if bad.size:
            p = postures[int(bad[0])]
            raise ParameterError(f"posture {int(bad[0])} at ({p[0]:.3f}, {p[1]:.3f}) m is out "
                                 f"of the patient's reach ({bad.size} of {len(postures)} "
                                 "postures): move or shrink the grid (--centre, --spacing-mm)")
    first = (float(postures[0, 0]), float(postures[0, 1]))
    b = _Builder(c, tuple(start_m) if start_m is not None else first)  # type: ignore[arg-type]
    nx, ny = c.grid
    for p_index, p in enumerate(postures):
        pos = (float(p[0]), float(p[1]))
        if "postural" in c.parts or "stiffness" in c.parts:
            b.move(pos)
            b.hold(c.settle_s)
        if "postural" in c.parts:
            b.hold(c.postural_hold_s, ("base", p_index, f"posture {p_index} hold"),
                   c.transient_s)
        if "stiffness" in c.parts:
            for k in range(c.directions):
                ang = 2 * math.pi * k / c.directions
                out = (pos[0] + c.displacement_m * math.cos(ang),
                       pos[1] + c.displacement_m * math.sin(ang))
                deg = round(math.degrees(ang))
                b.move(out, c.move_s)
                b.hold(c.hold_s, ("displaced", p_index, f"posture {p_index} displaced "
                                                        f"{deg}°"), c.transient_s)
                b.move(pos, c.move_s)
                b.hold(c.hold_s, ("base", p_index, f"posture {p_index} base after {deg}°"),
                       c.transient_s)
    if "stretch" in c.parts:
        _stretch(b, postures, nx, ny, arm)
    if not b.segments:
        b.hold(c.settle_s)
    return ProtocolPlan(c, postures, tuple(b.segments), tuple(b.trials), first, tuple(b.notes))


def _stroke_ends(c: ProtocolConfig, x: float, y_lo: float, y_hi: float, direction: int
                 ) -> tuple[tuple[float, float], tuple[float, float]]:
    ramp_d = 0.5 * c.stretch_speed_m_per_s * c.ramp_s
    lead = min(0.05, 0.25 * c.ramp_s) * c.stretch_speed_m_per_s
    lo, hi = y_lo - c.pass_margin_m, y_hi + c.pass_margin_m
    if direction > 0:
        return (x, lo - lead - ramp_d), (x, hi + ramp_d)
    return (x, hi + lead + ramp_d), (x, lo - ramp_d)


def _stretch(b: _Builder, postures: FloatArray, nx: int, ny: int, arm: Arm | None) -> None:
    """Strokes through each column; rows whose stroke would leave the patient's reach are
    left out of that stroke (from the far end), and said in the plan's notes."""
    c = b.c
    lead = min(0.05, 0.25 * c.ramp_s)
    left_out: list[str] = []
    for col in range(nx):
        ys = sorted(float(y) for y in postures[col::nx, 1])
        x_col = float(postures[col, 0])
        for direction in (+1, -1):
            rows = len(ys)
            while rows > 0:
                ends = [_stroke_ends(c, x_col + off, ys[0], ys[rows - 1], direction)
                        for off in (-c.stretch_offset_m, c.stretch_offset_m)]
                if arm is None or all(arm.reachable(np.array(e)).all() for e in ends):
                    break
                rows -= 1
            word = "away from the body" if direction > 0 else "toward the body"
            if rows < len(ys):
                left_out.append(f"column {col} {'away' if direction > 0 else 'toward'} "
                                f"{len(ys) - rows}")
            if rows == 0:
                continue
            for off in (0.0, -c.stretch_offset_m, c.stretch_offset_m):
                start, end = _stroke_ends(c, x_col + off, ys[0], ys[rows - 1], direction)
                ramp_d = 0.5 * c.stretch_speed_m_per_s * c.ramp_s
                plateau_len = abs(end[1] - start[1]) - 2 * ramp_d
                t_plateau = plateau_len / c.stretch_speed_m_per_s
                b.stroke(start, end, (c.ramp_s + lead, c.ramp_s + t_plateau),
                         f"column {col} {word} at {c.stretch_speed_m_per_s:g} m/s, "
                         f"offset {off * 1000:+.0f} mm")
    if left_out:  # one note, not one per stroke
        b.notes.append("far postures left out of the stretch, where the stroke would leave the "
                       "patient's reach (postures per column, stroking away from the body or "
                       "toward it): " + ", ".join(left_out))
