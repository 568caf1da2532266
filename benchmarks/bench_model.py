"""Benchmarks for the arm model (issue: the arm model and its force fields).

Prints:
* one simulation tick (arm dynamics + six muscles + coupling force), median and p99 in µs,
  and the same step done with numpy (forward_dynamics) as an in-process baseline;
* postural + stiffness map on a 50×50 grid (2,500 positions), median ms.

Targets: tick ≤ 5 µs median; maps ≤ 5 ms.
Run: python benchmarks/bench_model.py
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from fieldbank.dynamics import forward_dynamics
from fieldbank.evaluate.severity import synthesize
from fieldbank.maps import evaluate
from fieldbank.model import Arm
from fieldbank.sim import ArmSim


def _tick_times(fn, n_batches: int = 200, batch: int = 1000) -> list[float]:
    out = []
    for _ in range(n_batches):
        t0 = time.perf_counter_ns()
        for _ in range(batch):
            fn()
        out.append((time.perf_counter_ns() - t0) / batch / 1000.0)
    return out


def main() -> None:
    arm = Arm.from_params(synthesize({"elbow": "severe", "shoulder": "mild"}))
    sim = ArmSim(arm, dt_s=1e-3)
    x0, y0, _, _ = sim.hand()
    tick = sim.tick
    k = [0]

    def one_tick() -> None:
        k[0] += 1
        # a moving handle so the reflex branch runs on the lengthening muscles
        s = (k[0] % 1000) * 1e-4
        tick(x0 + 0.03 * s, y0 - 0.05 * s, 0.3, -0.5)

    times = _tick_times(one_tick)
    med = statistics.median(times)
    p99 = float(np.percentile(times, 99))

    q = np.array(arm.q_rest)
    qd = np.zeros(2)

    def numpy_tick() -> None:
        f = np.array([0.1, -0.2])
        qdd = forward_dynamics(arm, q, qd, f)[0]
        qd2 = qd + 1e-3 * qdd
        _ = q + 1e-3 * qd2

    base = _tick_times(numpy_tick, n_batches=20, batch=200)
    base_med = statistics.median(base)
    print(f"tick (plain floats): median {med:.2f} µs, p99 {p99:.2f} µs  (target ≤ 5 µs)")
    print(f"tick (numpy baseline, same physics): median {base_med:.1f} µs  "
          f"-> plain-float tick is {base_med / med:.1f}x faster")

    gx, gy = np.meshgrid(np.linspace(-0.20, 0.30, 50), np.linspace(0.25, 0.60, 50))
    grid = np.stack([gx.ravel(), gy.ravel()], axis=1)
    assert arm.reachable(grid).all()
    runs = []
    for _ in range(50):
        t0 = time.perf_counter()
        arm.field(grid, (0.0, 0.0))
        runs.append((time.perf_counter() - t0) * 1e3)
    moving = []
    for _ in range(50):
        t0 = time.perf_counter()
        arm.field(grid, (0.0, -0.5))
        moving.append((time.perf_counter() - t0) * 1e3)
    pots = []
    for _ in range(10):
        t0 = time.perf_counter()
        evaluate(arm, grid)
        pots.append((time.perf_counter() - t0) * 1e3)
    print(f"postural + stiffness map, 50x50 grid (2500 positions), static: median "
          f"{statistics.median(runs):.2f} ms (target ≤ 5 ms)")
    print(f"postural + stiffness + damping map at v = (0, -0.5) m/s: median "
          f"{statistics.median(moving):.2f} ms")
    print(f"with the passive potential as well: median {statistics.median(pots):.2f} ms")


if __name__ == "__main__":
    main()
