"""The measuring protocol's choices and defaults the command line shows: the parts of a
protocol and how each posture is probed.

A leaf: it imports nothing, so that :class:`fieldbank.measure.protocol.ProtocolConfig` and the
command line's options (``fieldbank haptic measure --help``) read these values from one place
without loading the numerics that plan a protocol.
"""

from __future__ import annotations

#: What a protocol measures: postural maps (holds), stiffness maps (small displacements from
#: each hold) and fast stretches (passes that can fire a reflex).
PARTS: tuple[str, ...] = ("postural", "stiffness", "stretch")
#: Displacement from each posture for a stiffness map, m (5-8 mm in Mussa-Ivaldi, Hogan &
#: Bizzi 1985).
DISPLACEMENT_M = 0.006
#: Directions of the displacements around each posture, evenly spread (8 in Mussa-Ivaldi,
#: Hogan & Bizzi 1985).
DIRECTIONS = 8
#: Hold at each displaced position, s.
HOLD_S = 0.6
#: Hand speed of a stretch pass, m/s: the seed's reflex fires only on a fast stretch; 180°/s at
#: the elbow is ≈ 1.1 m/s at the hand.
STRETCH_SPEED_M_PER_S = 1.2
