"""Breakdown of the haptic tick's cost, in the same process, no waiting.

Part 1 times each piece on its own (timeit, best of 5): the two virtual-arm ticks (coupling +
arm dynamics), protocol encode (FORCE) and decode (STATE), the safety layer (handle checks +
passivity + rate limit + saturation), trace recording. Part 2 runs the full renderer tick
against the in-process simulated robot (sim://, lockstep) and prints the per-phase means the
renderer measures itself; the device's own work happens inside the link phases there, so the
host share is Part 1's protocol figures. Part 3 runs Part 2 again with the station's snapshot
attached (haptic.snapshot: one record published per tick) and prints the record phase with and
without it, as a ratio.

    python benchmarks/bench_tick_cost.py [--ticks 20000]
"""

from __future__ import annotations

import argparse
import os
import sys
import timeit

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic import protocol as P
from fieldbank.haptic.clock import VirtualClock
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.pair import build_sim
from fieldbank.haptic.probe import sim_url
from fieldbank.haptic.recording import NCOL, TraceBuffer
from fieldbank.haptic.renderer import Renderer, RendererConfig
from fieldbank.haptic.safety import Safety, SafetyConfig
from fieldbank.haptic.snapshot import SnapshotWriter
from fieldbank.params import ArmParams


def per_call_us(fn: object, n: int = 20000) -> float:
    return min(timeit.repeat(fn, number=n, repeat=5)) / n * 1e6  # type: ignore[arg-type]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--ticks", type=int, default=20000)
    a = ap.parse_args()
    before = synthesize({"elbow": "severe"})
    after = ArmParams.from_anthropometry()
    sa, sb = build_sim(before, 1e-3), build_sim(after, 1e-3)
    x0, y0, _, _ = sa.hand()
    state = P.encode_frame(P.MsgType.STATE, 1, P.STATE_FMT.pack(1, x0, y0, 0.01, -0.02, 1, 1))
    reader = P.FrameReader()
    safety = Safety(SafetyConfig(), 1e-3)
    safety.rearm((x0, y0, 0.0, 0.0))
    buf = TraceBuffer(10**6)
    row = tuple(float(i) for i in range(NCOL))
    snap = SnapshotWriter()

    parts = {
        "arm A + arm B tick (coupling + dynamics)":
            lambda: (sa.tick(x0 + 0.01, y0, 0.0, 0.0), sb.tick(x0 + 0.01, y0, 0.0, 0.0)),
        "encode FORCE frame": lambda: P.encode_frame(P.MsgType.FORCE, 7,
                                                      P.FORCE_FMT.pack(1.5, -2.5)),
        "decode STATE frame (reader)": lambda: reader.feed(state),
        "safety (checks + passivity + limits)":
            lambda: (safety.check_handle(x0, y0, 0.01, 0.0), safety.output(3.0, 1.0, 0.01, 0.0)),
        "record one row": lambda: buf.add(0.0, row),
        "publish the snapshot (station)": lambda: snap.publish_row(0.0, 1, row, 3, False),
    }
    print("Part 1 — pieces in isolation (µs per call, best of 5):")
    total = 0.0
    for name, fn in parts.items():
        us = per_call_us(fn)
        total += us
        print(f"  {name:42s} {us:7.2f}")
    print(f"  {'sum':42s} {total:7.2f}")

    def full_run(with_snapshot: bool) -> dict[str, float]:
        link = RobotLink.open(sim_url(before, "circle"))
        link.handshake(1000, 20)
        rd = Renderer(link, before, after,
                      RendererConfig(state_wait_s=0.05, realtime_priority=False),
                      clock=VirtualClock())
        if with_snapshot:
            rd.snapshot = snap
        trace = rd.run(a.ticks / 1000)
        link.close()
        return dict(trace.stats["tick_cost_us"])

    plain = full_run(False)
    print(f"Part 2 — full renderer tick against sim:// ({a.ticks} ticks; the device's physics "
          f"runs inside link_in/link_out):")
    for k, v in plain.items():
        print(f"  {k:42s} {v:7.2f}")
    # alternate the two runs so drift in the machine's load falls on both
    runs: dict[bool, list[float]] = {False: [plain["record"]], True: []}
    for _ in range(2):
        runs[True].append(full_run(True)["record"])
        runs[False].append(full_run(False)["record"])
    runs[True].append(full_run(True)["record"])
    without, with_ = min(runs[False]), min(runs[True])
    print("Part 3 — the record phase (trace row, + snapshot for the station), µs per tick, "
          "best of 3 runs each:")
    print(f"  without the snapshot {without:7.2f}   with it {with_:7.2f}   ratio "
          f"{with_ / without:.2f} (+{with_ - without:.2f} µs per tick)")
    snap.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
