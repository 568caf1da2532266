"""Speed of the probe design against its target: the search must run while a clinician waits.

Target: ≤ 2 s for one most-informative stroke for 3 to 12 candidates, and for the whole set
(≤ n − 1 strokes) for the three severe groups, on this 2-core machine.

Baseline in the same process: scoring the seed's two fixed probes (pull, semi-ellipse) on the
same candidates with the same measures (``score_probes``: every execution of the motion noise,
every pair) - the price of looking at one fixed set, which any search pays many times over.
Beside the time, each search's score and that of the grid alone (no nlopt polish) say what the
polish buys.

Run: python benchmarks/bench_probe_design.py [--trials]
``--trials`` also runs the larger simulated confusion-matrix run quoted in docs/probing.md
(3 executions × 10 noise draws per arm, 6 N force noise; a few minutes).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.timing import timeit
from fieldbank.evaluate.design import (
    NoiseModel,
    design,
    score_probes,
    seed_probes,
    severity_candidates,
)

TARGET_S = 2.0
LEVELS = ("very mild", "mild", "moderate", "severe")



def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", action="store_true", help="also run the large trial run")
    args = ap.parse_args()
    # (label, candidates, design options, whether the 2 s target applies)
    cases = [
        ("3 severe groups, one stroke (feel)", severity_candidates(), {"max_probes": 1}, True),
        ("3 severe groups, the set (feel)", severity_candidates(), {}, True),
        ("12 groups x severities, one stroke (information, groups)",
         severity_candidates(levels=LEVELS),
         {"max_probes": 1, "criterion": "information", "target": "group"}, True),
        ("12 groups x severities, one stroke (feel)", severity_candidates(levels=LEVELS),
         {"max_probes": 1}, True),
        ("12 groups x severities, two strokes (information, groups; the trials' set)",
         severity_candidates(levels=LEVELS),
         {"max_probes": 2, "criterion": "information", "target": "group",
          "stop_when_separated": False}, False),
    ]
    print(f"target: <= {TARGET_S:g} s per search; baseline: scoring the seed's pull + "
          "semi-ellipse on the same candidates")
    for label, cands, opts, targeted in cases:
        base, _ = timeit(lambda c=cands: score_probes(c, seed_probes(c)), 5)
        found = design(cands, **opts)  # type: ignore[arg-type]
        t, _ = timeit(lambda c=cands, o=opts: design(c, **o), 3)  # type: ignore[arg-type]
        grid = design(cands, polish_evals=0, **opts)  # type: ignore[arg-type]
        crit = str(opts.get("criterion", "feel"))
        ok = ("OK" if t <= TARGET_S else "OVER") if targeted else "no target"
        print(f"{label}\n  baseline {base * 1e3:7.1f} ms   search {t:6.2f} s median "
              f"({t / base:5.1f}x baseline)  {ok}; {len(found.paths)} stroke(s), "
              f"{found.evaluations} paths evaluated\n  score ({crit}) {found.score.score(crit):.4f}"
              f" polished, {grid.score.score(crit):.4f} grid only")
    if args.trials:
        from fieldbank.haptic.identify import designed_vs_seed

        groups = ("shoulder", "elbow", "biarticular")
        t0 = time.perf_counter()
        rep, res = designed_vs_seed(severity_candidates(groups, LEVELS), groups=groups,
                                    levels=LEVELS, repetitions=3, noise_draws=10,
                                    noise=NoiseModel(force_sd_n=6.0, correlation_s=0.05))
        print(f"\ntrials ({time.perf_counter() - t0:.0f} s): designed "
              + "; ".join(p.describe() for p in rep.design.paths))
        print(res.table())


if __name__ == "__main__":
    main()
