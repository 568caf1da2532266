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

from fieldbank.model import Arm
from fieldbank.params import ArmParams
from haptic.link import RobotLink
from haptic.models import from_severity
from haptic.renderer import Renderer, RendererConfig
from haptic.simrobot import PtyRobot, SimRobotConfig


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--rate-hz", type=int, default=1000)
    ap.add_argument("--inproc", action="store_true",
                    help="use the in-process sim:// robot instead of a pty device process")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()

    before = from_severity({"elbow": "severe"})
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
                    rd.submit("switch", target="B" if (k // 20) % 2 else "A")
                if rd.running and rd.safety.mode.name == "FAULT":
                    rd.submit("arm")

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
    print(f"period        p50 {per['p50']:8.1f} µs   p99 {per['p99']:8.1f} µs   "
          f"max {per['max']:8.1f} µs")
    print(f"overruns > {s['overrun_threshold_ms']:g} ms: {s['overruns']}"
          + (f" at t = {', '.join(f'{t:.3f}' for t in s['overrun_times_s'][:20])} s"
             if s["overruns"] else "") + f"; ticks skipped: {s['skipped_ticks']}")
    print("tick cost (mean per tick):")
    for k, v in s["tick_cost_us"].items():
        print(f"  {k:9s} {v:7.2f} µs")
    print(f"faults: {[f['name'] for f in trace.faults] or 'none'}; link: {s['link']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
