"""Whether the link may carry force, tick by tick: what both ends of a remote session share.

Each port (:mod:`haptic.remote.ports`) is a :class:`LinkPort`; every tick it asks

* **its robot** (:meth:`LinkPort._local`): armed and free of latched faults
  (:attr:`LinkPort.fit`); a site *engages* only once that has held, with its loop on time (no
  tick woke a whole period late), for ``ready_s`` without a break (:attr:`LinkPort.ready`), so
  it never engages while its robot or its loop is still settling; once engaged it stays so while
  its robot is fit (a late tick is the robot's watchdog's business);
* **the peer** (:meth:`LinkPort._receive`): the newest STATE the endpoint released, used only
  after :mod:`haptic.remote.plausible` accepted it (the first implausible one is the link's
  fault, held to the end of the session); a BYE, or in lockstep the peer's silence, ends the
  session;
* **the watchdog**: no STATE for ``watchdog_s`` and the link is lost; after ``resume_s`` of
  STATEs again it is back (the first link-up counts at once);
* **the gain** (:meth:`LinkPort._gain`): a raised cosine over ``ramp_s`` toward 1 while the end
  may render and toward 0 otherwise. After the peer's end, and before this site's own planned
  end (:meth:`LinkPort.plan_end`; its operator's stop, :meth:`LinkPort.end_now`), it ramps to
  zero and only then is the session closed: the port says BYE at once and calls
  :attr:`LinkPort.on_end`. Neither a BYE, nor a silent peer, nor the end of the session's
  duration, nor the operator's stop steps the force.

Every change is an event (:attr:`LinkPort.events`: time, kind, what was seen); those a person
at either site must know — engaged, the link lost and back, a fault of this robot or the
peer's, data refused as implausible, the peer's end — are logged in words as they happen
(logger ``fieldbank.haptic.remote``: the site's terminal). In a real-time loop the records go
through the writer thread of :func:`haptic.clock.logging_off_the_loop`: the tick does no I/O.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from typing import Any, Self

from fieldbank.haptic.pair import Ramp
from fieldbank.haptic.protocol import FaultCode
from fieldbank.haptic.remote.channel import Endpoint
from fieldbank.haptic.remote.config import LinkConfig, SiteConfig
from fieldbank.haptic.remote.linklog import LinkLog
from fieldbank.haptic.remote.plausible import Plausibility, PlausibilityCheck
from fieldbank.haptic.remote.wire import FLAG_ARMED, FLAG_FAULT, FLAG_LINK_LOST, Kind, State

log = logging.getLogger("fieldbank.haptic.remote")


class _Watchdog:
    """Link lost when nothing was heard for ``watchdog_s``; back when heard for ``resume_s``."""

    __slots__ = ("lost_once", "ok", "resume_s", "since", "timeout_s")

    def __init__(self, cfg: LinkConfig) -> None:
        self.timeout_s = cfg.watchdog_s
        self.resume_s = cfg.resume_s
        self.ok = False
        self.lost_once = False     # the first link-up needs no wait; coming back after a loss does
        self.since = math.inf      # when STATEs started flowing again

    def update(self, now: float, last_heard: float) -> bool:
        fresh = now - last_heard <= self.timeout_s
        if not fresh:
            if self.ok:
                self.lost_once = True
            self.ok = False
            self.since = math.inf
        elif not self.ok:
            if self.since == math.inf:
                self.since = now
            if not self.lost_once or now - self.since >= self.resume_s:
                self.ok = True
        return self.ok


class _Readiness:
    """Ready after ``need`` ticks in a row with the robot fit to render and the loop on time."""

    __slots__ = ("need", "period_s", "run")

    def __init__(self, need: int, period_s: float) -> None:
        self.need = need
        self.period_s = period_s
        self.run = 0

    def update(self, fit: bool, late_s: float) -> bool:
        self.run = self.run + 1 if fit and late_s < self.period_s else 0
        return self.run >= self.need


class LinkPort:
    """What both ends share: the endpoint, the clock, watchdog, readiness, plausibility, the
    gain, the log and the events (module docstring).

    The site sets :attr:`robot_ok` (its robot is armed and renders), :attr:`latched` (its
    safety layer's latched faults, one bit per :class:`~haptic.protocol.FaultCode` − 1) and
    :attr:`late_s` (how late the present tick woke, s).
    """

    #: this end and its peer, in words
    role = "link"
    peer_name = "the peer"
    #: whether this end displays the peer's force (then its change per tick is checked too)
    displays_peer_force = False
    #: the columns of this end's log
    columns: tuple[tuple[str, str], ...] = ()

    def __init__(self, endpoint: Endpoint, config: LinkConfig, dt_s: float,
                 plausibility: Plausibility | None = None) -> None:
        self.endpoint = endpoint
        self.config = config
        self.dt = dt_s
        self.tick_n = 0
        self.watchdog = _Watchdog(config)
        self.readiness = _Readiness(max(1, round(config.ready_s / dt_s)), dt_s)
        self.ramp = Ramp(0.0)
        self._ramp_ticks = max(1, round(config.ramp_s / dt_s))
        self.log = LinkLog(self.columns)
        self.check = None if plausibility is None else PlausibilityCheck(plausibility)
        self.peer: State | None = None
        self.peer_flags = 0
        self.new_state = False
        self.events: list[dict[str, Any]] = []
        self._t0: float | None = None
        self.link_ok = False
        self.fit = False
        self.ready = False
        self.robot_ok: Callable[[], bool] = lambda: True
        self.latched: Callable[[], int] = lambda: 0
        self.late_s: Callable[[], float] = lambda: 0.0
        self._latched = 0
        #: why the peer's data was refused: the link's fault, held to the end ('' while none)
        self.link_fault = ""
        #: why the peer ended the session ('' while it goes on); whether by its BYE
        self.ended = ""
        self.bye = False
        #: the force has ramped to zero after the peer's end or before this site's planned end
        #: (:meth:`plan_end`); the BYE was sent and :attr:`on_end` called then
        self.closed = False
        self.on_end: Callable[[], None] | None = None
        self.end_tick: int | None = None
        self.end_reason = ""
        self.bye_sent = False
        self._closing_told = False

    @classmethod
    def for_site(cls, endpoint: Endpoint, config: SiteConfig,
                 offset_m: tuple[float, float]) -> Self:
        """The port of a site whose robot has the limits ``config.safety`` and whose robot
        frame is the patient's shoulder frame shifted by ``offset_m``: it accepts of its peer
        only what that robot could display (:mod:`haptic.remote.plausible`)."""
        lc = config.link
        dt = 1.0 / config.rate_hz
        limits = Plausibility.of(
            config.safety, offset_m, dt, step_margin_m=lc.peer_step_margin_m,
            force_slew_n_per_s=lc.peer_force_slew_n_per_s if cls.displays_peer_force else None,
            watchdog_s=lc.watchdog_s, peer=cls.peer_name)
        return cls(endpoint, lc, dt, limits)

    def plan_end(self, ticks: int, reason: str) -> None:
        """End the session after ``ticks`` ticks (its duration), the force ramped out by then."""
        self.end_tick = ticks
        self.end_reason = reason

    def end_now(self, reason: str) -> None:
        """End the session as soon as the force has ramped out over ``ramp_s`` (this site's
        operator stopped it), unless it ends sooner anyway."""
        end = self.tick_n + self._ramp_ticks + 1
        if self.end_tick is None or end < self.end_tick:
            self.plan_end(end, reason)

    @property
    def closing(self) -> bool:
        """The force ramps out for good: the peer ended, or this site's planned end is near."""
        return bool(self.ended) or (self.end_tick is not None
                                    and self.tick_n >= self.end_tick - self._ramp_ticks - 1)

    def say_bye(self, reason: str, final: bool = True) -> None:
        """Tell the peer the session is over (once): ``final`` — this site ticks no more; else
        it ramps its force out over ``ramp_s`` first, and the peer (in lockstep, still waiting
        for its ticks) ramps out with it."""
        if not self.bye_sent:
            self.bye_sent = True
            self.endpoint.send_message(Kind.BYE, {"reason": reason, "final": final},
                                       self.now())

    def now(self) -> float:
        """Session time, s, from the first tick: the tick's virtual time in lockstep, else the
        wall clock."""
        if self.endpoint.lockstep:
            return self.tick_n * self.dt
        m = time.monotonic()
        if self._t0 is None:
            self._t0 = m
        return m - self._t0

    def _event(self, kind: str, t: float, text: str = "", level: int = logging.INFO,
               **data: Any) -> None:
        ev: dict[str, Any] = {"t_s": round(t, 6), "event": kind, **data}
        if text:
            ev["text"] = text
            log.log(level, "%s", text)
        self.events.append(ev)

    def _local(self, t: float) -> None:
        """This site's robot: new latched faults and a disarm become events; fitness and
        readiness are updated."""
        latched = self.latched()
        new = latched & ~self._latched
        self._latched = latched
        if new:
            for code in FaultCode:
                if new & (1 << (int(code) - 1)):  # the safety layer logs it in words
                    self._event("fault", t, name=code.name, code=int(code))
        fit = self.robot_ok() and not latched
        if self.fit and not fit and not latched:
            self._event("not_ready", t, f"this site's robot was disarmed at t = {t:.2f} s: the "
                        "force ramps to zero", why="disarmed")
        self.fit = fit
        self.ready = self.readiness.update(fit, self.late_s())

    def may_render(self, engaged: bool) -> bool:
        """This end may render: its robot fit, and ready unless already engaged."""
        return self.fit and (engaged or self.ready)

    def _end(self, t: float, reason: str, level: int = logging.INFO) -> None:
        if not self.ended:
            self.ended = reason
            self._event("peer_ended", t, f"{self.peer_name} ended the session at t = {t:.2f} s "
                        f"({reason}): the force ramps to zero", level, reason=reason)

    def _receive(self, t: float) -> None:
        ep = self.endpoint
        if ep.lockstep:
            ep.wait_peer_tick(self.tick_n - 1, t, self.config.lockstep_wait_s
                              if ep.peer_tick >= 0 else self.config.start_wait_s)
        st = ep.receive(t)
        while ep.messages:
            d = ep.messages.popleft()
            if d.kind == Kind.BYE and not self.ended and not self._closing_told:
                self.bye = True  # (its BYE after this site's own end began is no news)
                self._end(t, str((d.message or {}).get("reason") or "it said BYE"))
        if ep.lockstep and ep.peer_silent and not self._closing_told:
            self._end(t, f"silent for {self.config.lockstep_wait_s:g} s", logging.WARNING)
        self.new_state = False
        if st is not None and not self.link_fault:
            why = self.check.check(st, ep.peer_flags) if self.check is not None else ""
            if why:
                self.link_fault = why
                self._event("fault", t, f"fault PEER at t = {t:.2f} s: {why}; the force ramps "
                            "to zero and stays there for the rest of the session",
                            logging.WARNING, name="PEER")
            else:
                self.new_state = True
                self.peer = st
                if ep.peer_flags & FLAG_FAULT and not self.peer_flags & FLAG_FAULT:
                    self._event("peer_fault", t, f"{self.peer_name} reports a fault of its "
                                f"robot at t = {t:.2f} s: the force ramps to zero",
                                logging.WARNING)
                self.peer_flags = ep.peer_flags
        was = self.link_ok
        self.link_ok = self.watchdog.update(t, ep.last_heard_s) and self.peer is not None
        if self.ended:
            return  # the peer said goodbye or fell silent: its silence is no news
        if was and not self.link_ok:
            silent = t - ep.last_heard_s
            self._event("link_lost", t, f"link lost at t = {t:.2f} s: nothing from "
                        f"{self.peer_name} for {silent:.2f} s; the force ramps to zero over "
                        f"{self.config.ramp_s:g} s", logging.WARNING, silent_s=round(silent, 6))
        elif self.link_ok and not was:
            rtt = ep.stats()["rtt_ms"]
            again = self.watchdog.lost_once
            self._event("link_up", t, f"link {'back' if again else 'up'} at t = {t:.2f} s"
                        + (f" (round trip {rtt:g} ms)" if rtt is not None else ""),
                        rtt_ms=rtt)

    def _gain(self, on: bool, t: float) -> float:
        """This tick's gain, toward 1 while ``on`` (and no link fault, no end), else toward 0;
        after the peer's end, or before this site's planned end, once at zero, the session is
        closed."""
        closing = self.closing
        if closing and not self.ended and not self._closing_told:
            self._closing_told = True
            self._event("closing", t, f"the session ends at t = {t:.2f} s ({self.end_reason}): "
                        f"the force ramps to zero over {self.config.ramp_s:g} s",
                        reason=self.end_reason)
            self.say_bye(self.end_reason, final=False)
        target = 1.0 if on and not self.link_fault and not closing else 0.0
        if self.ramp.end != target:
            self.ramp.go(target, self._ramp_ticks)
        g = self.ramp.step()
        if closing and not self.closed and g == 0.0 and not self.ramp.moving and (
                self.ended or self.tick_n + 1 >= (self.end_tick or 0)):
            self.closed = True
            self.say_bye(self.end_reason or f"the {self.role}'s site ended after "
                         f"{self.peer_name} did")
            if self.on_end is not None:
                end, self.on_end = self.on_end, None
                end()
        return g

    def _flags(self, engaged: bool) -> int:
        return ((FLAG_ARMED if engaged else 0) | (0 if self.link_ok else FLAG_LINK_LOST)
                | (FLAG_FAULT if self._latched or self.link_fault else 0))

    @property
    def rtt_s(self) -> float:
        return self.endpoint.counters.rtt_s

    def summary(self) -> dict[str, Any]:
        """The link's figures, the passivity controller's activity, the events (JSON-able)."""
        pc = self.pc
        return {"role": self.role, "ticks": self.tick_n, "passivity": self.config.passivity,
                "e_in_j": pc.energy.e_in, "e_out_j": pc.energy.e_out,
                "passivity_active_ticks": pc.active_ticks,
                "passivity_dissipated_j": pc.dissipated_j,
                "link_fault": self.link_fault or None, "peer_ended": self.ended or None,
                "link": self.endpoint.stats(), "events": list(self.events)}

    pc: Any  # the passivity controller of the subclass's port
