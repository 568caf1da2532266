"""Metrics week by week after a botulinum injection (BRIEF §7 time course).

:func:`time_course` evaluates the compiled arm before once and the plan's after model at each
week (:meth:`fieldbank.interventions.plan.Plan.at_week`: weeks after the most recent
injection), on the same standard conditions, and collects the headline figures per week. The
week models are compiled through the use case's :class:`fieldbank.evaluate.ArmCache`, so week 0
(no effect yet: the model before) and the plan's own week (the model after) are not compiled
again.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.compare import (
    Comparison,
    Conditions,
    compare_evaluations,
    evaluate_arm,
)
from fieldbank.interventions.catalogue import Botulinum
from fieldbank.interventions.errors import InterventionError
from fieldbank.interventions.plan import Plan
from fieldbank.model import Arm, FloatArray

DEFAULT_WEEKS: tuple[float, ...] = tuple(float(w) for w in range(25))


@dataclass(frozen=True, eq=False)
class TimeCourse:
    """Headline metrics per week.

    Attributes
    ----------
    weeks : ndarray, shape (W,)
    effect : dict group -> ndarray (W,)
        Botulinum effect e (fractional drop of α) per injected group, compounded over
        the plan's injections.
    moving_diff_rms_n : ndarray (W,)
        RMS force change at the first moving speed, N.
    probe_peak_n : dict probe -> ndarray (W,)
        Peak force along each probing motion, N.
    stretch_peak_n_m : dict stretch -> ndarray (W,)
        Peak resisting torque of each fast joint stretch, N·m.
    comparisons : tuple of Comparison
    """

    weeks: FloatArray
    effect: dict[str, FloatArray]
    moving_diff_rms_n: FloatArray
    probe_peak_n: dict[str, FloatArray]
    stretch_peak_n_m: dict[str, FloatArray]
    comparisons: tuple[Comparison, ...]

    def peak_week(self, group: str) -> float:
        """Week of the largest effect in ``group``."""
        return float(self.weeks[int(np.argmax(self.effect[group]))])

    def to_dict(self) -> dict[str, Any]:
        return {
            "weeks": self.weeks.tolist(),
            "effect": {g: e.tolist() for g, e in self.effect.items()},
            "moving_diff_rms_n": self.moving_diff_rms_n.tolist(),
            "probe_peak_n": {k: v.tolist() for k, v in self.probe_peak_n.items()},
            "stretch_peak_n_m": {k: v.tolist() for k, v in self.stretch_peak_n_m.items()},
        }


def time_course(arm: Arm, plan: Plan, weeks: ArrayLike = DEFAULT_WEEKS,
                conditions: Conditions | None = None,
                arms: ArmCache | None = None) -> TimeCourse:
    """Metrics of ``plan`` applied to ``arm`` at each of ``weeks`` after the injection.

    Parameters
    ----------
    arm : Arm
        The compiled model before.
    plan : Plan
        Must hold at least one botulinum step.
    weeks : array_like, shape (W,), weeks
        Finite, >= 0, not empty.
    conditions : Conditions, optional
        Default: :meth:`Conditions.standard` of ``arm``.
    arms : ArmCache, optional
        The use case's compiled arms (default: a new cache holding ``arm``).
    """
    w = np.asarray(weeks, dtype=float).reshape(-1)
    if not any(isinstance(s, Botulinum) for s in plan.steps):
        raise InterventionError("time course: the plan has no botulinum step to follow.")
    if w.size == 0 or np.any(w < 0) or np.any(~np.isfinite(w)):
        raise InterventionError("time course: weeks must be finite, >= 0, and not empty.")
    compiled = arms if arms is not None else ArmCache()
    compiled.add(arm)
    cond = conditions if conditions is not None else Conditions.standard(arm)
    before = evaluate_arm(arm, cond)
    groups = sorted({g for s in plan.steps if isinstance(s, Botulinum) for g in s.targets()})
    effect = {g: np.zeros(w.size) for g in groups}
    comps = []
    for i, week in enumerate(w):
        p_week = plan.at_week(float(week))
        keep = dict.fromkeys(groups, 1.0)
        for s in p_week.steps:
            if isinstance(s, Botulinum):
                for g, e in s.effect().items():
                    keep[g] *= 1.0 - e
        for g in groups:
            effect[g][i] = 1.0 - keep[g]
        week_params = p_week.apply(arm.params)
        after = (before if week_params == arm.params
                 else evaluate_arm(compiled(week_params), cond))
        comps.append(compare_evaluations(before, after))
    return TimeCourse(
        weeks=w,
        effect=effect,
        moving_diff_rms_n=np.array([c.fields[min(1, len(c.fields) - 1)].diff_rms_n
                                    for c in comps]),
        probe_peak_n={n: np.array([c.probe_rows()[k][2].peak_force_n for c in comps])
                      for k, (n, _, _) in enumerate(comps[0].probe_rows())},
        stretch_peak_n_m={n: np.array([c.stretch_rows()[k][2].peak_torque_n_m for c in comps])
                          for k, (n, _, _) in enumerate(comps[0].stretch_rows())},
        comparisons=tuple(comps),
    )
