"""Benchmark: measuring virtual patients on the simulated robot — accuracy and robot time.

Three parts, each printed as a table:

1. **Accuracy** over ``--patients`` virtual patients (default 30; shoulder, elbow and
   bi-articular groups at very mild … severe in turn, body mass 60–90 kg and height
   1.60–1.90 m drawn from a seeded generator; force-sensor noise 0.2 N and position noise
   0.02 mm, the virtual patient's defaults): the full protocol (postural + stiffness + stretch)
   on a ``--grid`` grid, estimated, then fitted (:class:`fieldbank.fitting.ArmFitter`, 20
   bootstrap replicates). Per patient: the share of postures whose static stiffness is within
   10 % of the model's (Frobenius, relative), the share of postural force components within
   2 sd of the model's, the same 10 % share for the moving maps; whether the fit grades the
   impaired group highest; and the share of identified parameters whose 95 % interval holds
   the truth. Targets: ≥ 90 % of postures, forces within 2 sd, the impaired group found, truth
   inside for ≥ 85 % of identified parameters.
2. **Robot time** of the full clinical protocol on a 5 × 5 grid, by part, against the 10-minute
   target (ratio), and the simulation's own wall and CPU time against the robot time it
   simulates (the speed-up over real time).
3. **Shortened protocols**: fewer postures, directions, shorter holds; per variant the robot
   time (and its ratio to the full protocol's), the static stiffness share within 10 % and the
   median error, the postural share within 2 sd, over ``--short-patients`` patients.

Run: python benchmarks/bench_measure.py [--patients 30] [--grid 5] [--short-patients 4]
     [--jobs 2]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace

import numpy as np

from fieldbank.fitting import ArmFitter
from fieldbank.fitting.synthetic import LEVELS, impaired_params
from fieldbank.haptic.measure import run_protocol
from fieldbank.maps import model_map_like
from fieldbank.measure.estimate import estimate
from fieldbank.measure.protocol import ProtocolConfig, plan
from fieldbank.measurechoices import PARTS
from fieldbank.model import Arm
from fieldbank.params import JOINT_GROUPS, ArmParams

GROUPS = list(JOINT_GROUPS)
FULL = ProtocolConfig()


def _patient(i: int) -> tuple[str, str, ArmParams]:
    rng = np.random.default_rng(500 + i)
    base = ArmParams.from_anthropometry(float(rng.uniform(60, 90)), float(rng.uniform(1.6, 1.9)))
    group, level = GROUPS[i % 3], LEVELS[(i // 3) % len(LEVELS)]
    return group, level, impaired_params(group, level, base)


def _measure(params: ArmParams, config: ProtocolConfig, seed: int
             ) -> tuple[Arm, object, object, float, float]:
    arm = Arm.from_params(params)
    the_plan = plan(config, arm)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "arm.json")
        with open(path, "w", encoding="utf-8") as f:
            f.write(params.to_json())
        t0, c0 = time.perf_counter(), time.process_time()
        rec, _ = run_protocol(f"sim://?patient=file:{path}&seed={seed}", the_plan)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    est = estimate(rec, arm, the_plan.postures_m)
    return arm, the_plan, est, wall, cpu


def _scores(arm: Arm, est: object) -> dict[str, float]:
    out: dict[str, float] = {}
    moving = []
    for m in est.maps:  # type: ignore[attr-defined]
        truth = model_map_like(arm, m)
        if m.kind == "postural":
            z = (m.values - truth.values) / m.sd
            out["postural_2sd"] = float(np.mean(np.abs(z) < 2))
            continue
        err = (np.linalg.norm(m.values - truth.values, axis=(1, 2))
               / np.linalg.norm(truth.values, axis=(1, 2)))
        if m.speed_m_per_s == 0:
            out["static_10"] = float(np.mean(err < 0.10))
            out["static_median_err"] = float(np.median(err))
        else:
            moving.extend(err.tolist())
    if moving:
        out["moving_10"] = float(np.mean(np.array(moving) < 0.10))
        out["moving_median_err"] = float(np.median(moving))
    return out


def _truth_vector(truth: ArmParams) -> dict[str, float]:
    names = [f"{k}_{g}" for k in ("km", "alpha", "beta")
             for g in ("sf", "se", "ef", "ee", "bf", "be")]
    return dict(zip(names, [*truth.km_n_per_m, *truth.alpha_n, *truth.beta], strict=True))


def accuracy_one(i: int, grid: int) -> dict[str, object]:
    group, level, truth = _patient(i)
    config = replace(FULL, grid=(grid, grid))
    arm, the_plan, est, wall, cpu = _measure(truth, config, seed=i)
    row: dict[str, object] = {"patient": i, "group": group, "level": level,
                              "robot_s": the_plan.duration_s, "wall_s": wall, "cpu_s": cpu,
                              **_scores(arm, est)}
    base = truth.with_unimpaired_muscles()
    fit = ArmFitter(seed=i, replicates=20, max_evals=400).fit(list(est.maps), base)
    unidentified = {u.name for u in fit.unidentified_}
    tv = _truth_vector(truth)
    inside = [iv["low"] <= tv[n] <= iv["high"] for n, iv in fit.intervals_.items()
              if n not in unidentified and n in tv]
    row["identified"] = len(inside)
    row["inside"] = int(sum(inside))
    members = {"shoulder": ("sf", "se"), "elbow": ("ef", "ee"), "biarticular": ("bf", "be")}
    sev = fit.severity_
    score = {g: max(max(sev[m]["passive"]["score"], sev[m]["dynamic"]["score"]) for m in ms)
             for g, ms in members.items()}
    row["found"] = max(score, key=lambda g: score[g]) == group
    row["status"] = fit.status_
    return row


def short_one(args: tuple[int, ProtocolConfig]) -> dict[str, float]:
    i, config = args
    _, _, truth = _patient(i)
    arm, the_plan, est, _, _ = _measure(truth, config, seed=100 + i)
    return {"robot_s": the_plan.duration_s, **_scores(arm, est)}


def _load() -> str:
    one, five, fifteen = os.getloadavg()
    return f"{one:.2f} {five:.2f} {fifteen:.2f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--patients", type=int, default=30)
    ap.add_argument("--grid", type=int, default=5)
    ap.add_argument("--short-patients", type=int, default=4)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", dest="json_out", default=None)
    a = ap.parse_args()
    print(f"load average at start: {_load()}")

    # 2. robot time of the full protocol (plan only: exact, no simulation)
    arm = Arm.from_params(ArmParams.from_anthropometry())
    print("\n## Robot time, full clinical protocol, 5 × 5 grid (target ≤ 600 s)\n")
    print("| part | robot time (s) | ratio to the 600 s target |")
    print("|---|---|---|")
    total = 0.0
    for part in PARTS:
        t = plan(replace(FULL, parts=(part,)), arm).duration_s
        total += t
        print(f"| {part} | {t:.0f} | {t / 600:.2f} |")
    t_all = plan(FULL, arm).duration_s
    print(f"| all three (one plan) | {t_all:.0f} | {t_all / 600:.2f} |")

    # 1. accuracy over virtual patients
    t0, c0 = time.perf_counter(), time.process_time()
    with ProcessPoolExecutor(max_workers=a.jobs) as pool:
        rows = list(pool.map(accuracy_one, range(a.patients), [a.grid] * a.patients))
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    print(f"\n## Accuracy over {a.patients} virtual patients ({a.grid} × {a.grid} grid, "
          "0.2 N and 0.02 mm noise)\n")
    print("| patient | group | level | static K ≤ 10 % | postural ≤ 2 sd | moving K ≤ 10 % "
          "| group found | truth in 95 % | fit |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['patient']} | {r['group']} | {r['level']} | {r.get('static_10', 0):.0%} "
              f"| {r.get('postural_2sd', 0):.0%} | {r.get('moving_10', float('nan')):.0%} "
              f"| {'yes' if r['found'] else 'no'} | {r['inside']}/{r['identified']} "
              f"| {r['status']} |")
    static = np.mean([r.get("static_10", 0.0) for r in rows])
    patients_90 = np.mean([r.get("static_10", 0.0) >= 0.9 for r in rows])
    post = np.mean([r.get("postural_2sd", 0.0) for r in rows])
    mov = np.nanmean([r.get("moving_10", np.nan) for r in rows])
    found = np.mean([bool(r["found"]) for r in rows])
    inside = sum(int(r["inside"]) for r in rows)  # type: ignore[misc]
    ident = sum(int(r["identified"]) for r in rows)  # type: ignore[misc]
    robot = sum(float(r["robot_s"]) for r in rows)  # type: ignore[misc]
    sim_wall = sum(float(r["wall_s"]) for r in rows)  # type: ignore[misc]
    sim_cpu = sum(float(r["cpu_s"]) for r in rows)  # type: ignore[misc]
    print("\n| figure | value | target |")
    print("|---|---|---|")
    print(f"| postures with static K within 10 % (all patients) | {static:.1%} | ≥ 90 % |")
    print(f"| patients with ≥ 90 % of postures within 10 % | {patients_90:.1%} | |")
    print(f"| postural force components within 2 sd | {post:.1%} | ≈ 95 % |")
    print(f"| moving-map postures within 10 % | {mov:.1%} | (reported) |")
    print(f"| impaired group graded highest by the fit | {found:.1%} | all |")
    print(f"| identified parameters with the truth in the 95 % interval | "
          f"{inside}/{ident} = {inside / max(1, ident):.1%} | ≥ 85 % |")
    print(f"\nsimulation: {robot:.0f} s of robot time in {sim_wall:.0f} s wall "
          f"({sim_cpu:.0f} s CPU) = {robot / max(sim_wall, 1e-9):.1f}× real time; "
          f"whole part {wall:.0f} s wall, {cpu:.0f} s CPU in this process; load "
          f"{_load()}")

    # 3. shortened protocols
    variants = [
        ("full: 5×5, 8 directions, 0.6 s holds", FULL),
        ("4×4 grid", replace(FULL, grid=(4, 4))),
        ("3×3 grid", replace(FULL, grid=(3, 3))),
        ("6 directions", replace(FULL, directions=6)),
        ("4 directions", replace(FULL, directions=4)),
        ("0.35 s holds", replace(FULL, hold_s=0.35, transient_s=0.15)),
        ("3×3, 4 directions, 0.35 s holds", replace(FULL, grid=(3, 3), directions=4,
                                                    hold_s=0.35, transient_s=0.15)),
    ]
    print(f"\n## Shortened protocols ({a.short_patients} virtual patients each; static parts: "
          "postural + stiffness)\n")
    print("| protocol | robot time (s) | ratio to full | static K ≤ 10 % | median K error "
          "| postural ≤ 2 sd |")
    print("|---|---|---|---|---|---|")
    full_time = None
    results = {}
    for name, cfg in variants:
        cfg = replace(cfg, parts=("postural", "stiffness"))
        with ProcessPoolExecutor(max_workers=a.jobs) as pool:
            rs = list(pool.map(short_one, [(i, cfg) for i in range(a.short_patients)]))
        t = float(np.mean([r["robot_s"] for r in rs]))
        full_time = full_time or t
        s10 = float(np.mean([r.get("static_10", 0) for r in rs]))
        med = float(np.median([r.get("static_median_err", np.nan) for r in rs]))
        p2 = float(np.mean([r.get("postural_2sd", 0) for r in rs]))
        results[name] = {"robot_s": t, "static_10": s10, "median_err": med, "postural_2sd": p2}
        print(f"| {name} | {t:.0f} | {t / full_time:.2f} | {s10:.0%} | {med:.1%} | {p2:.0%} |")
    print(f"\nload average at end: {_load()}")
    if a.json_out:
        with open(a.json_out, "w", encoding="utf-8") as f:
            json.dump({"accuracy": rows, "short": results}, f, indent=1, default=str)


if __name__ == "__main__":
    main()
