"""Benchmark: does ``fieldbank validate`` cry wolf? Verdicts against a known truth.

A seeded cohort of synthetic patients (:mod:`fieldbank.interventions.synthetic`: each muscle
group in turn, three severities, some reflex-only; seeds and positions of its own) was given
botulinum toxin into the hypertonic group. The first session is measured and fitted; the later
session is measured from the truth with the toxin's effect **1.3 ×** the predicted one, **as
predicted** (1), **half** (0.5) or **none** (0), with new noise, at the first session's
positions (the protocol repeated) or, with ``--new-positions``, at positions of its own. For
each map set (``static``: postural and
static stiffness maps, which cannot see a change of the stretch reflex; ``slow``: plus a
stiffness map moving at 0.5 m/s in one direction; ``moving``: plus stiffness maps moving at
1 m/s both ways) and each noise level, it prints the confusion table truth × verdict of the
check (:mod:`fieldbank.interventions.validate`) and, beside it, of the check as it was before
(the baseline, run on the same maps in the same process: the realised fraction's SE from the
later maps' noise alone, a map poor against the prediction or |f − 1| > 0.5 at SE ≤ 0.25 is
"failed", no partial verdict, no observability test).

Figures: the false-alarm rate (verdict failed or partial where the truth is as predicted;
target ≤ 5%), the coverage of decided cases (truth within 2 SE), the median |error| / SE, and
the CPU and wall time of one session's check against the baseline's (ratio), with the load
average.

With ``--contracture`` every patient's hypertonic group is also 5-15 mm short (its slack
length); ``--fit km,alpha,beta,slack`` fits the slack length too. The summary counts the
inconclusive checks and, of them, those a misfit of the later maps made inconclusive (maps
the model before differs from where the fit saw no map like them, or a guess explains).

Run: python benchmarks/bench_validate.py [--patients 12] [--noise 0.05 0.10]
     [--sets static slow moving] [--jobs 2] [--new-positions] [--contracture]
     [--fit km,alpha,beta,slack]
"""

from __future__ import annotations

import argparse
import math
import os
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

from fieldbank.fitting.quality import map_fit
from fieldbank.interventions import synthetic as syn
from fieldbank.interventions.realised import (
    CONFIRMED,
    FAILED,
    INCONCLUSIVE,
    OVER,
    PARTIAL,
    map_changes,
)
from fieldbank.interventions.validate import LaterSession, check_session, predicted_after

TRUTHS = ((1.3, "1.3 ×"), (1.0, "as predicted"), (0.5, "half"), (0.0, "none"))
VERDICTS = (CONFIRMED, OVER, PARTIAL, FAILED, INCONCLUSIVE)
SHORT = {CONFIRMED: "confirmed", OVER: "stronger", PARTIAL: "partial", FAILED: "failed",
         INCONCLUSIVE: "inconclusive"}


def baseline(fitted: syn.Fitted, later: LaterSession) -> tuple[str, float | None,
                                                                 float | None]:
    """The check as it was: noise-only SE, failed on a poor map or |f - 1| > 0.5."""
    p = fitted.patient
    weeks = (later.session_date - syn.GIVEN_ON).days / 7.0
    after, _ = predicted_after(fitted.before, p.plan, p.plan.apply(fitted.before), weeks)
    changes, _ = map_changes(fitted.before, after, later.maps)
    a = b = 0.0
    poor = False
    for c in changes:
        ai, bi, _, _ = c.sums()
        a, b = a + ai, b + bi
        shape = c.measured.values.shape
        poor |= map_fit(0, c.measured, c.after.reshape(shape),
                        c.sd.reshape(shape)).verdict == "poor"
    f = a / b if b > 0 else None
    se = 1.0 / math.sqrt(b) if b > 0 else None
    measurable = se is not None and se <= 0.25
    off = measurable and f is not None and abs(f - 1.0) > 0.5
    if poor or off:
        return FAILED, f, se
    return (CONFIRMED if measurable else INCONCLUSIVE), f, se


def run_patient(job: tuple[int, int, str, float, bool, bool, tuple[str, ...]]
                ) -> list[dict[str, Any]]:
    """Fit one patient's first session, check three later sessions now and as before."""
    i, n, map_set, noise, new_positions, contracture, kinds = job
    p = syn.cohort(n, contracture=contracture)[i]
    fitted = syn.fit_first_session(p, map_set, noise, fit_kinds=kinds)
    rows = []
    for truth, _ in TRUTHS:
        later = syn.later_session(fitted, truth, new_positions=new_positions)
        t0, c0 = time.perf_counter(), time.process_time()
        c = check_session(fitted.before, p.plan, p.plan.apply(fitted.before), syn.GIVEN_ON,
                              later, spread=fitted.spread)
        t1, c1 = time.perf_counter(), time.process_time()
        old, f_old, se_old = baseline(fitted, later)
        t2, c2 = time.perf_counter(), time.process_time()
        misfit = c.verdict == INCONCLUSIVE and any(
            "used no map measured like" in r or "explains the difference" in r
            for r in c.reasons)
        rows.append({"set": map_set, "noise": noise, "patient": p.code, "truth": truth,
                     "fit_status": fitted.status, "misfit": misfit,
                     "verdict": c.verdict, "f": c.realised_fraction, "se": c.realised_se,
                     "decided": c.decided, "old": old, "f_old": f_old, "se_old": se_old,
                     "wall": t1 - t0, "cpu": c1 - c0, "wall_old": t2 - t1, "cpu_old": c2 - c1})
    return rows


def _rate(rows: list[dict[str, Any]], key: str) -> tuple[int, int]:
    pred = [r for r in rows if r["truth"] == 1.0]
    return sum(r[key] in (FAILED, OVER, PARTIAL) for r in pred), len(pred)


def _coverage(rows: list[dict[str, Any]], f: str, se: str,
              decided: Any) -> tuple[int, int, float]:
    sel = [r for r in rows if decided(r)]
    z = [abs(r[f] - r["truth"]) / r[se] for r in sel]
    return (sum(x <= 2 for x in z), len(z), float(np.median(z)) if z else math.nan)


def table(rows: list[dict[str, Any]], key: str) -> list[str]:
    count = Counter((r["truth"], r[key]) for r in rows)
    head = "| truth \\ verdict | " + " | ".join(SHORT[v] for v in VERDICTS) + " |"
    out = [head, "|---|" + "---:|" * len(VERDICTS)]
    for truth, name in TRUTHS:
        out.append(f"| {name} | " + " | ".join(str(count[(truth, v)]) for v in VERDICTS) + " |")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--patients", type=int, default=12)
    ap.add_argument("--noise", type=float, nargs="+", default=[0.05, 0.10])
    ap.add_argument("--sets", nargs="+", default=list(syn.MAP_SETS),
                    choices=list(syn.MAP_SETS))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--new-positions", action="store_true",
                    help="Measure the later session at positions of its own (default: the "
                         "first session's, the protocol repeated).")
    ap.add_argument("--contracture", action="store_true",
                    help="Each patient's hypertonic group also 5-15 mm short.")
    ap.add_argument("--fit", default="km,alpha,beta",
                    help="Parameter kinds the first session's fit fits.")
    args = ap.parse_args()
    kinds = tuple(k.strip() for k in args.fit.split(",") if k.strip())
    jobs = [(i, args.patients, s, nz, args.new_positions, args.contracture, kinds)
            for s in args.sets for nz in args.noise for i in range(args.patients)]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        rows = [r for rs in pool.map(run_patient, jobs) for r in rs]
    wall = time.perf_counter() - t0
    print(f"bench_validate: {args.patients} patients × {len(args.sets)} map sets × "
          f"{len(args.noise)} noise levels × {len(TRUTHS)} truths = {len(rows)} checks; "
          "later maps at "
          f"{'new positions' if args.new_positions else 'the first session positions'}; "
          f"{'contractures; ' if args.contracture else ''}fit {','.join(kinds)}; "
          f"{wall:.0f} s wall on {args.jobs} processes; load average "
          + " ".join(f"{x:.2f}" for x in os.getloadavg()))
    for s in args.sets:
        for nz in args.noise:
            sub = [r for r in rows if r["set"] == s and r["noise"] == nz]
            fa, n = _rate(sub, "verdict")
            fa0, _ = _rate(sub, "old")
            inside, dec, med = _coverage(sub, "f", "se", lambda r: r["decided"])
            inside0, dec0, med0 = _coverage(
                sub, "f_old", "se_old",
                lambda r: r["old"] != INCONCLUSIVE and r["f_old"] is not None)
            print(f"\n### map set '{s}' ({syn.MAP_SETS[s].description}), noise "
                  f"{100 * nz:g}%\n")
            print("now:")
            print("\n".join(table(sub, "verdict")))
            print("\nbefore (baseline):")
            print("\n".join(table(sub, "old")))
            print(f"\nfalse alarms where the truth is as predicted: now {fa}/{n} "
                  f"({100 * fa / n:.0f}%), before {fa0}/{n} ({100 * fa0 / n:.0f}%); "
                  f"truth within 2 SE: now {inside}/{dec} decided"
                  + (f" (median |error|/SE {med:.2f})" if dec else "")
                  + f", before {inside0}/{dec0}"
                  + (f" (median {med0:.2f})" if dec0 else ""))
    fa, n = _rate(rows, "verdict")
    fa0, _ = _rate(rows, "old")
    inside, dec, med = _coverage(rows, "f", "se", lambda r: r["decided"])
    inconclusive = [r for r in rows if r["verdict"] == INCONCLUSIVE]
    poor = sum(r["fit_status"] == "poor" for r in rows) // len(TRUTHS)
    print(f"all: inconclusive {len(inconclusive)}/{len(rows)} "
          f"({100 * len(inconclusive) / len(rows):.0f}%), of which from a misfit of the later "
          f"maps {sum(r['misfit'] for r in inconclusive)}; first-session fits poor: {poor}/"
          f"{len(rows) // len(TRUTHS)}; stronger than predicted "
          f"{sum(r['verdict'] == OVER for r in rows)}")
    cpu, cpu0 = np.median([r["cpu"] for r in rows]), np.median([r["cpu_old"] for r in rows])
    w, w0 = np.median([r["wall"] for r in rows]), np.median([r["wall_old"] for r in rows])
    print(f"\nall: false alarms where the truth is as predicted: now {fa}/{n} "
          f"({100 * fa / n:.1f}%; target ≤ 5%), before {fa0}/{n} ({100 * fa0 / n:.1f}%); "
          f"ratio {'-' if fa0 == 0 else f'{fa / fa0:.2f}'}")
    print(f"all: truth within 2 SE in {inside}/{dec} decided checks "
          f"({100 * inside / max(dec, 1):.1f}%), median |error|/SE {med:.2f}")
    print(f"one session's check: {1e3 * cpu:.0f} ms CPU, {1e3 * w:.0f} ms wall (median); "
          f"baseline {1e3 * cpu0:.0f} ms CPU, {1e3 * w0:.0f} ms wall; ratio "
          f"{cpu / cpu0:.1f}× CPU, {w / w0:.1f}× wall")


if __name__ == "__main__":
    main()
