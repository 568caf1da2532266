"""The real-time haptic loop: two virtual arms behind one handle, rendered safely.

Each tick (default 1 kHz, 500 Hz–4 kHz):

1. read the link without blocking and take the newest handle state (robot frame → shoulder
   frame by subtracting ``shoulder_offset_m``, the shoulder's position in robot coordinates);
2. check it (timeout, CRC, sequence gap, device fault, NaN, workspace, speed: :mod:`safety`);
3. tick both virtual arms (A = before, B = after) with the same handle state; each returns the
   force its coupling puts on the handle (:class:`fieldbank.sim.ArmSim`);
4. blend them, F = (1 − w) F_A + w F_B, where w follows a raised-cosine ramp on each switch so
   the force has no step; multiply by the arming/push gain (also raised-cosine);
5. pass F through the passivity controller, rate limit and saturation; send it;
6. record the row.

Timing: absolute deadlines on :func:`time.perf_counter_ns`; sleep until ``spin_us`` before the
deadline, then spin; the garbage collector is frozen and disabled inside the loop; SCHED_FIFO is
requested and a warning logged when the OS refuses. The period of every tick is kept; p50, p99,
max of the period error and the overruns (ticks that woke more than ``overrun_ms`` late) are
reported with a per-phase breakdown of the tick's cost. A :class:`VirtualClock` replaces the
wall clock in tests so a minute of rendering takes a fraction of that.

Commands (switch, push, arm, disarm, A/B/X, stop) come from other threads through
:meth:`Renderer.submit` and are applied at the start of a tick, so the loop's state has one
owner.
"""

from __future__ import annotations

import array
import gc
import logging
import math
import os
import queue
import sys
import threading
import time
from dataclasses import asdict, dataclass
from typing import Any, Protocol

import numpy as np

from fieldbank.errors import ParameterError, UnreachableError
from fieldbank.haptic.abx import AbxSession
from fieldbank.haptic.errors import CommandError, HapticError, LinkDown
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.protocol import FLAG_WATCHDOG, FaultCode
from fieldbank.haptic.recording import NCOL, Trace, TraceBuffer
from fieldbank.haptic.safety import Mode, Safety, SafetyConfig
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.sim import ArmSim, CouplingConfig

log = logging.getLogger("fieldbank.haptic.renderer")

#: GIL switch interval while the loop runs (default 5 ms would let another thread hold the
#: interpreter for several ticks).
SWITCH_INTERVAL_S = 1e-4

PHASES = ("link_in", "checks", "models", "safety", "link_out", "record")


@dataclass(frozen=True)
class RendererConfig:
    """Loop settings, SI."""

    rate_hz: int = 1000
    crossfade_s: float = 0.5            # A↔B switch ramp
    push_fade_s: float = 0.3            # fade out, swap models, fade in
    shoulder_offset_m: tuple[float, float] = (0.0, 0.0)
    state_wait_s: float = 0.0           # > 0: block up to this long for each STATE (lockstep)
    spin_us: float = 200.0
    overrun_ms: float = 1.0
    realtime_priority: bool = True
    record: bool = True
    arm_on_start: bool = True

    def __post_init__(self) -> None:
        if not (isinstance(self.rate_hz, int) and 500 <= self.rate_hz <= 4000):
            raise ParameterError(f"The 'rate_hz' parameter must be an integer in [500, 4000] Hz; "
                                 f"got {self.rate_hz!r}.")
        for name in ("crossfade_s", "push_fade_s", "state_wait_s", "spin_us", "overrun_ms"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ParameterError(f"The '{name}' parameter must be finite and >= 0; got {v!r}.")


class Clock(Protocol):
    def now_ns(self) -> int: ...
    def sleep_until(self, deadline_ns: int) -> None: ...


class RealClock:
    """Wall clock: sleep to ``spin_ns`` before the deadline, then spin."""

    def __init__(self, spin_us: float = 200.0) -> None:
        self.spin_ns = int(spin_us * 1000)

    def now_ns(self) -> int:
        return time.perf_counter_ns()

    def sleep_until(self, deadline_ns: int) -> None:
        pc = time.perf_counter_ns
        rem = deadline_ns - pc()
        if rem > self.spin_ns:
            time.sleep((rem - self.spin_ns) * 1e-9)
        while pc() < deadline_ns:
            pass


class VirtualClock:
    """Simulated time: sleeping jumps to the deadline at once."""

    def __init__(self) -> None:
        self.t_ns = 0

    def now_ns(self) -> int:
        return self.t_ns

    def sleep_until(self, deadline_ns: int) -> None:
        if deadline_ns > self.t_ns:
            self.t_ns = deadline_ns


class _Ramp:
    """Raised-cosine ramp from ``start`` to ``end`` over ``n`` ticks."""

    __slots__ = ("end", "k", "n", "start", "value")

    def __init__(self, value: float) -> None:
        self.value = self.start = self.end = value
        self.k = self.n = 0

    def go(self, end: float, n: int) -> None:
        self.start = self.value
        self.end = end
        self.k = 0
        self.n = max(1, n)

    def step(self) -> float:
        if self.k < self.n:
            self.k += 1
            s = self.k / self.n
            self.value = self.start + (self.end - self.start) * (0.5 - 0.5 * math.cos(math.pi * s))
        return self.value

    @property
    def moving(self) -> bool:
        return self.k < self.n

    def set(self, value: float) -> None:
        self.value = self.start = self.end = value
        self.k = self.n = 0


class Command:
    """A request to the loop; ``wait`` returns its result or raises its error."""

    __slots__ = ("args", "done", "error", "name", "result")

    def __init__(self, name: str, **args: Any) -> None:
        self.name = name
        self.args = args
        self.done = threading.Event()
        self.result: Any = None
        self.error: Exception | None = None

    def wait(self, timeout_s: float = 2.0) -> Any:
        if not self.done.wait(timeout_s):
            raise HapticError(f"the renderer did not answer {self.name!r} within {timeout_s} s")
        if self.error is not None:
            raise self.error
        return self.result


def build_sim(params: ArmParams, dt_s: float, coupling: CouplingConfig | None = None) -> ArmSim:
    """Compile a model for the loop (slow part, done outside the loop)."""
    return ArmSim(Arm.from_params(params), dt_s=dt_s, coupling=coupling)


class Renderer:
    """Renders model A (before) and B (after) through ``link``.

    Parameters
    ----------
    link : RobotLink
        Connected (handshake done) link.
    before, after : ArmParams
    config : RendererConfig, optional
    safety : SafetyConfig, optional
    clock : Clock, optional
        :class:`RealClock` by default; :class:`VirtualClock` to run faster than real time.
    coupling : CouplingConfig, optional
    """

    def __init__(self, link: RobotLink, before: ArmParams, after: ArmParams,
                 config: RendererConfig | None = None, safety: SafetyConfig | None = None,
                 clock: Clock | None = None, coupling: CouplingConfig | None = None) -> None:
        self.link = link
        self.config = config or RendererConfig()
        self.dt_s = 1.0 / self.config.rate_hz
        self.period_ns = round(1e9 / self.config.rate_hz)
        self.safety = Safety(safety or SafetyConfig(), self.dt_s)
        self.clock: Clock = clock or RealClock(self.config.spin_us)
        self.coupling = coupling
        self.params = (before, after)
        self.sims = (build_sim(before, self.dt_s, coupling), build_sim(after, self.dt_s, coupling))
        self.blend = _Ramp(0.0)
        self.gain = _Ramp(0.0)
        self.commands: queue.SimpleQueue[Command] = queue.SimpleQueue()
        self.events: list[dict[str, Any]] = []
        self.abx: AbxSession | None = None
        self.abx_results: list[dict[str, Any]] = []
        self._pending: tuple[tuple[ArmSim, ArmSim], tuple[ArmParams, ArmParams]] | None = None
        self._pending_ids: dict[str, int | None] | None = None
        self._link_down = False
        self._stale = 0
        self._awaiting = False
        self._timeout_ticks = max(1, math.ceil(self.safety.config.state_timeout_ms * 1e-3
                                               / self.dt_s))
        self._device_faults_seen = 0
        self._stop = False
        self.running = False
        self.t_s = 0.0
        self.ticks = 0
        self.fx = self.fy = 0.0
        self.trace: Trace | None = None
        self._buf: TraceBuffer | None = None
        self._wake = array.array("q")
        self._late = array.array("q")
        self._cost = [0] * len(PHASES)
        self._tick_ns = array.array("q")
        self.realtime_scheduling: bool | None = None
        self.skipped_ticks = 0
        self.metadata: dict[str, Any] = {}

    # --- thread-safe requests ---------------------------------------------------------------
    def submit(self, name: str, **args: Any) -> Command:
        """Queue a command for the loop (``switch``, ``push``, ``arm``, ``disarm``, ``stop``,
        ``abx_start``, ``abx_present``, ``abx_answer``, ``status``)."""
        cmd = Command(name, **args)
        if not self.running and name not in ("push", "switch", "stop", "status"):
            cmd.error = HapticError("the renderer is not running")
            cmd.done.set()
            return cmd
        self.commands.put(cmd)
        if not self.running:
            self._drain()
        return cmd

    def push_params(self, before: ArmParams, after: ArmParams,
                    model_ids: dict[str, int | None] | None = None) -> Command:
        """Compile two models here (outside the loop) and queue them for a faded swap.

        ``model_ids``: database ids of the two models ({'A': id, 'B': id}), kept in the trace.
        """
        sims = (build_sim(before, self.dt_s, self.coupling),
                build_sim(after, self.dt_s, self.coupling))
        return self.submit("push", sims=sims, params=(before, after), model_ids=model_ids)

    # --- command handling (loop thread) -----------------------------------------------------
    def _drain(self) -> None:
        while True:
            try:
                cmd = self.commands.get_nowait()
            except queue.Empty:
                return
            try:
                cmd.result = self._apply(cmd)
            except Exception as exc:  # a bad command must never stop the loop
                cmd.error = exc
            cmd.done.set()

    def _event(self, kind: str, **data: Any) -> dict[str, Any]:
        ev = {"t_s": self.t_s, "event": kind, **data}
        self.events.append(ev)
        return ev

    def _apply(self, cmd: Command) -> Any:
        a = cmd.args
        n_fade = round(self.config.crossfade_s / self.dt_s)
        if cmd.name == "switch":
            target = a["target"]
            w = {"A": 0.0, "B": 1.0, "before": 0.0, "after": 1.0, 0: 0.0, 1: 1.0}.get(target)
            if w is None:
                raise HapticError(f"switch to 'before'/'A' or 'after'/'B'; got {target!r}")
            self.blend.go(w, n_fade)
            self._event("switch", to=w)
            return {"blend_target": w}
        if cmd.name == "push":
            self._pending = (a["sims"], a["params"])
            self._pending_ids = a.get("model_ids")
            if not self.running:
                self._swap()
            else:
                self.gain.go(0.0, round(self.config.push_fade_s / self.dt_s))
            self._event("push")
            return {"pushed": True}
        if cmd.name == "arm":
            self.arm()
            return {"mode": self.safety.mode.name}
        if cmd.name == "disarm":
            self.disarm()
            return {"mode": self.safety.mode.name}
        if cmd.name == "stop":
            self._stop = True
            self._event("stop")
            return {"stopping": True}
        if cmd.name == "status":
            return self.status()
        if cmd.name == "abx_start":
            self.abx = AbxSession(int(a.get("n_trials", 10)), int(a.get("seed", 0)),
                                  bool(a.get("hide_labels", True)))
            self._event("abx_start", n_trials=self.abx.n_trials, seed=self.abx.seed)
            return {"trial": 0, "n_trials": self.abx.n_trials}
        if cmd.name == "abx_present":
            if self.abx is None:
                raise HapticError("no A/B/X block running; start one with abx_start")
            label = str(a["label"]).upper()
            self.blend.go(float(self.abx.model_for(label)), n_fade)
            self._event("abx_present", label=label, trial=self.abx.trial)
            return {"presenting": label, "trial": self.abx.trial}
        if cmd.name == "abx_answer":
            if self.abx is None:
                raise HapticError("no A/B/X block running; start one with abx_start")
            rec = self.abx.answer(str(a["answer"]), self.t_s)
            self._event("abx_answer", trial=rec["trial"], answer=rec["answer"])
            out = {"trial": rec["trial"] + 1, "done": self.abx.done}
            if self.abx.done:
                self.abx_results.append(self.abx.result())
                out["result"] = self.abx.result()
                self.abx = None
            return out
        raise HapticError(f"unknown renderer command {cmd.name!r}")

    def _swap(self) -> None:
        assert self._pending is not None
        sims, params = self._pending
        self._pending = None
        self.sims = sims
        self.params = params
        if self._pending_ids:
            self.metadata["model_ids"] = dict(self._pending_ids)
        else:
            self.metadata.pop("model_ids", None)
        self._reset_arms()

    def _reset_arms(self) -> None:
        ox, oy = self.config.shoulder_offset_m
        hx, hy = self.link.x - ox, self.link.y - oy
        self._event("reset_arms", at_m=[hx, hy])
        for sim in self.sims:
            try:
                if math.isfinite(hx) and math.isfinite(hy):
                    sim.reset_at_hand(hx, hy)
                else:
                    sim.reset()
            except (UnreachableError, ValueError):
                sim.reset()

    def arm(self) -> None:
        """Arm (or re-arm after a fault): refused while the handle state is unsafe."""
        if self._link_down:
            raise CommandError("cannot arm: the robot link is down")
        if self.safety.latched & (1 << (FaultCode.MODEL - 1)):
            self._reset_arms()
        self.safety.rearm((self.link.x, self.link.y, self.link.vx, self.link.vy))
        self._stale = 0
        self._device_faults_seen = self.link.device_faults
        try:
            self.link.arm()
        except LinkDown as exc:
            self._trip(FaultCode.DISCONNECT, str(exc))
            raise CommandError(f"cannot arm: {exc}") from None
        self.gain.set(0.0)
        self.gain.go(1.0, round(self.safety.config.rearm_ramp_s / self.dt_s))
        self._event("arm")

    def disarm(self) -> None:
        self.safety.disarm()
        self.gain.set(0.0)
        if not self._link_down:
            try:
                self.link.disarm()
            except LinkDown as exc:
                self._trip(FaultCode.DISCONNECT, str(exc))
        self._event("disarm")

    def _trip(self, code: int, message: str) -> None:
        first = not (self.safety.latched & (1 << (code - 1)))
        self.safety.trip(code, self.t_s, message)
        self.gain.set(0.0)
        if first:
            self._event("fault", code=int(code), name=FaultCode(code).name)
        if not self._link_down:
            try:
                self.link.disarm()
            except LinkDown:
                self._link_down = True

    # --- the tick ---------------------------------------------------------------------------
    def tick(self) -> None:
        """One loop iteration (public so tests and benchmarks can drive it directly)."""
        pc = time.perf_counter_ns
        c0 = pc()
        link = self.link
        safety = self.safety
        armed = safety.mode == Mode.ARMED
        new = 0
        if not self._link_down:
            try:
                wait = self.config.state_wait_s
                # lockstep devices answer each FORCE with one STATE: wait for it, not for more
                new = link.wait_state(wait) if wait > 0 and self._awaiting else link.poll()
            except LinkDown as exc:
                self._link_down = True
                self._trip(FaultCode.DISCONNECT, str(exc))
        if self.commands.qsize():
            self._drain()
        c1 = pc()
        ox, oy = self.config.shoulder_offset_m
        x, y, vx, vy = link.x - ox, link.y - oy, link.vx, link.vy
        self._stale = 0 if new else self._stale + 1
        if armed:
            if safety.check_crc(link.crc_errors):
                self._trip(FaultCode.CRC, f"{link.crc_errors} CRC errors (leaky bucket "
                                          f"{safety.crc_bucket:.1f} > "
                                          f"{safety.config.crc_error_limit})")
            gap = link.take_gap()
            if gap > safety.config.max_seq_gap:
                self._trip(FaultCode.SEQ_GAP, f"{gap} frames lost in one gap")
            if self._stale > self._timeout_ticks:
                self._trip(FaultCode.TIMEOUT, f"no STATE for {self._stale} ticks")
            if link.device_faults != self._device_faults_seen:
                self._device_faults_seen = link.device_faults
                self._trip(FaultCode.DEVICE, f"device fault code {link.last_device_fault}")
            if link.flags & FLAG_WATCHDOG:
                self._trip(FaultCode.DEVICE, "device watchdog tripped")
            code, msg = safety.check_handle(link.x, link.y, vx, vy)
            if code:
                self._trip(code, msg)
        else:
            link.take_gap()
            safety.check_crc(link.crc_errors)
        c2 = pc()
        sim_a, sim_b = self.sims
        fa_x = fa_y = fb_x = fb_y = 0.0
        if math.isfinite(x) and math.isfinite(y) and math.isfinite(vx) and math.isfinite(vy):
            try:
                fa_x, fa_y = sim_a.tick(x, y, vx, vy)
                fb_x, fb_y = sim_b.tick(x, y, vx, vy)
                ok = math.isfinite(fa_x + fa_y) and math.isfinite(fb_x + fb_y)
            except (ArithmeticError, ValueError):  # overflow inside a diverging arm
                ok = False
            if not ok:
                self._trip(FaultCode.MODEL, "a virtual arm diverged (non-finite force)")
                self._reset_arms()
                fa_x = fa_y = fb_x = fb_y = 0.0
        w = self.blend.step()
        g = self.gain.step()
        if self._pending is not None and g == 0.0 and not self.gain.moving:
            self._swap()
            if safety.mode == Mode.ARMED:
                self.gain.go(1.0, round(self.config.push_fade_s / self.dt_s))
        mx = g * ((1.0 - w) * fa_x + w * fb_x)
        my = g * ((1.0 - w) * fa_y + w * fb_y)
        c3 = pc()
        fx, fy = safety.output(mx, my, vx, vy)
        if safety.limiter.nan_seen:
            safety.limiter.nan_seen = False
            self._trip(FaultCode.NAN, "non-finite force from the model")
            fx = fy = 0.0
        if safety.mode != Mode.ARMED:
            fx = fy = 0.0
        c4 = pc()
        if not self._link_down:
            try:
                link.send_force(fx, fy)
                self._awaiting = True
            except LinkDown as exc:
                self._link_down = True
                self._trip(FaultCode.DISCONNECT, str(exc))
                fx = fy = 0.0
        self.fx, self.fy = fx, fy
        c5 = pc()
        buf = self._buf
        if buf is not None:
            sa, sb = sim_a.state, sim_b.state
            buf.add(self.t_s, (link.x, link.y, vx, vy, fx, fy, mx, my, w, g,
                               sa.q1, sa.q2, sa.qd1, sa.qd2, sb.q1, sb.q2, sb.qd1, sb.qd2,
                               float(safety.mode), float(safety.latched), float(new),
                               safety.passivity.energy_j))
        c6 = pc()
        cost = self._cost
        cost[0] += c1 - c0
        cost[1] += c2 - c1
        cost[2] += c3 - c2
        cost[3] += c4 - c3
        cost[4] += c5 - c4
        cost[5] += c6 - c5
        self._tick_ns.append(c6 - c0)
        self.ticks += 1
        self.t_s += self.dt_s

    # --- the loop ---------------------------------------------------------------------------
    def _enter_realtime(self) -> Any:
        if not self.config.realtime_priority or not hasattr(os, "sched_setscheduler"):
            self.realtime_scheduling = False
            return None
        try:
            old = (os.sched_getscheduler(0), os.sched_getparam(0))
            prio = max(1, min(80, os.sched_get_priority_max(os.SCHED_FIFO) - 10))
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(prio))
            self.realtime_scheduling = True
            return old
        except (PermissionError, OSError) as exc:
            self.realtime_scheduling = False
            log.warning("real-time scheduling (SCHED_FIFO) refused by the OS (%s); the loop runs "
                        "with normal priority and its timing will show more jitter", exc)
            return None

    @staticmethod
    def _leave_realtime(old: Any) -> None:
        if old is not None:
            try:
                os.sched_setscheduler(0, old[0], old[1])
            except OSError:
                pass

    def start(self, first_state_timeout_s: float = 1.0, expected_ticks: int | None = None) -> None:
        """Wait for the first STATE, put both arms at the handle, arm (``arm_on_start``)."""
        cfg = self.config
        if not self.link.wait_state(first_state_timeout_s) and self.link.states == 0:
            raise HapticError(f"no STATE from the robot within {first_state_timeout_s} s")
        self._reset_arms()
        self._buf = TraceBuffer(expected_ticks or 60 * cfg.rate_hz) if cfg.record else None
        self._wake = array.array("q")
        self._late = array.array("q")
        self.running = True
        self._stop = False
        if cfg.arm_on_start:
            try:
                self.arm()
            except HapticError as exc:
                log.warning("not armed at start: %s", exc)

    def finish(self) -> Trace:
        """Command zero force, disarm the device, answer pending commands; return the trace."""
        self.running = False
        try:
            if not self._link_down:
                self.link.send_force(0.0, 0.0)
                self.link.disarm()
        except LinkDown:
            self._link_down = True
        self._drain()
        self.trace = self._make_trace()
        return self.trace

    def run(self, duration_s: float | None = None, first_state_timeout_s: float = 1.0) -> Trace:
        """Render until ``duration_s`` passes or a ``stop`` command; return the session trace."""
        cfg = self.config
        n_ticks = None if duration_s is None else max(1, round(duration_s * cfg.rate_hz))
        # collect and freeze before arming: a full collection can take longer than the device
        # watchdog, and nothing may stand between the ARM frame and the first FORCE
        gc.collect()
        gc.freeze()
        gc_was_enabled = gc.isenabled()
        gc.disable()
        old_sched = self._enter_realtime()
        try:
            self.start(first_state_timeout_s, n_ticks)
        except BaseException:
            if gc_was_enabled:
                gc.enable()
            gc.unfreeze()
            self._leave_realtime(old_sched)
            raise
        clock = self.clock
        period = self.period_ns
        wake = self._wake
        late = self._late
        end = None if n_ticks is None else self.ticks + n_ticks
        errstate = np.errstate(over="ignore", invalid="ignore")  # diverging arms are faults
        errstate.__enter__()
        # other threads (control channel) must hand the interpreter back quickly
        old_switch = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        try:
            deadline = clock.now_ns()
            while not self._stop and (end is None or self.ticks < end):
                clock.sleep_until(deadline)
                now = clock.now_ns()
                wake.append(now)
                late.append(now - deadline)
                self.tick()
                deadline += period
                if now >= deadline:
                    # a whole period late: skip the missed ticks instead of bursting through
                    # them back to back (which would read no new state and command stale forces)
                    skipped = (now - deadline) // period + 1
                    self.skipped_ticks += skipped
                    deadline += skipped * period
        except KeyboardInterrupt:
            self._event("interrupted")
        finally:
            sys.setswitchinterval(old_switch)
            errstate.__exit__(None, None, None)
            if gc_was_enabled:
                gc.enable()
            gc.unfreeze()
            self._leave_realtime(old_sched)
            self.running = False
        return self.finish()

    # --- reporting --------------------------------------------------------------------------
    def loop_stats(self, last: int | None = None) -> dict[str, Any]:
        """Period error (ns → µs) percentiles, overruns, tick cost breakdown; over the whole
        session or its ``last`` ticks. Safe to call from another thread while the loop runs
        (it works on copies: a numpy view would stop the loop's arrays from growing)."""
        k = -last if last else 0
        wake = np.array(self._wake[k:], dtype=np.float64)
        late = np.array(self._late[k:], dtype=np.float64)
        tick_ns = np.array(self._tick_ns[k:], dtype=np.float64)
        out: dict[str, Any] = {"ticks": self.ticks, "rate_hz": self.config.rate_hz,
                               "realtime_scheduling": self.realtime_scheduling}
        if late.size >= 2:
            # period error: actual period between wakes minus nominal
            periods_ns = np.diff(wake)
            per_err = np.abs(periods_ns - self.period_ns)
            out["period_error_us"] = {
                "p50": float(np.percentile(per_err, 50) / 1e3),
                "p99": float(np.percentile(per_err, 99) / 1e3),
                "max": float(per_err.max() / 1e3),
            }
            periods = periods_ns / 1e3
            out["period_us"] = {"p50": float(np.percentile(periods, 50)),
                                "p99": float(np.percentile(periods, 99)),
                                "max": float(periods.max())}
            out["wake_late_us"] = {"p50": float(np.percentile(late, 50) / 1e3),
                                   "p99": float(np.percentile(late, 99) / 1e3),
                                   "max": float(late.max() / 1e3)}
            thr = self.config.overrun_ms * 1e6
            over = late > thr
            out["overruns"] = int(over.sum())
            out["overrun_threshold_ms"] = self.config.overrun_ms
            out["skipped_ticks"] = self.skipped_ticks
            out["overrun_times_s"] = [float((wake[i] - wake[0]) / 1e9)
                                      for i in np.flatnonzero(over)[:100]]
        n = max(1, self.ticks)
        out["tick_cost_us"] = {name: self._cost[i] / n / 1e3 for i, name in enumerate(PHASES)}
        out["tick_cost_us"]["total"] = sum(self._cost) / n / 1e3
        if tick_ns.size:
            tc = tick_ns / 1e3
            # percentiles are robust to the few ticks preempted mid-way (the mean is not)
            out["tick_total_us"] = {"p50": float(np.percentile(tc, 50)),
                                    "p99": float(np.percentile(tc, 99)),
                                    "max": float(tc.max())}
        out["passivity_active_ticks"] = self.safety.passivity.active_ticks
        out["link"] = {"crc_errors": self.link.crc_errors,
                       "decode_errors": dict(self.link.reader.errors),
                       "frames_lost": self.link.frames_lost, "duplicates": self.link.duplicates,
                       "states": self.link.states, "frames_tx": self.link.frames_tx}
        return out

    def status(self) -> dict[str, Any]:
        s = self.safety
        return {
            "running": self.running, "mode": s.mode.name, "t_s": round(self.t_s, 4),
            "ticks": self.ticks, "gain": self.gain.value,
            # while an A/B/X block runs, which model is rendered is hidden
            "blend": "hidden" if self.abx is not None else self.blend.value,
            "force_n": [self.fx, self.fy],
            "handle_m": [self.link.x, self.link.y],
            "latched_faults": [c.name for c in FaultCode if s.latched & (1 << (c - 1))],
            "faults_logged": len(s.log_records),
            "loop_last_10s": {k: v for k, v in self.loop_stats(last=10 * self.config.rate_hz)
                              .items() if k in ("period_error_us", "overruns", "skipped_ticks",
                                                "tick_total_us", "realtime_scheduling")},
            "abx_trial": None if self.abx is None else self.abx.trial,
        }

    def _make_trace(self) -> Trace:
        if self._buf is not None:
            t, data = self._buf.arrays()
        else:
            t, data = np.zeros(0), np.zeros((0, NCOL), np.float32)
        meta = dict(self.metadata)
        meta.setdefault("renderer", {k: (list(v) if isinstance(v, tuple) else v)
                                     for k, v in asdict(self.config).items()})
        meta.setdefault("safety", {k: (list(v) if isinstance(v, tuple) else v)
                                   for k, v in asdict(self.safety.config).items()})
        if self.link.device is not None:
            meta.setdefault("device", asdict(self.link.device))
        if self.abx is not None:
            self.abx_results.append(self.abx.result())
        meta["abx"] = self.abx_results
        return Trace(t_s=t, data=data.astype(np.float32, copy=False),
                     rate_hz=float(self.config.rate_hz),
                     models={"A": self.params[0].to_dict(), "B": self.params[1].to_dict()},
                     events=list(self.events),
                     faults=[r.to_dict() for r in self.safety.log_records],
                     stats=self.loop_stats(), metadata=meta)
