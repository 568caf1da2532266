"""Benchmarks for the arm model (issue: the arm model and its force fields).

Prints:
* one simulation tick (arm dynamics + six muscles + coupling force), median and p99 in µs,
  and the same step done with numpy (forward_dynamics) as an in-process baseline;
* postural + stiffness map on a 50×50 grid (2,500 positions), median ms.

Targets: tick ≤ 5 µs median; maps ≤ 5 ms - judged on CPU time (this thread's), printed beside
wall time with the load average: on a shared machine wall time says as much about the
neighbours as about the code.
Run: python benchmarks/bench_model.py
"""

from __future__ import annotations

import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from timing import load_line

from fieldbank.dynamics import forward_dynamics
from fieldbank.evaluate.severity import synthesize
from fieldbank.maps import evaluate
from fieldbank.model import Arm
from fieldbank.sim import ArmSim


def _tick_times(fn, n_batches: int = 200, batch: int = 1000) -> tuple[list[float], list[float]]:
    """(wall, CPU) µs per call, one figure per batch."""
    wall, cpu = [], []
    for _ in range(n_batches):
        t0, c0 = time.perf_counter_ns(), time.thread_time_ns()
        for _ in range(batch):
            fn()
        cpu.append((time.thread_time_ns() - c0) / batch / 1000.0)
        wall.append((time.perf_counter_ns() - t0) / batch / 1000.0)
    return wall, cpu


def _ms(fn, n: int) -> tuple[float, float]:
    """(wall, CPU) ms, medians of ``n`` calls."""
    wall, cpu = [], []
    for _ in range(n):
        t0, c0 = time.perf_counter(), time.thread_time()
        fn()
        cpu.append((time.thread_time() - c0) * 1e3)
        wall.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(wall), statistics.median(cpu)


def _verdict(cpu: float, target: float) -> str:
    return f"target ≤ {target:g} on CPU time: {'met' if cpu <= target else 'NOT met'}"


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

    print(load_line())
    times, cpus = _tick_times(one_tick)
    med = statistics.median(times)
    p99 = float(np.percentile(times, 99))
    cmed = statistics.median(cpus)

    q = np.array(arm.q_rest)
    qd = np.zeros(2)

    def numpy_tick() -> None:
        f = np.array([0.1, -0.2])
        qdd = forward_dynamics(arm, q, qd, f)[0]
        qd2 = qd + 1e-3 * qdd
        _ = q + 1e-3 * qd2

    _, base_cpu = _tick_times(numpy_tick, n_batches=20, batch=200)
    base_med = statistics.median(base_cpu)
    print(f"tick (plain floats): CPU median {cmed:.2f} µs; wall median {med:.2f} µs, p99 "
          f"{p99:.2f} µs  ({_verdict(cmed, 5)} µs)")
    print(f"tick (numpy baseline, same physics): CPU median {base_med:.1f} µs  "
          f"-> plain-float tick is {base_med / cmed:.1f}x faster")

    gx, gy = np.meshgrid(np.linspace(-0.20, 0.30, 50), np.linspace(0.25, 0.60, 50))
    grid = np.stack([gx.ravel(), gy.ravel()], axis=1)
    assert arm.reachable(grid).all()
    static = _ms(lambda: arm.field(grid, (0.0, 0.0)), 50)
    moving = _ms(lambda: arm.field(grid, (0.0, -0.5)), 50)
    pots = _ms(lambda: evaluate(arm, grid), 10)
    print(f"postural + stiffness map, 50x50 grid (2500 positions), static: CPU median "
          f"{static[1]:.2f} ms, wall {static[0]:.2f} ms ({_verdict(static[1], 5)} ms)")
    print(f"postural + stiffness + damping map at v = (0, -0.5) m/s: CPU median "
          f"{moving[1]:.2f} ms, wall {moving[0]:.2f} ms")
    print(f"with the passive potential as well: CPU median {pots[1]:.2f} ms, wall "
          f"{pots[0]:.2f} ms")


if __name__ == "__main__":
    main()
