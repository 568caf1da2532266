"""The loop's timing with the station page connected and without, in one run.

One renderer runs at 1 kHz for the whole run (device in its own process on a pty, real time,
the simulated operator exploring), publishing its snapshot each tick, with the station process
serving it. The run alternates phases: *off* (station up, no page) and *on* (headless Chromium
showing the station page, drawing every frame). Each phase's period error comes from the same
loop's wake times, so the ratio on/off is a same-process comparison; the page's own drawing
rate (frames/s) is read from the station. Per phase it also prints the wake lateness and the
tick cost (p99), which tell a late wake-up (scheduling) from a long tick.

The simulated robot runs inside the link by default (``sim://``, real time), as a hardware
robot's own processor would: with ``--device-process`` it runs in its own process on a pty and
then competes with the browser for the machine's processors - on a small machine its STATE
frames then arrive in bursts (TIMEOUT faults) and the ticks that decode a burst grow, which is
the device's starvation, not the loop's. ``--blank`` shows an empty page instead of the station
(the browser alone).

Target: period-error p99 with the page connected within 10% of the p99 without it.

    python benchmarks/bench_station.py [--phase-s 15] [--rounds 2] [--device-process]
                                       [--blank] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import numpy as np

from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic.commands import Arm as ArmCommand
from fieldbank.haptic.control import ControlServer
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.simrobot import PtyRobot, SimRobotConfig
from fieldbank.haptic.snapshot import SnapshotWriter
from fieldbank.haptic.station.launch import StationProcess
from fieldbank.model import Arm
from fieldbank.params import ArmParams

CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--no-first-run",
                  "--disable-dev-shm-usage", "--window-size=1280,800")


def _stats(url: str) -> dict[str, object]:
    base, token = url.split("/?token=")
    with urllib.request.urlopen(f"{base}/stats?token={token}", timeout=5) as r:
        return json.loads(r.read())


def _figures(wake: np.ndarray, period_ns: int) -> dict[str, float]:
    err = np.abs(np.diff(wake) - period_ns) / 1e3
    return {"n": int(err.size), "p50": float(np.percentile(err, 50)),
            "p99": float(np.percentile(err, 99)), "max": float(err.max()),
            "over_1ms": int((err > 1000).sum())}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--phase-s", type=float, default=15.0)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--rate-hz", type=int, default=1000)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--device-process", action="store_true",
                    help="the simulated robot in its own process on a pty (it then competes "
                         "with the browser for the processors) instead of inside the link")
    ap.add_argument("--blank", action="store_true",
                    help="experiment: the browser shows an empty page instead of the station")
    a = ap.parse_args()
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        print("bench_station needs Debian's chromium (apt-get install -y chromium)",
              file=sys.stderr)
        return 2

    before = synthesize({"elbow": "severe"})
    after = ArmParams.from_anthropometry()
    x0, y0 = (float(v) for v in Arm.from_params(before).rest_position())
    cfg = SimRobotConfig(mode="realtime", motion="explore", x0_m=x0, y0_m=y0, seed=1)
    robot = None
    if a.device_process:
        robot = PtyRobot(cfg).start_process()
        link = RobotLink.open(robot.port)
    else:
        link = RobotLink.open("sim://?" + cfg.to_query())
    tmp = tempfile.mkdtemp(prefix="bench-station-")
    phases: list[tuple[str, int, int]] = []   # (name, start ns, end ns) on the loop's clock
    page_fps: list[float] = []
    try:
        link.handshake(a.rate_hz, 20, timeout_s=3.0)
        rd = Renderer(link, before, after, RendererConfig(rate_hz=a.rate_hz))
        snap = SnapshotWriter()
        rd.snapshot = snap
        server = ControlServer(rd, os.path.join(tmp, "h.sock")).start()
        station = StationProcess(str(snap.path), str(server.path)).start()

        def orchestrate() -> None:
            while not rd.running:
                time.sleep(0.01)
            time.sleep(2.0)  # settle
            for k in range(a.rounds):
                for name in ("off", "on"):
                    browser = None
                    if name == "on":
                        page = "about:blank" if a.blank else station.url
                        browser = subprocess.Popen(
                            [chromium, *CHROMIUM_FLAGS, f"--user-data-dir={tmp}/profile{k}",
                             page], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                        deadline = time.time() + 20
                        while (not a.blank and time.time() < deadline
                               and not _stats(station.url)["pages"]):
                            time.sleep(0.2)
                        time.sleep(2.0)  # the page is drawing
                    else:
                        _stats(station.url)  # the same request in both phases
                    t0 = time.perf_counter_ns()
                    time.sleep(a.phase_s)
                    t1 = time.perf_counter_ns()
                    if browser is not None:
                        st = _stats(station.url)
                        page_fps.extend(f for f in st["fps"] if f)  # type: ignore[union-attr]
                        browser.terminate()
                        browser.wait(10)
                        time.sleep(1.0)
                    phases.append((name, t0, t1))
                    if rd.safety.mode.name == "FAULT":  # re-arm as a clinician would
                        rd.submit(ArmCommand())
            rd.request_stop()

        threading.Thread(target=orchestrate, daemon=True).start()
        total = 2.0 + a.rounds * 2 * (a.phase_s + 25.0) + 30.0
        trace = rd.run(total)
        station.stop()
        server.close()
        snap.close()
    finally:
        link.close()
        if robot is not None:
            robot.close()
        shutil.rmtree(tmp, ignore_errors=True)
    wake = np.array(rd.times.wake_ns, dtype=np.int64)
    late = np.array(rd.times.late_ns, dtype=np.int64)
    cost = np.array(rd.times.tick_ns, dtype=np.int64)[-wake.size:]
    period = round(1e9 / a.rate_hz)
    out: dict[str, object] = {"rate_hz": a.rate_hz, "phase_s": a.phase_s, "rounds": a.rounds,
                              "realtime_scheduling": trace.stats["realtime_scheduling"],
                              "faults": [f["name"] for f in trace.faults],
                              "record_phase_us": trace.stats["tick_cost_us"]["record"],
                              "page_fps": page_fps}
    for name in ("off", "on"):
        sel = [(t0, t1) for n, t0, t1 in phases if n == name]
        parts = [wake[(wake >= t0) & (wake < t1)] for t0, t1 in sel]
        err = np.concatenate([np.abs(np.diff(p) - period) for p in parts if p.size > 1]) / 1e3
        mask = np.zeros(wake.size, bool)
        for t0, t1 in sel:
            mask |= (wake >= t0) & (wake < t1)
        out[name] = {"n": int(err.size), "p50": float(np.percentile(err, 50)),
                     "p99": float(np.percentile(err, 99)), "max": float(err.max()),
                     "over_1ms": int((err > 1000).sum()),
                     "wake_late_p99_us": float(np.percentile(late[mask], 99) / 1e3),
                     "tick_cost_p99_us": float(np.percentile(cost[mask], 99) / 1e3)}
    off, on = out["off"], out["on"]
    ratio = on["p99"] / off["p99"] if off["p99"] > 0 else float("inf")  # type: ignore[index]
    out["p99_ratio_on_off"] = ratio
    if a.json:
        print(json.dumps(out, indent=2))
        return 0
    print(f"station benchmark: {a.rounds} × (off, on) phases of {a.phase_s:g} s at {a.rate_hz} Hz; "
          f"SCHED_FIFO {'granted' if out['realtime_scheduling'] else 'refused'}")
    for name, label in (("off", "page not connected"), ("on", "page connected")):
        f = out[name]
        print(f"  {label:20s} period error p50 {f['p50']:7.1f} µs  p99 {f['p99']:7.1f} µs  "  # type: ignore[index]
              f"max {f['max']:8.1f} µs  > 1 ms: {f['over_1ms']}  ({f['n']} periods); "  # type: ignore[index]
              f"wake lateness p99 {f['wake_late_p99_us']:.1f} µs, tick cost p99 "  # type: ignore[index]
              f"{f['tick_cost_p99_us']:.1f} µs")  # type: ignore[index]
    fps = out["page_fps"]
    print(f"  p99 with the page / without: {ratio:.3f} (target <= 1.10: "
          f"{'met' if ratio <= 1.10 else 'NOT met'})")
    print(f"  page drawing: {', '.join(f'{v:.0f}' for v in fps) or '?'} frames/s; "  # type: ignore[union-attr]
          f"record+publish phase {out['record_phase_us']:.2f} µs/tick; faults: "
          f"{out['faults'] or 'none'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
