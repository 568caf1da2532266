"""Which measurement would see a predicted change the later maps cannot.

When the maps measured after a plan cannot see its predicted change (a change of the stretch
reflex on static maps, say), :mod:`fieldbank.interventions.validate` calls the check
inconclusive and names what to measure instead: for a reflex, a stiffness map measured while
the hand moves along the direction that lengthens the treated group (the reflex acts only
while the muscle lengthens) or a fast stretch of the joint; for passive stiffness, a static
stiffness or postural map or a slow stretch. Each suggestion carries the size of the predicted
change on such a map at the default relative sd, so a lab can judge it before measuring.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from fieldbank.evaluate.probing import STRETCH_SPEED_RAD_S, lengthening_direction
from fieldbank.evaluate.severity import MUSCLE_GROUP_NAMES
from fieldbank.evaluate.tone import GRADED_STRETCH, POSITIONED_STRETCH
from fieldbank.fitting.problem import DEFAULT_RELATIVE_SD, map_sd
from fieldbank.interventions.realised import Treated
from fieldbank.interventions.spread import arm_like
from fieldbank.maps import FieldMap, model_map_like, postural_map, stiffness_map
from fieldbank.model import Arm, FloatArray
from fieldbank.params import ArmParams

#: the hand moves this fast (the sample data's moving maps), with the default relative sd.
SUGGESTED_SPEED_M_PER_S = 1.0


def _sensitivity(arm_b: Arm, arm_a: Arm, m: FieldMap) -> float:
    """Whitened size (sd) of the change from ``arm_b`` to ``arm_a`` on a map like ``m`` with
    the default relative sd (:func:`fieldbank.fitting.problem.map_sd`)."""
    yb = model_map_like(arm_b, m)
    ya = model_map_like(arm_a, m).values
    sd = map_sd(yb).reshape(yb.values.shape)
    return float(np.sqrt(np.sum(((ya - yb.values) / sd) ** 2)))


def reflex_test(arm: Arm, group: str) -> str:
    """In words, the measurement that would show ``group``'s stretch reflex: a fast stretch of
    the joint it is graded on (a bi-articular group with the shoulder placed to lengthen it,
    :mod:`fieldbank.evaluate.tone`), or a stiffness map measured while the hand moves along the
    direction that lengthens it."""
    joint, direction = GRADED_STRETCH[group]
    placed = f" with the {POSITIONED_STRETCH[group]}" if group in POSITIONED_STRETCH else ""
    d = lengthening_direction(arm, group)
    return (f"a fast stretch of the {joint} into {direction}{placed} "
            f"(≈ {math.degrees(STRETCH_SPEED_RAD_S):.0f}°/s), or a stiffness map measured while "
            f"the hand moves at {SUGGESTED_SPEED_M_PER_S:g} m/s along ({d[0]:+.2f}, {d[1]:+.2f}) "
            "(shoulder frame)")


def suggestion(before: ArmParams, after: ArmParams, positions_m: FloatArray,
               what: Sequence[Treated]) -> str:
    """Which map or stretch would see the change of ``what`` (the first treated group): for a
    reflex a stiffness map measured while the hand moves along the direction that lengthens
    the group, for passive stiffness a static stiffness or postural map; each at
    ``positions_m``, with the size of the predicted change there at the default relative sd,
    and the clinical stretch that tests the group."""
    if not what or len(positions_m) == 0:
        return ("measure a stiffness map while the hand moves at "
                f"{SUGGESTED_SPEED_M_PER_S:g} m/s along the direction that stretches the treated "
                "groups")
    arm_b = Arm.from_params(before)
    arm_a = arm_like(arm_b, after)
    t = what[0]
    joint, direction = GRADED_STRETCH[t.group]
    noise = f"{100 * DEFAULT_RELATIVE_SD:g}%"
    if t.force == "reflex":
        d = lengthening_direction(arm_b, t.group)
        v = (float(d[0] * SUGGESTED_SPEED_M_PER_S), float(d[1] * SUGGESTED_SPEED_M_PER_S))
        s = _sensitivity(arm_b, arm_a, stiffness_map(arm_b, positions_m, v))
        stretch = (f"a fast stretch of the {joint} into {direction} "
                   f"(≈ {math.degrees(STRETCH_SPEED_RAD_S):.0f}°/s)")
        return (f"measure a stiffness map while the hand moves at {SUGGESTED_SPEED_M_PER_S:g} "
                f"m/s along ({d[0]:+.2f}, {d[1]:+.2f}) (shoulder frame; it lengthens the "
                f"{MUSCLE_GROUP_NAMES[t.group]}), where the predicted change is ≈ {s:.0f} sd "
                f"at {noise} noise on these {len(positions_m)} positions, or {stretch}")
    cands = [("a static stiffness map", stiffness_map(arm_b, positions_m)),
             ("a postural map", postural_map(arm_b, positions_m))]
    name, s = max(((n, _sensitivity(arm_b, arm_a, m)) for n, m in cands), key=lambda x: x[1])
    return (f"measure {name} (≈ {s:.0f} sd of predicted change at {noise} noise on these "
            f"{len(positions_m)} positions) or a slow stretch of the {joint} into {direction}")
