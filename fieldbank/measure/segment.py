"""Trials found in a recording that marks none: holds by their stillness, roles by position.

A lab's raw file often has no trial table fieldbank understands (a KINARM exam's events are
task-specific, a C3D or NWB file may have none). :func:`find_holds` then finds the holds
itself:

1. a **hold** is a stretch of at least ``min_hold_s`` where the hand's speed stays under
   ``still_speed_m_per_s`` (5 mm/s); its window is the hold after ``transient_s``;
2. holds whose mean positions lie within ``posture_radius_m`` (15 mm) of each other belong to
   one **posture** (grouped greedily in time order, each posture's centre the running median);
3. within a posture, the holds within ``base_radius_m`` (2 mm) of the posture's most common
   position are its **base** holds, the others **displaced** ones (MIHB 1985 displace by
   5–8 mm).

Passes (moving stiffness) cannot be found this way: they need the file's own trial marks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fieldbank.measure.recording import Recording, Trial
from fieldbank.validation import Interval, check_fields

#: The range of each threshold of :class:`SegmentConfig`.
SEGMENT_BOUNDS: dict[str, Interval] = {
    "still_speed_m_per_s": Interval(0.0, 1.0, "m/s", low_closed=False),
    "min_hold_s": Interval(0.0, 60.0, "s", low_closed=False),
    "transient_s": Interval(0.0, 10.0, "s"),
    "posture_radius_m": Interval(0.0, 0.2, "m", low_closed=False),
    "base_radius_m": Interval(0.0, 0.2, "m", low_closed=False),
}


@dataclass(frozen=True)
class SegmentConfig:
    """Thresholds of :func:`find_holds` (SI)."""

    still_speed_m_per_s: float = 0.005
    min_hold_s: float = 0.25
    transient_s: float = 0.15
    posture_radius_m: float = 0.015
    base_radius_m: float = 0.002

    def __post_init__(self) -> None:
        check_fields(self, SEGMENT_BOUNDS, what="hold-finding setting")


def find_holds(rec: Recording, config: SegmentConfig | None = None) -> list[Trial]:
    """The holds of ``rec`` as base and displaced trials (see the module docstring)."""
    cfg = config or SegmentConfig()
    speed = np.hypot(*rec.velocity_m_per_s.T)
    still = speed < cfg.still_speed_m_per_s
    t = rec.t_s
    edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(int), [0]])))
    spans = [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]
    holds = []
    for a, b in spans:
        t0, t1 = float(t[a]), float(t[b - 1])
        if t1 - t0 < cfg.min_hold_s:
            continue
        w0 = min(t0 + cfg.transient_s, t1)
        sl = rec.span(w0, t1)
        if sl.stop <= sl.start:
            continue
        holds.append((t0, t1, w0, rec.position_m[sl].mean(axis=0)))
    return _classify(rec, holds, cfg)


def holds_in_spans(rec: Recording, spans: list[tuple[float, float]],
                   config: SegmentConfig | None = None) -> list[Trial]:
    """Trials from spans the file marks (``--trial-events``: each from its event to the next),
    read after the transient, their roles by position as in :func:`find_holds`."""
    cfg = config or SegmentConfig()
    holds = []
    for t0, t1 in spans:
        w0 = min(t0 + cfg.transient_s, t1)
        sl = rec.span(w0, t1)
        if sl.stop - sl.start < 2:
            continue
        holds.append((t0, t1, w0, rec.position_m[sl].mean(axis=0)))
    return _classify(rec, holds, cfg)


def _classify(rec: Recording, holds: list[tuple[float, float, float, np.ndarray]],
              cfg: SegmentConfig) -> list[Trial]:
    centres: list[list[np.ndarray]] = []
    member: list[int] = []
    for *_, pos in holds:
        best, dist = -1, np.inf
        for k, members in enumerate(centres):
            d = float(np.hypot(*(pos - np.median(members, axis=0))))
            if d < dist:
                best, dist = k, d
        if best < 0 or dist > cfg.posture_radius_m:
            centres.append([pos])
            member.append(len(centres) - 1)
        else:
            centres[best].append(pos)
            member.append(best)
    bases = []
    for members in centres:
        pts = np.array(members)
        # the position most holds come back to: the one with the most neighbours within reach
        near = (np.hypot(*(pts[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
                <= cfg.base_radius_m).sum(axis=1)
        bases.append(pts[near == near.max()].mean(axis=0))
    trials = []
    for i, ((t0, t1, w0, pos), p) in enumerate(zip(holds, member, strict=True)):
        d = float(np.hypot(*(pos - bases[p])))
        role = "base" if d <= cfg.base_radius_m else "displaced"
        trials.append(Trial(i, role, p, t0, t1, (w0, t1),
                            label=f"hold found at {t0:.2f}–{t1:.2f} s, posture {p}"))
    return trials
