"""The in-process timers the benchmarks share.

* :func:`timeit` - a warm-up call, then the median and the worst of ``repeat`` timed calls;
* :func:`per_call` - wall-clock *and* CPU time per call of a short function (best of several
  runs of many calls): on a machine shared with other work, wall time says as much about the
  neighbours as about the code, while the CPU time this thread spent does not, so targets are
  judged on CPU time and both are printed;
* :func:`load_line` - the load average and core count, printed beside every figure.
"""

from __future__ import annotations

import os
import statistics
import time
from collections.abc import Callable


def timeit(fn: Callable[[], object], repeat: int) -> tuple[float, float]:
    """(median, max) seconds of ``repeat`` calls of ``fn`` after one untimed warm-up call."""
    fn()  # warm-up
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), max(times)


def per_call(fn: Callable[[], object], number: int = 20000,
             repeat: int = 5) -> tuple[float, float]:
    """(wall, CPU) µs per call of ``fn``: the best of ``repeat`` runs of ``number`` calls each
    (CPU: this thread's CPU time, :func:`time.thread_time_ns`)."""
    fn()
    walls, cpus = [], []
    for _ in range(repeat):
        w0, c0 = time.perf_counter_ns(), time.thread_time_ns()
        for _ in range(number):
            fn()
        cpus.append((time.thread_time_ns() - c0) / number / 1e3)
        walls.append((time.perf_counter_ns() - w0) / number / 1e3)
    return min(walls), min(cpus)


def load_line() -> str:
    """"load average 1.2 / 0.9 / 0.7 (1, 5, 15 min) on 2 cores"."""
    try:
        a, b, c = os.getloadavg()
    except OSError:
        return "load average unknown"
    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:
        n = os.cpu_count() or 0
    return f"load average {a:.2f} / {b:.2f} / {c:.2f} (1, 5, 15 min) on {n} cores"
