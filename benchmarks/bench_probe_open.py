"""Benchmark: are the open-set classifier's probabilities right, family by family?

Seeded arm families the tests do not use (:mod:`fieldbank.evaluate.reliability`: between
severities, two groups, reflex only, contracture only, outside the candidates; every arm a body
of its own), each probed with the clinic's fast stretch of every group
(:func:`fieldbank.evaluate.design.coverage.stretch_set`) performed with the operator's scatter,
the true arm's force replayed through the virtual coupling, sensor noise drawn, and classified
among every state of the groups of its body (:mod:`fieldbank.evaluate.openset`). Per family
and noise level: the stated probability of the answer against how often it was right, per bin,
the expected calibration error (points) and the wrong answers given with p ≥ 0.95 (targets:
ECE ≤ 5 points, wrong at p ≥ 0.95 ≤ 2 %) - as the posterior gives them (raw) and as the
classifier states them (:data:`fieldbank.evaluate.openset.CALIBRATED`, fitted on other arms:
``benchmarks/tune_open_calibration.py``); and per group (each group's impaired yes/no at the
stated probability). Beside it, unless ``--no-baseline``, the joint-group classifier of
``fieldbank probe classify`` with the twelve severity candidates and the unimpaired arm on the
same trials, and the CPU time per trial.

Run: python benchmarks/bench_probe_open.py [--arms 10] [--draws 3] [--noise 2 4] [--jobs 2]
     [--seed 31] [--no-baseline] [--save outcomes.json | --load outcomes.json]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.timing import load_line
from fieldbank.evaluate.design import NoiseModel
from fieldbank.evaluate.openset import CALIBRATED, RAW, Calibration
from fieldbank.evaluate.reliability import (
    FAMILIES,
    Outcome,
    calibration_error,
    family_arms,
    reliability_bins,
    run_trials,
    wrong_when_sure,
)
from fieldbank.params import GROUPS


def job(args: tuple[str, int, int, float, int, int, bool]
        ) -> tuple[str, float, list[Outcome], float]:
    family, n, draws, sd, seed, part, baseline = args
    arms = family_arms(family, n, seed)[part::2]
    c0 = time.process_time()
    out = run_trials(arms, NoiseModel(force_sd_n=sd), draws=draws, seed=seed + part,
                     baseline=baseline, calibration=RAW)
    return family, sd, out, time.process_time() - c0


def per_group(out: Sequence[Outcome], cal: Calibration) -> tuple[list[float], list[bool]]:
    """Every group of every trial: the stated probability of the group's verdict (impaired
    when its probability is at least one half) and whether the verdict is the truth's."""
    stated, right = [], []
    for o in out:
        gp = o.classification(cal).group_probability
        truth = set(o.truth.split("+"))
        for g in GROUPS:
            p = gp[g]
            stated.append(max(p, 1.0 - p))
            right.append((p >= 0.5) == (g in truth))
    return stated, right


def table(results: dict[tuple[str, float], list[Outcome]], sd: float, cal: Calibration,
          baseline: bool) -> None:
    print("| family | trials | right | ECE (points) | wrong at p ≥ 0.95 | said none | "
          "per group: ECE, wrong at p ≥ 0.95 | stated p: n, stated, right per bin |"
          + (" baseline: right, ECE, wrong at p ≥ 0.95 |" if baseline else ""))
    print("|---|---:|---:|---:|---:|---:|---|---|" + ("---|" if baseline else ""))
    for family in FAMILIES:
        raw = results[(family, sd)]
        out = [o.restated(cal) for o in raw]
        bins = reliability_bins([o.probability for o in out], [o.right for o in out])
        wrong, sure = wrong_when_sure(out)
        cells = "; ".join(f"[{b.low:.2f}, {b.high:.2f}{']' if b.high == 1 else ')'} "
                          f"{b.n}, {b.stated:.2f}, {b.observed:.2f}" for b in bins if b.n)
        gs, gr = per_group(raw, cal)
        gbins = reliability_bins(gs, gr)
        gw = sum(not r for s, r in zip(gs, gr, strict=True) if s >= 0.95)
        gn = sum(s >= 0.95 for s in gs)
        line = (f"| {family} | {len(out)} | {100 * np.mean([o.right for o in out]):.0f}% | "
                f"{100 * calibration_error(bins):.1f} | {wrong}/{sure} "
                f"({100 * wrong / max(sure, 1):.0f}%) | "
                f"{sum(o.answer == 'none of the candidates' for o in out)} | "
                f"{100 * calibration_error(gbins):.1f}, {gw}/{gn} "
                f"({100 * gw / max(gn, 1):.1f}%) | {cells} |")
        if baseline:
            base = reliability_bins([o.baseline_probability for o in out],
                                    [o.baseline_right for o in out])
            bw = sum(not o.baseline_right for o in out if o.baseline_probability >= 0.95)
            bs = sum(o.baseline_probability >= 0.95 for o in out)
            line += (f" {100 * np.mean([o.baseline_right for o in out]):.0f}%, "
                     f"{100 * calibration_error(base):.1f}, {bw}/{bs} |")
        print(line)
    misses = [o.restated(cal) for f in FAMILIES for o in results[(f, sd)]]
    misses = [o for o in misses if not o.right and o.probability >= 0.95]
    if misses:
        print("\nwrong at p ≥ 0.95:")
        for o in misses:
            print(f"  {o.family}: {o.arm} (truth {o.truth}) answered {o.answer} at "
                  f"p = {o.probability:.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arms", type=int, default=10, help="arms per family")
    ap.add_argument("--draws", type=int, default=3, help="sensor-noise draws per execution")
    ap.add_argument("--noise", type=float, nargs="+", default=[2.0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--seed", type=int, default=31)
    ap.add_argument("--no-baseline", action="store_true",
                    help="leave out the joint-group classifier")
    ap.add_argument("--save", type=Path, help="write the trials' outcomes here (JSON)")
    ap.add_argument("--load", type=Path, help="print the tables of outcomes saved before")
    args = ap.parse_args()
    baseline = not args.no_baseline
    results: dict[tuple[str, float], list[Outcome]] = {}
    if args.load is not None:
        for row in json.loads(args.load.read_text()):
            sd = float(row.pop("noise_n"))
            o = Outcome(**{**row, "labels": tuple(row["labels"]),
                           "label_probability": tuple(row["label_probability"])})
            results.setdefault((o.family, sd), []).append(o)
        noise = sorted({sd for _f, sd in results})
        baseline = all(o.baseline_answer for v in results.values() for o in v)
        print(f"bench_probe_open: {sum(len(v) for v in results.values())} trials from "
              f"{args.load.name}; {load_line()}")
    else:
        noise = args.noise
        jobs = [(f, args.arms, args.draws, sd, args.seed, part, baseline) for sd in noise
                for f in FAMILIES for part in (0, 1)]
        t0 = time.perf_counter()
        cpu = 0.0
        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            for family, sd, out, c in pool.map(job, jobs):
                results.setdefault((family, sd), []).extend(out)
                cpu += c
        wall = time.perf_counter() - t0
        n_trials = sum(len(v) for v in results.values())
        print(f"bench_probe_open: {len(FAMILIES)} families × {args.arms} arms × {args.draws} "
              f"noise draws × {len(noise)} noise level(s) = {n_trials} trials; {wall:.0f} s "
              f"wall, {cpu:.0f} s CPU ({cpu / n_trials:.2f} s a trial) on {args.jobs} "
              f"processes; {load_line()}")
        if args.save is not None:
            args.save.write_text(json.dumps(
                [{**dataclasses.asdict(o), "noise_n": sd} for (_f, sd), v in results.items()
                 for o in v]))
    for sd in noise:
        for what, cal in (("raw: the posterior as the likelihood and prior give it", RAW),
                          (f"stated: calibrated (power {CALIBRATED.power:g}, other "
                           f"{CALIBRATED.other:g})", CALIBRATED)):
            print(f"\n### force noise {sd:g} N per axis (τ 50 ms) - {what}\n")
            table(results, sd, cal, baseline)


if __name__ == "__main__":
    main()
