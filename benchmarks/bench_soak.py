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
   the same kind, at the same priority and on the same core as the device. The two are
   interleaved in blocks of 200 exchanges, so a busy spell of the machine lands on both.
   Target: round-trip p99 ≤ 2× the echo's p99.
3. **the platform alone** - ``--probe-s`` of a loop that only sleeps to 1 kHz deadlines at the
   host loop's priority on its core, and the CPU time the hypervisor took from the machine
   (``steal`` in ``/proc/stat``) during the session and the probe: stalls no code of ours can
   remove, printed beside the session's faults and overruns.

With ``--tty-workers fifo`` (root) the kernel threads that carry a pty's bytes (unbound
workers, ``kworker/u…``: a tty hands received bytes to its line discipline in one) run at
SCHED_FIFO 50 for the whole run and get their policy back after; workers the kernel starts
meanwhile are raised within 0.2 s. At normal priority a busy process can keep them off a core
for up to a scheduler tick (4 ms at HZ=250): with one busy process per core the bare pty
echo's worst round trip was 4.9-5.2 ms with them at normal priority, 0.36-0.41 ms raised.

    python benchmarks/bench_soak.py [--minutes 10] [--rate 1000] [--rtt-n 20000]
                                    [--load both|on|off] [--probe-s 60]
                                    [--tty-workers normal|fifo]
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
from fieldbank.haptic.clock import RealClock, cpu_plan, realtime
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
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


class TtyWorkers:
    """The kernel's unbound workers raised to SCHED_FIFO while this lives (see the module's
    docstring); each one's policy is given back at :meth:`stop`."""

    PRIORITY = 50

    def __init__(self) -> None:
        self.old: dict[int, tuple[int, int]] = {}
        self._stop = threading.Event()
        self.raise_all()
        self._th = threading.Thread(target=self._watch, daemon=True)
        self._th.start()

    @staticmethod
    def pids() -> list[int]:
        out = []
        for d in os.listdir("/proc"):
            if d.isdigit():
                try:
                    with open(f"/proc/{d}/comm", encoding="ascii") as f:
                        if f.read().startswith("kworker/u"):
                            out.append(int(d))
                except OSError:
                    pass
        return out

    def raise_all(self) -> None:
        for pid in self.pids():
            if pid in self.old:
                continue
            try:
                self.old[pid] = (os.sched_getscheduler(pid), os.sched_getparam(pid).sched_priority)
                os.sched_setscheduler(pid, os.SCHED_FIFO, os.sched_param(self.PRIORITY))
            except OSError:
                pass

    def _watch(self) -> None:
        while not self._stop.wait(0.2):
            self.raise_all()

    def stop(self) -> None:
        self._stop.set()
        self._th.join(2)
        for pid, (policy, prio) in self.old.items():
            try:
                os.sched_setscheduler(pid, policy, os.sched_param(prio))
            except OSError:
                pass  # the worker has gone


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
                if rd.running and rd.safety.mode.name == "FAULT":
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


class LockstepPeer:
    """The device process in lockstep: each FORCE answered at once with a STATE."""

    name = "FORCE→STATE"

    def __init__(self, spin_us: float) -> None:
        self.spin_s = spin_us * 1e-6
        self.robot = PtyRobot(SimRobotConfig(mode="lockstep")).start_process()
        self.link = RobotLink.open(self.robot.port)
        self.link.handshake(1000, 20, timeout_s=5.0)
        self.link.arm()

    def exchange(self) -> int:
        """One round trip, ns: FORCE out, the STATE that echoes its sequence number in."""
        link, pc = self.link, time.perf_counter_ns
        t0 = pc()
        seq = link.send_force(0.0, 0.0)
        give_up = t0 + 100_000_000
        while True:
            got = link.wait_state(0.1, self.spin_s)
            if (got and link.echo_seq == seq) or pc() > give_up:
                return pc() - t0

    def close(self) -> None:
        self.link.close()
        self.robot.close()


class EchoPeer:
    """The baseline: the same FORCE frame through a bare echo process (no protocol, no
    physics) on a pty of the same kind, at the device's priority and on its core; the host
    waits the same way (spin, then select)."""

    name = "raw pty echo"

    def __init__(self, spin_us: float) -> None:
        self.spin_ns = spin_us * 1e3
        self.m, self.s = os.openpty()
        tty.setraw(self.m)
        tty.setraw(self.s)
        cpu = cpu_plan()[1]
        root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
        self.proc = subprocess.Popen(
            [sys.executable, "-c", ECHO, str(self.m), "-" if cpu is None else str(cpu)],
            pass_fds=(self.m,), stdout=subprocess.PIPE, env={**os.environ, "PYTHONPATH": root})
        assert self.proc.stdout is not None
        self.proc.stdout.readline()
        self.frame = P.encode_frame(P.MsgType.FORCE, 1, P.FORCE_FMT.pack(0.0, 0.0))

    def exchange(self) -> int:
        s, frame, pc = self.s, self.frame, time.perf_counter_ns
        t0 = pc()
        os.write(s, frame)
        got = 0
        spin_end = t0 + self.spin_ns
        while got < len(frame):
            r, _, _ = select.select([s], [], [], 0 if pc() < spin_end else 0.1)
            if r:
                got += len(os.read(s, 4096))
        return pc() - t0

    def close(self) -> None:
        self.proc.kill()
        self.proc.wait()
        os.close(self.m)
        os.close(self.s)


def round_trips(n: int, spin_us: float, block: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """``n`` round trips, µs, of each: the device process in lockstep and the bare echo,
    interleaved in blocks of ``block`` so both meet the same neighbours (a busy spell of the
    machine lands on both, not on whichever happened to run then)."""
    peers = (LockstepPeer(spin_us), EchoPeer(spin_us))
    out = (np.empty(n), np.empty(n))
    try:
        with realtime():
            for start in range(0, n, block):
                stop = min(n, start + block)
                for peer, o in zip(peers, out, strict=True):
                    for i in range(start, stop):
                        o[i] = peer.exchange()
    finally:
        for peer in peers:
            peer.close()
    return out[0] / 1e3, out[1] / 1e3


def steal_ms() -> float:
    """CPU time the hypervisor took from this (virtual) machine so far, ms (``/proc/stat``;
    0 on bare metal)."""
    try:
        with open("/proc/stat", encoding="ascii") as f:
            fields = f.readline().split()
        return int(fields[8]) * 1e3 / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return 0.0


def empty_loop(seconds: float) -> dict[str, float]:
    """The platform's own stalls: a loop that only sleeps to 1 kHz deadlines, at the host
    loop's priority on its core (``realtime()``); how late it wakes, µs. What it sees no
    code of ours can remove."""
    c = RealClock(200.0)
    n = max(1, int(seconds * 1000))
    late = np.empty(n)
    s0 = steal_ms()
    with realtime():
        deadline = c.now_ns()
        for i in range(n):
            deadline += 1_000_000
            c.sleep_until(deadline)
            late[i] = c.now_ns() - deadline
    late /= 1e3
    return {"p99": float(np.percentile(late, 99)), "max": float(late.max()),
            "over_1ms": int((late > 1000).sum()), "over_5ms": int((late > 5000).sum()),
            "steal_ms": steal_ms() - s0}


def pct(x: np.ndarray) -> tuple[float, float, float]:
    p50, p99 = np.percentile(x, [50, 99])
    return float(p50), float(p99), float(x.max())


def phase(name: str, a: argparse.Namespace) -> dict[str, Any]:
    print(f"\n== {name} ({load_line()})", flush=True)
    st0 = steal_ms()
    s = session(a.minutes, a.rate)
    s["steal_ms"] = steal_ms() - st0
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
    print(f"  CPU time the hypervisor took from this machine meanwhile (steal): "
          f"{s['steal_ms']:.0f} ms")
    e = empty_loop(a.probe_s)
    print(f"the platform alone ({a.probe_s:g} s of an empty loop at the loop's priority and core, "
          f"1 kHz deadlines): wakes > 1 ms late {e['over_1ms']}, > 5 ms late {e['over_5ms']}, "
          f"p99 {e['p99']:.1f} µs, max {e['max']:.0f} µs; steal {e['steal_ms']:.0f} ms")
    s["empty_loop"] = e
    rtt, echo = round_trips(a.rtt_n, a.spin_us)
    r50, r99, rmax = pct(rtt)
    e50, e99, emax = pct(echo)
    ratio = r99 / e99
    print(f"round trip ({a.rtt_n} exchanges each, lockstep device process and bare echo "
          f"interleaved in blocks of 200, spin ≤ {a.spin_us:g} µs then select):")
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
    ap.add_argument("--probe-s", type=float, default=60.0,
                    help="seconds of the empty loop that shows the platform's own stalls")
    ap.add_argument("--tty-workers", choices=["normal", "fifo"], default="normal",
                    help="the priority of the kernel's tty workers during the run (fifo: root)")
    ap.add_argument("--json", help="also write the figures to this file")
    a = ap.parse_args()
    out: dict[str, Any] = {"tty_workers": a.tty_workers}
    workers = TtyWorkers() if a.tty_workers == "fifo" else None
    if workers is not None:
        print(f"kernel tty workers (kworker/u…): SCHED_FIFO {TtyWorkers.PRIORITY} for this run "
              f"({len(workers.old)} raised now)")
    try:
        run_phases(a, out)
    finally:
        if workers is not None:
            workers.stop()
    if a.json:
        with open(a.json, "w", encoding="utf-8") as f:
            json.dump(out, f, indent=1, default=str)
    return 0


def run_phases(a: argparse.Namespace, out: dict[str, Any]) -> None:
    if a.load in ("both", "off"):
        out["quiet"] = phase("without background load", a)
    if a.load in ("both", "on"):
        load = start_load()
        try:
            out["loaded"] = phase(f"with background load: {len(load)} busy processes, one "
                                  "per core", a)
        finally:
            stop_load(load)


if __name__ == "__main__":
    sys.exit(main())
