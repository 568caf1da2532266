"""Where the whole haptic tick spends its CPU time, tick by tick, by the number of STATE frames
it read.

The renderer renders ``--seconds`` at ``--rate`` (4000 Hz) in real time against the simulated
robot in its own process on a pty, as Part 4 of ``bench_tick_cost.py`` does, with each part of
every tick timed on this thread's CPU clock (:func:`time.thread_time_ns`): the link's system
calls (asking how many bytes are ready, reading them), the frame reader (COBS, CRC, header),
the rest of the poll (sequence numbers, counters, unpacking the newest STATE), the checks, the
models, the safety layer's output, sending FORCE, and what is left (commands, recording, the
loop's own bookkeeping). Each timed part adds two clock reads (≈ 0.5 µs each), so the tick here
costs more than in ``bench_tick_cost.py``; the split is what this is for.

Printed: the median of each part for ticks that read 0, 1, 2, … STATE frames and their share of
the ticks, then the mean of each part over the ticks between percentiles 95–99, 99–99.5 and
99.5–100 (what makes the p99), with the load average.

    python benchmarks/bench_tick_profile.py [--seconds 8] [--rate 4000]
"""

from __future__ import annotations

import argparse
import array
import os
import sys
import time
import types
from collections.abc import Callable
from typing import Any

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import numpy as np
from timing import load_line

from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic import link as link_module
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.simrobot import PtyRobot, SimRobotConfig
from fieldbank.model import Arm
from fieldbank.params import ArmParams

PARTS = ("syscalls", "frames", "poll rest", "checks", "models", "output", "send", "rest")
_tt = time.thread_time_ns


class Split:
    """The CPU time of each part of the current tick, ns, and what the tick read."""

    def __init__(self) -> None:
        self.cur: dict[str, int] = {}
        self.rows: dict[str, array.array[int]] = {k: array.array("q")
                                                  for k in (*PARTS, "tick", "poll", "new")}

    def timed(self, part: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        cur = self.cur

        def call(*args: Any) -> Any:
            c0 = _tt()
            try:
                return fn(*args)
            finally:
                cur[part] = cur.get(part, 0) + _tt() - c0
        return call

    def close_tick(self, tick_ns: int) -> None:
        cur, rows = self.cur, self.rows
        rows["tick"].append(tick_ns)
        for k in ("syscalls", "frames", "poll", "checks", "models", "output", "send", "new"):
            rows[k].append(cur.get(k, 0))
        cur.clear()


class FeedTimed:
    """The link's frame reader with its :meth:`feed` timed."""

    def __init__(self, reader: Any, split: Split) -> None:
        self.errors = reader.errors
        self.feed = split.timed("frames", reader.feed)
        self.reset = reader.reset


def instrument(rd: Renderer, link: RobotLink, split: Split) -> None:
    """Time the parts of ``rd``'s tick (the link module's system calls included)."""
    names = {k: getattr(os, k) for k in dir(os) if not k.startswith("__")}
    names["read"] = split.timed("syscalls", os.read)
    link_module.os = types.SimpleNamespace(**names)  # type: ignore[assignment]
    if hasattr(link_module, "ioctl"):
        link_module.ioctl = split.timed("syscalls", link_module.ioctl)  # type: ignore[attr-defined]
    link.reader = FeedTimed(link.reader, split)  # type: ignore[assignment]
    m = rd.monitor
    read = m.read

    def timed_read(wait_s: float, t_s: float) -> int:
        c0 = _tt()
        n = read(wait_s, t_s)
        split.cur["poll"] = _tt() - c0
        split.cur["new"] = n
        return n
    m.read = timed_read  # type: ignore[method-assign]
    m.check = split.timed("checks", m.check)  # type: ignore[method-assign]
    m.output = split.timed("output", m.output)  # type: ignore[method-assign]
    m.send = split.timed("send", m.send)  # type: ignore[method-assign]
    rd.pair.tick = split.timed("models", rd.pair.tick)  # type: ignore[method-assign]
    tick = rd.tick

    def timed_tick() -> None:
        c0 = _tt()
        tick()
        split.close_tick(_tt() - c0)
    rd.tick = timed_tick  # type: ignore[method-assign]


def report(split: Split, skip: int) -> None:
    a = {k: np.array(v[skip:], dtype=np.float64) for k, v in split.rows.items()}
    for k in a:
        if k != "new":
            a[k] /= 1e3
    a["poll rest"] = a["poll"] - a["syscalls"] - a["frames"]
    a["rest"] = a["tick"] - sum(a[k] for k in ("poll", "checks", "models", "output", "send"))
    new = a["new"].astype(int)
    p50, p99 = np.percentile(a["tick"], [50, 99])
    print(f"  {new.size} ticks, CPU per tick p50 {p50:.1f} µs, p99 {p99:.1f} µs (timed parts "
          f"included)")
    head = "".join(f"{k:>10s}" for k in ("tick", *PARTS))
    print(f"  {'STATEs read':12s}{'share':>7s}{head}   (median CPU µs)")
    for n in range(int(new.max()) + 1):
        sel = new == n
        if sel.sum() < 10:
            continue
        print(f"  {n:<12d}{100 * sel.mean():6.1f}%" + "".join(
            f"{np.median(a[k][sel]):10.1f}" for k in ("tick", *PARTS)))
    print(f"  {'percentiles':12s}{'STATEs':>7s}{head}   (mean CPU µs)")
    for lo, hi in ((50, 95), (95, 99), (99, 99.5), (99.5, 100)):
        t_lo, t_hi = np.percentile(a["tick"], [lo, hi])
        sel = (a["tick"] >= t_lo) & (a["tick"] <= t_hi)
        print(f"  {f'p{lo:g}-p{hi:g}':12s}{new[sel].mean():7.2f}" + "".join(
            f"{a[k][sel].mean():10.1f}" for k in ("tick", *PARTS)))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--rate", type=int, default=4000)
    a = ap.parse_args()
    params = synthesize({"elbow": "severe"})
    x0, y0 = (float(v) for v in Arm.from_params(params).rest_position())
    robot = PtyRobot(SimRobotConfig(mode="realtime", motion="explore", x0_m=x0, y0_m=y0))
    robot.start_process()
    link = RobotLink.open(robot.port)
    try:
        link.handshake(a.rate, 20, timeout_s=5.0)
        rd = Renderer(link, params, ArmParams.from_anthropometry(),
                      RendererConfig(rate_hz=a.rate, record=True))
        split = Split()
        instrument(rd, link, split)
        load = load_line()
        trace = rd.run(a.seconds)
    finally:
        link.close()
        robot.close()
    print(f"The tick's parts at {a.rate} Hz, {a.seconds:g} s real time against the simulated "
          f"robot on a pty ({load}); loop {trace.stats.get('realtime')}; faults "
          f"{len(trace.faults)}:")
    report(split, a.rate // 10)
    return 0


if __name__ == "__main__":
    sys.exit(main())
