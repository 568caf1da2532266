"""Speed of the what-if module against its targets (issue: what-if).

* all before/after metrics for one plan (``fieldbank.evaluate.compare``, both arms compiled):
  target ≤ 50 ms;
* a 24-week botulinum time course (weeks 0..24, 25 evaluations): target ≤ 0.5 s;
* the fit's uncertainty carried through the plan: the headline metrics before and after for
  each of 40 parameter samples (:func:`fieldbank.interventions.guesses.prediction_intervals`;
  no target, printed against one compare).

Baseline in the same process: one plain model field evaluation on the same grid
(``Arm.field`` at every standard condition), the floor any metric must pay.

Run: python benchmarks/bench_whatif.py
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from benchmarks.timing import timeit
from fieldbank.evaluate import ArmCache
from fieldbank.evaluate.compare import Conditions, compare
from fieldbank.evaluate.severity import synthesize
from fieldbank.fitting.prior import full_ranges
from fieldbank.fitting.uncertainty import FitSamples
from fieldbank.interventions.catalogue import Botulinum, Lengthening
from fieldbank.interventions.course import time_course
from fieldbank.interventions.guesses import FitBasis, prediction_intervals
from fieldbank.interventions.inverse import optimise_botulinum
from fieldbank.interventions.plan import Plan
from fieldbank.model import Arm
from fieldbank.params import GROUPS, ArmParams


def main() -> None:
    before = synthesize({"elbow": "severe", "shoulder": "mild"})
    plan = Plan.of(Lengthening(group="bf", delta_m=0.01), Botulinum({"ef": 200.0, "ee": 100.0}))
    after = plan.apply(before)
    arm, arm_after = Arm.from_params(before), Arm.from_params(after)
    cond = Conditions.standard(arm)

    def fields_only() -> None:
        for k in range(len(cond.velocities)):
            x, v = cond.points(k)
            arm.field(x, v)

    base, _ = timeit(fields_only, 50)
    one, one_max = timeit(lambda: compare(arm, arm_after), 30)
    course, course_max = timeit(lambda: time_course(arm, plan), 5)
    inv, _ = timeit(lambda: optimise_botulinum(arm, 300.0, groups=("ef", "ee", "sf")), 3)
    n = cond.grid_m.shape[0]
    pts = sum(v.shape[0] for v in cond.velocities) * n
    print(f"standard conditions: {n} grid points, {pts} field evaluations per model")
    print(f"baseline  one model's fields (Arm.field)      {base * 1e3:8.2f} ms")
    print(f"compare   all before/after metrics, one plan  {one * 1e3:8.2f} ms median, "
          f"{one_max * 1e3:.2f} ms max  (target <= 50 ms; {one / base:.1f}x baseline)  "
          f"{'OK' if one <= 0.050 else 'OVER'}")
    print(f"course    24-week time course (25 weeks)      {course:8.3f} s  median, "
          f"{course_max:.3f} s max  (target <= 0.5 s; {course / one:.1f}x one compare)  "
          f"{'OK' if course <= 0.5 else 'OVER'}")
    print(f"inverse   3-group dose split (COBYLA)         {inv:8.3f} s  median (no target)")
    basis = _basis(before, 40)
    ivs, _ = timeit(lambda: prediction_intervals(basis, arm, plan, cond, ArmCache()), 3)
    print(f"intervals 40 fit samples through the plan     {ivs:8.3f} s  median (no target; "
          f"{ivs / one:.1f}x one compare)")
    # a fit that held the reflexes of four groups: drawn from their prior range, and the same
    # samples with the held values kept, in one pass (twice the sets) plus the prior's table
    held = dataclasses.replace(basis, ranges=full_ranges(
        [f"{k}_{g}" for g in ("sf", "se", "bf", "be") for k in ("alpha", "beta")]))
    ivg, _ = timeit(lambda: prediction_intervals(held, arm, plan, cond, ArmCache()), 3)
    print(f"intervals with 4 held reflexes drawn          {ivg:8.3f} s  median (no target; "
          f"{ivg / ivs:.1f}x the intervals without)")


def _basis(before: ArmParams, n: int) -> FitBasis:
    """A fit basis with ``n`` samples: Km, α, β of every group 5% log-normal about ``before``."""
    rng = np.random.default_rng(0)
    names = [f"{k}_{g}" for k in ("km", "alpha", "beta") for g in GROUPS]
    centre = np.array([*before.km_n_per_m, *before.alpha_n, *before.beta])
    values = centre * np.exp(rng.normal(scale=0.05, size=(n, centre.size)))
    values[:, 12:] = np.minimum(values[:, 12:], 1.0)
    return FitBasis(1, 1, True, "good", "good", (), (), (),
                    FitSamples(tuple(names), values))


if __name__ == "__main__":
    main()
