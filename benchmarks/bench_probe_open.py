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
classifier states them (:data:`fieldbank.evaluate.opencalibration.CALIBRATED`, fitted on other arms:
``benchmarks/tune_open_calibration.py``); and per group (each group's impaired yes/no at the
stated probability). Beside it, unless ``--no-baseline``, the joint-group classifier of
``fieldbank probe classify`` with the twelve severity candidates and the unimpaired arm on the
same trials, and the CPU time per trial.

Run: python benchmarks/bench_probe_open.py [--arms 10] [--draws 3] [--noise 2 4] [--jobs 2]
     [--seed 31] [--no-baseline] [--save outcomes.json | --load outcomes.json ...]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.timing import load_line
from fieldbank.evaluate.design import NoiseModel
from fieldbank.evaluate.opencalibration import CALIBRATED, RAW, Calibration
from fieldbank.evaluate.reliability import (
    FAMILIES,
    Outcome,
    ReliabilityBin,
    calibration_error,
    ece_noise_floor,
    family_arms,
    reliability_bins,
    run_trials,
    stated_claims,
)


def job(args: tuple[str, int, int, float, int, int, int, bool]
        ) -> tuple[str, float, list[Outcome], float]:
    family, n, draws, sd, seed, part, parts, baseline = args
    arms = family_arms(family, n, seed)[part::parts]
    c0 = time.process_time()
    out = run_trials(arms, NoiseModel(force_sd_n=sd), draws=draws, seed=seed + part,
                     baseline=baseline, calibration=RAW)
    return family, sd, out, time.process_time() - c0


def _cells(bins: Sequence[ReliabilityBin]) -> str:
    return "; ".join(f"[{b.low:.2f}, {b.high:.2f}{']' if b.high == 1 else ')'} "
                     f"{b.n}, {b.stated:.3f}, {b.observed:.3f}" for b in bins if b.n)


def _ece(stated: Sequence[float], right: Sequence[bool]) -> str:
    """ECE (points) with the noise floor of a calibrated classifier on the same stated
    probabilities (mean, 95th percentile)."""
    bins = reliability_bins(stated, right)
    mean, p95 = ece_noise_floor(stated)
    return f"{100 * calibration_error(bins):.1f} ({100 * mean:.1f}, {100 * p95:.1f})"


def _sure(stated: Sequence[float], right: Sequence[bool]) -> str:
    wrong = sum(not r for p, r in zip(stated, right, strict=True) if p >= 0.95)
    sure = sum(p >= 0.95 for p in stated)
    return f"{wrong}/{sure} ({100 * wrong / max(sure, 1):.1f}%)"


def table(results: dict[tuple[str, float], list[Outcome]], sd: float, cal: Calibration,
          baseline: bool) -> None:
    print("What is stated - per group, or partner groups as a set "
          "(fieldbank.evaluate.statements):\n")
    print("| family | trials | statements (sets of partners) | ECE (floor: mean, 95th pct) | "
          "wrong at p ≥ 0.95 | stated p: n, stated, right per bin |")
    print("|---|---:|---:|---:|---:|---|")
    for family in FAMILIES:
        claims = [(st, r) for _o, st, r in stated_claims(results.get((family, sd), []), cal)
                  if st.groups]
        ps, rs = [st.probability for st, _r in claims], [r for _st, r in claims]
        pairs = sum(st.kind == "partners" for st, _r in claims)
        print(f"| {family} | {len(results.get((family, sd), []))} | {len(claims)} ({pairs}) | "
              f"{_ece(ps, rs)} | {_sure(ps, rs)} | {_cells(reliability_bins(ps, rs))} |")
    print("\n\"None of the candidates explains this recording\" (stated when its "
          "probability is above one half; right for an arm outside the candidates):\n")
    print("| family | trials | said none | of which right | its p: n, stated, right per bin |")
    print("|---|---:|---:|---:|---|")
    for family in FAMILIES:
        none = [(st, r) for _o, st, r in stated_claims(results.get((family, sd), []), cal)
                if not st.groups]
        bins = reliability_bins([st.probability for st, _r in none], [r for _st, r in none])
        print(f"| {family} | {len(results.get((family, sd), []))} | {len(none)} | "
              f"{sum(r for _st, r in none)} | {_cells(bins)} |")
    print("\nThe most probable set of impaired groups (the joint answer, for comparison):\n")
    print("| family | trials | right | ECE (floor: mean, 95th pct) | wrong at p ≥ 0.95 | "
          "stated p: n, stated, right per bin |"
          + (" baseline: right, ECE, wrong at p ≥ 0.95 |" if baseline else ""))
    print("|---|---:|---:|---:|---:|---|" + ("---|" if baseline else ""))
    for family in FAMILIES:
        out = [o.restated(cal) for o in results.get((family, sd), [])]
        if not out:
            continue
        ps, rs = [o.probability for o in out], [o.right for o in out]
        line = (f"| {family} | {len(out)} | {100 * np.mean(rs):.0f}% | {_ece(ps, rs)} | "
                f"{_sure(ps, rs)} | {_cells(reliability_bins(ps, rs))} |")
        if baseline:
            base = reliability_bins([o.baseline_probability for o in out],
                                    [o.baseline_right for o in out])
            bw = sum(not o.baseline_right for o in out if o.baseline_probability >= 0.95)
            bs = sum(o.baseline_probability >= 0.95 for o in out)
            line += (f" {100 * np.mean([o.baseline_right for o in out]):.0f}%, "
                     f"{100 * calibration_error(base):.1f}, {bw}/{bs} |")
        print(line)
    misses = [(o, st) for f in FAMILIES for o, st, r in stated_claims(results.get((f, sd), []), cal)
              if not r and st.probability >= 0.95]
    if misses:
        print("\nstatements wrong at p ≥ 0.95:")
        for o, st in misses:
            print(f"  {o.family}: {o.arm} (truth {o.truth}; fit p {o.fit_p_value:.2g}) - "
                  f"{st.text} at p = {st.probability:.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arms", type=int, default=10, help="arms per family")
    ap.add_argument("--draws", type=int, default=3, help="sensor-noise draws per execution")
    ap.add_argument("--noise", type=float, nargs="+", default=[2.0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--parts", type=int, default=2,
                    help="split each family's arms into this many jobs")
    ap.add_argument("--seed", type=int, default=31)
    ap.add_argument("--no-baseline", action="store_true",
                    help="leave out the joint-group classifier")
    ap.add_argument("--save", type=Path, help="write the trials' outcomes here (JSON)")
    ap.add_argument("--load", type=Path, nargs="+",
                    help="print the tables of outcomes saved before (several files: their "
                         "trials together, e.g. the runs of several seeds)")
    ap.add_argument("--calibration", type=float, nargs="+",
                    metavar="NUMBER",
                    help="state with this calibration instead of the classifier's own "
                         "(power, misfit slope, unseen share, share for none, misfit level; "
                         "then, optionally, the evidence over which the unseen share falls "
                         "and the reflex score it is read at; then, optionally, the prior "
                         "probability of no group and of two groups impaired; then, "
                         "optionally, the weight of an arm outside the set in what is stated "
                         "per group, a group's probability of an impairment there, and that "
                         "of a group the set does not name where the residual is far off)")
    args = ap.parse_args()
    baseline = not args.no_baseline
    results: dict[tuple[str, float], list[Outcome]] = {}
    if args.load is not None:
        for path in args.load:
            for row in json.loads(path.read_text()):
                o = Outcome.from_record(row)
                results.setdefault((o.family, float(row["noise_n"])), []).append(o)
        noise = sorted({sd for _f, sd in results})
        baseline = all(o.baseline_answer for v in results.values() for o in v)
        print(f"bench_probe_open: {sum(len(v) for v in results.values())} trials from "
              f"{', '.join(p.name for p in args.load)}; {load_line()}")
    else:
        noise = args.noise
        # part by part over every family, the outcomes saved as each part ends: a run stopped
        # early still holds every family
        jobs = [(f, args.arms, args.draws, sd, args.seed, part, args.parts, baseline)
                for sd in noise for part in range(args.parts) for f in FAMILIES]
        t0 = time.perf_counter()
        cpu = 0.0
        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            for done in as_completed([pool.submit(job, j) for j in jobs]):
                family, sd, out, c = done.result()
                results.setdefault((family, sd), []).extend(out)
                cpu += c
                if args.save is not None:
                    args.save.write_text(json.dumps(
                        [{**dataclasses.asdict(o), "noise_n": sd}
                         for (_f, sd), v in results.items() for o in v]))
        wall = time.perf_counter() - t0
        n_trials = sum(len(v) for v in results.values())
        print(f"bench_probe_open: {len(FAMILIES)} families × {args.arms} arms × {args.draws} "
              f"noise draws × {len(noise)} noise level(s) = {n_trials} trials; {wall:.0f} s "
              f"wall, {cpu:.0f} s CPU ({cpu / n_trials:.2f} s a trial) on {args.jobs} "
              f"processes; {load_line()}")
    if args.calibration is not None and len(args.calibration) not in (5, 7, 9, 12):
        ap.error("--calibration takes five numbers, seven, nine or twelve")
    stated = CALIBRATED if args.calibration is None else Calibration(
        *(args.calibration[k] for k in (0, 3, 4, 1, 2)), *args.calibration[5:])
    for sd in noise:
        for what, cal in (("raw: the posterior as the likelihood and prior give it", RAW),
                          (f"stated: calibrated (power {stated.power:g}, misfit slope "
                           f"{stated.misfit_slope:g}, unseen {stated.unseen:g} over evidence "
                           f"{stated.unseen_evidence:g} at score {stated.unseen_score:g}, other "
                           f"{stated.other:g}, misfit level {stated.misfit_level:g}, prior of "
                           f"no group {stated.prior_none:.3g} and of two {stated.prior_two:.3g}, "
                           f"outside the set counted per group with weight "
                           f"{stated.outside_weight:g}, a group then impaired at "
                           f"{stated.outside_group:g}, far off {stated.outside_far:g} beside "
                           "what the set says)",
                           stated)):
            print(f"\n### force noise {sd:g} N per axis (τ 50 ms) - {what}\n")
            table(results, sd, cal, baseline)


if __name__ == "__main__":
    main()
