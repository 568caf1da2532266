"""Soak: does the loop hold on a busy machine? A long session on the simulated robot in its own
process, with and without a background load, and the round trip against the raw pty echo
measured in the same run.

Background load (documented, reproducible): one busy process per core (``python -c "while
True: pass"``, normal priority), started before the phase and stopped after it.

For each condition (quiet, loaded):

1. **session** - the renderer at ``--rate`` Hz (real-time loop: SCHED_FIFO, its own core) on
   the simulated robot in its own process (realtime mode, free-running STATE, device watchdog
   20 ms live, SCHED_FIFO on the other core), the operator exploring freely, for ``--minutes``.
   A fault is counted by kind and re-armed after 0.5 s so every later one is counted too.
   Printed: faults (device watchdog trips among them), period error p50/p99/max, overruns
   > 1 ms, skipped ticks, tick cost p99, the loop's CPU time beside its wall time.
   Target: no watchdog trip.
2. **round trip** - ``--rtt-n`` FORCE→STATE exchanges with the device process in lockstep
   (it answers each FORCE at once), the host waiting as the renderer does (bounded spin, then
   select), against the baseline: a bare echo process (no protocol, no physics) on a pty of
   the same kind, at the same priority and on the same core as the device. Target: round-trip
   p99 ≤ 2× the echo's p99.

    python benchmarks/bench_soak.py [--minutes 10] [--rate 1000] [--rtt-n 20000]
                                    [--load both|on|off]
"""

from __future__ import annotations

import argparse
import json
import os
import select
import subprocess
import sys
import threading
import time
import tty
from typing import Any

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import numpy as np
from timing import load_line

from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic import protocol as P
from fieldbank.haptic.clock import cpu_plan, realtime
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.renderer import Renderer, RendererConfig
from fieldbank.haptic.simrobot import PtyRobot, SimRobotConfig
from fieldbank.model import Arm

#: The background load: one of these per core.
BUSY = "while True: pass"
#: The baseline echo, at the device's priority and on its core.
ECHO = """
import os, select, sys
from fieldbank.haptic.clock import enter_device_realtime
cpu = None if sys.argv[2] == "-" else int(sys.argv[2])
enter_device_realtime(cpu)
fd = int(sys.argv[1])
print("ready", flush=True)
while True:
    select.select([fd], [], [])
    data = os.read(fd, 4096)
    if not data:
        break
    os.write(fd, data)
"""


def start_load() -> list[subprocess.Popen[bytes]]:
    n = len(os.sched_getaffinity(0))
    return [subprocess.Popen([sys.executable, "-c", BUSY]) for _ in range(n)]


def stop_load(procs: list[subprocess.Popen[bytes]]) -> None:
    for p in procs:
        p.kill()
    for p in procs:
        p.wait()


def session(minutes: float, rate_hz: int) -> dict[str, Any]:
    """A session on the device process; faults counted and re-armed."""
    params = synthesize({"elbow": "severe"})
    x0, y0 = (float(v) for v in Arm.from_params(params).rest_position())
    robot = PtyRobot(SimRobotConfig(mode="realtime", motion="explore", x0_m=x0, y0_m=y0))
    robot.start_process()
    link = RobotLink.open(robot.port)
    rearms = 0
    try:
        link.handshake(rate_hz, 20, timeout_s=5.0)
        rd = Renderer(link, params, params, RendererConfig(rate_hz=rate_hz, record=False))
        stop = threading.Event()

        def rearm() -> None:
            nonlocal rearms
            while not stop.wait(0.5):
                if rd.running and rd.mode_name == "FAULT":
                    try:
                        rd.submit("arm").wait(2.0)
                        rearms += 1
                    except Exception:  # refused now: try again in 0.5 s
                        pass

        th = threading.Thread(target=rearm, daemon=True)
        th.start()
        c0, w0 = time.process_time(), time.perf_counter()
        trace = rd.run(minutes * 60.0)
        cpu_s, wall_s = time.process_time() - c0, time.perf_counter() - w0
        stop.set()
        th.join(2)
    finally:
        link.close()
        robot.close()
    kinds: dict[str, int] = {}
    for f in trace.faults:
        kinds[f["name"]] = kinds.get(f["name"], 0) + 1
    watchdog = sum(1 for f in trace.faults if "watchdog" in f["message"])
    st = trace.stats
    return {"faults": kinds, "watchdog_trips": watchdog, "rearms": rearms,
            "period_error_us": st.get("period_error_us"), "overruns": st.get("overruns"),
            "skipped_ticks": st.get("skipped_ticks"), "tick_total_us": st.get("tick_total_us"),
            "realtime": st.get("realtime"), "device": robot.grant.to_dict() if robot.grant
            else None, "cpu_s": cpu_s, "wall_s": wall_s, "ticks": st.get("ticks")}


def round_trip(n: int, spin_us: float) -> np.ndarray:
    """FORCE→STATE round trips, µs, with the device process in lockstep."""
    robot = PtyRobot(SimRobotConfig(mode="lockstep")).start_process()
    link = RobotLink.open(robot.port)
    out = np.empty(n)
    pc = time.perf_counter_ns
    try:
        link.handshake(1000, 20, timeout_s=5.0)
        link.arm()
        with realtime():
            for i in range(n):
                t0 = pc()
                seq = link.send_force(0.0, 0.0)
                give_up = t0 + 100_000_000
                while True:
                    got = link.wait_state(0.1, spin_us * 1e-6)
                    if (got and link.echo_seq == seq) or pc() > give_up:
                        break
                out[i] = pc() - t0
    finally:
        link.close()
        robot.close()
    return out / 1e3


def raw_echo(n: int, spin_us: float) -> np.ndarray:
    """Baseline round trips, µs: the same frame through a bare echo process on a pty, the
    host waiting the same way."""
    m, s = os.openpty()
    tty.setraw(m)
    tty.setraw(s)
    cpu = cpu_plan()[1]
    root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
    proc = subprocess.Popen([sys.executable, "-c", ECHO, str(m), "-" if cpu is None else str(cpu)],
                            pass_fds=(m,), stdout=subprocess.PIPE,
                            env={**os.environ, "PYTHONPATH": root})
    assert proc.stdout is not None
    proc.stdout.readline()
    frame = P.encode_frame(P.MsgType.FORCE, 1, P.FORCE_FMT.pack(0.0, 0.0))
    out = np.empty(n)
    pc = time.perf_counter_ns
    try:
        with realtime():
            for i in range(n):
                t0 = pc()
                os.write(s, frame)
                got = 0
                spin_end = t0 + spin_us * 1e3
                while got < len(frame):
                    if pc() < spin_end:
                        r, _, _ = select.select([s], [], [], 0)
                    else:
                        r, _, _ = select.select([s], [], [], 0.1)
                    if r:
                        got += len(os.read(s, 4096))
                out[i] = pc() - t0
    finally:
        proc.kill()
        proc.wait()
        os.close(m)
        os.close(s)
    return out / 1e3


def pct(x: np.ndarray) -> tuple[float, float, float]:
    p50, p99 = np.percentile(x, [50, 99])
    return float(p50), float(p99), float(x.max())


def phase(name: str, a: argparse.Namespace) -> dict[str, Any]:
    print(f"\n== {name} ({load_line()})", flush=True)
    s = session(a.minutes, a.rate)
    pe = s["period_error_us"] or {}
    tt = s["tick_total_us"] or {}
    print(f"session {a.minutes:g} min at {a.rate} Hz, device in its own process "
          f"({s['device']}), loop {s['realtime']}:")
    print(f"  faults {s['faults'] or 'none'}; device watchdog trips {s['watchdog_trips']} "
          f"(target 0: {'met' if s['watchdog_trips'] == 0 else 'NOT met'}); re-arms "
          f"{s['rearms']}")
    print(f"  period error p50 {pe.get('p50', 0):.1f} µs  p99 {pe.get('p99', 0):.1f} µs  max "
          f"{pe.get('max', 0):.1f} µs; overruns > 1 ms {s['overruns']}; skipped ticks "
          f"{s['skipped_ticks']}; tick p99 {tt.get('p99', 0):.1f} µs")
    print(f"  loop process CPU {s['cpu_s']:.1f} s over {s['wall_s']:.1f} s wall "
          f"({100 * s['cpu_s'] / max(s['wall_s'], 1e-9):.0f}%: the spin before each deadline)")
    rtt = round_trip(a.rtt_n, a.spin_us)
    echo = raw_echo(a.rtt_n, a.spin_us)
    r50, r99, rmax = pct(rtt)
    e50, e99, emax = pct(echo)
    ratio = r99 / e99
    print(f"round trip ({a.rtt_n} exchanges, lockstep device process, spin ≤ {a.spin_us:g} µs "
          f"then select):")
    print(f"  FORCE→STATE  p50 {r50:7.1f} µs  p99 {r99:7.1f} µs  max {rmax:8.1f} µs")
    print(f"  raw pty echo p50 {e50:7.1f} µs  p99 {e99:7.1f} µs  max {emax:8.1f} µs")
    print(f"  ratio p99 / echo p99 {ratio:.2f}× (target ≤ 2×: "
          f"{'met' if ratio <= 2.0 else 'NOT met'})", flush=True)
    return {**s, "rtt_us": [r50, r99, rmax], "echo_us": [e50, e99, emax], "rtt_ratio": ratio,
            "load": load_line()}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--rate", type=int, default=1000)
    ap.add_argument("--rtt-n", type=int, default=20000)
    ap.add_argument("--spin-us", type=float, default=200.0)
    ap.add_argument("--load", choices=["both", "on", "off"], default="both")
    ap.add_argument("--json", help="also write the figures to this file")
    a = ap.parse_args()
    out: dict[str, Any] = {}
    if a.load in ("both", "off"):
        out["quiet"] = phase("without background load", a)
    if a.load in ("both", "on"):
        load = start_load()
        try:
            out["loaded"] = phase(f"with background load: {len(load)} busy processes, one "
                                  "per core", a)
        finally:
            stop_load(load)
    if a.json:
        with open(a.json, "w", encoding="utf-8") as f:
            json.dump(out, f, indent=1, default=str)
    return 0


if __name__ == "__main__":
    sys.exit(main())
