"""What a site accepts of its peer's STATE: values its own robot could have produced.

A datagram that opens (:mod:`haptic.remote.wire`) was sealed by a holder of the session's keys;
that says who sent it, not that it is safe to act on. Each site checks every STATE it receives
against its own robot's limits before using it (:class:`Plausibility`):

* **force** — ‖(fx, fy)‖ no larger than this site's force clamp (``SafetyConfig.force_limit_n``):
  a force this robot could not display is not one it should be handed; and, where the site
  displays the peer's force (the clinician's), no faster change than
  :data:`~haptic.remote.ports.LinkConfig` ``peer_force_slew_n_per_s`` per second, applied per
  tick (10 N per tick at 1 kHz: this site's own force-rate limit; the patient's force sent
  through a 100 ms link changed by up to 7.3 N per tick in the benchmark's sessions);
* **position** — inside this site's workspace box (``SafetyConfig.workspace_m``, taken into the
  shoulder frame of the patient with this site's own offset), and between two STATEs of one
  engaged run no further than this site's speed limit allows in the ticks between them, plus
  ``peer_step_margin_m`` (1 mm: encoder noise and rounding); the velocity no faster than the
  speed limit;
* **tick** — increasing with the sequence number (a sender's ticks never go back).

The first violation is a fault of the link (the site's port holds it to the end of the
session): the force ramps to zero from the last plausible value, the implausible one is never
used, and both terminals say what arrived and which limit it broke.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from fieldbank.haptic.remote.wire import FLAG_ARMED, State
from fieldbank.haptic.safety import SafetyConfig


@dataclass(frozen=True)
class Plausibility:
    """One site's limits on its peer's STATEs (module docstring).

    Attributes
    ----------
    force_limit_n : float, N
    force_slew_n_per_tick : float or None, N
        None: the peer's force is not displayed here, so only its size is checked.
    speed_limit_m_per_s : float, m/s
    step_margin_m : float, m
    workspace_m : (xmin, xmax, ymin, ymax), m
        Shoulder frame of the patient.
    dt_s : float, s
        This site's tick.
    gap_ticks : int
        The most ticks a slew allowance grows over (a longer silence loses the link).
    peer : str
        The peer in words ("the patient's site").
    """

    force_limit_n: float
    force_slew_n_per_tick: float | None
    speed_limit_m_per_s: float
    step_margin_m: float
    workspace_m: tuple[float, float, float, float]
    dt_s: float
    gap_ticks: int
    peer: str

    @classmethod
    def of(cls, safety: SafetyConfig, offset_m: tuple[float, float], dt_s: float, *,
           force_slew_n_per_s: float | None, step_margin_m: float, watchdog_s: float,
           peer: str) -> Plausibility:
        """The limits of a site whose robot is ``safety`` and whose robot frame is the
        patient's shoulder frame shifted by ``offset_m`` (robot = shoulder + offset)."""
        x0, x1, y0, y1 = safety.workspace_m
        ox, oy = offset_m
        return cls(safety.force_limit_n,
                   None if force_slew_n_per_s is None else force_slew_n_per_s * dt_s,
                   safety.speed_limit_m_per_s, step_margin_m,
                   (x0 - ox, x1 - ox, y0 - oy, y1 - oy), dt_s,
                   max(1, math.ceil(watchdog_s / dt_s)), peer)


class PlausibilityCheck:
    """Checks one peer's STATEs in order (:meth:`check`), remembering the last one accepted."""

    def __init__(self, limits: Plausibility) -> None:
        self.limits = limits
        self.last: State | None = None
        self._last_armed = False

    def check(self, st: State, flags: int) -> str:
        """Why ``st`` (with the sender's ``flags``) cannot be used, in words ('' when it can);
        an accepted one becomes the reference of the next."""
        lim = self.limits
        who = lim.peer
        f = math.hypot(st.fx, st.fy)
        if f > lim.force_limit_n:
            return (f"{who} sent a force of {f:.4g} N, beyond this robot's "
                    f"{lim.force_limit_n:g} N limit")
        x0, x1, y0, y1 = lim.workspace_m
        if not (x0 <= st.x <= x1 and y0 <= st.y <= y1):
            return (f"{who} sent a position ({st.x:.4g}, {st.y:.4g}) m outside this robot's "
                    f"workspace (x {x0:.3g} … {x1:.3g}, y {y0:.3g} … {y1:.3g} m, shoulder frame)")
        v = math.hypot(st.vx, st.vy)
        if v > lim.speed_limit_m_per_s:
            return (f"{who} sent a speed of {v:.4g} m/s, beyond this robot's "
                    f"{lim.speed_limit_m_per_s:g} m/s limit")
        prev = self.last
        armed = bool(flags & FLAG_ARMED)
        if prev is not None:
            ticks = st.tick - prev.tick
            if ticks <= 0:
                return f"{who} sent tick {st.tick} after tick {prev.tick}"
            n = min(ticks, lim.gap_ticks)
            slew = lim.force_slew_n_per_tick
            df = math.hypot(st.fx - prev.fx, st.fy - prev.fy)
            if slew is not None and df > slew * n:
                return (f"{who}'s force changed by {df:.4g} N in {ticks} tick(s), beyond the "
                        f"{slew:g} N per tick this site accepts")
            step = math.hypot(st.x - prev.x, st.y - prev.y)
            allowed = lim.speed_limit_m_per_s * lim.dt_s * n + lim.step_margin_m
            if armed and self._last_armed and step > allowed:
                return (f"{who}'s position moved {step * 1e3:.4g} mm in {ticks} tick(s), beyond "
                        f"the {allowed * 1e3:.3g} mm this robot's speed limit allows")
        self.last = st
        self._last_armed = armed
        return ""
