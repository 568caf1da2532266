"""Benchmark: does the fit recover a contracture? The slack length over a seeded cohort.

Every muscle group in turn is given a contracture - its slack length shorter by 5 to 20 mm
(drawn uniform, the brief's range: optimal fibre length 0.80-0.95 of a 10 cm fibre) - alone,
with its Km raised to the scale's moderate passive level, or with its stretch reflex raised to
the moderate dynamic level; each patient has a body of its own (55-95 kg, 1.55-1.90 m, right or
left arm), a postural map (25 positions) and stiffness maps (9 positions) static and moving at
±1 m/s, with 3 % or 8 % noise (each value's sd that fraction of the value's size, stored with
the map). Seeds and positions are the benchmark's own, apart from the tests'.

Each patient is fitted twice in this process: ``--fit km,alpha,beta`` (the baseline: what the
fit could do before it fitted the slack length) and ``--fit km,alpha,beta,slack``. Per group,
condition and noise the table prints the slack error (mean |fitted − true|, mm), how often the
95 % interval holds the truth, how often the slack is identified (not held), χ²/n of the fit
and of the baseline, how many fits are poor, and the severity grade of the group's passive
component; then the CPU time of a fit with and without the slack, as a ratio, with the load.

Run: python benchmarks/bench_contracture.py [--per-cell 2] [--noise 0.03 0.08] [--jobs 2]
     [--groups sf se ef ee bf be]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.timing import load_line
from fieldbank.evaluate.severity import synthesize
from fieldbank.fitting import ArmFitter
from fieldbank.fitting.synthetic import synthetic_patient
from fieldbank.params import GROUPS, ArmParams

#: The benchmark's own seed (bodies, contractures, positions, noise).
SEED = 32_017
CONDITIONS = ("alone", "with Km", "with reflex")
BASELINE = ("km", "alpha", "beta")
WITH_SLACK = ("km", "alpha", "beta", "slack")


def patient(group: str, condition: str, noise: float, k: int) -> tuple[ArmParams, ArmParams,
                                                                         float, int]:
    """(base, truth, slack m, seed) of the k-th patient of one cell."""
    cell = (GROUPS.index(group), CONDITIONS.index(condition), round(1000 * noise), k)
    rng = np.random.default_rng([SEED, *cell])
    base = ArmParams.from_anthropometry(float(rng.uniform(55.0, 95.0)),
                                        float(rng.uniform(1.55, 1.90)),
                                        "left" if rng.uniform() < 0.3 else "right")
    slack = -float(rng.uniform(0.005, 0.020))
    extra = {"alone": {}, "with Km": {f"{group}:passive": "moderate"},
             "with reflex": {f"{group}:dynamic": "moderate"}}[condition]
    truth = synthesize(extra, base).with_group(group, slack_offset_m=slack)
    return base, truth, slack, int(rng.integers(1 << 30))


def run(job: tuple[str, str, float, int]) -> dict[str, Any]:
    group, condition, noise, k = job
    base, truth, slack, seed = patient(group, condition, noise, k)
    maps = synthetic_patient(truth, seed=seed, n_postural=25, n_stiffness=9, noise=noise,
                             patient=f"CON-{group}-{k}").maps
    out: dict[str, Any] = {"group": group, "condition": condition, "noise": noise,
                           "slack": slack}
    for name, kinds in (("base", BASELINE), ("slack", WITH_SLACK)):
        c0 = time.process_time()
        f = ArmFitter(seed=0, fit=kinds).fit(maps, base)
        out[f"cpu_{name}"] = time.process_time() - c0
        out[f"chi2_{name}"] = f.goodness_.chi2_per_dof
        out[f"poor_{name}"] = f.status_ == "poor"
        out[f"passive_{name}"] = f.severity_[group]["passive"]["level"]
        if name == "slack":
            iv = f.intervals_[f"slack_{group}"]
            out["fitted"] = float(f.params_.slack_offset_m[GROUPS.index(group)])
            out["low"], out["high"] = float(iv["low"]), float(iv["high"])
            out["held"] = f"slack_{group}" in f.held_
            out["identified"] = f"slack_{group}" not in {u.name for u in f.unidentified_}
            # the other groups' slack lengths (truth 0): inside their intervals?
            others = [f.intervals_[f"slack_{h}"] for h in GROUPS if h != group]
            out["others_inside"] = sum(o["low"] <= 1e-12 and o["high"] >= -1e-12
                                       for o in others)
            out["others_err"] = float(np.mean([abs(o["value"]) for o in others]))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-cell", type=int, default=2,
                    help="patients per group, condition and noise level")
    ap.add_argument("--noise", type=float, nargs="+", default=[0.03, 0.08])
    ap.add_argument("--groups", nargs="+", default=list(GROUPS), choices=list(GROUPS))
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    jobs = [(g, c, nz, k) for nz in args.noise for g in args.groups for c in CONDITIONS
            for k in range(args.per_cell)]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        rows = list(pool.map(run, jobs))
    wall = time.perf_counter() - t0
    print(f"bench_contracture: {len(rows)} patients ({len(args.groups)} groups × "
          f"{len(CONDITIONS)} conditions × {len(args.noise)} noise levels × {args.per_cell}), "
          f"each fitted with and without the slack; {wall:.0f} s wall on {args.jobs} "
          f"processes; {load_line()}")
    print("\n| noise | group | with | n | slack true mm | error mm | 95% holds truth | "
          "identified | χ²/n with slack | χ²/n without | poor with / without | passive grade "
          "with / without |")
    print("|---|---|---|---:|---|---:|---:|---:|---:|---:|---|---|")
    cells: dict[tuple[float, str, str], list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        cells[(r["noise"], r["group"], r["condition"])].append(r)
    for (nz, g, c), rs in cells.items():
        err = np.mean([abs(r["fitted"] - r["slack"]) for r in rs]) * 1000
        inside = sum(r["low"] <= r["slack"] <= r["high"] for r in rs)
        ident = sum(r["identified"] for r in rs)
        truths = ", ".join(f"{1000 * r['slack']:.0f}" for r in rs)
        grades = "; ".join(f"{r['passive_slack']} / {r['passive_base']}" for r in rs)
        print(f"| {100 * nz:g}% | {g} | {c} | {len(rs)} | {truths} | {err:.2f} | "
              f"{inside}/{len(rs)} | {ident}/{len(rs)} | "
              f"{np.median([r['chi2_slack'] for r in rs]):.2f} | "
              f"{np.median([r['chi2_base'] for r in rs]):.1f} | "
              f"{sum(r['poor_slack'] for r in rs)} / {sum(r['poor_base'] for r in rs)} | "
              f"{grades} |")
    for nz in args.noise:
        sub = [r for r in rows if r["noise"] == nz]
        inside = sum(r["low"] <= r["slack"] <= r["high"] for r in sub)
        err = [1000 * abs(r["fitted"] - r["slack"]) for r in sub]
        poor = sum(r["poor_slack"] for r in sub)
        poor0 = sum(r["poor_base"] for r in sub)
        print(f"\nnoise {100 * nz:g}%: slack error {np.mean(err):.2f} mm mean, "
              f"{np.max(err):.2f} mm worst; "
              f"95% interval holds the truth in {inside}/{len(sub)}; identified in "
              f"{sum(r['identified'] for r in sub)}/{len(sub)}; poor fits {poor}"
              f"/{len(sub)} with the slack, {poor0}/{len(sub)} without; "
              f"the other groups' slack (truth 0) inside its interval "
              f"{sum(r['others_inside'] for r in sub)}/{5 * len(sub)}, mean |fitted| "
              f"{1000 * np.mean([r['others_err'] for r in sub]):.2f} mm")
    cpu_s = np.median([r["cpu_slack"] for r in rows])
    cpu_b = np.median([r["cpu_base"] for r in rows])
    print(f"\nCPU of one fit (median): {cpu_s:.2f} s with the slack, {cpu_b:.2f} s without "
          f"(baseline, same patients, same process): ratio {cpu_s / cpu_b:.2f}×; {load_line()}")


if __name__ == "__main__":
    main()
