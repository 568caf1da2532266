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
(3 executions × 10 noise draws per arm, 6 N force noise; a few minutes), and the classifier's
reliability: the probability each answer is given with against how often such answers are
right, at force noise 2, 4, 6 and 8 N, on the candidates themselves (each group at each
level) and on arms between and around their severities (:func:`haptic.identify.between_patients`),
before and after the classifier's model-error correction; then arms outside the candidates
(the flexor group alone): how often "no candidate explains the trace" is said, and how many
wrong answers still come with p ≥ 0.95 (docs/probing.md, "Are the probabilities right?").
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.timing import timeit
from fieldbank.evaluate.design import (
    NoiseModel,
    design,
    design_report,
    score_probes,
    seed_probes,
    severity_candidates,
)
from fieldbank.evaluate.reliability import ReliabilityBin, calibration_error
from fieldbank.haptic.identify import (
    Trial,
    between_patients,
    designed_vs_seed,
    flexor_patients,
    grid_patients,
    reliability,
    run_trials,
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
        groups = ("shoulder", "elbow", "biarticular")
        t0 = time.perf_counter()
        rep, res = designed_vs_seed(severity_candidates(groups, LEVELS), groups=groups,
                                    levels=LEVELS, repetitions=3, noise_draws=10,
                                    noise=NoiseModel(force_sd_n=6.0, correlation_s=0.05))
        print(f"\ntrials ({time.perf_counter() - t0:.0f} s): designed "
              + "; ".join(p.describe() for p in rep.design.paths))
        print(res.table())
        reliability_run(groups)


def _cell(b: ReliabilityBin) -> str:
    if not b.n:
        return f"{0:>6}{'':>8}{'':>8}{'':>8}"
    return f"{b.n:>6}{b.stated:>8.3f}{b.observed:>8.3f}{100 * b.gap:>+8.1f}"


def _bins_table(trials: Sequence[Trial], label: str) -> list[str]:
    """Reliability of ``trials`` before and after the classifier's correction, as text."""
    lines = [f"  {label}: {len(trials)} trials, group right in "
             f"{100 * sum(t.correct_group for t in trials) / len(trials):.1f}%",
             f"    {'stated p':<14}{'raw: n':>6}{'stated':>8}{'right':>8}{'gap':>8}   "
             f"{'calib.: n':>6}{'stated':>8}{'right':>8}{'gap':>8}{'± SE':>7}"]
    raw, cal = reliability(trials, raw=True), reliability(trials)
    for a, b in zip(raw, cal, strict=True):
        se = f"{100 * b.se:>7.1f}" if b.n else ""
        span = f"[{a.low:.2f}, {a.high:.2f}{']' if a.high == 1.0 else ')'}"
        lines.append(f"    {span:<14}{_cell(a)}   {_cell(b)}{se}")
    lines.append(f"    expected calibration error: raw {100 * calibration_error(raw):.1f} "
                 f"points, calibrated {100 * calibration_error(cal):.1f} points")
    return lines


def reliability_run(groups: tuple[str, ...], noise_levels: tuple[float, ...] = (2, 4, 6, 8),
                    between: int = 24, draws: int = 8) -> None:
    """The classifier's reliability at several noise levels, and arms outside its candidates
    (module docstring)."""
    cands = severity_candidates(groups, LEVELS)
    pooled = []
    t0 = time.perf_counter()
    print("\nreliability: stated group probability against observed accuracy (the designed "
          "two strokes for each noise, replay, τ 50 ms)")
    for sd in noise_levels:
        noise = NoiseModel(force_sd_n=sd, correlation_s=0.05)
        rep = design_report(cands, criterion="information", target="group", max_probes=2,
                            stop_when_separated=False, noise=noise)
        sets = {"designed": list(rep.design.motions)}
        arms = (*grid_patients(groups, LEVELS),
                *between_patients(groups, between, seed=int(10 * sd)))
        res = run_trials(sets, cands, groups=groups, levels=LEVELS, repetitions=1,
                         noise_draws=draws, noise=noise, seed=int(sd), patients=arms)
        trials = list(res.trials)
        pooled += trials
        print(f"force noise {sd:g} N ({len(grid_patients(groups, LEVELS))} candidate arms and "
              f"{between} between them, {draws} noise draws each)")
        print("\n".join(_bins_table(trials, f"{sd:g} N")))
    print(f"all noise levels ({time.perf_counter() - t0:.0f} s)")
    print("\n".join(_bins_table(pooled, "pooled")))
    stood = [t for t in pooled if t.explains]
    print(f"  of which a candidate explains the trace ({len(stood)} of {len(pooled)}; the "
          "others are said to be none of the candidates)")
    print("\n".join(_bins_table(stood, "pooled, explained")))
    noise = NoiseModel(force_sd_n=4.0, correlation_s=0.05)
    rep = design_report(cands, criterion="information", target="group", max_probes=2,
                        stop_when_separated=False, noise=noise)
    res = run_trials({"designed": list(rep.design.motions)}, cands, groups=groups,
                     levels=LEVELS, repetitions=1, noise_draws=draws, noise=noise, seed=99,
                     patients=flexor_patients(groups, LEVELS))
    tr = list(res.trials)
    wrong = [t for t in tr if not t.correct_group]
    raw_wrong = [t for t in tr if t.raw_answer_group != t.group]
    print(f"\noutside the candidates: the flexor group alone, 4 N ({len(tr)} trials)")
    print(f"  'no candidate explains the trace': {sum(not t.explains for t in tr)} of "
          f"{len(tr)} trials; {sum(not t.explains for t in wrong)} of {len(wrong)} wrong "
          "answers")
    sure_raw = sum(t.raw_group_probability >= 0.95 for t in raw_wrong)
    sure = [t for t in wrong if t.group_probability >= 0.95]
    print(f"  wrong answers with p >= 0.95: raw {sure_raw} of {len(raw_wrong)}, calibrated "
          f"{len(sure)} of {len(wrong)}, of which not flagged {sum(t.explains for t in sure)}")
    print("\n".join(_bins_table(tr, "flexors only")))


if __name__ == "__main__":
    main()
