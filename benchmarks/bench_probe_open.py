"""Benchmark: are the open-set classifier's probabilities right, family by family?

Seeded arm families the tests do not use (:mod:`fieldbank.evaluate.reliability`: between
severities, two groups, reflex only, contracture only, outside the candidates; every arm a body
of its own), each probed with the clinic's fast stretch of every group
(:func:`fieldbank.evaluate.design.coverage.stretch_set`) performed with the operator's scatter,
the true arm's force replayed through the virtual coupling, sensor noise drawn, and classified
among every state of the groups of its body (:mod:`fieldbank.evaluate.openset`). Per family
and noise level: the stated probability of the answer against how often it was right, per bin,
the expected calibration error (points) and the wrong answers given with p ≥ 0.95 (targets:
ECE ≤ 5 points, wrong at p ≥ 0.95 ≤ 2 %). Beside it the baseline - the joint-group classifier
of ``fieldbank probe classify`` with the twelve severity candidates and the unimpaired arm on
the same trials - and the CPU time per trial of both.

Run: python benchmarks/bench_probe_open.py [--arms 10] [--draws 3] [--noise 2 4] [--jobs 2]
     [--seed 31]
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
from fieldbank.evaluate.reliability import (
    FAMILIES,
    Outcome,
    calibration_error,
    family_arms,
    reliability_bins,
    run_trials,
    wrong_when_sure,
)


def job(args: tuple[str, int, int, float, int, int]) -> tuple[str, float, list[Outcome], float]:
    family, n, draws, sd, seed, part = args
    arms = family_arms(family, n, seed)[part::2]
    c0 = time.process_time()
    out = run_trials(arms, NoiseModel(force_sd_n=sd), draws=draws, seed=seed + part,
                     baseline=True)
    return family, sd, out, time.process_time() - c0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arms", type=int, default=10, help="arms per family")
    ap.add_argument("--draws", type=int, default=3, help="sensor-noise draws per execution")
    ap.add_argument("--noise", type=float, nargs="+", default=[2.0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--seed", type=int, default=31)
    args = ap.parse_args()
    jobs = [(f, args.arms, args.draws, sd, args.seed, part) for sd in args.noise
            for f in FAMILIES for part in (0, 1)]
    t0 = time.perf_counter()
    results: dict[tuple[str, float], list[Outcome]] = {}
    cpu = 0.0
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for family, sd, out, c in pool.map(job, jobs):
            results.setdefault((family, sd), []).extend(out)
            cpu += c
    wall = time.perf_counter() - t0
    n_trials = sum(len(v) for v in results.values())
    print(f"bench_probe_open: {len(FAMILIES)} families × {args.arms} arms × {args.draws} noise "
          f"draws × {len(args.noise)} noise level(s) = {n_trials} trials; {wall:.0f} s wall, "
          f"{cpu:.0f} s CPU ({cpu / n_trials:.2f} s a trial) on {args.jobs} processes; "
          f"{load_line()}")
    for sd in args.noise:
        print(f"\n### force noise {sd:g} N per axis (τ 50 ms)\n")
        print("| family | trials | right | ECE (points) | wrong at p ≥ 0.95 | said none | "
              "stated p: n, stated, right per bin | baseline: right, ECE, wrong at p ≥ 0.95 |")
        print("|---|---:|---:|---:|---:|---:|---|---|")
        for family in FAMILIES:
            out = results[(family, sd)]
            bins = reliability_bins([o.probability for o in out], [o.right for o in out])
            wrong, sure = wrong_when_sure(out)
            cells = "; ".join(f"[{b.low:.2f}, {b.high:.2f}{']' if b.high == 1 else ')'} "
                              f"{b.n}, {b.stated:.2f}, {b.observed:.2f}" for b in bins if b.n)
            base = reliability_bins([o.baseline_probability for o in out],
                                    [o.baseline_right for o in out])
            bw = sum(not o.baseline_right for o in out if o.baseline_probability >= 0.95)
            bs = sum(o.baseline_probability >= 0.95 for o in out)
            print(f"| {family} | {len(out)} | {100 * np.mean([o.right for o in out]):.0f}% | "
                  f"{100 * calibration_error(bins):.1f} | {wrong}/{sure} "
                  f"({100 * wrong / max(sure, 1):.0f}%) | "
                  f"{sum(o.answer == 'none of the candidates' for o in out)} | {cells} | "
                  f"{100 * np.mean([o.baseline_right for o in out]):.0f}%, "
                  f"{100 * calibration_error(base):.1f}, {bw}/{bs} |")
        misses = [o for f in FAMILIES for o in results[(f, sd)] if not o.right
                  and o.probability >= 0.95]
        if misses:
            print("\nwrong at p ≥ 0.95:")
            for o in misses:
                print(f"  {o.family}: {o.arm} (truth {o.truth}) answered {o.answer} at "
                      f"p = {o.probability:.3f}")


if __name__ == "__main__":
    main()
