"""Strokes that stretch every direction in which the candidates differ.

A stroke shows a group's passive force where it lengthens the group past its slack length and
its stretch reflex only where it lengthens the group fast while it is long (the seed's reflex
fires near the long end of the range, more so at a low gain). Two strokes designed for the
information between three joint groups never stretched the directions in which an
elbow-extensor reflex or a shoulder-flexor contracture differs from the unimpaired arm, so the
nearest candidate fitted within the noise and the classifier was confidently wrong.

:func:`coverage_strokes` gives, for every muscle group in which the candidates' muscle values
differ, the longest, fastest stroke from the candidates' equilibrium along the direction that
lengthens that group fastest (:func:`fieldbank.evaluate.probing.lengthening_direction`, turned by
up to :data:`TURN_DEG` when the limits need it) that keeps every limit in every execution of
the motion noise (:class:`~fieldbank.evaluate.design.config.ProbeLimits`): the clinic's fast
stretch of that group, started where the arm rests. The information search
(:func:`fieldbank.evaluate.design.design`) may add strokes after them.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence

import numpy as np

from fieldbank.evaluate.design.candidates import Candidate, check_candidates, equilibrium
from fieldbank.evaluate.design.config import NoiseModel, ProbeLimits
from fieldbank.evaluate.design.paths import Stroke
from fieldbank.evaluate.design.predict import executions, feasible
from fieldbank.evaluate.probing import ProbeMotion, lengthening_direction, min_jerk
from fieldbank.model import Arm, FloatArray
from fieldbank.params import GROUP_NAMES, GROUPS, PER_GROUP_FIELDS

#: Turns from the lengthening direction tried, in order, when a stroke along it breaks a limit.
TURN_DEG = (0.0, 10.0, -10.0, 20.0, -20.0, 30.0, -30.0)
#: Stroke lengths tried, the longest first, as fractions of the family's maximal length.
LENGTH_STEPS = (1.0, 0.85, 0.7, 0.55, 0.45)
#: Samples at which a stroke's limits are checked.
CHECK_SAMPLES = 241


def differing_groups(candidates: Sequence[Candidate]) -> tuple[str, ...]:
    """The muscle groups whose Km, α, β or slack offset differ between the candidates."""
    out = []
    for i, g in enumerate(GROUPS):
        values = {tuple(getattr(c.arm.params, f)[i] for f in PER_GROUP_FIELDS)
                  for c in candidates}
        if len(values) > 1:
            out.append(g)
    return tuple(out)


def coverage_strokes(candidates: Sequence[Candidate], limits: ProbeLimits | None = None,
                     noise: NoiseModel | None = None,
                     start_m: Sequence[float] | None = None) -> tuple[Stroke, ...]:
    """One stroke per group in which the candidates differ (module docstring), in the model's
    group order; a group no stroke within the limits can stretch is left out."""
    cands = check_candidates(candidates, 2)
    start = equilibrium(cands) if start_m is None else np.asarray(start_m, dtype=float)
    return strokes_stretching(cands, differing_groups(cands), (float(start[0]), float(start[1])),
                              limits, noise)


def strokes_stretching(arms: Sequence[Candidate], groups: Sequence[str], start_m: Sequence[float],
                       limits: ProbeLimits | None = None,
                       noise: NoiseModel | None = None) -> tuple[Stroke, ...]:
    """For each of ``groups``, the longest, fastest stroke from ``start_m`` along the
    direction that lengthens it (module docstring), within the limits for every arm of
    ``arms`` in every execution of the motion noise."""
    lim = limits or ProbeLimits()
    nz = noise or NoiseModel()
    cands = tuple(arms)
    start = np.asarray(start_m, dtype=float)
    arm = cands[0].arm
    # the peak speed of every execution (speeds up to +1 SD, as the robust check) within it
    peak = lim.max_speed_m_per_s / (1.0 + nz.speed_sd)
    out = []
    for g in groups:
        d = lengthening_direction(arm, g)
        angle = math.degrees(math.atan2(float(d[1]), float(d[0])))
        found = None
        for frac in LENGTH_STEPS:
            length = max(lim.min_length_m, frac * lim.max_length_m)
            duration = min(max(1.875 * length / peak, lim.min_duration_s), lim.max_duration_s)
            for turn in TURN_DEG:
                s = Stroke((float(start[0]), float(start[1])), angle + turn, length, duration)
                if _keeps_limits(cands, s, lim, nz):
                    found = s
                    break
            if found is not None:
                break
        if found is not None:
            out.append(found)
    return tuple(out)


#: How far inside its range of motion each joint ends a group's stretch, degrees; and the
#: margin every execution of it keeps (a clinical stretch goes to the end of the range, so
#: closer than a probing stroke's).
STRETCH_END_MARGIN_DEG = 20.0
STRETCH_ROM_MARGIN_DEG = 5.0
#: The elbow's extended end kept further off, the first of these that keeps every execution
#: within reach: a straight elbow is where the hand's reach ends.
EXTENDED_ELBOW_MARGINS_DEG = (30.0, 35.0, 40.0, 45.0)
#: Hand path of the fast part of a group's stretch, m, and of the slow approach to its start.
STRETCH_LENGTH_M = 0.15
APPROACH_SPEED_M_PER_S = 0.4
#: Sample period of a stretch motion, s (the renderer's 1 kHz).
STRETCH_SAMPLE_S = 1e-3
#: The two-joint partner of each one-joint group: the group's stretch holds its other joint
#: where the partner is short, so that the partner's force does not mix in (the clinic tells
#: brachialis from biceps with the shoulder flexed). Held at the partner's short end of the
#: range - the shoulder :data:`STRETCH_END_MARGIN_DEG` inside it, the elbow the first of
#: :data:`EXTENDED_ELBOW_MARGINS_DEG` inside either end -, or the first of
#: :data:`HOLD_FRACTIONS` of the way there from the rest posture that keeps every limit.
SLACKENED_PARTNER: dict[str, str] = {"sf": "bf", "ef": "bf", "se": "be", "ee": "be"}
HOLD_FRACTIONS = (1.0, 0.75, 0.5, 0.25, 0.0)


def stretch_noise(noise: NoiseModel | None = None) -> NoiseModel:
    """The operator's scatter on a group's stretch: the speed within 10 %, the direction within
    3° and the length exact - a practised fast stretch the joints' range guides, not a free
    stroke (assumption)."""
    nz = noise or NoiseModel()
    return dataclasses.replace(nz, direction_sd_deg=min(nz.direction_sd_deg, 3.0),
                               length_sd=0.0, speed_sd=min(nz.speed_sd, 0.10))


def group_stretch(arm: Arm, group: str, limits: ProbeLimits | None = None,
                  noise: NoiseModel | None = None) -> ProbeMotion | None:
    """The clinic's fast stretch of one group, as a handle motion from where the arm rests:
    a slow approach to a posture short of the group's longest (a one-joint group's other
    joint moved to where its two-joint partner is short: :data:`SLACKENED_PARTNER`), then a
    fast stretch of the joints that lengthen it (the bi-articular groups: both) into the end
    of their range,
    :data:`STRETCH_END_MARGIN_DEG` inside it - where the seed's reflex fires at any gain. Joint
    space, minimum jerk; the fast part's hand path :data:`STRETCH_LENGTH_M` long at a peak
    speed within the limits for every execution of the motion noise. None when no such motion
    keeps the limits."""
    lim = dataclasses.replace(limits or ProbeLimits(), rom_margin_deg=min(
        (limits or ProbeLimits()).rom_margin_deg, STRETCH_ROM_MARGIN_DEG))
    nz = stretch_noise(noise)
    p = arm.params
    margin = math.radians(STRETCH_END_MARGIN_DEG)
    grad = arm.jl[GROUPS.index(group)]  # ∂λ/∂q: the joints that lengthen the group
    q_rest = np.asarray(arm.q_rest, dtype=float)
    u = np.sign(grad) * (grad != 0)
    peak = 0.98 * lim.max_speed_m_per_s / (1.0 + nz.speed_sd)
    held = _partner_short(arm, group)
    for frac, elbow_margin, length in itertools.product(
            HOLD_FRACTIONS if held is not None else (0.0,),
            EXTENDED_ELBOW_MARGINS_DEG if grad[1] < 0 else (0.0,),
            (STRETCH_LENGTH_M, 0.8 * STRETCH_LENGTH_M, 0.6 * STRETCH_LENGTH_M)):
        q_end = q_rest.copy()
        if held is not None:
            q_end[held[0]] += frac * (held[1] - q_rest[held[0]])
        for j, (lo, hi) in enumerate((p.shoulder_range_rad, p.elbow_range_rad)):
            if grad[j] > 0:
                q_end[j] = hi - margin
            elif grad[j] < 0:
                q_end[j] = lo + (math.radians(elbow_margin) if j == 1 else margin)
        # the joint excursion whose hand path is ``length``, ending at q_end
        speed = float(np.linalg.norm(arm.jacobian(q_end)[0] @ u))
        q_start = q_end - u * (length / max(speed, 1e-6))
        motion = _joint_motion(arm, [q_rest, q_start, q_end],
                               [APPROACH_SPEED_M_PER_S, peak], group)
        if motion is not None and all(bool(feasible(
                [Candidate("unimpaired", arm)], e.positions_m[None],
                e.velocities_m_per_s[None], lim)[0]) for e in executions(motion, nz)):
            return motion
    return None


def _partner_short(arm: Arm, group: str) -> tuple[int, float] | None:
    """For a one-joint group with a two-joint partner (:data:`SLACKENED_PARTNER`): the joint
    the group does not cross and the angle at which the partner is shortest within the range
    (module constants' margins); None for the others."""
    partner = SLACKENED_PARTNER.get(group)
    if partner is None:
        return None
    grad = arm.jl[GROUPS.index(group)]
    j = 0 if grad[0] == 0 else 1
    lo, hi = (arm.params.shoulder_range_rad, arm.params.elbow_range_rad)[j]
    margin = math.radians(EXTENDED_ELBOW_MARGINS_DEG[0] if j == 1 else STRETCH_END_MARGIN_DEG)
    # the partner shortens toward the end where its length falls
    return j, (lo + margin if arm.jl[GROUPS.index(partner), j] > 0 else hi - margin)


def _joint_motion(arm: Arm, postures: Sequence[FloatArray], peaks: Sequence[float],
                  group: str) -> ProbeMotion | None:
    """Minimum-jerk joint-space legs through ``postures``, each timed for its hand peak
    speed, sampled at :data:`STRETCH_SAMPLE_S`; positions and velocities of the hand."""
    qs: list[FloatArray] = []
    qds: list[FloatArray] = []
    ts: list[FloatArray] = []
    t0 = 0.0
    for a, b, v in zip(postures[:-1], postures[1:], peaks, strict=True):
        fine = np.linspace(0.0, 1.0, 201)
        path = a[None] + fine[:, None] * (b - a)[None]
        hand = arm.fk(path)
        length = float(np.sum(np.hypot(*np.diff(hand, axis=0).T)))
        if length < 1e-4:
            continue
        duration = max(1.875 * length / v, 0.1)
        n = max(3, round(duration / STRETCH_SAMPLE_S) + 1)
        tau = np.linspace(0.0, 1.0, n)
        s, ds = min_jerk(tau)
        start = 1 if qs else 0
        qs.append((a[None] + s[:, None] * (b - a)[None])[start:])
        qds.append((ds[:, None] * (b - a)[None] / duration)[start:])
        ts.append((t0 + tau * duration)[start:])
        t0 += duration
    if not qs:
        return None
    q = np.concatenate(qs)
    qd = np.concatenate(qds)
    t = np.concatenate(ts)
    if not arm.reachable(arm.fk(q)).all():
        return None
    pos = arm.fk(q)
    vel = np.einsum("nij,nj->ni", arm.jacobian(q), qd)
    if arm.mirror:
        vel[:, 0] = -vel[:, 0]
    return ProbeMotion(f"stretch {group}", t, pos, vel,
                       f"slow to where the {GROUP_NAMES[group]} are short of their longest, "
                       "then a fast stretch of them into the end of their range")


def stretch_set(arm: Arm, groups: Sequence[str] = GROUPS, limits: ProbeLimits | None = None,
                noise: NoiseModel | None = None) -> tuple[ProbeMotion, ...]:
    """:func:`group_stretch` of each of ``groups`` that has one."""
    out = [group_stretch(arm, g, limits, noise) for g in groups]
    return tuple(m for m in out if m is not None)


def _keeps_limits(cands: Sequence[Candidate], s: Stroke, lim: ProbeLimits,
                  noise: NoiseModel) -> bool:
    m = s.motion(CHECK_SAMPLES)
    return all(bool(feasible(cands, e.positions_m[None], e.velocities_m_per_s[None], lim)[0])
               for e in executions(m, noise))
