"""The real-time haptic loop: two virtual arms behind one handle, rendered safely.

:meth:`Renderer.tick` reads top to bottom as each tick runs (default 1 kHz, 500 Hz–4 kHz):
read state → models → safety → force out → record. The renderer keeps the loop alone; what it
ticks is behind seams: the robot (:class:`~haptic.port.RobotPort`), every fault check and the
counters they keep (:class:`~haptic.monitor.SafetyMonitor`), arms A (before) and B (after) with
their raised-cosine blend and fades (:class:`~haptic.pair.ModelPair`), the A/B/X blocks and
training protocols the commands address (:mod:`haptic.activities`), a display's snapshot in
shared memory (:mod:`haptic.snapshot`). ``docs/haptics.md`` describes every step.

Timing (:mod:`haptic.clock`): absolute deadlines on a :class:`~haptic.clock.Clock` (a
:class:`~haptic.clock.VirtualClock` runs faster than real time), inside
:func:`~haptic.clock.realtime`; each tick's wake time and phase costs are kept
(:mod:`haptic.loopstats`). Commands (:mod:`haptic.commands`) from other threads
(:meth:`Renderer.submit`) are applied at the start of a tick: the loop's state has one owner.
Read-outs: :mod:`haptic.readouts`; the session's trace: :mod:`haptic.assemble`.
"""

from __future__ import annotations

import logging
import queue
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from fieldbank.haptic import commands, readouts
from fieldbank.haptic.activities.base import Activities
from fieldbank.haptic.assemble import assemble_trace, utc_now
from fieldbank.haptic.clock import Clock, Grant, RealClock, realtime
from fieldbank.haptic.commandbase import RendererCommand, Result
from fieldbank.haptic.commands import Request
from fieldbank.haptic.errors import CommandError, HapticError
from fieldbank.haptic.loopstats import LoopTimes, loop_stats
from fieldbank.haptic.modelinfo import ModelIds, ModelInfoPair
from fieldbank.haptic.monitor import SafetyMonitor
from fieldbank.haptic.pair import Environment, ModelPair, SimPair
from fieldbank.haptic.port import RobotPort
from fieldbank.haptic.protocol import FaultCode
from fieldbank.haptic.recording import Trace, TraceBuffer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.safety import Mode, SafetyConfig
from fieldbank.haptic.snapshot import SnapshotWriter
from fieldbank.params import ArmParams
from fieldbank.sim import CouplingConfig

log = logging.getLogger("fieldbank.haptic.renderer")
_MODEL_BIT = 1 << (FaultCode.MODEL - 1)


class Renderer:
    """Renders model A (before) and B (after) through ``port`` (a connected robot, handshake
    done); ``clock``: :class:`~haptic.clock.RealClock` by default; ``environment``: what is
    ticked in place of each compiled arm (:data:`haptic.pair.Environment`: the remote link)."""

    def __init__(self, port: RobotPort, before: ArmParams, after: ArmParams,
                 config: RendererConfig | None = None, safety: SafetyConfig | None = None,
                 clock: Clock | None = None, coupling: CouplingConfig | None = None,
                 environment: Environment | None = None) -> None:
        cfg = self.config = config or RendererConfig()
        self.port = port
        self.dt_s = 1.0 / cfg.rate_hz
        self.period_ns = round(1e9 / cfg.rate_hz)
        self.monitor = SafetyMonitor(port, safety or SafetyConfig(), self.dt_s, self._on_fault,
                                     spin_s=min(cfg.spin_us * 1e-6, 0.5 * self.dt_s))
        #: the latched state machine and the force path (the monitor's)
        self.safety = self.monitor.safety
        self.clock: Clock = clock or RealClock(cfg.spin_us)
        self.pair = ModelPair(before, after, self.dt_s, cfg.crossfade_s, cfg.push_fade_s,
                              coupling, cfg.compiled_tick, environment)
        self.activities = Activities()
        self.commands: queue.SimpleQueue[Request] = queue.SimpleQueue()
        self.events: list[dict[str, Any]] = []
        #: Publishes each tick's state for a display in another process (haptic.station).
        self.snapshot: SnapshotWriter | None = None
        self.metadata: dict[str, Any] = {}
        self.running = self._stop = self._awaiting = False
        self.t_s, self.ticks, self.fx, self.fy = 0.0, 0, 0.0, 0.0
        self.trace: Trace | None = None
        self._buf: TraceBuffer | None = None
        self.times = LoopTimes()
        # the tick appends to these two directly (never replaced, unlike the wake records)
        self._cost = self.times.phase_ns
        self._tick_ns = self.times.tick_ns
        #: What the OS granted the loop: priority, core, refusals (haptic.clock.Grant).
        self.realtime_grant: Grant | None = None
        #: How a stop winds down (None: at once; a remote link ramps out, then :meth:`stop_now`)
        self.wind_down: Callable[[], None] | None = None

    # --- the tick ---------------------------------------------------------------------------
    def tick(self) -> None:
        """One loop iteration (public so tests and benchmarks can drive it directly)."""
        pc = time.perf_counter_ns
        c0 = pc()
        # read state: the port, then the commands of this tick, then the tick's evidence
        # judged (a re-arm applied now is checked now, before any force goes out)
        m = self.monitor
        st = m.state
        new = m.read(self.config.state_wait_s if self._awaiting else 0.0, self.t_s)
        if self.commands.qsize():
            self._drain()
        c1 = pc()
        m.check(new)
        c2 = pc()
        # models: both arms with the same handle state, blended and scaled in one call
        ox, oy = self.config.shoulder_offset_m
        x, y, vx, vy = st.x - ox, st.y - oy, st.vx, st.vy
        pair = self.pair
        arms = pair.sims
        mx, my, ok = pair.tick(x, y, vx, vy)
        w, g = pair.blend.value, pair.gain.value
        if not ok:
            m.diverged()
            self._reset_arms()
        if pair.pending is not None and g == 0.0 and not pair.gain.moving:
            self._swap()  # pushed models, once the gain has faded out
        c3 = pc()
        # safety: passivity, rate limit, saturation; zero unless armed
        fx, fy = m.output(mx, my, vx, vy)
        c4 = pc()
        # force out
        if m.send(fx, fy):
            self._awaiting = True
        else:
            fx = fy = 0.0
        self.fx, self.fy = fx, fy
        c5 = pc()
        # record: the running activity's trial window, the trace row, a display's snapshot
        safety = m.safety
        act = self.activities.running
        if act is not None:
            act.tick(fx, fy, safety.mode == Mode.ARMED)
        buf, snap = self._buf, self.snapshot
        if buf is not None or snap is not None:
            row = (st.x, st.y, vx, vy, fx, fy, mx, my, w, g, *arms.joints(),
                   float(safety.mode), float(safety.latched), float(new),
                   safety.passivity.energy_j)
            if buf is not None:
                buf.add(self.t_s, row)
            if snap is not None:
                snap.publish_row(self.t_s, self.ticks, row, len(self.events),
                                 act is not None and act.blinded)
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
    def run(self, duration_s: float | None = None, first_state_timeout_s: float = 1.0) -> Trace:
        """Render for ``duration_s`` (None: until stopped) or until a ``stop`` command or Ctrl-C,
        the robot's first state awaited ``first_state_timeout_s``; the session's trace."""
        cfg = self.config
        n_ticks = None if duration_s is None else max(1, round(duration_s * cfg.rate_hz))
        # prepared before arming: nothing may stand between the ARM and the first FORCE
        with realtime(cfg.realtime_priority) as granted:
            self.realtime_grant = granted
            try:
                self.start(first_state_timeout_s, n_ticks)
                end = None if n_ticks is None else self.ticks + n_ticks
                with np.errstate(over="ignore", invalid="ignore"):  # diverging arms are faults
                    while not self._loop(end):  # Ctrl-C: stopped as asked (winding down)
                        self.log_event("interrupted")
                        if self.wind_down is None:
                            break
                        self.request_stop()  # a second Ctrl-C ends it at once
            finally:
                self.running = False
        return self.finish()

    def start(self, first_state_timeout_s: float = 1.0, expected_ticks: int | None = None) -> None:
        """Wait for the first state, put both arms at the handle, arm (``arm_on_start``)."""
        cfg = self.config
        if (not self.port.wait_state(first_state_timeout_s)
                and self.monitor.state.states == 0):
            raise HapticError(f"no STATE from the robot within {first_state_timeout_s} s")
        self._reset_arms()
        self.metadata.setdefault("started_at", utc_now())
        self._buf = TraceBuffer(expected_ticks or 60 * cfg.rate_hz) if cfg.record else None
        self.times.restart()
        self.running = True
        self._stop = False
        if cfg.arm_on_start:
            try:
                self.arm()
            except HapticError as exc:
                log.warning("not armed at start: %s", exc)

    def _loop(self, end: int | None) -> bool:
        """Tick until ``end`` ticks or a stop; False when Ctrl-C interrupted it."""
        clock, period, times = self.clock, self.period_ns, self.times
        wake, late = times.wake_ns, times.late_ns
        deadline = clock.now_ns()
        try:
            while not self._stop and (end is None or self.ticks < end):
                clock.sleep_until(deadline)
                now = clock.now_ns()
                wake.append(now)
                late.append(now - deadline)
                self.tick()
                deadline += period
                if now >= deadline:  # a whole period late: skip the missed ticks (no bursts)
                    skipped = (now - deadline) // period + 1
                    times.skipped_ticks += skipped
                    deadline += skipped * period
        except KeyboardInterrupt:
            return False
        return True

    def finish(self) -> Trace:
        """Command zero force, disarm the robot, answer pending commands; the trace."""
        self.running = False
        self.metadata["ended_at"] = utc_now()
        self.monitor.release()
        self._drain()
        self.activities.close(self.t_s)
        self.trace = assemble_trace(
            self._buf, rate_hz=self.config.rate_hz, params=self.pair.session_params,
            events=self.events, safety=self.safety, stats=self.loop_stats(),
            metadata=self.metadata, renderer_config=self.config, device=self.port.device,
            results=self.activities.results)
        return self.trace

    # --- commands: thread-safe requests, applied at tick boundaries -------------------------
    def submit(self, command: RendererCommand | str, /, **args: Any) -> Request:
        """Queue a command for the loop; its :class:`~haptic.commands.Request` answers.

        ``command`` is a :mod:`haptic.commands` value, or its name with keywords
        (``submit("switch", target="B")``). A command that cannot be built, or needs the loop
        while it is not running, is answered with its error; nothing raises here.
        """
        req = Request(command if isinstance(command, str) else command.name)
        try:
            cmd = command if not isinstance(command, str) else commands.from_name(command, args)
            if cmd.needs_running and not self.running:
                raise CommandError("the renderer is not running")
            req.command = cmd.prepare(self)
        except Exception as exc:  # answered like an error applying it
            return req.fail(exc)
        if not req.command.in_loop:
            req.run(self)
            return req
        self.commands.put(req)
        if not self.running:
            self._drain()
        return req

    def _drain(self) -> None:
        while True:
            try:
                req = self.commands.get_nowait()
            except queue.Empty:
                return
            req.run(self)

    def arm(self) -> None:
        """Arm (or re-arm after a fault), refused with every reason the monitor finds; after a
        diverged model both arms restart at the handle. The tick that applies it runs every
        check before any force goes out; the force ramps in."""
        if self.monitor.arm(self.running) & _MODEL_BIT:
            self._reset_arms()
        self.pair.gain.set(0.0)
        self.pair.gain.go(1.0, round(self.safety.config.rearm_ramp_s / self.dt_s))
        self.log_event("arm")

    def disarm(self) -> None:
        self.monitor.disarm()
        self.pair.gain.set(0.0)
        self.log_event("disarm")

    def request_stop(self) -> None:
        """End the run after this tick, or when :attr:`wind_down` is done (a second: at once)."""
        wind, self.wind_down = self.wind_down, None
        if wind is not None and self.running:
            wind()
        else:
            self._stop = True

    def stop_now(self) -> None:
        """End the run after the current tick."""
        self._stop = True

    def log_event(self, kind: str, **data: Any) -> dict[str, Any]:
        """Record an event at the current session time (kept in the trace)."""
        ev = {"t_s": self.t_s, "event": kind, **data}
        self.events.append(ev)
        return ev

    def _on_fault(self, code: int, first: bool) -> None:
        self.pair.gain.set(0.0)
        if first:
            self.log_event("fault", code=int(code), name=FaultCode(code).name)

    # --- the models -------------------------------------------------------------------------
    def queue_models(self, sims: SimPair, params: tuple[ArmParams, ArmParams],
                     model_ids: ModelIds | None, model_info: ModelInfoPair | None = None,
                     session: bool = True) -> None:
        """Swap in compiled models: at once when idle, else behind a fade out and in
        (:meth:`haptic.pair.ModelPair.queue`: ``session`` False for a training arm)."""
        self.pair.queue(sims, params, model_ids, model_info, session)
        if not self.running:
            self._swap()
        else:
            self.pair.fade(0.0)

    def _swap(self) -> None:
        self.pair.swap(self.metadata)
        self._reset_arms()
        if self.running and self.safety.mode == Mode.ARMED:
            self.pair.fade(1.0)

    def _reset_arms(self) -> None:
        st = self.monitor.state
        ox, oy = self.config.shoulder_offset_m
        hx, hy = st.x - ox, st.y - oy
        self.log_event("reset_arms", at_m=[hx, hy])
        self.pair.reset_at(hx, hy)

    # --- reporting --------------------------------------------------------------------------
    def loop_stats(self, last: int | None = None) -> dict[str, Any]:
        """Period error, overruns, tick cost (:func:`haptic.loopstats.loop_stats`) over the
        whole session or its ``last`` ticks; safe to call while the loop runs."""
        grant = self.realtime_grant
        return loop_stats(self.times, ticks=self.ticks, rate_hz=self.config.rate_hz,
                          overrun_ms=self.config.overrun_ms,
                          realtime_scheduling=None if grant is None else grant.fifo,
                          passivity_active_ticks=self.safety.passivity.active_ticks,
                          link=self.port.counters(), last=last,
                          realtime=None if grant is None else grant.to_dict())

    def status(self) -> Result:
        """What ``fieldbank haptic status`` shows (:func:`haptic.readouts.status`)."""
        return readouts.status(self)

    def info(self) -> Result:
        """What a display needs besides the snapshot (:func:`haptic.readouts.info`)."""
        return readouts.info(self)

    def felt(self) -> Result:
        """The renderer's true state in a few fields (:func:`haptic.readouts.felt`)."""
        return readouts.felt(self)
