"""Benchmark: a batch report over 100 synthetic patients (target ≤ 60 s on 2 cores).

Builds a fresh SQLite database with N synthetic patients (severities drawn from a seeded
generator, models from :func:`fieldbank.severity.synthesize`, stored with one plan each:
botulinum for even patients, which adds the 25-week time course, lengthening for odd ones; no
fits are run), then writes the whole batch report with ``--jobs 1`` and with ``--jobs 2`` in
this process, prints the total and per-case times and the speed-up, and checks that both runs
wrote identical bytes.

Run: python benchmarks/bench_report.py [--patients 100] [--jobs 2]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from fieldbank.interventions import Botulinum, Lengthening, Plan
from fieldbank.interventions.report import Selection, build_report
from fieldbank.params import ArmParams
from fieldbank.severity import LEVELS, synthesize
from fieldbank.storage import Database

JOINTS = ("shoulder", "elbow", "biarticular")
GROUPS = {"shoulder": ("sf", "se"), "elbow": ("ef", "ee"), "biarticular": ("bf", "be")}


def store_synthetic_batch(db: Database, n: int, seed: int = 7) -> None:
    """N synthetic patients, each with a synthetic model and one stored plan."""
    rng = np.random.default_rng(seed)
    for i in range(n):
        code = f"BENCH-{i:03d}"
        mass, height = float(rng.uniform(50, 95)), float(rng.uniform(1.5, 1.95))
        side = ("right", "left")[i % 2]
        db.add_patient(code, round(mass, 1), round(height, 2), side, notes="synthetic")
        joint = JOINTS[int(rng.integers(3))]
        sev = {joint: LEVELS[int(rng.integers(2, 5))]}
        p = synthesize(sev, ArmParams.from_anthropometry(mass, height, side))
        base = db.add_model(p, "synthetic", f"synthetic {joint} {sev[joint]}", code)
        g = GROUPS[joint][int(rng.integers(2))]
        plan = (Plan.of(Botulinum({g: float(rng.integers(50, 300))}), label=f"botulinum {g}")
                if i % 2 == 0 else
                Plan.of(Lengthening(group=g, delta_m=float(rng.uniform(0.005, 0.02))),
                        label=f"lengthening {g}"))
        after, lineage = plan.derive(p)
        child = db.add_model(after, "intervention", plan.label, code, parent_id=base.id)
        db.add_plan(base.id, child.id, lineage.to_dict(), label=plan.label, patient_code=code)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--patients", type=int, default=100)
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        url = f"sqlite:///{Path(tmp) / 'bench.sqlite3'}"
        with Database.open(url) as db:
            t = time.perf_counter()
            store_synthetic_batch(db, args.patients)
            print(f"stored {args.patients} synthetic patients, models and plans in "
                  f"{time.perf_counter() - t:.1f} s")
            times = {}
            for jobs in (1, args.jobs):
                t = time.perf_counter()
                out = build_report(db, Selection(), Path(tmp) / f"jobs{jobs}", jobs=jobs)
                times[jobs] = time.perf_counter() - t
                size = out.html.stat().st_size / 1e6
                print(f"--jobs {jobs}: {out.n_cases} cases in {times[jobs]:.1f} s "
                      f"({1000 * times[jobs] / out.n_cases:.0f} ms per case, "
                      f"{out.jobs_used} process(es)); report.html {size:.1f} MB")
        same = all((Path(tmp) / "jobs1" / f).read_bytes()
                   == (Path(tmp) / f"jobs{args.jobs}" / f).read_bytes()
                   for f in ("report.html", "metrics.csv", "metrics.json"))
    best = min(times.values())
    print(f"speed-up of --jobs {args.jobs} over --jobs 1: {times[1] / times[args.jobs]:.2f}x")
    print(f"identical bytes from both runs: {'yes' if same else 'NO'}")
    print(f"target: batch of {args.patients} <= 60 s: {best:.1f} s "
          f"({'met' if best <= 60 else 'NOT met'})")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
