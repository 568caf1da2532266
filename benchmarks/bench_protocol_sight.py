"""Benchmark: what a measuring protocol sees of each muscle group, before the robot moves.

For the default protocol and two shortened ones (a 3×3 grid; a 4×4 grid without the stiffness
displacements, passes at 0.8 m/s) it prints the table ``fieldbank haptic measure`` prints
(:mod:`fieldbank.measure.visibility`) for the default adult (75 kg, 1.75 m, right arm) with the
robot time of each protocol, then how many bodies of a seeded cohort (50-100 kg, 1.50-1.95 m,
either side; the benchmark's own seed) each protocol sees in every group, and per group how
often. Beside it the same for the earlier default (a fixed grid around (0, 0.50) m, 40 mm
apart, passes at 1 m/s) as the baseline, and the CPU time of one check.

Run: python benchmarks/bench_protocol_sight.py [--bodies 40]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.timing import load_line
from fieldbank.errors import ParameterError
from fieldbank.measure.protocol import ProtocolConfig, plan
from fieldbank.measure.visibility import sight
from fieldbank.model import Arm
from fieldbank.params import GROUPS, ArmParams

SEED = 32_303
PROTOCOLS: dict[str, tuple[str, ProtocolConfig]] = {
    "default": ("fieldbank haptic measure ... (defaults)", ProtocolConfig()),
    "3x3": ("fieldbank haptic measure ... --grid 3x3", ProtocolConfig(grid=(3, 3))),
    "4x4 no stiffness, 0.8 m/s": (
        "fieldbank haptic measure ... --grid 4x4 --protocol postural --protocol stretch "
        "--stretch-speed 0.8",
        ProtocolConfig(grid=(4, 4), parts=("postural", "stretch"), stretch_speed_m_per_s=0.8)),
    "earlier default (baseline)": (
        "fieldbank haptic measure ... --centre 0,0.50 --spacing-mm 40 --stretch-speed 1",
        ProtocolConfig(centre_m=(0.0, 0.50), spacing_m=0.04, stretch_speed_m_per_s=1.0)),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bodies", type=int, default=40)
    args = ap.parse_args()
    adult = Arm.from_params(ArmParams.from_anthropometry())
    for name, (command, cfg) in PROTOCOLS.items():
        c0 = time.process_time()
        p = plan(cfg, adult)
        s = sight(p, adult)
        cpu = time.process_time() - c0
        print(f"\n{name}: {command}\nrobot time {p.duration_s / 60:.1f} min; check "
              f"{cpu:.2f} s CPU (first call synthesises the scale's reflexes)")
        print("\n".join(s.table()))
    rng = np.random.default_rng(SEED)
    bodies = [ArmParams.from_anthropometry(float(rng.uniform(50, 100)),
                                           float(rng.uniform(1.50, 1.95)),
                                           "left" if rng.uniform() < 0.5 else "right")
              for _ in range(args.bodies)]
    print(f"\ncohort of {len(bodies)} bodies (50-100 kg, 1.50-1.95 m, either side): bodies seen "
          "in all six groups, then per group (passive and reflex both seen)")
    print(f"| protocol | all six | {' | '.join(GROUPS)} | unreachable | CPU per check |")
    print("|---|---:|" + "---:|" * len(GROUPS) + "---:|---:|")
    for name, (_, cfg) in PROTOCOLS.items():
        seen = dict.fromkeys(GROUPS, 0)
        every = unreachable = 0
        cpu = []
        for b in bodies:
            arm = Arm.from_params(b)
            c0 = time.process_time()
            try:
                s = sight(plan(cfg, arm), arm)
            except ParameterError:
                unreachable += 1
                continue
            cpu.append(time.process_time() - c0)
            every += s.sees_all
            for g in GROUPS:
                seen[g] += s.of(g).seen
        n = len(bodies)
        print(f"| {name} | {every}/{n} | " + " | ".join(f"{seen[g]}/{n}" for g in GROUPS)
              + f" | {unreachable} | {np.median(cpu):.2f} s |")
    print(load_line())


if __name__ == "__main__":
    main()
