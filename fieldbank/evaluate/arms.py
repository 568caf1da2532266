"""Compile each model once per use case.

Compiling an arm (:meth:`fieldbank.model.Arm.from_params`) derives the muscle-length Jacobian,
the length extremes over the range of motion, λ̇_max on the seed's fast circle and the
potential's normalising integrals. One what-if meets the same parameter sets several times:
week 0 of a time course is the model before, the plan's own week is the model after, the
dose search starts at the split it later reports as the baseline. An :class:`ArmCache` lives
for one use case and hands back the compiled arm of a parameter set it has already seen, so
each distinct model is compiled exactly once; it is dropped with the use case.

It also keeps what a use case derives from the model before alone (:meth:`ArmCache.derived`:
the standard conditions, the prior table, the fit's drawn samples and their metrics), so a
use case that lives longer than one call - the workspace's composer, where every dose change
is a new plan on the same model - computes those once, and each call computes exactly what a
fresh use case would (the same functions on the same inputs). Such a long-lived cache is
bounded (``limit``): the oldest arms it compiled are dropped first; the ones it was given and
the derived values stay.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any, TypeVar

from fieldbank.model import Arm
from fieldbank.params import ArmParams

T = TypeVar("T")


class ArmCache:
    """Compiled arms of one use case, keyed by their (frozen, hashable) parameters.

    Parameters
    ----------
    *arms : Arm
        Arms compiled already (e.g. the model before), handed back for their parameters.
    """

    def __init__(self, *arms: Arm, limit: int | None = None) -> None:
        self._arms: OrderedDict[ArmParams, Arm] = OrderedDict()
        self._kept: set[ArmParams] = set()
        self._derived: dict[Hashable, Any] = {}
        self.limit = limit
        self.add(*arms)

    def add(self, *arms: Arm) -> None:
        """Keep arms compiled elsewhere (an arm already held for the same parameters stays)."""
        for a in arms:
            self._arms.setdefault(a.params, a)
            self._kept.add(a.params)

    def __call__(self, params: ArmParams) -> Arm:
        """The compiled arm of ``params``, compiling it on first use."""
        arm = self._arms.get(params)
        if arm is None:
            arm = self._arms[params] = Arm.from_params(params)
            if self.limit is not None and len(self._arms) > self.limit:
                old = next((k for k in self._arms if k not in self._kept), None)
                if old is not None:
                    del self._arms[old]
        return arm

    def derived(self, key: Hashable, compute: Callable[[], T]) -> T:
        """``compute()`` the first time ``key`` is asked for, the same value after that
        (``key`` names what it is and everything it depends on)."""
        try:
            return self._derived[key]
        except KeyError:
            value = self._derived[key] = compute()
            return value

    def __len__(self) -> int:
        return len(self._arms)
