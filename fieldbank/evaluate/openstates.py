"""The states the open-set classifier describes each muscle group by, and its prior over
arms of them (:mod:`fieldbank.evaluate.openset`).

A group is unimpaired, or its passive stiffness, its reflex or both raised to a half step of the
severity scale, its reflex raised off the scale's path (α alone, or the stretch gain β alone),
or its slack length short (a contracture). An arm has at most :data:`MAX_GROUPS` groups in such
states; the prior takes each group to be impaired independently with :data:`GROUP_PRIOR`, each
impaired group equally likely in each of its states.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fieldbank.params import GROUPS

#: Severity scores of a group's passive, reflex or both states (half Weber steps).
SCORES: tuple[float, ...] = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5)
#: A group's contractures: its slack length this much short, m.
CONTRACTURES_M: tuple[float, ...] = (0.005, 0.010, 0.015, 0.020)
COMPONENTS: tuple[str, ...] = ("passive", "dynamic", "both")
#: A group's reflex raised off the scale's path: ('alpha', k) α k-fold at the unimpaired
#: stretch gain, ('beta', b) the stretch gain β at b with α unimpaired.
REFLEX_ALONE: tuple[tuple[str, float], ...] = (("alpha", 5.0), ("alpha", 10.0),
                                               ("alpha", 20.0), ("beta", 0.5), ("beta", 0.75),
                                               ("beta", 1.0))
#: The clinic's words for a group's states: passive stiffness (position-dependent, slack
#: length normal), spasticity (velocity-dependent: the reflex), both, contracture (the slack
#: length short).
KINDS: tuple[str, ...] = ("stiffness", "spasticity", "spasticity and stiffness", "contracture")
STATES_PER_GROUP = len(COMPONENTS) * len(SCORES) + len(REFLEX_ALONE) + len(CONTRACTURES_M)
#: The kind (index into :data:`KINDS`) of each component of a state.
KIND_OF: dict[str, int] = {"passive": 0, "dynamic": 1, "alpha": 1, "beta": 1, "both": 2,
                           "contracture": 3}
#: Prior probability that a group is impaired (each group independently; assumption).
GROUP_PRIOR = 0.3
#: Most impaired groups an arm of the set has.
MAX_GROUPS = 2
#: The set's own prior probability of no, one and two impaired groups (each group impaired
#: independently with :data:`GROUP_PRIOR`, at most :data:`MAX_GROUPS`).
SET_COUNT_PRIOR: tuple[float, ...] = tuple(
    w / sum(ws) for ws in [[math.comb(len(GROUPS), n) * GROUP_PRIOR ** n
                            * (1.0 - GROUP_PRIOR) ** (len(GROUPS) - n)
                            for n in range(MAX_GROUPS + 1)]] for w in ws)


@dataclass(frozen=True)
class GroupState:
    """One impaired state of one group: ``component`` 'passive', 'dynamic', 'both' at
    ``score``, 'alpha' (α ``factor``-fold) or 'beta' (β at ``factor``) alone, or
    'contracture' of ``slack_m`` (m short)."""

    group: str
    component: str
    score: float = 0.0
    slack_m: float = 0.0
    factor: float = 0.0

    @property
    def name(self) -> str:
        if self.component == "contracture":
            return f"{self.group} contracture {self.slack_m * 1000:g} mm"
        if self.component == "alpha":
            return f"{self.group} reflex α ×{self.factor:g}"
        if self.component == "beta":
            return f"{self.group} reflex β {self.factor:g}"
        return f"{self.group} {self.component} {self.score:g}"


def label_counts(labels: Sequence[str]) -> np.ndarray:
    """How many groups each label ('unimpaired', 'ef', 'ef+bf') holds."""
    return np.array([0 if lab == "unimpaired" else lab.count("+") + 1 for lab in labels],
                    dtype=int)


__all__ = [
    "COMPONENTS",
    "CONTRACTURES_M",
    "GROUP_PRIOR",
    "KINDS",
    "KIND_OF",
    "MAX_GROUPS",
    "REFLEX_ALONE",
    "SCORES",
    "SET_COUNT_PRIOR",
    "STATES_PER_GROUP",
    "GroupState",
    "label_counts",
]
