"""Fit the open-set classifier's calibration on arms of its own, never the benchmark's.

The posterior over the sets of impaired groups rests on a grid of states and on a model of
the misfit that leaves it over-confident on arms between the grid's states or with a partner
group compensating, and on arms the set does not hold. :func:`fieldbank.evaluate.reliability.
fit_calibration` chooses the power of the posterior and the share set aside for "none of the
candidates" under which the truth is most probable (a proper score) over the tuning arms:

* families **between severities**, **two groups** and **outside the candidates**, seed 7 (the
  benchmark, ``benchmarks/bench_probe_open.py``, uses seed 31: other bodies, other arms);
* families **reflex only** and **contracture only** are held out altogether: the benchmark
  measures the calibration on them as on families it never saw.

The result is :data:`fieldbank.evaluate.openset.CALIBRATED`.

Run: python benchmarks/tune_open_calibration.py [--arms 8] [--draws 3] [--seed 7] [--jobs 2]
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.timing import load_line
from fieldbank.evaluate.design import NoiseModel
from fieldbank.evaluate.openset import RAW
from fieldbank.evaluate.reliability import (
    Outcome,
    calibration_error,
    family_arms,
    fit_calibration,
    reliability_bins,
    run_trials,
)

TUNING_FAMILIES = ("between severities", "two groups", "outside the candidates")


def job(args: tuple[str, int, int, int, int]) -> list[Outcome]:
    family, n, draws, seed, part = args
    return run_trials(family_arms(family, n, seed)[part::2], NoiseModel(force_sd_n=2.0),
                      draws=draws, seed=seed + part, calibration=RAW)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arms", type=int, default=8, help="arms per family")
    ap.add_argument("--draws", type=int, default=3)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    t0 = time.perf_counter()
    out: list[Outcome] = []
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for o in pool.map(job, [(f, args.arms, args.draws, args.seed, part)
                                for f in TUNING_FAMILIES for part in (0, 1)]):
            out.extend(o)
    cal, score = fit_calibration(out)
    print(f"tune_open_calibration: {len(out)} trials ({', '.join(TUNING_FAMILIES)}; seed "
          f"{args.seed}), {time.perf_counter() - t0:.0f} s wall; {load_line()}")
    raw = float(np.mean([np.log(max(o.truth_probability(RAW), 1e-6)) for o in out]))
    print(f"fitted: power {cal.power:g}, other {cal.other:g}; mean log probability of the "
          f"truth {score:.3f} (raw {raw:.3f})")
    for family in TUNING_FAMILIES:
        for name, c in (("raw", RAW), ("fitted", cal)):
            got = [o.restated(c) for o in out if o.family == family]
            bins = reliability_bins([o.probability for o in got], [o.right for o in got])
            print(f"  {family:<24} {name:<7} right {100 * np.mean([o.right for o in got]):3.0f}%"
                  f"  ECE {100 * calibration_error(bins):5.1f}  wrong at p ≥ 0.95 "
                  f"{sum(not o.right for o in got if o.probability >= 0.95)}/"
                  f"{sum(o.probability >= 0.95 for o in got)}")


if __name__ == "__main__":
    main()
