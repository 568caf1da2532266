"""The real-time haptic loop: two virtual arms behind one handle, rendered safely.

Each tick (default 1 kHz, 500 Hz–4 kHz):

1. read the link without blocking and take the newest handle state (robot frame → shoulder
   frame by subtracting ``shoulder_offset_m``, the shoulder's position in robot coordinates);
   apply the commands queued since the last tick (an operator's re-arm among them);
2. check it, whenever the renderer is armed - including the tick on which it was re-armed
   (timeout, CRC, sequence gap, device FAULT frames and the fault or watchdog flag of every
   STATE frame read, NaN, workspace, speed: :mod:`safety`); a fault zeroes this tick's force;
3. tick both virtual arms (A = before, B = after) with the same handle state; each returns the
   force its coupling puts on the handle (:class:`fieldbank.sim.ArmSim`);
4. blend them, F = (1 − w) F_A + w F_B, where w follows a raised-cosine ramp on each switch so
   the force has no step; multiply by the arming/push gain (also raised-cosine): the pair, its
   blend and its fades are :class:`haptic.pair.ModelPair`;
5. pass F through the passivity controller, rate limit and saturation; send it;
6. record the row, and publish the tick's state for a display in another process
   (:mod:`haptic.snapshot`: a seqlock in shared memory, never waited on).

Timing (:mod:`haptic.clock`): absolute deadlines on a :class:`~haptic.clock.Clock`; the loop
runs inside :func:`~haptic.clock.realtime` (garbage collector frozen and off, SCHED_FIFO, short
thread switch interval). The wake time and cost of every tick are kept (:mod:`haptic.loopstats`:
period error, overruns, per-phase cost). A :class:`~haptic.clock.VirtualClock` replaces the
wall clock in tests so a minute of rendering takes a fraction of that.

Commands (:mod:`haptic.commands`: switch, push, arm, disarm, A/B/X, stop, status) come from
other threads through :meth:`Renderer.submit` and are applied at the start of a tick, so the
loop's state has one owner. What the renderer tells other processes (status, a display's info)
is :mod:`haptic.readouts`; the session's trace is put together by :mod:`haptic.assemble`.
"""

from __future__ import annotations

import logging
import math
import queue
import time
from typing import Any

import numpy as np

from fieldbank.errors import UnreachableError
from fieldbank.haptic import commands, readouts
from fieldbank.haptic.abx import AbxSession
from fieldbank.haptic.assemble import assemble_trace, close_blocks, utc_now
from fieldbank.haptic.clock import Clock, Grant, RealClock, realtime
from fieldbank.haptic.commands import RendererCommand, Request, Result, SimPair
from fieldbank.haptic.errors import CommandError, HapticError, LinkDown
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.loopstats import LoopTimes, loop_stats
from fieldbank.haptic.modelinfo import ModelIds, ModelInfoPair
from fieldbank.haptic.pair import Environment, ModelPair
from fieldbank.haptic.protocol import FLAG_FAULT, FaultCode
from fieldbank.haptic.recording import Trace, TraceBuffer
from fieldbank.haptic.rendererconfig import RENDERER_BOUNDS as RENDERER_BOUNDS
from fieldbank.haptic.rendererconfig import RendererConfig as RendererConfig
from fieldbank.haptic.safety import Mode, Safety, SafetyConfig
from fieldbank.haptic.snapshot import SnapshotWriter
from fieldbank.haptic.training import TrainingSession
from fieldbank.haptic.trialwindow import TrialWindow
from fieldbank.params import ArmParams
from fieldbank.sim import CouplingConfig

log = logging.getLogger("fieldbank.haptic.renderer")

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
        :class:`~haptic.clock.RealClock` by default; :class:`~haptic.clock.VirtualClock` to run
        faster than real time.
    coupling : CouplingConfig, optional
    environment : callable, optional
        What is ticked in place of each compiled arm (:data:`haptic.pair.Environment`; the
        remote link puts a distant patient there).
    """

    def __init__(self, link: RobotLink, before: ArmParams, after: ArmParams,
                 config: RendererConfig | None = None, safety: SafetyConfig | None = None,
                 clock: Clock | None = None, coupling: CouplingConfig | None = None,
                 environment: Environment | None = None) -> None:
        self.link = link
        self.config = config or RendererConfig()
        self.dt_s = 1.0 / self.config.rate_hz
        self.period_ns = round(1e9 / self.config.rate_hz)
        self.safety = Safety(safety or SafetyConfig(), self.dt_s)
        self.clock: Clock = clock or RealClock(self.config.spin_us)
        self.coupling = coupling
        self.pair = ModelPair(before, after, self.dt_s, self.config.crossfade_s,
                              self.config.push_fade_s, coupling, self.config.compiled_tick,
                              environment)
        self.commands: queue.SimpleQueue[Request] = queue.SimpleQueue()
        self.events: list[dict[str, Any]] = []
        self.abx: AbxSession | None = None
        self.abx_results: list[dict[str, Any]] = []
        self.training: TrainingSession | None = None
        self.training_results: list[dict[str, Any]] = []
        #: Publishes each tick's state for a display in another process (haptic.station).
        self.snapshot: SnapshotWriter | None = None
        self._link_down = False
        self._stale = 0
        self._awaiting = False
        self._timeout_ticks = max(1, math.ceil(self.safety.config.state_timeout_ms * 1e-3
                                               / self.dt_s))
        self._device_faults_seen = 0
        self._fault_flags_seen = 0
        self._fault_flags_before_poll = 0
        self._watchdog_flags_seen = 0
        self._reply_spin_s = min(self.config.spin_us * 1e-6, 0.5 * self.dt_s)
        self._stop = False
        self.running = False
        self.t_s = 0.0
        self.ticks = 0
        self.fx = self.fy = 0.0
        self.trace: Trace | None = None
        self._buf: TraceBuffer | None = None
        self.times = LoopTimes()
        # the tick appends to these two directly (never replaced, unlike the wake records)
        self._cost = self.times.phase_ns
        self._tick_ns = self.times.tick_ns
        self.realtime_scheduling: bool | None = None
        #: What the OS granted the loop: priority, core, refusals (haptic.clock.Grant).
        self.realtime_grant: Grant | None = None
        self.metadata: dict[str, Any] = {}
        #: Ticks on which the renderer was not armed (force zero by command), since the start.
        self.unarmed_ticks = 0
        #: Largest ‖F‖² commanded since the current trial's window opened, N².
        self.peak_force_n2 = 0.0
        self._window = TrialWindow()
        #: The patient's pair while a training protocol renders its own arms (restored after).
        self._home: tuple[SimPair, tuple[ArmParams, ArmParams]] | None = None

    @property
    def skipped_ticks(self) -> int:
        """Ticks skipped because the loop woke a whole period late."""
        return self.times.skipped_ticks

    @property
    def swapping(self) -> bool:
        """True while pushed models fade out, swap or fade in."""
        return self.pair.swapping

    @property
    def params(self) -> tuple[ArmParams, ArmParams]:
        """The parameters of models A and B being rendered."""
        return self.pair.params

    @property
    def rate_hz(self) -> int:
        return self.config.rate_hz

    @property
    def shoulder_offset_m(self) -> tuple[float, float]:
        return self.config.shoulder_offset_m

    @property
    def mode_name(self) -> str:
        """The safety state machine's mode: DISARMED, ARMED or FAULT."""
        return self.safety.mode.name

    # --- thread-safe requests ---------------------------------------------------------------
    def submit(self, command: RendererCommand | str, /, **args: Any) -> Request:
        """Queue a command for the loop; its :class:`~haptic.commands.Request` answers.

        ``command`` is a :mod:`haptic.commands` value, or its name with keywords
        (``submit("switch", target="B")``). A command that cannot be built, or needs the loop
        while it is not running, is answered with its error; nothing raises here.
        """
        name = command if isinstance(command, str) else command.name
        req = Request(name)
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

    def push_params(self, before: ArmParams, after: ArmParams,
                    model_ids: ModelIds | None = None) -> Request:
        """Compile two models here (outside the loop) and queue them for a faded swap.

        ``model_ids``: database ids of the two models ({'A': id, 'B': id}), kept in the trace.
        """
        return self.submit(commands.Push(before, after, model_ids))

    # --- what commands do (loop thread; see haptic.commands) --------------------------------
    def _drain(self) -> None:
        while True:
            try:
                req = self.commands.get_nowait()
            except queue.Empty:
                return
            req.run(self)

    def log_event(self, kind: str, **data: Any) -> dict[str, Any]:
        """Record an event at the current session time (kept in the trace)."""
        ev = {"t_s": self.t_s, "event": kind, **data}
        self.events.append(ev)
        return ev

    def crossfade(self, weight: float) -> None:
        """Ramp the blend to ``weight`` (0 = A, 1 = B) over ``crossfade_s``."""
        self.pair.crossfade(weight)

    def compile_pair(self, before: ArmParams, after: ArmParams) -> SimPair:
        """Both models compiled for this loop's period (slow: call outside the loop)."""
        return self.pair.compile(before, after)

    def queue_models(self, sims: SimPair, params: tuple[ArmParams, ArmParams],
                     model_ids: ModelIds | None, model_info: ModelInfoPair | None = None,
                     session: bool = True) -> None:
        """Swap in compiled models: at once when idle, else behind a fade out and in.

        ``model_info``: what a display says about each (``{"A": ModelInfo, "B": ModelInfo}``).
        ``session``: the pair becomes the session's models (the clinician's choice: their ids
        and descriptions go into the trace's metadata, their parameters into its models);
        False for a training arm, which the session does not keep.
        """
        self.pair.queue(sims, params, model_ids, model_info, session)
        if not self.running:
            self._swap()
        else:
            self.pair.fade(0.0)

    def request_stop(self) -> None:
        """End the run after the current tick."""
        self._stop = True

    def _swap(self) -> None:
        self.pair.swap(self.metadata)
        self._reset_arms()

    def _reset_arms(self) -> None:
        ox, oy = self.config.shoulder_offset_m
        hx, hy = self.link.x - ox, self.link.y - oy
        self.log_event("reset_arms", at_m=[hx, hy])
        for sim in self.pair.sims:
            try:
                if math.isfinite(hx) and math.isfinite(hy):
                    sim.reset_at_hand(hx, hy)
                else:
                    sim.reset()
            except (UnreachableError, ValueError):
                sim.reset()

    def arm_problems(self) -> list[str]:
        """Why arming would be refused now, in words (empty: it would be accepted): the link
        is down, the robot reports a device fault in its newest state, no state arrives, or
        the handle is outside the workspace, too fast or not a number. Safe to call from any
        thread (it only reads)."""
        if self._link_down:
            return ["the robot link is down: reconnect the robot and start a new session"]
        link = self.link
        out = []
        if link.flags & FLAG_FAULT:
            out.append("the robot reports a device fault in its latest state: clear it on the "
                       "robot first")
        if self.running and self._stale > self._timeout_ticks:
            out.append(f"no state from the robot for {self._stale * self.dt_s * 1e3:.0f} ms")
        code, msg = self.safety.check_handle(link.x, link.y, link.vx, link.vy)
        if code:
            out.append(msg)
        return out

    def require_armed(self, what: str) -> None:
        """CommandError saying why ``what`` waits, unless the renderer is armed: a protocol
        pauses on a fault (and while disarmed) and goes on only after a re-arm."""
        self.safety.require_armed(what)

    def open_window(self) -> None:
        """A trial starts: judge the coming window from here (:mod:`haptic.trialwindow`)."""
        self._window = TrialWindow(self.ticks, self.unarmed_ticks,
                                   len(self.safety.log_records),
                                   self.safety.mode == Mode.FAULT)
        self.peak_force_n2 = 0.0

    def trial_window(self) -> dict[str, Any]:
        """The verdict on the window since :meth:`open_window`: flagged, flags, peak force."""
        return self._window.judge(self.ticks, self.unarmed_ticks, self.safety.log_records,
                                  math.sqrt(self.peak_force_n2), self.dt_s)

    def begin_training(self) -> None:
        """Keep the patient's pair while a training protocol renders its own arms (refused
        while pushed models are still waiting to be swapped in: they would be lost)."""
        if self.pair.pending is not None:
            raise CommandError("training start refused: pushed models are being swapped in; "
                               "start it once they are rendered")
        self._home = (self.pair.sims, self.pair.params)

    def end_training(self) -> None:
        """Put the patient's pair (and its blend) back after a training protocol."""
        if self._home is not None:
            sims, params = self._home
            self._home = None
            self.queue_models(sims, params, None, None, session=False)
            self.log_event("training_pair_restored")

    def arm(self) -> None:
        """Arm (or re-arm after a fault), refused with every reason of :meth:`arm_problems`.
        The tick that applies it runs every safety check before any force goes out."""
        problems = self.arm_problems()
        if problems:
            raise CommandError("cannot arm: " + "; ".join(problems))
        link = self.link
        if self.safety.latched & (1 << (FaultCode.MODEL - 1)):
            self._reset_arms()
        self.safety.rearm((link.x, link.y, link.vx, link.vy))
        self._stale = 0
        self._device_faults_seen = link.device_faults
        # fault flags read before this tick are forgiven by the operator's re-arm; those read
        # on this tick are checked on it (the watchdog flag clears only once the device has the
        # ARM, so every earlier one is forgiven)
        self._fault_flags_seen = (self._fault_flags_before_poll if self.running
                                  else link.fault_flag_frames)
        self._watchdog_flags_seen = link.watchdog_flag_frames
        try:
            self.link.arm()
        except LinkDown as exc:
            self._trip(FaultCode.DISCONNECT, str(exc))
            raise CommandError(f"cannot arm: {exc}") from None
        self.pair.gain.set(0.0)
        self.pair.gain.go(1.0, round(self.safety.config.rearm_ramp_s / self.dt_s))
        self.log_event("arm")

    def disarm(self) -> None:
        self.safety.disarm()
        self.pair.gain.set(0.0)
        if not self._link_down:
            try:
                self.link.disarm()
            except LinkDown as exc:
                self._trip(FaultCode.DISCONNECT, str(exc))
        self.log_event("disarm")

    def _trip(self, code: int, message: str) -> None:
        first = not (self.safety.latched & (1 << (code - 1)))
        self.safety.trip(code, self.t_s, message)
        self.pair.gain.set(0.0)
        if first:
            self.log_event("fault", code=int(code), name=FaultCode(code).name)
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
        new = 0
        self._fault_flags_before_poll = link.fault_flag_frames
        if not self._link_down:
            try:
                wait = self.config.state_wait_s
                # lockstep devices answer each FORCE with one STATE: wait for it, not for more
                # (a bounded spin first, then sleep: a device sharing the core is not starved)
                new = (link.wait_state(wait, self._reply_spin_s) if wait > 0 and self._awaiting
                       else link.poll())
            except LinkDown as exc:
                self._link_down = True
                self._trip(FaultCode.DISCONNECT, str(exc))
        if self.commands.qsize():
            self._drain()
        # after the commands: a re-arm applied this tick is checked this tick
        armed = safety.mode == Mode.ARMED
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
            if link.fault_flag_frames != self._fault_flags_seen:
                self._fault_flags_seen = link.fault_flag_frames
                self._trip(FaultCode.DEVICE, "the robot's STATE reports a device fault")
            if link.watchdog_flag_frames != self._watchdog_flags_seen:
                self._watchdog_flags_seen = link.watchdog_flag_frames
                self._trip(FaultCode.DEVICE, "device watchdog tripped")
            code, msg = safety.check_handle(link.x, link.y, vx, vy)
            if code:
                self._trip(code, msg)
        else:
            link.take_gap()
            safety.check_crc(link.crc_errors)
        c2 = pc()
        pair = self.pair
        arms = pair.sims
        # the blend and gain of this tick first: the compiled call blends as it ticks
        w = pair.blend.step()
        g = pair.gain.step()
        mx = my = 0.0
        if math.isfinite(x) and math.isfinite(y) and math.isfinite(vx) and math.isfinite(vy):
            try:
                mx, my, fa_x, fa_y, fb_x, fb_y = arms.tick(x, y, vx, vy, w, g)
                ok = math.isfinite(fa_x + fa_y) and math.isfinite(fb_x + fb_y)
            except (ArithmeticError, ValueError):  # overflow inside a diverging arm
                ok = False
            if not ok:
                self._trip(FaultCode.MODEL, "a virtual arm diverged (non-finite force)")
                self._reset_arms()
                mx = my = 0.0
        if pair.pending is not None and g == 0.0 and not pair.gain.moving:
            self._swap()
            if safety.mode == Mode.ARMED:
                pair.fade(1.0)
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
        f2 = fx * fx + fy * fy
        if f2 > self.peak_force_n2:
            self.peak_force_n2 = f2
        if safety.mode != Mode.ARMED:
            self.unarmed_ticks += 1
        c5 = pc()
        buf = self._buf
        snap = self.snapshot
        if buf is not None or snap is not None:
            row = (link.x, link.y, vx, vy, fx, fy, mx, my, w, g, *arms.joints(),
                   float(safety.mode), float(safety.latched), float(new),
                   safety.passivity.energy_j)
            if buf is not None:
                buf.add(self.t_s, row)
            if snap is not None:  # for a display in another process (no waiting, no lock)
                tr = self.training
                snap.publish_row(self.t_s, self.ticks, row, len(self.events),
                                 self.abx is not None or (tr is not None and tr.blinded))
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
    def start(self, first_state_timeout_s: float = 1.0, expected_ticks: int | None = None) -> None:
        """Wait for the first STATE, put both arms at the handle, arm (``arm_on_start``)."""
        cfg = self.config
        if not self.link.wait_state(first_state_timeout_s) and self.link.states == 0:
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

    def finish(self) -> Trace:
        """Command zero force, disarm the device, answer pending commands; return the trace."""
        self.running = False
        self.metadata["ended_at"] = utc_now()
        try:
            if not self._link_down:
                self.link.send_force(0.0, 0.0)
                self.link.disarm()
        except LinkDown:
            self._link_down = True
        self._drain()
        close_blocks(self.t_s, self.abx, self.abx_results, self.training, self.training_results)
        self.trace = assemble_trace(
            self._buf, rate_hz=self.config.rate_hz, params=self.pair.session_params,
            events=self.events,
            safety=self.safety, stats=self.loop_stats(), metadata=self.metadata,
            renderer_config=self.config, device=self.link.device, abx_results=self.abx_results,
            training_results=self.training_results)
        return self.trace

    def run(self, duration_s: float | None = None, first_state_timeout_s: float = 1.0) -> Trace:
        """Render until ``duration_s`` passes or a ``stop`` command; return the session trace.

        Parameters
        ----------
        duration_s : float, s, optional
            How long to render (None: until a ``stop`` command or Ctrl-C).
        first_state_timeout_s : float, s
            How long to wait for the robot's first STATE.
        """
        cfg = self.config
        n_ticks = None if duration_s is None else max(1, round(duration_s * cfg.rate_hz))
        # the process is prepared before arming: nothing may stand between the ARM frame and
        # the first FORCE (haptic.clock.realtime)
        with realtime(cfg.realtime_priority) as granted:
            self.realtime_scheduling = granted.fifo
            self.realtime_grant = granted
            try:
                self.start(first_state_timeout_s, n_ticks)
                with np.errstate(over="ignore", invalid="ignore"):  # diverging arms are faults
                    self._loop(n_ticks)
            except KeyboardInterrupt:
                if not self.running:
                    raise
                self.log_event("interrupted")
            finally:
                self.running = False
        return self.finish()

    def _loop(self, n_ticks: int | None) -> None:
        clock = self.clock
        period = self.period_ns
        times = self.times
        wake = times.wake_ns
        late = times.late_ns
        end = None if n_ticks is None else self.ticks + n_ticks
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
                times.skipped_ticks += skipped
                deadline += skipped * period

    # --- reporting --------------------------------------------------------------------------
    def loop_stats(self, last: int | None = None) -> dict[str, Any]:
        """Period error, overruns, tick cost (:func:`haptic.loopstats.loop_stats`) over the
        whole session or its ``last`` ticks; safe to call while the loop runs."""
        return loop_stats(self.times, ticks=self.ticks, rate_hz=self.config.rate_hz,
                          overrun_ms=self.config.overrun_ms,
                          realtime_scheduling=self.realtime_scheduling,
                          passivity_active_ticks=self.safety.passivity.active_ticks,
                          link=self.link, last=last,
                          realtime=None if self.realtime_grant is None
                          else self.realtime_grant.to_dict())

    def status(self) -> Result:
        """What ``fieldbank haptic status`` shows (:func:`haptic.readouts.status`)."""
        return readouts.status(self)

    @property
    def blinded(self) -> bool:
        """True while an A/B/X block or a training assessment hides which model is rendered."""
        tr = self.training
        return self.abx is not None or (tr is not None and tr.blinded)

    def info(self) -> Result:
        """What a display needs besides the snapshot (:func:`haptic.readouts.info`)."""
        return readouts.info(self)

    def felt(self) -> Result:
        """The renderer's true state in a few fields (:func:`haptic.readouts.felt`)."""
        return readouts.felt(self)
