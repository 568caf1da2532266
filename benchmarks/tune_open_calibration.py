"""Fit the open-set classifier's calibration on arms of its own, never the benchmark's.

The posterior over the sets of impaired groups rests on a grid of states and on a model of
the misfit that leaves it over-confident on arms between the grid's states, with a partner
group compensating, or outside the set, and under-confident on others.
:func:`fieldbank.evaluate.reliability.fit_calibration` chooses the calibration that meets the
targets (ECE ≤ 5 points, wrong at p ≥ 0.95 ≤ 2 %) in every tuning family, or misses them by
least, and among those the best by a proper score (the mean log probability stated for the
truth):

* the case mix's prior on how many groups are impaired, the power of the posterior, how fast
  it falls with the best arm's misfit, and each group's share of an impairment the recording
  does not show - falling with how well the strokes see that group's reflex -, by what is
  stated per group (each group impaired or not);
* then the share set aside for "none of the candidates", the misfit level, and how far what
  is stated per group counts it, by the same targets and the score of both.

Tuning arms: every family (between severities, two groups, reflex only, contracture only,
outside the candidates) at seeds other than the benchmark's seed 31 - other bodies and arms
(``benchmarks/bench_probe_open.py``). ``--hold-out "reflex only" "contracture only"`` leaves
families out of the fit, so that the benchmark measures the calibration on families it never
saw. ``--load`` fits on trials saved by ``bench_probe_open.py --seed S --save`` (one file or
several). :data:`fieldbank.evaluate.opencalibration.CALIBRATED` was fitted on
``--load tune7.json tune8.json tune9.json tune10.json tune11.json``: ``bench_probe_open.py
--arms 12 --draws 3 --parts 4 --seed 7`` and ``--arms 24 --draws 2 --parts 4`` at seeds 8 to
11, each with ``--no-baseline --jobs 2 --save``.

Run: python benchmarks/tune_open_calibration.py [--arms 10] [--draws 3] [--seed 7] [--jobs 2]
     [--hold-out FAMILY ...] [--load outcomes.json ...]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.timing import load_line
from fieldbank.evaluate.design import NoiseModel
from fieldbank.evaluate.opencalibration import RAW
from fieldbank.evaluate.reliability import (
    FAMILIES,
    Outcome,
    calibration_error,
    family_arms,
    fit_calibration,
    reliability_bins,
    run_trials,
    stated_claims,
)


def job(args: tuple[str, int, int, int, int]) -> list[Outcome]:
    family, n, draws, seed, part = args
    return run_trials(family_arms(family, n, seed)[part::2], NoiseModel(force_sd_n=2.0),
                      draws=draws, seed=seed + part, calibration=RAW)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arms", type=int, default=10, help="arms per family")
    ap.add_argument("--draws", type=int, default=3)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--hold-out", nargs="*", default=[], choices=FAMILIES, metavar="FAMILY",
                    help="families left out of the fit")
    ap.add_argument("--load", type=Path, nargs="+",
                    help="fit on trials saved before (bench_probe_open --save, at seeds other "
                         "than the benchmark's)")
    args = ap.parse_args()
    tuned = tuple(f for f in FAMILIES if f not in args.hold_out)
    t0 = time.perf_counter()
    out: list[Outcome] = []
    if args.load is not None:
        for path in args.load:
            out.extend(Outcome.from_record(row) for row in json.loads(path.read_text()))
        out = [o for o in out if o.family in tuned]
        source = ", ".join(p.name for p in args.load)
    else:
        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            for o in pool.map(job, [(f, args.arms, args.draws, args.seed, part)
                                    for f in tuned for part in (0, 1)]):
                out.extend(o)
        source = f"seed {args.seed}"
    cal, score = fit_calibration(out)
    print(f"tune_open_calibration: {len(out)} trials ({', '.join(tuned)}; {source}), "
          f"{time.perf_counter() - t0:.0f} s wall; {load_line()}")
    print(f"fitted: power {cal.power:g}, misfit slope {cal.misfit_slope:g}, unseen "
          f"{cal.unseen:g} falling over an evidence of {cal.unseen_evidence:g} of the reflex "
          f"at score {cal.unseen_score:g}, other "
          f"{cal.other:g}, misfit level {cal.misfit_level:g}, prior of no group "
          f"{cal.prior_none:.3g} and of two {cal.prior_two:.3g}, outside the set counted "
          f"with weight {cal.outside_weight:g} and a group then impaired at "
          f"{cal.outside_group:g} (far off: {cal.outside_far:g} beside what the set says); "
          f"mean log probability stated "
          f"for a group's truth {score:.4f}")
    for family in tuned:
        for name, c in (("raw", RAW), ("fitted", cal)):
            claims = [(st, r) for o, st, r in stated_claims(out, c)
                      if o.family == family and st.groups]
            bins = reliability_bins([st.probability for st, _r in claims],
                                    [r for _st, r in claims])
            sure = [r for st, r in claims if st.probability >= 0.95]
            print(f"  {family:<24} {name:<7} statements {len(claims):4d}  right "
                  f"{100 * np.mean([r for _st, r in claims]):3.0f}%  ECE "
                  f"{100 * calibration_error(bins):5.1f}  wrong at p ≥ 0.95 "
                  f"{sum(not r for r in sure)}/{len(sure)}")


if __name__ == "__main__":
    main()
