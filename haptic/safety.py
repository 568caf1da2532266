"""Safety layer of the haptic loop: limits, passivity, and a latched fault state machine.

Every force the host commands passes, in this order::

    model force ─► passivity controller ─► force-rate limit ─► saturation (‖F‖ ≤ limit) ─► wire

- **Saturation** scales the force vector so its norm stays below ``force_limit_n`` (default
  40 N), with a margin of 1 ppm so that float32 rounding on the wire cannot push it over. A
  non-finite force becomes zero and trips a NAN fault. Saturation is the last step: nothing
  after it can raise the force.
- **Force-rate limit** bounds ‖ΔF‖ per tick to ``force_rate_n_per_s · dt`` (smooths steps from
  model pushes or arming; not applied to the drop to zero on a fault).
- **Passivity observer/controller** (Hannaford & Ryu 2002): the observer sums the energy the
  virtual environment has absorbed through the handle port, E(n) = E(n−1) − F(n)·v(n) Δt (F the
  force on the handle, v the handle velocity). A passive environment keeps E ≥ 0; when E < 0
  the controller adds a damping force −α v with α = −E / (Δt ‖v‖²) (capped at
  ``passivity_max_damping_n_s_per_m``) so the energy it dissipates makes up the deficit.
- **Faults** (:class:`haptic.protocol.FaultCode`): CRC errors over a leaky-bucket threshold,
  no STATE within the timeout, a sequence gap over the threshold, NaN, handle outside the
  workspace box or faster than the speed limit, a failed port, a device fault or watchdog trip,
  a diverging virtual arm, an operator stop. A fault zeroes the command at once (the same
  tick), latches, is logged, and only an explicit :meth:`Safety.rearm` resumes, after the
  condition has cleared; output then ramps back in.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from enum import IntEnum

from fieldbank.errors import ParameterError
from fieldbank.haptic.errors import CommandError
from fieldbank.haptic.protocol import FaultCode
from fieldbank.validation import Interval, check_fields, check_tuple

log = logging.getLogger("fieldbank.haptic.safety")

#: Fraction of the limit the saturation scales to, so float32 rounding cannot exceed it.
_LIMIT_MARGIN = 1.0 - 1e-6


class Mode(IntEnum):
    """Renderer state."""

    DISARMED = 0   # zero force, waiting for arm
    ARMED = 1      # rendering
    FAULT = 2      # latched fault, zero force, waiting for re-arm


#: Allowed range of every numeric limit of :class:`SafetyConfig` (messages are generated).
SAFETY_BOUNDS: dict[str, Interval] = {
    "force_limit_n": Interval(0.0, None, "N", low_closed=False),
    "force_rate_n_per_s": Interval(0.0, None, "N/s", low_closed=False),
    "speed_limit_m_per_s": Interval(0.0, None, "m/s", low_closed=False),
    "passivity_max_damping_n_s_per_m": Interval(0.0, None, "N·s/m"),
    "state_timeout_ms": Interval(0.0, None, "ms", low_closed=False),
    "crc_error_limit": Interval(0.0, None, "errors"),
    "crc_leak_per_s": Interval(0.0, None, "errors/s"),
    "max_seq_gap": Interval(0.0, None, "frames"),
    "rearm_ramp_s": Interval(0.0, None, "s"),
}
#: Each coordinate of the workspace box, robot frame.
WORKSPACE_BOUNDS = Interval(None, None, "m")
WORKSPACE_LABELS = ("workspace_m[0] (xmin)", "workspace_m[1] (xmax)", "workspace_m[2] (ymin)",
                    "workspace_m[3] (ymax)")


@dataclass(frozen=True)
class SafetyConfig:
    """Limits and thresholds, SI; ranges in :data:`SAFETY_BOUNDS`. Defaults are assumptions
    sized for a clinical planar robot.

    Attributes
    ----------
    force_limit_n : float, N
        Saturation of the commanded force's norm.
    force_rate_n_per_s : float, N/s
        Largest change of the force per second (per tick: times the period).
    workspace_m : tuple of 4 float, m
        (xmin, xmax, ymin, ymax) of the box the handle must stay in, robot frame.
    speed_limit_m_per_s : float, m/s
    passivity : bool
        Whether the passivity controller runs.
    passivity_max_damping_n_s_per_m : float, N·s/m
        Cap of the damping the passivity controller may add.
    state_timeout_ms : float, ms
        Longest time without a STATE frame before a TIMEOUT fault.
    crc_error_limit : float
        CRC leaky bucket: trips above this many errors.
    crc_leak_per_s : float
        Errors forgiven per second.
    max_seq_gap : int
        Frames lost in one gap before a SEQ_GAP fault.
    rearm_ramp_s : float, s
        Raised-cosine ramp-in after arming.
    """

    force_limit_n: float = 40.0
    force_rate_n_per_s: float = 10_000.0          # 10 N per ms
    workspace_m: tuple[float, float, float, float] = (-0.5, 0.6, 0.05, 0.8)  # xmin xmax ymin ymax
    speed_limit_m_per_s: float = 2.5
    passivity: bool = True
    passivity_max_damping_n_s_per_m: float = 60.0
    state_timeout_ms: float = 5.0
    crc_error_limit: float = 5.0                  # leaky bucket: trips above this many
    crc_leak_per_s: float = 1.0                   # forgiven per second
    max_seq_gap: int = 3                          # frames lost in one gap before a fault
    rearm_ramp_s: float = 0.3                     # raised-cosine ramp-in after arming

    def __post_init__(self) -> None:
        check_fields(self, SAFETY_BOUNDS, what="safety parameter")
        x0, x1, y0, y1 = check_tuple("workspace_m", self.workspace_m, 4, WORKSPACE_BOUNDS,
                                     labels=WORKSPACE_LABELS, what="safety parameter")
        if not (x0 < x1 and y0 < y1):
            raise ParameterError(
                f"The 'workspace_m' safety parameter must be (xmin, xmax, ymin, ymax) with "
                f"min < max; got {self.workspace_m!r} instead."
            )


@dataclass(frozen=True)
class FaultRecord:
    """One fault: time (s since session start), code, human message."""

    t_s: float
    code: int
    message: str

    def to_dict(self) -> dict[str, object]:
        return {"t_s": self.t_s, "code": self.code, "name": FaultCode(self.code).name,
                "message": self.message}


class ForceLimiter:
    """Rate limit then saturation, per tick. ``last`` is the last force let through."""

    __slots__ = ("last_fx", "last_fy", "limit", "max_step", "nan_seen")

    def __init__(self, force_limit_n: float, force_rate_n_per_s: float, dt_s: float) -> None:
        self.limit = force_limit_n * _LIMIT_MARGIN
        self.max_step = force_rate_n_per_s * dt_s
        self.last_fx = 0.0
        self.last_fy = 0.0
        self.nan_seen = False

    def __call__(self, fx: float, fy: float) -> tuple[float, float]:
        if not (math.isfinite(fx) and math.isfinite(fy)):
            self.nan_seen = True
            self.last_fx = self.last_fy = 0.0
            return 0.0, 0.0
        dx = fx - self.last_fx
        dy = fy - self.last_fy
        d = math.hypot(dx, dy)
        if d > self.max_step:
            s = self.max_step / d
            fx = self.last_fx + dx * s
            fy = self.last_fy + dy * s
        n = math.hypot(fx, fy)
        if n > self.limit:
            s = self.limit / n
            fx *= s
            fy *= s
        self.last_fx = fx
        self.last_fy = fy
        return fx, fy

    def zero(self) -> None:
        self.last_fx = self.last_fy = 0.0


class PassivityController:
    """Time-domain passivity observer and controller on the handle port (Hannaford & Ryu 2002).

    ``energy_j`` is the energy the virtual environment has absorbed from the operator so far.
    """

    __slots__ = ("active_ticks", "alpha_max", "dissipated_j", "dt", "energy_j")

    def __init__(self, dt_s: float, max_damping_n_s_per_m: float) -> None:
        self.dt = dt_s
        self.alpha_max = max_damping_n_s_per_m
        self.energy_j = 0.0
        self.active_ticks = 0
        self.dissipated_j = 0.0

    def correct(self, fx: float, fy: float, vx: float, vy: float) -> tuple[float, float]:
        """Force with the damping needed to keep the observed energy non-negative."""
        e = self.energy_j - (fx * vx + fy * vy) * self.dt
        if e >= 0.0:
            return fx, fy
        v2 = vx * vx + vy * vy
        if v2 < 1e-12:
            return fx, fy
        a = -e / (self.dt * v2)
        if a > self.alpha_max:
            a = self.alpha_max
        self.active_ticks += 1
        return fx - a * vx, fy - a * vy

    def observe(self, fx: float, fy: float, vx: float, vy: float) -> None:
        """Account for the force actually commanded this tick."""
        self.energy_j -= (fx * vx + fy * vy) * self.dt

    def reset(self) -> None:
        self.energy_j = 0.0


@dataclass
class Safety:
    """Fault state machine plus the per-tick checks; owned by one renderer."""

    config: SafetyConfig
    dt_s: float
    mode: Mode = Mode.DISARMED
    latched: int = 0                     # bitmask of latched fault codes (bit code-1)
    log_records: list[FaultRecord] = field(default_factory=list)
    crc_bucket: float = 0.0

    def __post_init__(self) -> None:
        c = self.config
        self.limiter = ForceLimiter(c.force_limit_n, c.force_rate_n_per_s, self.dt_s)
        self.passivity = PassivityController(self.dt_s, c.passivity_max_damping_n_s_per_m)
        self._crc_seen = 0
        self._leak = c.crc_leak_per_s * self.dt_s
        self._x0, self._x1, self._y0, self._y1 = c.workspace_m
        self._v2max = c.speed_limit_m_per_s ** 2

    # --- checks -----------------------------------------------------------------------------
    def check_handle(self, x: float, y: float, vx: float, vy: float) -> tuple[int, str]:
        """Fault code (0 = fine) and message for one handle state."""
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(vx)
                and math.isfinite(vy)):
            return FaultCode.NAN, f"non-finite handle state ({x}, {y}, {vx}, {vy})"
        if not (self._x0 <= x <= self._x1 and self._y0 <= y <= self._y1):
            return FaultCode.WORKSPACE, (
                f"handle at ({x:.3f}, {y:.3f}) m outside the workspace {self.config.workspace_m}"
            )
        if vx * vx + vy * vy > self._v2max:
            return FaultCode.SPEED, (
                f"handle speed {math.hypot(vx, vy):.2f} m/s over the limit "
                f"{self.config.speed_limit_m_per_s} m/s"
            )
        return 0, ""

    def check_crc(self, crc_errors_total: int) -> bool:
        """Update the leaky bucket with the link's cumulative CRC count; True when over."""
        new = crc_errors_total - self._crc_seen
        self._crc_seen = crc_errors_total
        b = self.crc_bucket + new - self._leak
        self.crc_bucket = b if b > 0.0 else 0.0
        return self.crc_bucket > self.config.crc_error_limit

    # --- state machine ----------------------------------------------------------------------
    def trip(self, code: int, t_s: float, message: str) -> None:
        """Latch a fault: zero force now, log it. Repeats of a latched code are not re-logged."""
        bit = 1 << (code - 1)
        self.limiter.zero()
        if self.latched & bit and self.mode == Mode.FAULT:
            return
        self.latched |= bit
        self.mode = Mode.FAULT
        rec = FaultRecord(t_s, int(code), message)
        self.log_records.append(rec)
        log.warning("haptic fault %s at t=%.4f s: %s", FaultCode(code).name, t_s, message)

    def rearm(self, handle: tuple[float, float, float, float]) -> None:
        """Clear latched faults and arm, if the handle state is safe now; else CommandError."""
        code, msg = self.check_handle(*handle)
        if code:
            raise CommandError(f"cannot arm: {msg}")
        self.latched = 0
        self.crc_bucket = 0.0
        self.limiter.zero()
        self.passivity.reset()
        self.mode = Mode.ARMED
        log.info("haptic renderer armed")

    def disarm(self) -> None:
        self.limiter.zero()
        if self.mode == Mode.ARMED:
            self.mode = Mode.DISARMED

    def output(self, fx: float, fy: float, vx: float, vy: float) -> tuple[float, float]:
        """The force to command for a model force (fx, fy) at handle velocity (vx, vy)."""
        if self.mode != Mode.ARMED:
            return 0.0, 0.0
        if self.config.passivity:
            fx, fy = self.passivity.correct(fx, fy, vx, vy)
        fx, fy = self.limiter(fx, fy)
        self.passivity.observe(fx, fy, vx, vy)
        return fx, fy
