"""Transparency of the remote link, measured: both sites simulated in one process.

A severe-elbow virtual patient on the simulated patient's robot; the simulated clinician's
robot follows a scripted probing (a slow stretch of the elbow, 5 cm in 2.5 s, and a fast one,
5 cm in 0.3 s, each held and released; :func:`haptic.remote.simulate.stretch_script`); the two
sites exchange authenticated datagrams through an in-memory link with the injected one-way
delay, jitter and loss, on virtual clocks (lockstep: faster than real time, repeatable).

For each setting (the script twice over, so each read-out averages two stretches) it prints
(:func:`haptic.remote.simulate.transparency`): the stiffness and the velocity-dependent
resistance the clinician felt against the patient's own (each side against its own motion),
the peak force felt against the patient's, the largest energy the link
created over the session (≤ 0: passive), what the passivity controllers dissipated and on what
share of ticks they acted, and the patient's robot's largest drift from the clinician's hand.
The 0 ms row is the baseline every error is a ratio to (the link at its least latency: one tick
each way). Then the same link without the passivity controller (observer only), the force step
response (the clinician holds still; at 1 s the patient's hand pushes 5 N more), and the
peak-force error over a 30 s probing session at 100 ms one-way with 5 % loss for several seeds
(what docs/remote.md documents as the error the two-process test checks against).

Timing: simulated seconds per wall second and per CPU second of each run, beside the load
average.

    python benchmarks/bench_remote.py [--quick] [--seeds 5] [--json]
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

import numpy as np

from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic.remote.channel import Impairment
from fieldbank.haptic.remote.config import LinkConfig, SiteConfig
from fieldbank.haptic.remote.simulate import (
    Pair,
    Script,
    clinician_robot,
    push_patient,
    run_link,
    stretch_script,
    transparency,
)
from fieldbank.model import Arm
from fieldbank.params import ArmParams

#: (one-way delay ms, loss, jitter ms) of the transparency table.
SETTINGS = [(0, 0.0, 0), (5, 0.0, 0), (15, 0.0, 0), (50, 0.0, 0), (100, 0.0, 0), (300, 0.0, 0),
            (15, 0.05, 0), (100, 0.05, 0), (15, 0.10, 0), (100, 0.10, 0), (15, 0.0, 5),
            (100, 0.05, 20), (300, 0.10, 50)]
QUICK = [(0, 0.0, 0), (15, 0.0, 0), (100, 0.05, 0)]
STEP_DELAYS_MS = (0, 15, 100, 300)


def patient_and_script(repeat: int = 1) -> tuple[ArmParams, Script]:
    """The severe elbow and its stretches (along the hand's radius: elbow extension)."""
    p = synthesize({"elbow": "severe"})
    hand = tuple(float(v) for v in Arm.from_params(p).rest_position())
    r = math.hypot(*hand)
    return p, stretch_script((hand[0], hand[1]), (hand[0] / r, hand[1] / r), repeat=repeat)


def _timed(fn: Any) -> tuple[Any, float, float]:
    w0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w0, time.process_time() - c0


def row(p: ArmParams, script: Script, delay_ms: float, loss: float, jitter_ms: float,
        passivity: str = "tdpa", seed: int = 0) -> dict[str, Any]:
    cfg = SiteConfig(lockstep=True, link=LinkConfig(passivity=passivity),
                     impairment=Impairment(delay_ms / 1000, jitter_ms / 1000, loss, seed))
    run, wall, cpu = _timed(lambda: run_link(p, script, config=cfg, seed=seed))
    sim_s = len(run.trace) / 1000
    return {"delay_ms": delay_ms, "loss": loss, "jitter_ms": jitter_ms, "passivity": passivity,
            "seed": seed, **transparency(run, script), "simulated_s": sim_s, "wall_s": wall,
            "cpu_s": cpu}


def step_response(p: ArmParams, delay_ms: float, push_n: float = 5.0) -> dict[str, float]:
    """The clinician holds still; at 1 s the patient pushes ``push_n`` more along +y: delay to
    half the step, 10–90 % rise time, overshoot, and the final felt step over the patient's."""
    hand = tuple(float(v) for v in Arm.from_params(p).rest_position())
    cfg = SiteConfig(lockstep=True, impairment=Impairment(delay_ms / 1000))
    pair = Pair(p, cfg, clinician_robot((hand[0], hand[1]), cfg.rate_hz))
    push_patient(pair, at_s=1.0, force_n=(0.0, push_n))
    for _ in range(3000):
        pair.tick()
    run = pair.finish()
    t = run.trace.t_s
    f = np.asarray(run.trace.column("fy_n"), dtype=float)
    fp = run.patient["hand_fy_n"]
    before = float(np.mean(f[(t > 0.7) & (t < 1.0)]))
    after = float(np.mean(f[(t > 2.5) & (t < 3.0)]))
    pb = float(np.mean(fp[(run.patient["t_s"] > 0.7) & (run.patient["t_s"] < 1.0)]))
    pa = float(np.mean(fp[(run.patient["t_s"] > 2.5) & (run.patient["t_s"] < 3.0)]))
    step = after - before
    rel = (f - before) / step if step else np.zeros_like(f)
    later = t >= 1.0

    def first(level: float) -> float:
        hit = np.flatnonzero(later & (rel >= level))
        return float(t[hit[0]] - 1.0) if len(hit) else math.nan

    return {"delay_ms": delay_ms, "half_s": first(0.5), "rise_s": first(0.9) - first(0.1),
            "overshoot": float(np.max(rel[later]) - 1.0), "felt_step_n": step,
            "patient_step_n": pa - pb, "step_ratio": step / (pa - pb) if pa != pb else math.nan}


def _md(rows: list[dict[str, Any]], cols: list[tuple[str, str, str]]) -> str:
    head = "| " + " | ".join(h for _, h, _ in cols) + " |"
    sep = "|" + "|".join("---" for _ in cols) + "|"
    lines = [head, sep]
    for r in rows:
        lines.append("| " + " | ".join(format(r[k], f) if isinstance(r[k], (int, float))
                                       and not (isinstance(r[k], float) and math.isnan(r[k]))
                                       else "–" for k, _, f in cols) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="three settings, one seed")
    ap.add_argument("--seeds", type=int, default=5, help="seeds of the 30 s session")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    p, script = patient_and_script(repeat=2)
    out: dict[str, Any] = {"load_average_start": os.getloadavg()}
    rows = [row(p, script, d, lo, j) for d, lo, j in (QUICK if a.quick else SETTINGS)]
    out["transparency"] = rows
    cols = [("delay_ms", "one-way delay ms", "g"), ("loss", "loss", ".0%"),
            ("jitter_ms", "jitter ± ms", "g"),
            ("stiffness_felt_n_per_m", "stiffness felt N/m", ".0f"),
            ("stiffness_patient_n_per_m", "patient's N/m", ".0f"),
            ("stiffness_error", "error", "+.1%"),
            ("velocity_resistance_felt_n", "velocity-dep. resistance felt N", ".2f"),
            ("velocity_resistance_patient_n", "patient's N", ".2f"),
            ("velocity_resistance_error", "error", "+.0%"),
            ("peak_felt_n", "peak felt N", ".1f"), ("peak_patient_n", "patient's N", ".1f"),
            ("peak_error", "error", "+.0%"), ("created_max_j", "link created, max J", ".1e"),
            ("dissipated_j", "dissipated J", ".3f"),
            ("pc_active_clinician", "controller on (clinician)", ".0%"),
            ("pc_active_patient", "(patient)", ".0%"), ("drift_max_m", "drift max m", ".3f"),
            ("rtt_ms", "round trip ms", ".0f"), ("loss_measured", "loss measured", ".1%")]
    print("## Transparency (severe elbow; slow and fast stretch)\n")
    print(_md(rows, cols))
    timing = [(r["simulated_s"] / r["wall_s"], r["simulated_s"] / r["cpu_s"]) for r in rows]
    print(f"\nspeed: {np.median([t[0] for t in timing]):.2f} simulated s per wall s, "
          f"{np.median([t[1] for t in timing]):.2f} per CPU s (median over runs)")
    off = [row(p, script, d, 0.0, 0, passivity="off") for d in ((15,) if a.quick else (15, 100))]
    out["without_passivity"] = off
    print("\n## Without the passivity controller (observer only)\n")
    print(_md(off, [("delay_ms", "one-way delay ms", "g"),
                    ("created_max_j", "link created, max J", ".3g"),
                    ("peak_felt_n", "peak felt N", ".1f"),
                    ("peak_patient_n", "patient's N", ".1f")]))
    steps = [step_response(p, d) for d in ((0, 100) if a.quick else STEP_DELAYS_MS)]
    out["step_response"] = steps
    print("\n## Force step response (patient pushes 5 N more at 1 s; clinician holds)\n")
    print(_md(steps, [("delay_ms", "one-way delay ms", "g"), ("half_s", "to 50 % s", ".3f"),
                      ("rise_s", "rise 10–90 % s", ".3f"), ("overshoot", "overshoot", "+.0%"),
                      ("felt_step_n", "felt step N", ".2f"),
                      ("patient_step_n", "patient's step N", ".2f"),
                      ("step_ratio", "felt / patient's", ".2f")]))
    p30, s30 = patient_and_script(repeat=3)
    seeds = 1 if a.quick else a.seeds
    sess = [row(p30, s30, 100, 0.05, 0, seed=s) for s in range(seeds)]
    out["session_100ms_5pct"] = sess
    errs = [r["peak_error"] for r in sess]
    print(f"\n## 30 s probing session, 100 ms one-way, 5 % loss, {seeds} seed(s)\n")
    print(_md(sess, [("seed", "seed", "d"), ("peak_felt_n", "peak felt N", ".2f"),
                     ("peak_patient_n", "patient's N", ".2f"), ("peak_error", "error", "+.1%"),
                     ("created_max_j", "link created, max J", ".1e"),
                     ("loss_measured", "loss measured", ".1%")]))
    print(f"\npeak-force error: {min(errs):+.1%} … {max(errs):+.1%}")
    out["load_average_end"] = os.getloadavg()
    print(f"\nload average: {out['load_average_start'][0]:.2f} at the start, "
          f"{out['load_average_end'][0]:.2f} at the end ({os.cpu_count()} CPUs)")
    if a.json:
        print(json.dumps(out, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
