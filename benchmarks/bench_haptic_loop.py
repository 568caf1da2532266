"""Haptic loop timing: N seconds at 1 kHz on the simulated robot (device in its own process on
a pty, real time), rendering a severe-elbow arm (before) and an unimpaired arm (after) while
the simulated operator explores, switching between them every 5 s.

Prints the period error p50/p99/max (target: p99 <= 100 µs), every overrun above 1 ms (count
and when), ticks skipped, whether SCHED_FIFO was granted, and the tick cost per phase.

    python benchmarks/bench_haptic_loop.py [--seconds 60] [--rate-hz 1000] [--inproc]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import numpy as np

from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic.clock import RealClock, realtime
from fieldbank.haptic.commands import Arm as ArmCommand
from fieldbank.haptic.commands import Switch
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.simrobot import PtyRobot, SimRobotConfig
from fieldbank.model import Arm
from fieldbank.params import ArmParams


def empty_loop(seconds: float, rate_hz: int) -> dict[str, float]:
    """Baseline: the same sleep-then-spin deadline loop with no work, prepared for real time
    the same way (haptic.clock.realtime), so the figures show what the machine itself adds
    (virtual-machine and host scheduling)."""
    clock = RealClock()
    period = round(1e9 / rate_hz)
    n = int(seconds * rate_hz)
    wake = np.empty(n, dtype=np.int64)
    late = np.empty(n, dtype=np.int64)
    with realtime():
        deadline = clock.now_ns()
        for i in range(n):
            clock.sleep_until(deadline)
            now = clock.now_ns()
            wake[i] = now
            late[i] = now - deadline
            deadline += period
            if now >= deadline:
                deadline += ((now - deadline) // period + 1) * period
    err = np.abs(np.diff(wake) - period) / 1e3
    return {"p50": float(np.percentile(err, 50)), "p99": float(np.percentile(err, 99)),
            "max": float(err.max()), "overruns": int((late > 1e6).sum())}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--rate-hz", type=int, default=1000)
    ap.add_argument("--inproc", action="store_true",
                    help="use the in-process sim:// robot instead of a pty device process")
    ap.add_argument("--baseline-seconds", type=float, default=10.0,
                    help="length of the empty-loop baseline run first (0: skip)")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    base = empty_loop(a.baseline_seconds, a.rate_hz) if a.baseline_seconds > 0 else None

    before = synthesize({"elbow": "severe"})
    after = ArmParams.from_anthropometry()
    x0, y0 = (float(v) for v in Arm.from_params(before).rest_position())
    cfg = SimRobotConfig(mode="realtime", motion="explore", x0_m=x0, y0_m=y0, seed=1)
    robot = None
    if a.inproc:
        link = RobotLink.open("sim://?" + cfg.to_query())
    else:
        robot = PtyRobot(cfg).start_process()
        link = RobotLink.open(robot.port)
    try:
        link.handshake(a.rate_hz, 20, timeout_s=3.0)
        rd = Renderer(link, before, after, RendererConfig(rate_hz=a.rate_hz))

        def switcher() -> None:
            # switch A/B every 5 s; re-arm after a fault like a clinician would (faults are
            # counted and printed; they must not leave the rest of the run without load)
            k = 0
            while not rd.running:
                time.sleep(0.01)
            while rd.running:
                time.sleep(0.25)
                k += 1
                if rd.running and k % 20 == 0:
                    rd.submit(Switch("B" if (k // 20) % 2 else "A"))
                if rd.running and rd.safety.mode.name == "FAULT":
                    rd.submit(ArmCommand())

        threading.Thread(target=switcher, daemon=True).start()
        trace = rd.run(a.seconds)
    finally:
        link.close()
        if robot is not None:
            robot.close()
    s = trace.stats
    if a.json:
        print(json.dumps(s, indent=2))
        return 0
    pe, per = s["period_error_us"], s["period_us"]
    print(f"haptic loop: {s['ticks']} ticks at {a.rate_hz} Hz over {a.seconds:g} s "
          f"({'in-process sim://' if a.inproc else 'pty, device process'}); "
          f"SCHED_FIFO {'granted' if s['realtime_scheduling'] else 'refused'}")
    print(f"period error  p50 {pe['p50']:8.1f} µs   p99 {pe['p99']:8.1f} µs   "
          f"max {pe['max']:8.1f} µs   (target p99 <= 100 µs: "
          f"{'met' if pe['p99'] <= 100 else 'NOT met'})")
    if base is not None:
        print(f"baseline (empty loop, {a.baseline_seconds:g} s): period error p50 "
              f"{base['p50']:.1f} µs p99 {base['p99']:.1f} µs max {base['max']:.1f} µs; "
              f"overruns > 1 ms: {base['overruns']} "
              f"({base['overruns'] / a.baseline_seconds:.2f}/s vs "
              f"{s['overruns'] / a.seconds:.2f}/s rendering)")
    print(f"period        p50 {per['p50']:8.1f} µs   p99 {per['p99']:8.1f} µs   "
          f"max {per['max']:8.1f} µs")
    print(f"overruns > {s['overrun_threshold_ms']:g} ms: {s['overruns']}"
          + (f" at t = {', '.join(f'{t:.3f}' for t in s['overrun_times_s'][:20])} s"
             if s["overruns"] else "") + f"; ticks skipped: {s['skipped_ticks']}")
    print("tick cost (mean per tick; a tick preempted mid-way inflates the mean of its phase):")
    for k, v in s["tick_cost_us"].items():
        print(f"  {k:9s} {v:7.2f} µs")
    tt = s["tick_total_us"]
    print(f"tick total    p50 {tt['p50']:.1f} µs   p99 {tt['p99']:.1f} µs   max {tt['max']:.1f} µs "
          f"(budget {1e6 / a.rate_hz:.0f} µs)")
    print(f"faults: {[f['name'] for f in trace.faults] or 'none'}; link: {s['link']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
