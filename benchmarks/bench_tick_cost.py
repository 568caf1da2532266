"""What the haptic tick costs, against MuJoCo's ``mj_step`` on the same arm in the same run.

Part 1 - **the arm tick, as ratios to MuJoCo**: MuJoCo's ``mj_step`` on the same two-link arm
(the same segment lengths, masses, centres of mass and inertias, horizontal plane, Euler, the
loop's time step) is the baseline; beside it the plain-Python reference tick of one arm
(:meth:`fieldbank.sim.ArmSim.tick`: coupling + six muscles + joint stops + dynamics), the
compiled tick of one arm called from Python, the compiled call the loop makes (both arms and
the blend), the compiled tick inside compiled code (no call from Python) and, for the choice
between numba and a C extension, the floor of any call into C from Python (``math.hypot``).
Wall and CPU time per call are printed; the target (arm tick ≤ 0.5× ``mj_step``) is judged on
CPU time (neighbours on a shared machine inflate wall time, not the CPU this thread spends).
MuJoCo is optional (``pip install fieldbank[bench]``): without it the table says so and gives
the absolute figures only.

Part 2 - the other pieces of the tick in isolation (protocol encode and decode, safety,
recording, the station's snapshot).

Part 3 - the full renderer tick against the in-process simulated robot (sim://, lockstep): the
per-phase means the renderer measures itself; and the record phase with and without the
station's snapshot, as a ratio.

Part 3b - **the loop's own cost**: the renderer's tick against a robot port that answers at
once (:class:`InstantPort`: the handle on a Lissajous path, no device, no system call), CPU
time per tick in blocks of 5,000 (best block and median), beside MuJoCo's ``mj_step`` of the
same run as the ratio: what the renderer, its safety monitor, its models and its recording
cost, without the link.

Part 4 - **the whole haptic tick at ``--rate`` (4000 Hz) with the device in its own process**
(the simulated robot on a pty, real-time priority, its own core; the loop SCHED_FIFO on the
other where the system grants it), run twice in the same process: on the machine as it is (the
baseline) and beside ``--busy`` processes that spin on the processor (default: one per core,
what a clinic's PC running other software looks like). Each run renders ``--seconds`` in real
time and times every tick twice: wall time (what the loop's own clock saw, preemption
included) and this thread's CPU time (:func:`time.thread_time_ns`: what the tick itself cost).
The target - the tick's p99 at most 25 % of the period - is judged on the CPU time of the run
beside the busy processes; the wall time and the ratios busy / baseline are printed beside it,
and then the same ticks back to back (no waiting, the collector off as in the loop, the normal
scheduling policy: the busy processes share this thread's core) for their CPU time alone.

    python benchmarks/bench_tick_cost.py [--ticks 20000] [--rate 4000] [--seconds 10]
                                         [--busy N] [--only-whole-tick]
"""

from __future__ import annotations

import argparse
import array
import math
import os
import subprocess
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import numpy as np
from numba import njit
from timing import load_line, per_call

from fieldbank.armkernel import ArmPair, tick_one
from fieldbank.armkernel import tick_pair as kernel_pair
from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic import protocol as P
from fieldbank.haptic.clock import VirtualClock, realtime
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.pair import build_sim
from fieldbank.haptic.port import HandleState
from fieldbank.haptic.probe import sim_url
from fieldbank.haptic.recording import NCOL, TraceBuffer
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.safety import Safety, SafetyConfig
from fieldbank.haptic.simrobot import PtyRobot, SimRobotConfig
from fieldbank.haptic.snapshot import SnapshotWriter
from fieldbank.model import Arm
from fieldbank.params import ArmParams

#: Target: the compiled arm tick costs at most this share of MuJoCo's mj_step on the same arm.
ARM_TARGET = 0.5
#: Target: the whole tick's p99 at 4 kHz, as a share of the period.
TICK_TARGET = 0.25


def mujoco_arm(p: ArmParams, dt_s: float) -> tuple[object, object] | None:
    """MuJoCo's model and data of the arm ``p`` (two hinges about z, no gravity: the
    horizontal plane), or None when MuJoCo is not installed."""
    try:
        import mujoco
    except ImportError:
        return None
    # a point-like inertia about the link axis, the arm's own about z (valid: a + b >= c)
    i1, i2 = p.upper_arm_inertia_kg_m2, p.forearm_inertia_kg_m2
    xml = f"""<mujoco><option timestep="{dt_s}" integrator="Euler" gravity="0 0 0"/>
<worldbody><body name="upper"><joint name="shoulder" type="hinge" axis="0 0 1"/>
<inertial pos="{p.upper_arm_com_m} 0 0" mass="{p.upper_arm_mass_kg}"
  diaginertia="{i1} {i1} {i1}"/>
<body name="forearm" pos="{p.upper_arm_length_m} 0 0">
<joint name="elbow" type="hinge" axis="0 0 1"/>
<inertial pos="{p.forearm_com_m} 0 0" mass="{p.forearm_mass_kg}"
  diaginertia="{i2} {i2} {i2}"/></body></body></worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    d.qpos[:] = (0.5, 1.5)
    d.qfrc_applied[:] = (0.3, -0.2)  # the coupling's torque, as the loop's arm feels one
    return m, d


@njit(cache=True)
def _inside(params: np.ndarray, state: np.ndarray, n: int, hx: float, hy: float) -> float:
    """n one-arm ticks in compiled code (the cost without a call from Python)."""
    acc = 0.0
    for k in range(n):
        fx, fy = tick_one(params, state, hx + 1e-6 * (k % 7), hy, 0.0, 0.0)
        acc += fx + fy
    return acc


def arm_table(n: int, dt_s: float) -> float | None:
    """Part 1; MuJoCo's ``mj_step`` CPU µs per call (None without MuJoCo)."""
    before = synthesize({"elbow": "severe"})
    after = ArmParams.from_anthropometry()
    ref = build_sim(before, dt_s)
    x0, y0, _, _ = ref.hand()
    pair = ArmPair(Arm.from_params(before), Arm.from_params(after), dt_s)
    assert pair.params is not None and pair.state is not None
    p0, s0 = pair.params[0].copy(), pair.state[0].copy()
    out = np.zeros(6)
    P_, S_ = pair.params, pair.state
    _inside(p0, s0.copy(), 10, x0, y0)
    rows: list[tuple[str, float, float, float]] = []  # name, wall, cpu, arms per call

    def add(name: str, fn: object, arms: float = 1.0, number: int = n) -> None:
        w, c = per_call(fn, number)  # type: ignore[arg-type]
        rows.append((name, w, c, arms))

    mj = mujoco_arm(before, dt_s)
    if mj is not None:
        import mujoco

        m, d = mj
        add("MuJoCo mj_step, the same arm (baseline)", lambda: mujoco.mj_step(m, d))
    add("arm tick, plain Python (reference ArmSim.tick)",
        lambda: ref.tick(x0 + 0.01, y0, 0.0, 0.0))
    add("arm tick, compiled, one call per arm",
        lambda: tick_one(p0, s0, x0 + 0.01, y0, 0.0, 0.0))
    add("both arms + blend, compiled, one call (the loop's)",
        lambda: kernel_pair(P_, S_, out, x0 + 0.01, y0, 0.0, 0.0, 0.3, 1.0), arms=2.0)
    reps = max(1, n // 10)
    add("arm tick inside compiled code (x1000 per call)",
        lambda: _inside(p0, s0, 1000, x0, y0), arms=1000.0, number=reps)
    add("floor of a call into C from Python (math.hypot)", lambda: math.hypot(x0, y0))
    base_cpu = rows[0][2] if mj is not None else None
    print(f"Part 1 - the arm tick at {1 / dt_s:.0f} Hz, µs per arm (best of 5 runs of {n} "
          f"calls; {load_line()}):")
    print(f"  {'':52s} {'wall':>8s} {'CPU':>8s}  {'ratio to mj_step (CPU)':>22s}")
    for name, w, c, arms in rows:
        ratio = f"{c / arms / base_cpu:8.2f}×" if base_cpu else "   (no MuJoCo)"
        print(f"  {name:52s} {w / arms:8.3f} {c / arms:8.3f}  {ratio:>22s}")
    if base_cpu is None:
        print("  MuJoCo is not installed (pip install 'fieldbank[bench]'): no ratios, no "
              "verdict on the 0.5× target")
        return None
    one = rows[2][2] / base_cpu
    per_arm = rows[3][2] / 2 / base_cpu
    print(f"  target arm tick <= {ARM_TARGET:g}× mj_step (CPU): one call per arm {one:.2f}× "
          f"({'met' if one <= ARM_TARGET else 'NOT met'}); in the loop's call {per_arm:.2f}× "
          f"per arm ({'met' if per_arm <= ARM_TARGET else 'NOT met'})")
    return base_cpu


class InstantPort:
    """A robot port that answers at once: a new state on every poll, the handle on a
    Lissajous path of a few centimetres around (x0, y0), forces taken and dropped."""

    def __init__(self, x0: float, y0: float) -> None:
        self.state = HandleState(x=x0, y=y0)
        self.device = P.DeviceInfo(P.PROTOCOL_VERSION, "instant", 4000, 60.0, 20)
        self.x0, self.y0, self.k = x0, y0, 0

    def poll(self) -> int:
        st = self.state
        self.k += 1
        t = self.k * 1e-3
        st.x, st.y = self.x0 + 0.05 * math.sin(2 * t), self.y0 + 0.03 * math.sin(3 * t)
        st.vx, st.vy = 0.1 * math.cos(2 * t), 0.09 * math.cos(3 * t)
        st.states += 1
        return 1

    def wait_state(self, timeout_s: float, spin_s: float = 0.0) -> int:
        return self.poll()

    def send_force(self, fx_n: float, fy_n: float) -> None:
        pass

    def heartbeat(self) -> None:
        pass

    def arm(self) -> None:
        pass

    def disarm(self) -> None:
        pass

    def counters(self) -> dict[str, int]:
        return {"states": self.state.states}

    def close(self) -> None:
        pass


def own_cost(ticks: int, mj_step_cpu_us: float | None) -> None:
    """Part 3b: the renderer's tick against :class:`InstantPort`, CPU µs per tick."""
    before = synthesize({"elbow": "severe"})
    x0, y0 = (float(v) for v in Arm.from_params(before).rest_position())
    rd = Renderer(InstantPort(x0, y0), before, ArmParams.from_anthropometry(),
                  RendererConfig(realtime_priority=False))
    rd.start(expected_ticks=ticks + 10)
    block = 5000
    per_tick = []
    for _ in range(max(1, ticks // block)):
        c0 = time.thread_time_ns()
        for _ in range(block):
            rd.tick()
        per_tick.append((time.thread_time_ns() - c0) / block / 1e3)
    per_tick.sort()
    best, med = per_tick[0], per_tick[len(per_tick) // 2]
    ratio = f"; {best / mj_step_cpu_us:.1f}× mj_step" if mj_step_cpu_us else ""
    print(f"Part 3b - the loop's own cost: the renderer's tick against a port that answers at "
          f"once ({rd.safety.mode.name}, {len(per_tick)} blocks of {block} ticks; "
          f"{load_line()}):")
    print(f"  CPU per tick: best block {best:.2f} µs, median {med:.2f} µs{ratio}")


class _CpuTimedRenderer(Renderer):
    """The renderer with each tick's CPU time (this thread's) kept beside the wall time the
    renderer keeps itself."""

    cpu_ns: array.array[int]

    def tick(self) -> None:
        c0 = time.thread_time_ns()
        super().tick()
        self.cpu_ns.append(time.thread_time_ns() - c0)


def start_busy(n: int) -> list[subprocess.Popen[bytes]]:
    """``n`` processes that spin on the processor until killed (ordinary priority)."""
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]


def stop_busy(procs: list[subprocess.Popen[bytes]]) -> None:
    for p in procs:
        p.kill()
    for p in procs:
        p.wait()


def _busy_cpu_s(procs: list[subprocess.Popen[bytes]]) -> float:
    """The CPU time the busy processes spent so far, s (from /proc; 0 where there is none)."""
    total = 0.0
    tck = os.sysconf("SC_CLK_TCK")
    for p in procs:
        try:
            fields = open(f"/proc/{p.pid}/stat").read().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / tck
        except (OSError, IndexError, ValueError):
            pass
    return total


def _fixed_work() -> float:
    """A fixed piece of plain arithmetic, about as long as a tick (the back-to-back baseline)."""
    acc = 0.0
    for k in range(400):
        acc += k * 0.5
    return acc


def whole_tick(rate_hz: int, seconds: float, back_to_back: int,
               busy: int) -> dict[str, float]:
    """One run of Part 4 beside ``busy`` spinning processes; its figures (µs, shares)."""
    params = synthesize({"elbow": "severe"})
    after = ArmParams.from_anthropometry()
    x0, y0 = (float(v) for v in Arm.from_params(params).rest_position())
    period_us = 1e6 / rate_hz
    robot = PtyRobot(SimRobotConfig(mode="realtime", motion="explore", x0_m=x0, y0_m=y0))
    robot.start_process()
    link = RobotLink.open(robot.port)
    procs = start_busy(busy)
    try:
        link.handshake(rate_hz, 20, timeout_s=5.0)
        time.sleep(1.0 if busy else 0.0)  # the busy processes running before the loop starts
        load = load_line()
        spent0, w0 = _busy_cpu_s(procs), time.monotonic()
        rd = _CpuTimedRenderer(link, params, after, RendererConfig(rate_hz=rate_hz,
                                                                   record=True))
        rd.cpu_ns = array.array("q")
        trace = rd.run(seconds)
        busy_share = (_busy_cpu_s(procs) - spent0) / max(time.monotonic() - w0, 1e-9)
        st = trace.stats
        # the same ticks back to back (no waiting): CPU time per tick, this thread's own
        rd2 = Renderer(link, params, after, RendererConfig(rate_hz=rate_hz, record=True,
                                                           arm_on_start=False))
        rd2.start(expected_ticks=back_to_back)
        cpu = np.empty(back_to_back)
        tt_ = time.thread_time_ns
        # the collector frozen and off as in the loop (a collection inside a tick is not the
        # tick's cost: the loop never runs one), at the normal policy: the busy processes
        # compete with this thread for its core
        # the baseline: a fixed piece of arithmetic, timed the same way and interleaved with
        # the ticks, so what the platform adds (interrupts are charged to the running thread
        # where the kernel does not account them apart) falls on both
        fixed = np.empty(back_to_back)
        with realtime(priority=False):
            for i in range(back_to_back):
                c0 = tt_()
                rd2.tick()
                c1 = tt_()
                _fixed_work()
                fixed[i] = tt_() - c1
                cpu[i] = c1 - c0
        cpu /= 1e3
        fixed /= 1e3
        rd2.finish()
    finally:
        stop_busy(procs)
        link.close()
        robot.close()
    # every tick of the real-time run but the first 0.1 s (arming, the first states)
    skip = rate_hz // 10
    cpu_rt = np.array(rd.cpu_ns[skip:], dtype=np.float64) / 1e3
    wall_rt = np.array(rd.times.tick_ns[skip:], dtype=np.float64) / 1e3
    c50, c99, c999, cmax = np.percentile(cpu_rt, [50, 99, 99.9, 100])
    w50, w99, w999, wmax = np.percentile(wall_rt, [50, 99, 99.9, 100])
    b50, b99 = np.percentile(cpu, [50, 99])
    pe = st.get("period_error_us") or {}
    what = (f"beside {busy} busy process{'es' if busy != 1 else ''} (together "
            f"{busy_share:.2f} cores' worth of CPU meanwhile)" if busy else "the machine as it is")
    print(f"Part 4 - the whole tick at {rate_hz} Hz ({period_us:.0f} µs), {what}; device in "
          f"its own process ({robot.grant.text() if robot.grant else 'grant unknown'}), loop "
          f"{st.get('realtime')}; {seconds:g} s real time, {cpu_rt.size} ticks ({load}):")
    print(f"  CPU  per tick p50 {c50:6.1f} µs  p99 {c99:6.1f} µs  p99.9 {c999:7.1f} µs  max "
          f"{cmax:7.1f} µs: p99 = {100 * c99 / period_us:.1f}%, p99.9 = "
          f"{100 * c999 / period_us:.1f}% of the period")
    print(f"  wall per tick p50 {w50:6.1f} µs  p99 {w99:6.1f} µs  p99.9 {w999:7.1f} µs  max "
          f"{wmax:7.1f} µs: p99 = {100 * w99 / period_us:.1f}% of the period (wall p99 / CPU "
          f"p99 {w99 / c99:.1f}×)")
    print(f"  period error p50 {pe.get('p50', 0):.1f} µs  p99 {pe.get('p99', 0):.1f} µs; "
          f"overruns {st.get('overruns')}; skipped ticks {rd.times.skipped_ticks}; faults "
          f"{len(trace.faults)}")
    print("  phases (mean wall µs): " + ", ".join(f"{k} {v:.1f}"
                                                   for k, v in st["tick_cost_us"].items()))
    f50, f99 = np.percentile(fixed, [50, 99])
    print(f"  {back_to_back} ticks back to back at the normal policy, collector off: CPU per "
          f"tick p50 {b50:.1f} µs  p99 {b99:.1f} µs ({100 * b99 / period_us:.1f}% of the period)"
          f"; the fixed arithmetic between them p50 {f50:.1f} µs  p99 {f99:.1f} µs (p99 / p50: "
          f"tick {b99 / b50:.1f}×, fixed work {f99 / f50:.1f}×)")
    return {"cpu_p50": c50, "cpu_p99": c99, "cpu_p99.9": c999, "wall_p50": w50,
            "wall_p99": w99, "wall_p99.9": w999,
            "b2b_p99": b99, "fixed_p99": f99, "period_us": period_us}


def judge(base: dict[str, float], busy: dict[str, float] | None, n_busy: int) -> None:
    """The verdict on the 4 kHz target, and the busy run's ratios to the baseline run."""
    run = busy or base
    share = run["cpu_p99"] / run["period_us"]
    beside = f"beside {n_busy} busy processes" if busy else "without busy processes"
    print(f"Part 4 - verdict: the tick's CPU p99 {run['cpu_p99']:.1f} µs = {100 * share:.1f}% "
          f"of the period {beside} on {os.cpu_count()} cores"
          f" (target <= {100 * TICK_TARGET:.0f}%: {'met' if share <= TICK_TARGET else 'NOT met'})")
    if busy is not None:
        print("  busy / baseline, same run: " + ", ".join(
            f"{k.replace('_', ' ')} {busy[k] / base[k]:.2f}×"
            for k in ("cpu_p50", "cpu_p99", "cpu_p99.9", "wall_p50", "wall_p99", "wall_p99.9",
                      "b2b_p99", "fixed_p99")))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--ticks", type=int, default=20000)
    ap.add_argument("--rate", type=int, default=4000, help="Part 4's tick rate, Hz")
    ap.add_argument("--seconds", type=float, default=10.0, help="Part 4's real-time run, s")
    ap.add_argument("--busy", type=int, default=os.cpu_count() or 1,
                    help="Part 4's busy processes (default: one per core; 0: no busy run)")
    ap.add_argument("--only-whole-tick", action="store_true", help="Part 4 alone")
    a = ap.parse_args()
    if a.only_whole_tick:
        part4(a)
        return 0
    mj_cpu = arm_table(a.ticks, 1.0 / a.rate)
    before = synthesize({"elbow": "severe"})
    after = ArmParams.from_anthropometry()
    sa = build_sim(before, 1e-3)
    x0, y0, _, _ = sa.hand()
    state = P.encode_frame(P.MsgType.STATE, 1, P.STATE_FMT.pack(1, x0, y0, 0.01, -0.02, 1, 1))
    reader = P.FrameReader()
    safety = Safety(SafetyConfig(), 1e-3)
    safety.rearm((x0, y0, 0.0, 0.0))
    buf = TraceBuffer(10**6)
    row = tuple(float(i) for i in range(NCOL))
    snap = SnapshotWriter()

    parts = {
        "encode FORCE frame": lambda: P.encode_frame(P.MsgType.FORCE, 7,
                                                      P.FORCE_FMT.pack(1.5, -2.5)),
        "decode STATE frame (reader)": lambda: reader.feed(state),
        "safety (checks + passivity + limits)":
            lambda: (safety.check_handle(x0, y0, 0.01, 0.0), safety.output(3.0, 1.0, 0.01, 0.0)),
        "record one row": lambda: buf.add(0.0, row),
        "publish the snapshot (station)": lambda: snap.publish_row(0.0, 1, row, 3, False),
    }
    print("Part 2 - the other pieces in isolation (µs per call, best of 5; wall, CPU):")
    for name, fn in parts.items():
        w, c = per_call(fn, a.ticks)
        print(f"  {name:42s} {w:7.2f} {c:7.2f}")

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
    print(f"Part 3 - full renderer tick against sim:// ({a.ticks} ticks; the device's physics "
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
    print("Part 3 - the record phase (trace row, + snapshot for the station), µs per tick, "
          "best of 3 runs each:")
    print(f"  without the snapshot {without:7.2f}   with it {with_:7.2f}   ratio "
          f"{with_ / without:.2f} (+{with_ - without:.2f} µs per tick)")
    snap.close()
    own_cost(max(a.ticks, 50_000), mj_cpu)
    part4(a)
    return 0


def part4(a: argparse.Namespace) -> None:
    base = whole_tick(a.rate, a.seconds, a.ticks, 0)
    busy = whole_tick(a.rate, a.seconds, a.ticks, a.busy) if a.busy > 0 else None
    judge(base, busy, a.busy)


if __name__ == "__main__":
    sys.exit(main())
