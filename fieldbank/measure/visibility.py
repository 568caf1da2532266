"""What a measuring protocol can see, per muscle group, before the robot moves.

A fit identifies a group's passive stiffness and slack length only from postures where the
group is stretched past its slack length (its passive force acts there), and its stretch reflex
only from passes that lengthen it fast where it is long enough for the reflex to fire (the
seed's Γ = (λ − λ_min)/ℓ − (λ_rest/λ_max)(1 − u) > 0: near the long end of its range, more so
at a low gain). A grid 6 cm nearer the body than the default never brought the elbow flexors
into their reflex's firing range: the fit then graded a severe group as passive "very mild" and
held its reflex as unidentified. So, for the patient's arm and the planned postures and passes
(:mod:`fieldbank.measure.protocol`), each group gets:

* **passive** - the postures at which the group is more than the passive smoothing width
  (2 mm) past its slack length; seen with at least :data:`MIN_POSTURES`;
* **reflex** - the pass points (a posture on a pass, at the pass's velocity: where the moving
  stiffness map is read) at which the scale's reflex of the group at :data:`REFLEX_LEVEL`
  (:func:`fieldbank.evaluate.severity.synthesize`: mild, α ≈ 850 N, β ≈ 0.85 on the default
  arm) fires; seen with at least :data:`MIN_PASS_POINTS`. The read-out also gives the lowest
  level of the scale whose reflex fires anywhere on the passes.

:func:`check_must_see` refuses a protocol that would not see a group the operator names, with
a suggestion - the smallest change of grid centre, spacing, grid size or pass speed (in that
order of preference) that sees every named group (:func:`suggest`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fieldbank.errors import ParameterError
from fieldbank.evaluate.severity import LEVELS, synthesize
from fieldbank.measure.protocol import ProtocolConfig, ProtocolPlan, plan
from fieldbank.model import Arm, FloatArray
from fieldbank.params import GROUP_LEGEND, GROUP_NAMES, GROUPS

#: Postures past the slack length a group needs for its passive force to be seen.
MIN_POSTURES = 2
#: Pass points at which its reflex must fire for a group's reflex to be seen.
MIN_PASS_POINTS = 2
#: The level of the scale whose reflex a protocol must see (a milder one may go unseen).
REFLEX_LEVEL = "mild"


class ProtocolBlind(ParameterError):
    """The protocol would not see a muscle group the operator named."""


@dataclass(frozen=True)
class GroupSight:
    """What a protocol shows of one group (module docstring).

    ``stretched``: postures past its slack length (of ``postures``); ``firing``: pass points
    where its reflex at :data:`REFLEX_LEVEL` fires (of ``pass_points``); ``lowest_level``: the
    lowest level of the scale whose reflex fires at some pass point (None: none does).
    """

    group: str
    stretched: int
    postures: int
    firing: int
    pass_points: int
    lowest_level: str | None

    @property
    def passive_seen(self) -> bool:
        return self.stretched >= MIN_POSTURES

    @property
    def reflex_seen(self) -> bool:
        return self.firing >= MIN_PASS_POINTS

    @property
    def seen(self) -> bool:
        return self.passive_seen and self.reflex_seen

    def to_dict(self) -> dict[str, Any]:
        return {"group": self.group, "postures_past_slack_length": self.stretched,
                "postures": self.postures, "pass_points_firing": self.firing,
                "pass_points": self.pass_points, "reflex_seen_from": self.lowest_level,
                "passive_seen": self.passive_seen, "reflex_seen": self.reflex_seen}


@dataclass(frozen=True)
class ProtocolSight:
    """Every group's :class:`GroupSight` for one protocol on one arm."""

    config: ProtocolConfig
    groups: tuple[GroupSight, ...]

    def of(self, group: str) -> GroupSight:
        return next(s for s in self.groups if s.group == group)

    def unseen(self, groups: Sequence[str] = GROUPS) -> list[str]:
        """The named groups this protocol would not see (passive or reflex)."""
        return [g for g in groups if not self.of(g).seen]

    @property
    def sees_all(self) -> bool:
        return not self.unseen()

    def table(self) -> list[str]:
        """The read-out as text: one line per group."""
        c = self.config
        head = (f"what the protocol sees ({c.grid[0]}×{c.grid[1]} postures {c.spacing * 1000:.0f}"
                f" mm apart around ({c.centre[0]:.3f}, {c.centre[1]:.3f}) m, passes at "
                f"{c.stretch_speed_m_per_s:g} m/s):")
        fires = f"{REFLEX_LEVEL} reflex fires"
        lines = [head, f"  {'group':<27}{'past slack length':>18}{fires:>19}"
                       f"{'reflex seen from':>18}  verdict"]
        for s in self.groups:
            verdict = "seen" if s.seen else "NOT SEEN: " + " and ".join(
                w for w, ok in (("passive", s.passive_seen), ("reflex", s.reflex_seen)) if not ok)
            lines.append(f"  {s.group} {GROUP_NAMES[s.group]:<24}"
                         f"{f'{s.stretched}/{s.postures} postures':>18}"
                         f"{f'{s.firing}/{s.pass_points} points':>19}"
                         f"{s.lowest_level or 'no level':>18}  {verdict}")
        return lines

    def to_dict(self) -> dict[str, Any]:
        return {"config": {"grid": list(self.config.grid), "spacing_m": self.config.spacing_m,
                           "centre_m": list(self.config.centre),
                           "stretch_speed_m_per_s": self.config.stretch_speed_m_per_s,
                           "parts": list(self.config.parts)},
                "criteria": {"min_postures": MIN_POSTURES, "min_pass_points": MIN_PASS_POINTS,
                             "reflex_level": REFLEX_LEVEL},
                "groups": [s.to_dict() for s in self.groups], "sees_all": self.sees_all}


def pass_points(p: ProtocolPlan) -> tuple[FloatArray, FloatArray]:
    """Where the moving stiffness maps of plan ``p`` are read: every posture on a pass, with
    the pass's velocity: positions (K, 2) m and velocities (K, 2) m/s, shoulder frame."""
    pos, vel = [], []
    for seg in p.segments:
        if seg.kind != "pass":
            continue
        (x0, y0), (x1, y1) = seg.start_m, seg.end_m
        length = float(np.hypot(x1 - x0, y1 - y0))
        u = np.array([x1 - x0, y1 - y0]) / length
        for q in p.postures_m:
            rel = q - np.array([x0, y0])
            along = float(rel @ u)
            if abs(float(rel[0] * u[1] - rel[1] * u[0])) < 1e-6 and 0.0 <= along <= length:
                pos.append(q)
                vel.append(seg.speed_m_per_s * u)
    return np.reshape(np.array(pos, dtype=float), (-1, 2)), np.reshape(
        np.array(vel, dtype=float), (-1, 2))


@dataclass(frozen=True, eq=False)
class _Reflexes:
    """The scale's reflex of each group at each impaired level, compiled once per arm."""

    arms: dict[tuple[str, str], Arm]

    @classmethod
    def of(cls, arm: Arm) -> _Reflexes:
        return cls({(g, lvl): arm.with_muscles(synthesize({f"{g}:dynamic": lvl}, arm.params))
                    for g in GROUPS for lvl in LEVELS[1:]})


def _firing(arm: Arm, positions: FloatArray, velocities: FloatArray, group: str) -> int:
    if len(positions) == 0:
        return 0
    q = arm.ik(positions)
    qdot = np.linalg.solve(arm.jacobian(q), velocities[..., None])[..., 0]
    phi = arm.reflex_forces(arm.muscle_lengths(q), arm.muscle_velocities(qdot))[0]
    return int(np.count_nonzero(phi[:, GROUPS.index(group)] > 0.0))


def sight(p: ProtocolPlan, arm: Arm, reflexes: _Reflexes | None = None) -> ProtocolSight:
    """Every group's sight of plan ``p`` on the patient's ``arm`` (module docstring)."""
    refl = reflexes or _Reflexes.of(arm)
    past = arm.muscle_lengths(arm.ik(p.postures_m)) - arm.lam_slack
    pos, vel = pass_points(p)
    out = []
    for i, g in enumerate(GROUPS):
        counts = {lvl: _firing(refl.arms[(g, lvl)], pos, vel, g) for lvl in LEVELS[1:]}
        lowest = next((lvl for lvl in LEVELS[1:] if counts[lvl] > 0), None)
        out.append(GroupSight(g, int(np.count_nonzero(past[:, i] > arm.w)), len(p.postures_m),
                              counts[REFLEX_LEVEL], len(pos), lowest))
    return ProtocolSight(p.config, tuple(out))


def _variants(c: ProtocolConfig) -> list[tuple[str, ProtocolConfig]]:
    """Changes to try, the smallest first: the centre moved (2-8 cm), the spacing widened,
    a posture more each way, a faster pass."""
    cx, cy = c.centre
    out: list[tuple[str, ProtocolConfig]] = []
    for d in (0.02, 0.04, 0.06, 0.08):
        for dx, dy in ((0.0, d), (0.0, -d), (d, 0.0), (-d, 0.0)):
            centre = (round(cx + dx, 3), round(cy + dy, 3))
            out.append((f"--centre {centre[0]:g},{centre[1]:g}",
                        dataclasses.replace(c, centre_m=centre)))
    for f in (1.25, 1.5):
        sp = round(c.spacing * f, 3)
        if sp <= 0.2:
            out.append((f"--spacing-mm {sp * 1000:g}", dataclasses.replace(c, spacing_m=sp)))
    nx, ny = c.grid
    for grid in ((nx + 1, ny + 1), (nx + 2, ny + 2)):
        if max(grid) <= 15:
            out.append((f"--grid {grid[0]}x{grid[1]}", dataclasses.replace(c, grid=grid)))
    for v in (1.2, 1.4, 1.6, 1.8, 2.0):
        if v > c.stretch_speed_m_per_s:
            out.append((f"--stretch-speed {v:g}",
                        dataclasses.replace(c, stretch_speed_m_per_s=v)))
    return out


def suggest(config: ProtocolConfig, arm: Arm, groups: Sequence[str],
            fits: Callable[[ProtocolPlan], bool] | None = None) -> tuple[str, ProtocolSight] | None:
    """The first change (:func:`_variants`) whose protocol sees every group of ``groups`` on
    ``arm``, reachable and accepted by ``fits`` (e.g. the robot's workspace and speed limit),
    with its sight; None when no single change does."""
    refl = _Reflexes.of(arm)
    if "stretch" not in config.parts:
        config = dataclasses.replace(config, parts=(*config.parts, "stretch"))
    for words, c in _variants(config):
        try:
            p = plan(c, arm)
        except ParameterError:
            continue
        if fits is not None and not fits(p):
            continue
        s = sight(p, arm, refl)
        if not s.unseen(groups):
            return words, s
    return None


def parse_groups(text: str) -> tuple[str, ...]:
    """'ef,bf' (or 'all') as muscle group codes, in the model's order."""
    items = [t.strip().lower() for t in text.split(",") if t.strip()]
    if items == ["all"]:
        return GROUPS
    bad = [t for t in items if t not in GROUPS]
    if bad or not items:
        raise ParameterError(f"--must-see: unknown muscle group(s) {', '.join(bad) or '(none)'};"
                             f" give codes separated by commas, or 'all' ({GROUP_LEGEND}).")
    return tuple(g for g in GROUPS if g in items)


def check_must_see(p: ProtocolPlan, arm: Arm, must_see: Sequence[str],
                   fits: Callable[[ProtocolPlan], bool] | None = None,
                   seen: ProtocolSight | None = None) -> ProtocolSight:
    """The sight of plan ``p`` (``seen``, when already computed); :class:`ProtocolBlind`
    when it would not see a group of ``must_see``, with the change that would
    (:func:`suggest`)."""
    s = seen if seen is not None else sight(p, arm)
    missing = s.unseen(must_see)
    if not missing:
        return s
    why = "; ".join(
        f"{g} ({GROUP_NAMES[g]}): " + " and ".join(
            w for w, ok in ((f"its passive force (past its slack length at "
                             f"{s.of(g).stretched} of {s.of(g).postures} postures, "
                             f"{MIN_POSTURES} needed)", s.of(g).passive_seen),
                            (f"its stretch reflex (a {REFLEX_LEVEL} reflex fires at "
                             f"{s.of(g).firing} of {s.of(g).pass_points} pass points, "
                             f"{MIN_PASS_POINTS} needed)", s.of(g).reflex_seen)) if not ok)
        for g in missing)
    found = suggest(p.config, arm, must_see, fits)
    hint = (f"try {found[0]}, which sees {', '.join(must_see)}" if found is not None else
            "no single change of centre, spacing, grid or pass speed sees them all: measure "
            "those groups in a session of their own")
    raise ProtocolBlind(f"the protocol would not see {why}; {hint}. Nothing was measured.")
