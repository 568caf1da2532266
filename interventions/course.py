"""Metrics week by week after a botulinum injection (BRIEF §7 time course).

Two forms: :func:`time_course` evaluates every metric at every week (``whatif --timecourse``);
:func:`stretch_course` gives the joint-stretch read-outs week by week at almost no cost, for
reports (see there).

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

from fieldbank.armbatch import ArmBatch
from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.batch import standard_stretch_torques
from fieldbank.evaluate.compare import (
    Comparison,
    Conditions,
    compare_evaluations,
    evaluate_arm,
)
from fieldbank.evaluate.probing import STRETCHES, Profiles, stretch_profiles
from fieldbank.interventions.catalogue import Botulinum
from fieldbank.interventions.errors import InterventionError
from fieldbank.interventions.plan import Plan
from fieldbank.model import Arm, FloatArray
from fieldbank.params import GROUP_INDEX

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


def _check(plan: Plan, weeks: ArrayLike) -> FloatArray:
    w = np.asarray(weeks, dtype=float).reshape(-1)
    if not any(isinstance(s, Botulinum) for s in plan.steps):
        raise InterventionError("time course: the plan has no botulinum step to follow.")
    if w.size == 0 or np.any(w < 0) or np.any(~np.isfinite(w)):
        raise InterventionError("time course: weeks must be finite, >= 0, and not empty.")
    return w


def botulinum_effects(plan: Plan, weeks: ArrayLike) -> dict[str, FloatArray]:
    """Effect e (fractional drop of α) per injected group at each of ``weeks`` after the most
    recent injection, compounded over the plan's injections: 1 - Π (1 - e_step)."""
    w = np.asarray(weeks, dtype=float).reshape(-1)
    groups = sorted({g for s in plan.steps if isinstance(s, Botulinum) for g in s.targets()},
                    key=GROUP_INDEX.__getitem__)
    effect = {g: np.zeros(w.size) for g in groups}
    for i, week in enumerate(w):
        keep = dict.fromkeys(groups, 1.0)
        for s in plan.at_week(float(week)).steps:
            if isinstance(s, Botulinum):
                for g, e in s.effect().items():
                    keep[g] *= 1.0 - e
        for g in groups:
            effect[g][i] = 1.0 - keep[g]
    return effect


@dataclass(frozen=True, eq=False)
class StretchCourse:
    """Joint-stretch read-outs per week (:func:`stretch_course`).

    Attributes
    ----------
    weeks : ndarray, shape (W,)
    plan_week : float
        The week the plan itself stands at (weeks since its most recent injection).
    effect : dict group -> ndarray (W,)
        Botulinum effect per injected group (:func:`botulinum_effects`).
    fast_peak_n_m, velocity_dependent_n_m : dict stretch name -> ndarray (W,), N·m
        Peak torque resisting the fast stretch, and its largest velocity-dependent part.
    slow_peak_n_m : dict stretch name -> ndarray (W,), N·m
        Peak torque resisting the slow stretch (nearly unchanged by botulinum, whose effect is
        on the reflex, velocity-dependent torque; Gäverth 2014).
    """

    weeks: FloatArray
    plan_week: float
    effect: dict[str, FloatArray]
    fast_peak_n_m: dict[str, FloatArray]
    velocity_dependent_n_m: dict[str, FloatArray]
    slow_peak_n_m: dict[str, FloatArray]

    def to_dict(self) -> dict[str, Any]:
        return {"weeks": self.weeks.tolist(), "plan_week": self.plan_week,
                "effect": {g: e.tolist() for g, e in self.effect.items()},
                "fast_peak_n_m": {k: v.tolist() for k, v in self.fast_peak_n_m.items()},
                "velocity_dependent_n_m": {k: v.tolist()
                                           for k, v in self.velocity_dependent_n_m.items()},
                "slow_peak_n_m": {k: v.tolist() for k, v in self.slow_peak_n_m.items()}}


def stretch_course(arm: Arm, plan: Plan, weeks: ArrayLike = DEFAULT_WEEKS,
                   arms: ArmCache | None = None) -> StretchCourse:
    """The joint-stretch read-outs of ``plan`` applied to ``arm``, week by week.

    Between weeks only the botulinum effect changes, and the toxin scales α (BRIEF §7); the
    reflex force φ = max(0, α u Γ e^(-Γ²)) is linear in α ≥ 0, so each group's reflex torque
    at week w is its torque in the plan without toxin effect (every injection seen at week
    0) times 1 - e_g(w). One set of stretch profiles therefore gives every week exactly
    (``tests/test_report_figures.py`` checks it against :func:`time_course`). A plan stored
    before the recalibration (``scale_beta``) also scales β, where this does not hold; its
    weeks are then evaluated together, one parameter set each, in one pass
    (:func:`fieldbank.evaluate.batch.standard_stretch_torques`).
    """
    w = _check(plan, weeks)
    compiled = arms if arms is not None else ArmCache()
    compiled.add(arm)
    effect = botulinum_effects(plan, w)
    bots = [s for s in plan.steps if isinstance(s, Botulinum)]
    plan_week = min(s.weeks_since for s in bots)
    names = [f"{j} {d}" for j, d in STRETCHES]
    fast = {n: np.zeros(w.size) for n in names}
    vel = {n: np.zeros(w.size) for n in names}
    slow = {n: np.zeros(w.size) for n in names}
    if any(s.scale_beta for s in bots):
        sets = [plan.at_week(float(week)).apply(arm.params) for week in w]
        for st in standard_stretch_torques(ArmBatch.from_params(sets, arm)):
            fast[st.name][:] = st.fast_n_m.max(axis=1)
            vel[st.name][:] = (st.fast_n_m - st.slow_n_m).max(axis=1)
            slow[st.name][:] = st.slow_n_m.max(axis=1)
    else:
        untreated = Plan(tuple(s.at_week(0.0) if isinstance(s, Botulinum) else s
                               for s in plan.steps), plan.label)
        prof = stretch_profiles(compiled(untreated.apply(arm.params)))
        for i in range(w.size):
            keep = np.ones(6)
            for g, e in effect.items():
                keep[GROUP_INDEX[g]] = 1.0 - e[i]
            _read_week(prof, keep, i, fast, vel, slow)
    return StretchCourse(w, float(plan_week), effect, fast, vel, slow)


def _read_week(prof: Profiles, keep: FloatArray, i: int, fast: dict[str, FloatArray],
               vel: dict[str, FloatArray], slow: dict[str, FloatArray]) -> None:
    for (j, d), p in prof.items():
        name = f"{j} {d}"
        slow_t = (p.passive_n_m + p.reflex_slow_n_m * keep).sum(axis=1)
        fast_t = (p.passive_n_m + p.reflex_fast_n_m * keep).sum(axis=1)
        fast[name][i] = float(fast_t.max())
        vel[name][i] = float(np.max(fast_t - slow_t))
        slow[name][i] = float(slow_t.max())


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
    w = _check(plan, weeks)
    compiled = arms if arms is not None else ArmCache()
    compiled.add(arm)
    cond = conditions if conditions is not None else Conditions.standard(arm)
    before = evaluate_arm(arm, cond)
    effect = botulinum_effects(plan, w)
    comps = []
    for week in w:
        p_week = plan.at_week(float(week))
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
