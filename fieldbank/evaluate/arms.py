"""Compile each model once per use case.

Compiling an arm (:meth:`fieldbank.model.Arm.from_params`) derives the muscle-length Jacobian,
the length extremes over the range of motion, λ̇_max on the seed's fast circle and the
potential's normalising integrals. One what-if meets the same parameter sets several times:
week 0 of a time course is the model before, the plan's own week is the model after, the
dose search starts at the split it later reports as the baseline. An :class:`ArmCache` lives
for one use case and hands back the compiled arm of a parameter set it has already seen, so
each distinct model is compiled exactly once; it is dropped with the use case.
"""

from __future__ import annotations

from fieldbank.model import Arm
from fieldbank.params import ArmParams


class ArmCache:
    """Compiled arms of one use case, keyed by their (frozen, hashable) parameters.

    Parameters
    ----------
    *arms : Arm
        Arms compiled already (e.g. the model before), handed back for their parameters.
    """

    def __init__(self, *arms: Arm) -> None:
        self._arms: dict[ArmParams, Arm] = {}
        self.add(*arms)

    def add(self, *arms: Arm) -> None:
        """Keep arms compiled elsewhere (an arm already held for the same parameters stays)."""
        for a in arms:
            self._arms.setdefault(a.params, a)

    def __call__(self, params: ArmParams) -> Arm:
        """The compiled arm of ``params``, compiling it on first use."""
        arm = self._arms.get(params)
        if arm is None:
            arm = self._arms[params] = Arm.from_params(params)
        return arm

    def __len__(self) -> int:
        return len(self._arms)
