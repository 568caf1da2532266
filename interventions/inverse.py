"""Inverse what-if: the botulinum dose split that brings a model's field closest to unimpaired.

Within one family of plans - botulinum toxin A into chosen groups, units u_i ≥ 0 with
Σ u_i ≤ a total-dose limit, all seen at the same week - search (nlopt, derivative-free COBYLA
with the dose limit as an inequality constraint) for the split minimising the distance to the
patient's unimpaired reference.

Reference: the same arm (segments, moment arms, rest posture, range) with the unimpaired
muscle values of :mod:`fieldbank.params` (Km 600 N/m, α 100 N, β 0.1, no slack offset), so
only the muscles differ.

Distance (on the standard conditions of :mod:`fieldbank.evaluate.compare`, all speeds and
directions)::

    D = RMS_x,v |F - F_ref|  +  L · RMS_x,v ‖K - K_ref‖_F,     L = 0.01 m (assumption)

L turns stiffness into the force a 1 cm displacement would add, so both terms are in N.

Every candidate model is compiled once through the use case's
:class:`fieldbank.evaluate.ArmCache` and its distance computed once.

The answer is a model result - what this model predicts for this family of plans - and is
labelled so; it is not a treatment recommendation.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import nlopt
import numpy as np

from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.compare import Conditions, fields_per_velocity
from fieldbank.interventions.catalogue import Botulinum
from fieldbank.interventions.defaults import DOSE_UNIT, value
from fieldbank.interventions.errors import InterventionError
from fieldbank.interventions.plan import Plan
from fieldbank.model import Arm, FloatArray
from fieldbank.params import GROUP_INDEX, GROUP_LEGEND, GROUPS, ArmParams

STIFFNESS_LENGTH_M = 0.01
NOTICE = ("Model result: the dose split this model predicts brings the field closest to its "
          "unimpaired reference. It is not a treatment recommendation.")


def unimpaired_reference(params: ArmParams) -> ArmParams:
    """The same arm with unimpaired muscle values (:meth:`ArmParams.with_unimpaired_muscles`)."""
    return params.with_unimpaired_muscles()


def _fields(arm: Arm, cond: Conditions) -> tuple[FloatArray, FloatArray]:
    """Force (M, 2) N and stiffness (M, 2, 2) N/m over every point of every condition."""
    fs, ks = fields_per_velocity(arm, cond)
    return np.concatenate(fs), np.concatenate(ks)


def field_distance(arm: Arm, reference: tuple[FloatArray, FloatArray],
                   cond: Conditions) -> float:
    """D of the module docstring, N, of ``arm`` from the reference fields (:func:`_fields`)."""
    f, k = _fields(arm, cond)
    fr, kr = reference
    df = float(np.sqrt(np.mean(np.sum((f - fr) ** 2, axis=1))))
    dk = float(np.sqrt(np.mean(np.sum((k - kr) ** 2, axis=(1, 2)))))
    return df + STIFFNESS_LENGTH_M * dk


@dataclass(frozen=True, eq=False)
class DoseSplitResult:
    """Outcome of :func:`optimise_botulinum`.

    units : dict group -> U (the best split found); plan : Plan with that injection;
    distance_n : D after; distance_untreated_n : D without treatment;
    distance_even_split_n : D with the limit split evenly (a simple baseline);
    evaluations, elapsed_s, algorithm : how the search ran.
    """

    units: dict[str, float]
    plan: Plan
    after: ArmParams
    distance_n: float
    distance_untreated_n: float
    distance_even_split_n: float
    total_units_limit: float
    weeks_since: float
    evaluations: int
    elapsed_s: float
    algorithm: str
    notice: str = NOTICE

    def to_dict(self) -> dict[str, Any]:
        return {
            "notice": self.notice,
            "units": self.units,
            "dose_unit": DOSE_UNIT,
            "total_units_limit": self.total_units_limit,
            "weeks_since": self.weeks_since,
            "distance_n": self.distance_n,
            "distance_untreated_n": self.distance_untreated_n,
            "distance_even_split_n": self.distance_even_split_n,
            "evaluations": self.evaluations,
            "elapsed_s": self.elapsed_s,
            "algorithm": self.algorithm,
            "plan": self.plan.to_dict(),
        }


def optimise_botulinum(
    arm: Arm,
    total_units: float,
    groups: Sequence[str] | None = None,
    weeks_since: float = value("botulinum.weeks_since"),
    max_evaluations: int = 300,
    conditions: Conditions | None = None,
    arms: ArmCache | None = None,
) -> DoseSplitResult:
    """Best split of at most ``total_units`` U among ``groups`` (default: all six).

    Deterministic: a fixed start (even split) and a derivative-free local search.

    Parameters
    ----------
    arm : Arm
        The compiled model before.
    total_units : float, U
        Dose limit, > 0 and at most the per-group cap times the number of groups.
    groups : sequence of str, optional
        Muscle groups the search may inject (default all six).
    weeks_since : float, weeks
        When every candidate injection is seen.
    max_evaluations : int
        Objective evaluations allowed (>= 10).
    conditions : Conditions, optional
        Default: :meth:`Conditions.standard` of ``arm``.
    arms : ArmCache, optional
        The use case's compiled arms (default: a new cache holding ``arm``).
    """
    gs = tuple(groups) if groups is not None else GROUPS
    bad = [g for g in gs if g not in GROUP_INDEX]
    if bad or not gs:
        raise InterventionError(
            f"inverse what-if: unknown muscle group(s) {bad} (known: {GROUP_LEGEND})"
            if bad else "inverse what-if: choose at least one muscle group.")
    if len(set(gs)) != len(gs):
        raise InterventionError("inverse what-if: a muscle group is named twice.")
    cap = value("botulinum.max_units_per_group")
    if not (isinstance(total_units, (int, float)) and 0 < total_units <= cap * len(gs)):
        raise InterventionError(
            f"inverse what-if: total_units must be > 0 and <= {cap * len(gs):g} U "
            f"({cap:g} U per group); got {total_units!r}.")
    if max_evaluations < 10:
        raise InterventionError("inverse what-if: max_evaluations must be at least 10.")
    params = arm.params
    compiled = arms if arms is not None else ArmCache()
    compiled.add(arm)
    cond = conditions if conditions is not None else Conditions.standard(arm)
    ref = _fields(arm.with_muscles(unimpaired_reference(params)), cond)
    per_group = min(float(total_units), cap)
    distances: dict[ArmParams, float] = {}

    def distance(p: ArmParams) -> float:
        d = distances.get(p)
        if d is None:
            d = distances[p] = field_distance(compiled(p), ref, cond)
        return d

    def plan_for(x: FloatArray) -> Plan:
        units = {g: float(min(max(u, 0.0), per_group)) for g, u in zip(gs, x, strict=True)}
        return Plan.of(Botulinum(units, weeks_since=weeks_since),
                       label="inverse what-if (model result)")

    evals = 0

    def objective(x: FloatArray, grad: FloatArray) -> float:
        nonlocal evals
        evals += 1
        return distance(plan_for(x).apply(params))

    def dose_limit(x: FloatArray, grad: FloatArray) -> float:
        return float(np.sum(x) - total_units)

    n = len(gs)
    opt = nlopt.opt(nlopt.LN_COBYLA, n)
    opt.set_lower_bounds(np.zeros(n))
    opt.set_upper_bounds(np.full(n, per_group))
    opt.add_inequality_constraint(dose_limit, 1e-6 * total_units)
    opt.set_min_objective(objective)
    opt.set_maxeval(max_evaluations)
    opt.set_xtol_abs(0.5)  # half a unit: finer splits are not injectable anyway
    opt.set_initial_step(np.full(n, 0.25 * per_group))
    x0 = np.full(n, total_units / n)
    t0 = time.perf_counter()
    x = opt.optimize(x0)
    elapsed = time.perf_counter() - t0
    # COBYLA may end a hair outside the dose limit; scale back onto it.
    if np.sum(x) > total_units:
        x = x * (total_units / np.sum(x))
    x = np.floor(np.maximum(x, 0.0) * 10.0) / 10.0  # whole tenths of a unit, never above
    best = plan_for(x)
    after = best.apply(params)
    dist = distance(after)
    even = distance(plan_for(x0).apply(params))
    untreated = distance(params)
    if even < dist:  # never report worse than the starting point
        best, after, dist, x = plan_for(x0), plan_for(x0).apply(params), even, x0
    return DoseSplitResult(
        units={g: round(float(u), 1) for g, u in zip(gs, x, strict=True)},
        plan=best, after=after, distance_n=dist, distance_untreated_n=untreated,
        distance_even_split_n=even, total_units_limit=float(total_units),
        weeks_since=float(weeks_since), evaluations=evals, elapsed_s=elapsed,
        algorithm="nlopt LN_COBYLA, start at the even split",
    )
