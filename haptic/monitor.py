"""The safety monitor: every fault check of a loop that drives a robot, and every counter the
checks keep, in one place.

A loop (the renderer, :mod:`haptic.renderer`; a measurement, :mod:`haptic.measure`) reaches its
robot through one :class:`SafetyMonitor` and never judges the robot itself:

* :meth:`SafetyMonitor.read` polls the :class:`~haptic.port.RobotPort` (a lock-step robot's
  reply is waited for) and :meth:`SafetyMonitor.send` commands a force; a port that fails trips
  DISCONNECT, and nothing is sent to it again;
* :meth:`SafetyMonitor.check` judges the evidence of a tick while armed - the port's CRC count
  against a leaky bucket, the largest sequence gap, ticks without a state (TIMEOUT), the
  robot's fault reports and the fault and watchdog flags of every state it sent, a handle
  state that is not a number, outside the workspace or too fast;
* :meth:`SafetyMonitor.output` passes the model's force through the safety layer (passivity,
  rate limit, saturation: :class:`~haptic.safety.Safety`) and zeroes it unless armed; a
  non-finite force trips NAN;
* :meth:`SafetyMonitor.arm` re-arms only when :meth:`SafetyMonitor.problems` finds nothing in
  the way, and forgives what the port counted until then - fault flags read on the tick of the
  re-arm are still judged on that tick;
* :meth:`SafetyMonitor.trip` latches a fault (zero force the same tick, the robot disarmed,
  the record kept) and tells the loop through ``on_fault``.

The counters are the monitor's: ticks without a state, and the port's fault reports and
flagged states already judged. Re-arming sets them; only the checks read them.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from fieldbank.haptic.errors import CommandError, LinkDown
from fieldbank.haptic.port import RobotPort
from fieldbank.haptic.protocol import FLAG_FAULT, FLAG_WATCHDOG, FaultCode, device_report
from fieldbank.haptic.safety import Mode, Safety, SafetyConfig

#: Told of each fault tripped: its code, and whether it was not latched before.
OnFault = Callable[[int, bool], None]


class SafetyMonitor:
    """The fault checks and counters of one loop on one robot.

    Parameters
    ----------
    port : RobotPort
        The robot (connected, handshake done).
    config : SafetyConfig
        Limits and thresholds.
    dt_s : float, s
        The loop's period.
    on_fault : callable(code, first), optional
        Called on every trip, after the fault is latched and before the robot is disarmed.
    spin_s : float, s
        How long :meth:`read` busy-polls for a lock-step reply before it sleeps.
    force_from : str
        What computes the forces :meth:`output` is given, in words (its NAN fault names it).

    Attributes
    ----------
    safety : Safety
        The latched state machine and the force path (limits, passivity).
    link_down : bool
        The port failed; it is not used again.
    stale : int
        Ticks since the last state arrived.
    t_s : float, s
        Session time of the newest :meth:`read` (faults are recorded at it).
    """

    def __init__(self, port: RobotPort, config: SafetyConfig, dt_s: float,
                 on_fault: OnFault | None = None, spin_s: float = 0.0,
                 force_from: str = "the model") -> None:
        self.port = port
        self.force_from = force_from
        self.state = port.state
        self.safety = Safety(config, dt_s)
        self.dt_s = dt_s
        self.on_fault = on_fault
        self.spin_s = spin_s
        self.timeout_ticks = max(1, math.ceil(config.state_timeout_ms * 1e-3 / dt_s))
        self.link_down = False
        self.stale = 0
        self.t_s = 0.0
        self._device_faults_seen = 0
        self._fault_flags_seen = 0
        self._fault_flags_before_read = 0
        self._watchdog_flags_seen = 0
        self._crc_judged = 0

    @property
    def mode(self) -> Mode:
        return self.safety.mode

    # --- the port ---------------------------------------------------------------------------
    def read(self, wait_s: float, t_s: float) -> int:
        """Take what the robot reported (waiting up to ``wait_s`` for a lock-step reply, 0:
        never block) at session time ``t_s``; the number of new states."""
        self.t_s = t_s
        self._fault_flags_before_read = self.state.fault_flag_frames
        if self.link_down:
            return 0
        try:
            return (self.port.wait_state(wait_s, self.spin_s) if wait_s > 0
                    else self.port.poll())
        except LinkDown as exc:
            self.link_down = True
            self.trip(FaultCode.DISCONNECT, str(exc))
            return 0

    def send(self, fx: float, fy: float) -> bool:
        """Command (fx, fy), N; False when nothing reached the robot (its port is down)."""
        if self.link_down:
            return False
        try:
            self.port.send_force(fx, fy)
        except LinkDown as exc:
            self.link_down = True
            self.trip(FaultCode.DISCONNECT, str(exc))
            return False
        return True

    def release(self) -> None:
        """Zero force and disarm the robot at the end of a session (a failing port is left)."""
        if self.link_down:
            return
        try:
            self.port.send_force(0.0, 0.0)
            self.port.disarm()
        except LinkDown:
            self.link_down = True

    # --- the checks -------------------------------------------------------------------------
    def check(self, new: int) -> None:
        """Judge this tick's evidence after a :meth:`read` that brought ``new`` states (the
        commands of the tick applied first: a re-arm is judged on its own tick)."""
        st = self.state
        safety = self.safety
        self.stale = 0 if new else self.stale + 1
        gap = st.max_gap  # the largest gap since the last tick (taken: the port starts anew)
        if gap:
            st.max_gap = 0
        # the leaky bucket changes only with new errors or while it holds some
        crc = st.crc_errors != self._crc_judged or safety.crc_bucket > 0.0
        if crc:
            self._crc_judged = st.crc_errors
            crc = safety.check_crc(st.crc_errors)
        if safety.mode != Mode.ARMED:
            return
        if crc:
            self.trip(FaultCode.CRC, f"{st.crc_errors} CRC errors (leaky bucket "
                                     f"{safety.crc_bucket:.1f} > "
                                     f"{safety.config.crc_error_limit})")
        if gap > safety.config.max_seq_gap:
            self.trip(FaultCode.SEQ_GAP, f"{gap} frames lost in one gap")
        if self.stale > self.timeout_ticks:
            self.trip(FaultCode.TIMEOUT, f"no STATE for {self.stale} ticks")
        if st.device_faults != self._device_faults_seen:
            self._device_faults_seen = st.device_faults
            self.trip(FaultCode.DEVICE, device_report(st.last_device_fault, 0))
        if st.fault_flag_frames != self._fault_flags_seen:
            self._fault_flags_seen = st.fault_flag_frames
            self.trip(FaultCode.DEVICE, device_report(0, FLAG_FAULT))
        if st.watchdog_flag_frames != self._watchdog_flags_seen:
            self._watchdog_flags_seen = st.watchdog_flag_frames
            self.trip(FaultCode.DEVICE, device_report(0, FLAG_WATCHDOG))
        code, msg = safety.check_handle(st.x, st.y, st.vx, st.vy)
        if code:
            self.trip(code, msg)

    def output(self, fx: float, fy: float, vx: float, vy: float) -> tuple[float, float]:
        """The force to command for the model's (fx, fy) at handle velocity (vx, vy): through
        passivity, rate limit and saturation; zero unless armed, and on a non-finite force
        (NAN)."""
        safety = self.safety
        fx, fy = safety.output(fx, fy, vx, vy)
        limiter = safety.limiter
        if limiter.nan_seen:
            limiter.nan_seen = False
            self.trip(FaultCode.NAN, f"non-finite force from {self.force_from}")
            return 0.0, 0.0
        if safety.mode != Mode.ARMED:
            return 0.0, 0.0
        return fx, fy

    def diverged(self) -> None:
        """A virtual arm's force is not a number: trip MODEL (the loop resets its arms)."""
        self.trip(FaultCode.MODEL, "a virtual arm diverged (non-finite force)")

    # --- arming -----------------------------------------------------------------------------
    def problems(self, running: bool) -> list[str]:
        """Why arming would be refused now, in words (empty: it would be accepted): the link
        is down, the robot reports a device fault in its newest state, no state arrives (while
        the loop runs), or the handle is outside the workspace, too fast or not a number. Safe
        to call from any thread (it only reads)."""
        if self.link_down:
            return ["the robot link is down: reconnect the robot and start a new session"]
        st = self.state
        out = []
        if st.flags & FLAG_FAULT:
            out.append("the robot reports a device fault in its latest state: clear it on the "
                       "robot first")
        if running and self.stale > self.timeout_ticks:
            out.append(f"no state from the robot for {self.stale * self.dt_s * 1e3:.0f} ms")
        code, msg = self.safety.check_handle(st.x, st.y, st.vx, st.vy)
        if code:
            out.append(msg)
        return out

    def arm(self, running: bool) -> int:
        """Arm (or re-arm after a fault), refused with every reason of :meth:`problems`; the
        bitmask of the faults it cleared. What the port counted until now is forgiven, except
        what the running loop read on its current tick (fault flags, a sequence gap), which
        :meth:`check` judges next; before a loop runs (``running`` False) also the frames lost
        so far."""
        problems = self.problems(running)
        if problems:
            raise CommandError("cannot arm: " + "; ".join(problems))
        st = self.state
        cleared = self.safety.latched
        self.safety.rearm((st.x, st.y, st.vx, st.vy))
        self.stale = 0
        self._device_faults_seen = st.device_faults
        # fault flags read before this tick are forgiven by the operator's re-arm, those read
        # on this tick are judged on it; the watchdog flag clears only once the device has the
        # ARM, so every earlier one is forgiven
        self._fault_flags_seen = (self._fault_flags_before_read if running
                                  else st.fault_flag_frames)
        self._watchdog_flags_seen = st.watchdog_flag_frames
        if not running:  # frames lost before the loop (the handshake) are forgiven
            st.max_gap = 0
        try:
            self.port.arm()
        except LinkDown as exc:
            self.trip(FaultCode.DISCONNECT, str(exc))
            raise CommandError(f"cannot arm: {exc}") from None
        return cleared

    def disarm(self) -> None:
        """Zero the force and disarm (a failing port trips DISCONNECT)."""
        self.safety.disarm()
        if not self.link_down:
            try:
                self.port.disarm()
            except LinkDown as exc:
                self.trip(FaultCode.DISCONNECT, str(exc))

    def trip(self, code: int, message: str) -> None:
        """Latch fault ``code`` now: zero force this tick, the record kept, the loop told, the
        robot disarmed."""
        safety = self.safety
        first = not (safety.latched & (1 << (code - 1)))
        safety.trip(code, self.t_s, message)
        if self.on_fault is not None:
            self.on_fault(code, first)
        if not self.link_down:
            try:
                self.port.disarm()
            except LinkDown:
                self.link_down = True
