"""Host-side protocol round trip over a pty: FORCE out, the device's STATE reply back.

The simulated robot runs in its own process on the master end of a pty in lockstep mode (it
answers each FORCE with a STATE after stepping its physics); the host uses the same RobotLink
as the renderer, busy-polling for the reply up to ``--spin-us`` (300 µs) and then sleeping in
select(); the same run also times select() alone (``--spin`` busy-polls without limit). The time
runs from just before encoding the FORCE to the moment the STATE echoing that FORCE's sequence
number is decoded. Target: p99 <= 150 µs. The host asks for SCHED_FIFO like the renderer
(``--no-fifo`` not to). A second figure times the framing alone, in one process.

    python benchmarks/bench_protocol_rtt.py [--n 20000] [--spin] [--no-fifo]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import numpy as np

from fieldbank.haptic import protocol as P
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.simrobot import PtyRobot, SimRobotConfig

ECHO = """
import os, select, sys
fd = int(sys.argv[1])
while True:
    select.select([fd], [], [])
    data = os.read(fd, 4096)
    if not data:
        break
    os.write(fd, data)
"""


def raw_echo_rtt(n: int) -> np.ndarray:
    """Baseline: the same pty, a process that echoes bytes back with no protocol at all."""
    import subprocess
    import tty

    m, s = os.openpty()
    tty.setraw(m)
    tty.setraw(s)
    proc = subprocess.Popen([sys.executable, "-c", ECHO, str(m)], pass_fds=(m,))
    frame = P.encode_frame(P.MsgType.FORCE, 1, P.FORCE_FMT.pack(0.0, 0.0))
    import select

    out = np.empty(n)
    pc = time.perf_counter_ns
    try:
        for i in range(n):
            t0 = pc()
            os.write(s, frame)
            got = 0
            while got < len(frame):
                select.select([s], [], [], 0.1)
                got += len(os.read(s, 4096))
            out[i] = pc() - t0
    finally:
        proc.kill()
        proc.wait()
        os.close(m)
        os.close(s)
    return out / 1e3


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=20000)
    ap.add_argument("--spin", action="store_true",
                    help="poll for the reply in a busy loop instead of sleeping in select()")
    ap.add_argument("--spin-us", type=float, default=300.0,
                    help="busy-poll this long for each reply before sleeping in select() "
                         "(the hybrid wait; default 300)")
    ap.add_argument("--no-fifo", action="store_true", help="do not ask for SCHED_FIFO")
    a = ap.parse_args()
    robot = PtyRobot(SimRobotConfig(mode="lockstep")).start_process()
    fifo = False
    try:
        if a.no_fifo:
            raise OSError("not asked")  # the same priority the renderer asks for
        os.sched_setscheduler(0, os.SCHED_FIFO,
                              os.sched_param(os.sched_get_priority_max(os.SCHED_FIFO) - 10))
        fifo = True
    except (OSError, AttributeError):
        pass
    link = RobotLink.open(robot.port)
    try:
        link.handshake(1000, 20, timeout_s=3.0)
        link.arm()
        pc = time.perf_counter_ns

        def exchanges(spin_s: float, busy: bool) -> tuple[np.ndarray, int]:
            rtt = np.empty(a.n)
            lost = 0
            for i in range(a.n):
                t0 = pc()
                seq = link.send_force(0.0, 0.0)
                give_up = t0 + 100_000_000
                while True:
                    got = link.poll() if busy else link.wait_state(0.1, spin_s)
                    if got and link.echo_seq == seq:
                        break
                    if pc() > give_up:
                        lost += 1
                        break
                rtt[i] = pc() - t0
            return rtt, lost

        rtt, lost = exchanges(a.spin_us * 1e-6, a.spin)
        rtt_select, lost_select = exchanges(0.0, False)
        # baseline in the same process: encode + decode of the two frames, no I/O
        f = P.encode_frame(P.MsgType.STATE, 1, P.STATE_FMT.pack(0, 0, 0, 0, 0, 0, 0))
        r = P.FrameReader()
        t0 = pc()
        for _ in range(a.n):
            r.feed(P.encode_frame(P.MsgType.FORCE, 1, P.FORCE_FMT.pack(0.0, 0.0)))
            r.feed(f)
        codec_us = (pc() - t0) / a.n / 1e3
    finally:
        link.close()
        robot.close()
    us = rtt / 1e3
    p50, p99 = np.percentile(us, [50, 99])
    echo = raw_echo_rtt(a.n)
    e50, e99 = np.percentile(echo, [50, 99])
    print(f"protocol round trip over a pty ({a.n} FORCE→STATE exchanges, device process; "
          f"SCHED_FIFO {'granted' if fifo else 'refused'}):")
    mode = "busy poll" if a.spin else f"spin ≤ {a.spin_us:g} µs, then select()"
    print(f"  {mode}: p50 {p50:7.1f} µs   p99 {p99:7.1f} µs   max {us.max():8.1f} µs   "
          f"lost {lost}   (target p99 <= 150 µs: {'met' if p99 <= 150 else 'NOT met'})")
    us_sel = rtt_select / 1e3
    s50, s99 = np.percentile(us_sel, [50, 99])
    print(f"  select() only (no spin): p50 {s50:7.1f} µs   p99 {s99:7.1f} µs   max "
          f"{us_sel.max():8.1f} µs   lost {lost_select}")
    print(f"  baseline, raw byte echo over the same kind of pty (no protocol, no physics): "
          f"p50 {e50:.1f} µs   p99 {e99:.1f} µs   max {echo.max():.1f} µs  "
          f"(ratio p99 / baseline p99 {p99 / e99:.2f}×)")
    print(f"  of which framing alone (encode FORCE, decode FORCE, decode STATE; no I/O) "
          f"in one process: {codec_us:.1f} µs (ratio p50 / codec {p50 / codec_us:.1f}×)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
