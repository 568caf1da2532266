"""The real-time loop's settings (:class:`RendererConfig`), checked where they are made."""

from __future__ import annotations

from dataclasses import dataclass

from fieldbank.validation import Interval, check_fields, check_tuple

#: Allowed range of each numeric setting of :class:`RendererConfig` (messages are generated).
RENDERER_BOUNDS: dict[str, Interval] = {
    "rate_hz": Interval.whole(500, 4000, "Hz"),
    "crossfade_s": Interval(0.0, None, "s"),
    "push_fade_s": Interval(0.0, None, "s"),
    "state_wait_s": Interval(0.0, None, "s"),
    "spin_us": Interval(0.0, None, "µs"),
    "overrun_ms": Interval(0.0, None, "ms"),
}


@dataclass(frozen=True)
class RendererConfig:
    """Loop settings, SI; ranges in :data:`RENDERER_BOUNDS`.

    Attributes
    ----------
    rate_hz : int, Hz
        Tick rate, 500–4000.
    crossfade_s : float, s
        Raised-cosine ramp of an A↔B switch.
    push_fade_s : float, s
        Fade out before and in after swapping pushed models.
    shoulder_offset_m : tuple of 2 float, m
        The shoulder's position in robot coordinates (robot frame − offset = shoulder frame).
    state_wait_s : float, s
        > 0: block up to this long for each STATE (lockstep devices); 0: never block.
    spin_us : float, µs
        The real clock spins (instead of sleeping) this long before each deadline.
    overrun_ms : float, ms
        A tick waking later than this is counted as an overrun.
    realtime_priority : bool
        Ask for SCHED_FIFO.
    record : bool
        Keep a trace row per tick.
    arm_on_start : bool
        Arm as soon as the first STATE arrives.
    compiled_tick : bool
        Tick both arms and the blend in one compiled call (:mod:`fieldbank.armkernel`);
        False: the plain-Python reference (:meth:`fieldbank.sim.ArmSim.tick`), same forces.
    """

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
    compiled_tick: bool = True

    def __post_init__(self) -> None:
        check_fields(self, RENDERER_BOUNDS, what="renderer parameter")
        check_tuple("shoulder_offset_m", self.shoulder_offset_m, 2, Interval(None, None, "m"),
                    what="renderer parameter")
