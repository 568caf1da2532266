"""Perception through the link: the simulated trainee's accuracy against the one-way delay.

The seed's training protocol (reduced: one familiarisation round, ``--reps`` repetitions of
each group × severity, instructed: the seed's pull and semi-ellipse) runs with the simulated
trainee (:mod:`haptic.trainee`: direction blur ``--noise-deg``, size blur ``--size-noise``)
on the simulated robot, each arm felt through a simulated remote link
(:func:`haptic.remote.simulate.linked_environment`: the same ports, passivity controllers and
patient's robot as two sites over UDP) with the injected one-way delay — and once without any
link (the baseline each row is compared with). For each delay it prints the share of trials in
which the trainee named the group, and the severity, with 95 % intervals (Wilson), and what
the link did to the severity judgements (answered level minus true, on the 4-level scale; how
often a mild arm was read as moderate or stronger); and it draws the accuracy-vs-delay figure
(``--figure``, PNG, SVG or PDF).

    python benchmarks/bench_remote_perception.py [--reps 2] [--figure accuracy_vs_delay.png]
                                                 [--quick] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from typing import Any

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from fieldbank.figures import save
from fieldbank.haptic.remote.channel import Impairment
from fieldbank.haptic.remote.config import SiteConfig
from fieldbank.haptic.remote.figure import accuracy_vs_delay
from fieldbank.haptic.remote.simulate import linked_environment
from fieldbank.haptic.safety import SafetyConfig
from fieldbank.haptic.trainee import DirectionRule, SimulationResult, simulate
from fieldbank.haptic.training import TrainingProtocol

DELAYS_MS = (0, 5, 15, 50, 100, 300)
QUICK = (0, 100)
LEVELS = ("very mild", "mild", "moderate", "severe")


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval of k successes in n."""
    if n == 0:
        return (0.0, 1.0)
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return (max(0.0, c - h), min(1.0, c + h))


def summarise(res: SimulationResult, delay_ms: float | None, wall_s: float) -> dict[str, Any]:
    acc = res.summary["accuracy"]
    sev = res.severities
    right = sum(1 for r in sev if r["answered_severity"] == r["severity"])
    shifts = [LEVELS.index(r["answered_severity"]) - LEVELS.index(r["severity"])
              for r in sev if r["answered_severity"] in LEVELS]
    milder = [r for r in sev if r["severity"] in ("very mild", "mild")]
    over = sum(1 for r in milder if r["answered_severity"] in ("moderate", "severe"))
    return {"delay_ms": delay_ms, "n": acc["n"],
            "group_accuracy": acc["accuracy"], "group_ci": wilson(acc["correct"], acc["n"]),
            "severity_accuracy": right / len(sev) if sev else math.nan,
            "severity_ci": wilson(right, len(sev)),
            "severity_shift": sum(shifts) / len(shifts) if shifts else math.nan,
            "mild_read_stronger": over / len(milder) if milder else math.nan,
            "by_severity": {k: v["accuracy"] for k, v in res.summary["by_severity"].items()},
            "confusion": res.summary["confusion"]["counts"],
            "simulated_s": res.simulated_s, "wall_s": wall_s}


def run(protocol: TrainingProtocol, rule: DirectionRule, delay_ms: float | None
        ) -> dict[str, Any]:
    t0 = time.perf_counter()
    if delay_ms is None:
        res = simulate(protocol, rule)
    else:
        env, chains = linked_environment(SiteConfig(
            lockstep=True, impairment=Impairment(delay_ms / 1000.0)))
        try:
            res = simulate(protocol, rule, environment=env,
                           safety=SafetyConfig(passivity=False))
        finally:
            for c in chains:
                c.close()
    return summarise(res, delay_ms, time.perf_counter() - t0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reps", type=int, default=2, help="repetitions of each group × severity")
    ap.add_argument("--noise-deg", type=float, default=20.0,
                    help="the trainee's direction blur, degrees (assumption)")
    ap.add_argument("--size-noise", type=float, default=0.1,
                    help="the trainee's size blur, SD of the log (assumption)")
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--figure", default=None, help="write the figure here (.png/.svg/.pdf)")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    protocol = TrainingProtocol(instruction="instructed", familiarisation_rounds=1,
                                assessment_repetitions=a.reps, seed=a.seed)
    rule = DirectionRule(direction_noise_deg=a.noise_deg, magnitude_noise=a.size_noise,
                         seed=a.seed)
    load0 = os.getloadavg()
    direct = run(protocol, rule, None)
    rows = [run(protocol, rule, d) for d in (QUICK if a.quick else DELAYS_MS)]
    print(f"## The simulated trainee through the link ({rows[0]['n']} assessment trials each; "
          f"direction blur {a.noise_deg:g}°, size blur {a.size_noise:g})\n")
    print("| one-way delay ms | group right | 95 % | severity right | 95 % | severity shift "
          "(levels) | very mild/mild read moderate or severe | simulated s | wall s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in [direct, *rows]:
        d = "no link" if r["delay_ms"] is None else f"{r['delay_ms']:g}"
        print(f"| {d} | {r['group_accuracy']:.0%} | {r['group_ci'][0]:.0%}–"
              f"{r['group_ci'][1]:.0%} | {r['severity_accuracy']:.0%} | "
              f"{r['severity_ci'][0]:.0%}–{r['severity_ci'][1]:.0%} | "
              f"{r['severity_shift']:+.2f} | {r['mild_read_stronger']:.0%} | "
              f"{r['simulated_s']:.0f} | {r['wall_s']:.0f} |")
    speed = sum(r["simulated_s"] for r in rows) / sum(r["wall_s"] for r in rows)
    load1 = os.getloadavg()
    print(f"\nspeed {speed:.2f} simulated s per wall s; load average {load0[0]:.2f} at the "
          f"start, {load1[0]:.2f} at the end ({os.cpu_count()} CPUs)")
    if a.figure:
        scene = accuracy_vs_delay(
            rows, direct, "The simulated trainee through the link: accuracy against delay",
            noticed_ms=[(15, "damper 15 ms"), (36, "spring 36 ms"), (72, "inertia 72 ms")])
        print(f"figure: {save(scene, a.figure)}")
    if a.json:
        print(json.dumps({"direct": direct, "rows": rows}, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
