"""The two ends of a remote assessment, one tick at a time: the clinician's port and the
patient's port, joined by an :class:`~haptic.remote.channel.Endpoint` each.

Architecture (position–force, the usual two-channel teleoperator)::

    clinician's handle x_c, v_c ──STATE──► patient site: the patient's robot follows
                                           (servo toward x_cmd, v_cmd; x_cmd tracks x_c)
    clinician feels F ◄──STATE── the force the patient's hand puts on the patient's handle

Positions travel in the **shoulder frame of the patient**: each site converts with its own
offset (the clinician's robot sits wherever it sits). When a side engages (the clinician arms,
or the link comes back) the clinician's port takes a *clutch* offset so that the patient's
robot starts from where the patient's hand is, never with a jump.

Each port keeps its own safety: a **watchdog** (no STATE from the peer for ``watchdog_s`` → the
link is lost: the force ramps to zero over ``ramp_s``, raised cosine, and the patient's robot
stops following; when STATEs have flowed again for ``resume_s`` it ramps back in; the first
link-up engages as soon as STATEs flow), the
**passivity** controller of :mod:`haptic.remote.passivity` (an energy tank per port, topped up
by what the other port hands over), and — in the site that owns the robot — the robot's own limits
(:mod:`haptic.safety`). Every tick is one row of a :class:`LinkLog` (energy per tick included).

The patient's side (:class:`PatientPort`) turns the clinician's position into the motion of
the patient's robot: the nominal velocity is the clinician's, plus a pull back toward the
clinician's position over ``drift_time_s`` (the passivity controller may have held the robot
back); the passivity controller may slow it; the integral is the robot's reference x_cmd. The
servo force is K (x_cmd − x) + B (v_cmd − v) − k_ff F_patient (``servo_ff``: the patient's
measured force fed forward; off by default). The pull back toward the clinician's position
never acts against the clinician's motion: when the clinician gives way the robot follows at
once, and that is what hands the patient's energy back.
"""

from __future__ import annotations

import array
import io
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from fieldbank.files import to_json
from fieldbank.haptic.pair import Ramp
from fieldbank.haptic.remote.channel import Endpoint
from fieldbank.haptic.remote.passivity import DEFAULT_RESERVE_J, ForcePort, VelocityPort
from fieldbank.haptic.remote.tap import TapWriter
from fieldbank.haptic.remote.wire import FLAG_ARMED, FLAG_FAULT, FLAG_LINK_LOST, Kind, State
from fieldbank.validation import Interval, check_fields

#: Allowed range of every numeric field of :class:`LinkConfig`.
LINK_BOUNDS: dict[str, Interval] = {
    "watchdog_s": Interval(0.005, 2.0, "s"),
    "resume_s": Interval(0.0, 10.0, "s"),
    "ramp_s": Interval(0.01, 2.0, "s"),
    "lockstep_wait_s": Interval(0.01, 60.0, "s"),
    "start_wait_s": Interval(0.01, 3600.0, "s"),
    "drift_time_s": Interval(0.01, 5.0, "s"),
    "extrapolate_s": Interval(0.0, 0.2, "s"),
    "servo_k_n_per_m": Interval(100.0, 50000.0, "N/m"),
    "servo_b_n_s_per_m": Interval(0.0, 2000.0, "N·s/m"),
    "servo_ff": Interval(0.0, 1.0, "1"),
    "reserve_j": Interval(0.0, 1.0, "J"),
    "patient_reserve_j": Interval(0.0, 1.0, "J"),
    "damping_n_s_per_m": Interval(0.0, 200.0, "N·s/m"),
    "force_filter_hz": Interval(0.0, 500.0, "Hz"),
}
#: Passivity modes: the time-domain controller of :mod:`haptic.remote.passivity`, or none
#: (observer only: for measuring what the link would create).
PASSIVITY_MODES = ("tdpa", "off")


@dataclass(frozen=True)
class LinkConfig:
    """Settings of a port (ranges in :data:`LINK_BOUNDS`); both sites should agree.

    Attributes
    ----------
    watchdog_s : float, s
        No STATE from the peer for this long: the link is lost.
    resume_s : float, s
        STATEs must flow this long again before the force ramps back in.
    ramp_s : float, s
        Raised-cosine ramp of the force out (link lost) and in (engaged, resumed).
    lockstep_wait_s : float, s
        Lockstep: longest wall-clock wait for the peer's previous tick.
    start_wait_s : float, s
        Lockstep: longest wait for the peer's first STATE (its loop may start later: a station
        to launch, a robot to arm).
    drift_time_s : float, s
        Patient's side: time constant of the pull of the robot's reference back to the
        clinician's position.
    extrapolate_s : float, s
        Patient's side: the clinician's position is carried forward at its last velocity for
        at most this long after the newest STATE (lost datagrams).
    servo_k_n_per_m, servo_b_n_s_per_m : float
        Patient's side: the servo that moves the patient's robot (assumption: stiff enough
        that a hypertonic arm moves it ≤ 2 mm, damped enough for ≈ 3 kg of handle and arm).
    servo_ff : float
        Patient's side: fraction of the patient's measured force the servo compensates.
    reserve_j : float, J
        Energy the clinician's port keeps in its tank before handing the rest to the
        patient's (:mod:`haptic.remote.passivity`): it pays the small give of a hand holding
        still against a force without waiting a round trip. The patient's port keeps none: it
        hands back at once whatever the patient returns.
    damping_n_s_per_m : float, N·s/m
        Clinician's side: a damper added to what is displayed (0: none).
    force_filter_hz : float, Hz
        Patient's side: cut-off of the low-pass filter (second-order Butterworth) on the
        patient's measured force before it is used and sent (0: none). A hand gripping a
        handle through a stiff grip rings at a few hundred hertz, and the force sensor reads
        it; nobody feels it at the hand, but it would shake the clinician's handle.
    passivity : str
        'tdpa' (time-domain passivity controller) or 'off' (observer only).
    """

    watchdog_s: float = 0.1
    resume_s: float = 0.5
    ramp_s: float = 0.2
    lockstep_wait_s: float = 5.0
    start_wait_s: float = 120.0
    drift_time_s: float = 0.2
    extrapolate_s: float = 0.02
    servo_k_n_per_m: float = 8000.0
    servo_b_n_s_per_m: float = 120.0
    servo_ff: float = 0.0
    reserve_j: float = DEFAULT_RESERVE_J
    patient_reserve_j: float = 0.0
    damping_n_s_per_m: float = 0.0
    force_filter_hz: float = 80.0
    passivity: str = "tdpa"

    def __post_init__(self) -> None:
        check_fields(self, LINK_BOUNDS, what="remote link setting")
        if self.passivity not in PASSIVITY_MODES:
            raise ValueError(f"passivity must be one of {', '.join(PASSIVITY_MODES)}; got "
                             f"{self.passivity!r}")

    def to_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


class LinkLog:
    """Per-tick rows of named float64 columns with units (grows in chunks, never copies)."""

    def __init__(self, columns: tuple[tuple[str, str], ...]) -> None:
        self.columns = columns
        self._cols = [array.array("d") for _ in columns]
        self.n = 0

    def add(self, row: tuple[float, ...]) -> None:
        for c, v in zip(self._cols, row, strict=True):
            c.append(v)
        self.n += 1

    def arrays(self) -> dict[str, np.ndarray]:
        return {name: np.frombuffer(c, dtype=np.float64).copy()
                for (name, _), c in zip(self.columns, self._cols, strict=True)}

    def last(self, name: str) -> float:
        i = [c for c, _ in self.columns].index(name)
        return self._cols[i][-1] if self.n else math.nan

    @property
    def units(self) -> dict[str, str]:
        return dict(self.columns)

    def to_hdf5(self, attrs: dict[str, Any]) -> bytes:
        """The log as an HDF5 image: one dataset per column with its ``unit``; ``attrs`` (JSON)
        on the file."""
        import h5py  # heavy: loaded only when a session's log is written

        bio = io.BytesIO()
        with h5py.File(bio, "w") as f:
            for name, data in self.arrays().items():
                d = f.create_dataset(name, data=data, compression="gzip", fletcher32=True)
                d.attrs["unit"] = self.units[name]
            for k, v in attrs.items():
                f.attrs[k] = to_json(v)
        return bio.getvalue()


CLINICIAN_COLUMNS: tuple[tuple[str, str], ...] = (
    ("t_s", "s"), ("tick", "1"),
    ("x_m", "m"), ("y_m", "m"), ("vx_m_per_s", "m/s"), ("vy_m_per_s", "m/s"),  # port (sent)
    ("want_fx_n", "N"), ("want_fy_n", "N"),          # received patient force × ramp gain
    ("fx_n", "N"), ("fy_n", "N"),                    # displayed (booked: what was commanded)
    ("e_in_j", "J"), ("e_out_j", "J"),               # this port's observer
    ("e_sent_j", "J"), ("e_received_j", "J"),        # its tank's hand-overs
    ("peer_e_in_j", "J"), ("peer_e_out_j", "J"),     # the patient port, as last received
    ("alpha_n_s_per_m", "N·s/m"),                    # passivity controller's damping
    ("gain", "1"), ("link_ok", "1"), ("engaged", "1"), ("rtt_s", "s"),
    ("peer_x_m", "m"), ("peer_y_m", "m"), ("peer_vx_m_per_s", "m/s"),
    ("peer_vy_m_per_s", "m/s"), ("peer_fx_n", "N"), ("peer_fy_n", "N"),
    ("peer_tick", "1"), ("peer_flags", "1"), ("new_state", "1"), ("lost", "1"),
    ("dissipated_j", "J"),
)
PATIENT_COLUMNS: tuple[tuple[str, str], ...] = (
    ("t_s", "s"), ("tick", "1"),
    ("x_m", "m"), ("y_m", "m"), ("vx_m_per_s", "m/s"), ("vy_m_per_s", "m/s"),  # patient handle
    ("hand_fx_n", "N"), ("hand_fy_n", "N"),          # the patient's force on the handle
    ("target_x_m", "m"), ("target_y_m", "m"),        # the clinician's position (received)
    ("cmd_x_m", "m"), ("cmd_y_m", "m"),              # the robot's reference
    ("cmd_vx_m_per_s", "m/s"), ("cmd_vy_m_per_s", "m/s"),
    ("servo_fx_n", "N"), ("servo_fy_n", "N"),        # commanded to the patient's robot
    ("e_in_j", "J"), ("e_out_j", "J"),
    ("e_sent_j", "J"), ("e_received_j", "J"),
    ("peer_e_in_j", "J"), ("peer_e_out_j", "J"),
    ("beta_m_per_n_s", "m/(N·s)"),
    ("gain", "1"), ("link_ok", "1"), ("engaged", "1"), ("rtt_s", "s"),
    ("new_state", "1"), ("lost", "1"),
)


class LowPass:
    """Second-order Butterworth low-pass (bilinear transform), one per axis, plain floats."""

    __slots__ = ("a1", "a2", "b0", "b1", "b2", "zs")

    def __init__(self, cutoff_hz: float, dt_s: float, axes: int = 2) -> None:
        k = math.tan(math.pi * cutoff_hz * dt_s)
        q = math.sqrt(2.0)
        norm = 1.0 / (1.0 + q * k + k * k)
        self.b0 = k * k * norm
        self.b1 = 2.0 * self.b0
        self.b2 = self.b0
        self.a1 = 2.0 * (k * k - 1.0) * norm
        self.a2 = (1.0 - q * k + k * k) * norm
        self.zs = [[0.0, 0.0] for _ in range(axes)]

    def reset(self, values: tuple[float, ...]) -> None:
        """Start at rest at ``values`` (no transient)."""
        for z, v in zip(self.zs, values, strict=True):
            z[0] = v * (1.0 - self.b0)
            z[1] = v * (self.b2 - self.a2)

    def __call__(self, i: int, x: float) -> float:
        """Filter one sample of axis ``i`` (transposed direct form II)."""
        z = self.zs[i]
        y = self.b0 * x + z[0]
        z[0] = self.b1 * x - self.a1 * y + z[1]
        z[1] = self.b2 * x - self.a2 * y
        return y


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


class _Port:
    """What both ends share: the endpoint, the clock, the watchdog, the ramp, the log."""

    def __init__(self, endpoint: Endpoint, config: LinkConfig, dt_s: float,
                 columns: tuple[tuple[str, str], ...]) -> None:
        self.endpoint = endpoint
        self.config = config
        self.dt = dt_s
        self.tick_n = 0
        self.watchdog = _Watchdog(config)
        self.ramp = Ramp(0.0)
        self._ramp_ticks = max(1, round(config.ramp_s / dt_s))
        self.log = LinkLog(columns)
        self.peer: State | None = None
        self.peer_flags = 0
        self.new_state = False
        self.events: list[dict[str, Any]] = []
        self._t0 = time.monotonic()
        self.link_ok = False
        self.fault = False
        #: why the peer ended the session ('' while it goes on): its BYE, or its silence in
        #: lockstep; ``on_end`` is called once when it does
        self.ended = ""
        self.on_end: Callable[[], None] | None = None

    def now(self) -> float:
        """Session time, s: the tick's virtual time in lockstep, else the wall clock."""
        if self.endpoint.lockstep:
            return self.tick_n * self.dt
        return time.monotonic() - self._t0

    def _event(self, kind: str, t: float, **data: Any) -> None:
        self.events.append({"t_s": round(t, 6), "event": kind, **data})

    def _receive(self, t: float) -> None:
        ep = self.endpoint
        if ep.lockstep:
            ep.wait_peer_tick(self.tick_n - 1, t, self.config.lockstep_wait_s
                              if ep.peer_tick >= 0 else self.config.start_wait_s)
        st = ep.receive(t)
        while ep.messages:
            d = ep.messages.popleft()
            if d.kind == Kind.BYE and not self.ended:
                self.ended = str((d.message or {}).get("reason") or "the peer said BYE")
        if ep.lockstep and ep.peer_silent and not self.ended:
            self.ended = "the peer fell silent"
        if self.ended and self.on_end is not None:
            self._event("peer_ended", t, reason=self.ended)
            end, self.on_end = self.on_end, None
            end()
        self.new_state = st is not None
        if st is not None:
            self.peer = st
            self.peer_flags = ep.peer_flags
        was = self.link_ok
        self.link_ok = self.watchdog.update(t, ep.last_heard_s) and self.peer is not None
        if was and not self.link_ok:
            self._event("link_lost", t, silent_s=round(t - ep.last_heard_s, 6))
        elif self.link_ok and not was:
            self._event("link_up", t, rtt_ms=ep.stats()["rtt_ms"])

    def _set_ramp(self, on: bool) -> float:
        target = 1.0 if on else 0.0
        if self.ramp.end != target:
            self.ramp.go(target, self._ramp_ticks)
        return self.ramp.step()

    def _flags(self, engaged: bool) -> int:
        return ((FLAG_ARMED if engaged else 0) | (0 if self.link_ok else FLAG_LINK_LOST)
                | (FLAG_FAULT if self.fault else 0))

    @property
    def rtt_s(self) -> float:
        return self.endpoint.counters.rtt_s

    def summary(self) -> dict[str, Any]:
        """The link's figures and the passivity controller's activity (JSON-able)."""
        raise NotImplementedError


class ClinicianPort(_Port):
    """The clinician's end: handle in, force out (shoulder frame of the patient).

    ``armed``: whether the clinician's robot renders (the session tells the port); ``commanded``:
    the force the robot was actually commanded on the previous tick (after the site's limits),
    booked by the observer in place of what the port asked for.
    """

    def __init__(self, endpoint: Endpoint, config: LinkConfig, dt_s: float) -> None:
        super().__init__(endpoint, config, dt_s, CLINICIAN_COLUMNS)
        self.pc = ForcePort(dt_s, config.reserve_j)
        self.armed: Callable[[], bool] = lambda: True
        self.commanded: Callable[[], tuple[float, float]] | None = None
        self.offset = (0.0, 0.0)
        self.engaged = False
        self._pending: tuple[float, float, float, float] | None = None
        self.fx = self.fy = 0.0
        #: mirrors every log row for another process (the station), when set
        self.tap: TapWriter | None = None

    def tick(self, x: float, y: float, vx: float, vy: float) -> tuple[float, float]:
        """One tick with the clinician's handle at (x, y) moving at (vx, vy) (shoulder frame);
        returns the force to display on the handle, N."""
        pc = self.pc
        if self._pending is not None:  # book the previous tick with what was really sent
            fx0, fy0, vx0, vy0 = self._pending
            if self.commanded is not None:
                fx0, fy0 = self.commanded()
            pc.book(fx0, fy0, vx0, vy0)
        t = self.now()
        self._receive(t)
        peer = self.peer
        armed = self.armed()
        engaged = armed and self.link_ok and peer is not None
        if engaged and not self.engaged:
            assert peer is not None
            self.offset = (peer.x - x, peer.y - y)  # the clutch: start where the patient is
            self._event("engaged", t, clutch_m=[round(v, 6) for v in self.offset])
        elif self.engaged and not engaged:
            self._event("disengaged", t, link_ok=self.link_ok, armed=armed)
        self.engaged = engaged
        peer_engaged = bool(self.peer_flags & FLAG_ARMED)
        g = self._set_ramp(engaged and peer_engaged)
        wx = wy = 0.0
        if peer is not None:
            b = self.config.damping_n_s_per_m
            wx, wy = g * (peer.fx - b * vx), g * (peer.fy - b * vy)
        fx, fy = wx, wy
        if peer is not None:
            pc.energy.receive(peer.e_sent)
        if self.config.passivity == "tdpa":
            fx, fy = pc.correct(wx, wy, vx, vy)
        self._pending = (fx, fy, vx, vy)
        self.fx, self.fy = fx, fy
        ox, oy = self.offset
        e = pc.energy
        self.endpoint.send_state(State(self.tick_n, x + ox, y + oy, vx, vy, fx, fy, e.e_in,
                                       e.e_out, e.sent), t, self._flags(engaged))
        nan = math.nan
        p = peer
        row = (t, self.tick_n, x + ox, y + oy, vx, vy, wx, wy, fx, fy, e.e_in, e.e_out,
               e.sent, e.received, p.e_in if p else 0.0, p.e_out if p else 0.0,
               pc.last_alpha, g, float(self.link_ok), float(engaged), self.rtt_s,
               p.x if p else nan, p.y if p else nan, p.vx if p else nan, p.vy if p else nan,
               p.fx if p else nan, p.fy if p else nan, p.tick if p else -1.0,
               float(self.peer_flags), float(self.new_state),
               float(self.endpoint.counters.lost), pc.dissipated_j)
        self.log.add(row)
        if self.tap is not None:
            self.tap.add(row)
        self.tick_n += 1
        return fx, fy

    def finish(self) -> None:
        """Book the last tick."""
        if self._pending is not None:
            fx0, fy0, vx0, vy0 = self._pending
            if self.commanded is not None:
                fx0, fy0 = self.commanded()
            self.pc.book(fx0, fy0, vx0, vy0)
            self._pending = None

    def summary(self) -> dict[str, Any]:
        pc = self.pc
        return {"role": "clinician", "ticks": self.tick_n,
                "passivity": self.config.passivity,
                "e_in_j": pc.energy.e_in, "e_out_j": pc.energy.e_out,
                "passivity_active_ticks": pc.active_ticks,
                "passivity_dissipated_j": pc.dissipated_j,
                "link": self.endpoint.stats(), "events": list(self.events)}


class PatientPort(_Port):
    """The patient's end: the patient's handle and its force in, the servo force out.

    ``robot_ok``: whether the patient's robot is armed and free of faults (the site tells the
    port).
    """

    def __init__(self, endpoint: Endpoint, config: LinkConfig, dt_s: float) -> None:
        super().__init__(endpoint, config, dt_s, PATIENT_COLUMNS)
        self.pc = VelocityPort(dt_s, config.patient_reserve_j)
        self.robot_ok: Callable[[], bool] = lambda: True
        self.engaged = False
        self.cmd = (math.nan, math.nan)
        self._peer_at = 0.0
        self.fx = self.fy = 0.0
        self.filter = (LowPass(config.force_filter_hz, dt_s)
                       if config.force_filter_hz > 0 else None)
        self._filter_primed = False

    def tick(self, x: float, y: float, vx: float, vy: float, hand_fx: float,
             hand_fy: float) -> tuple[float, float]:
        """One tick with the patient's handle at (x, y), (vx, vy) and the patient's hand
        pushing it with (hand_fx, hand_fy) (shoulder frame, SI); returns the servo force to
        command on the patient's robot, N."""
        cfg = self.config
        t = self.now()
        lp = self.filter
        if lp is not None:
            if not self._filter_primed:
                lp.reset((hand_fx, hand_fy))
                self._filter_primed = True
            hand_fx, hand_fy = lp(0, hand_fx), lp(1, hand_fy)
        self._receive(t)
        if self.new_state:
            self._peer_at = t
        peer = self.peer
        want = (self.link_ok and peer is not None and bool(self.peer_flags & FLAG_ARMED)
                and self.robot_ok())
        if want and not self.engaged:
            self.cmd = (x, y)
            self._event("engaged", t)
        elif self.engaged and not want:
            self._event("disengaged", t, link_ok=self.link_ok)
        if want:
            self.engaged = True
        g = self._set_ramp(want)
        if not want and g == 0.0:
            self.engaged = False
        tx = ty = tvx = tvy = math.nan
        cvx = cvy = 0.0
        fx = fy = 0.0
        # the port's force: what the link exerts on the patient's side (minus the patient's)
        px, py = -hand_fx, -hand_fy
        pc = self.pc
        if peer is not None:
            pc.energy.receive(peer.e_sent)
        if self.engaged and peer is not None:
            age = min(t - self._peer_at, cfg.extrapolate_s)
            tx, ty = peer.x + peer.vx * age, peer.y + peer.vy * age
            tvx, tvy = peer.vx, peer.vy
            cx, cy = self.cmd
            k = 1.0 / cfg.drift_time_s
            dx, dy = k * (tx - cx), k * (ty - cy)
            if dx * tvx + dy * tvy < 0.0:
                # never pull back against the clinician's motion: following it is what hands
                # the patient's energy back when the clinician gives way
                dx = dy = 0.0
            nvx, nvy = tvx + dx, tvy + dy
            if g < 1.0:  # ramping in or out: the reference follows only as far as the gain
                nvx, nvy = g * nvx, g * nvy
            if cfg.passivity == "tdpa":
                cvx, cvy = pc.correct(nvx, nvy, px, py)
            else:
                cvx, cvy = nvx, nvy
            pc.book(cvx, cvy, px, py)
            cx, cy = cx + cvx * self.dt, cy + cvy * self.dt
            self.cmd = (cx, cy)
            ks, bs, ff = cfg.servo_k_n_per_m, cfg.servo_b_n_s_per_m, cfg.servo_ff
            fx = g * (ks * (cx - x) + bs * (cvx - vx) - ff * hand_fx)
            fy = g * (ks * (cy - y) + bs * (cvy - vy) - ff * hand_fy)
        self.fx, self.fy = fx, fy
        e = pc.energy
        self.endpoint.send_state(State(self.tick_n, x, y, vx, vy, hand_fx, hand_fy, e.e_in,
                                       e.e_out, e.sent), t, self._flags(self.engaged))
        p = peer
        cx, cy = self.cmd
        self.log.add((t, self.tick_n, x, y, vx, vy, hand_fx, hand_fy, tx, ty, cx, cy, cvx, cvy,
                      fx, fy, e.e_in, e.e_out, e.sent, e.received, p.e_in if p else 0.0,
                      p.e_out if p else 0.0,
                      pc.last_beta, g, float(self.link_ok), float(self.engaged), self.rtt_s,
                      float(self.new_state), float(self.endpoint.counters.lost)))
        self.tick_n += 1
        return fx, fy

    def summary(self) -> dict[str, Any]:
        pc = self.pc
        return {"role": "patient", "ticks": self.tick_n, "passivity": self.config.passivity,
                "e_in_j": pc.energy.e_in, "e_out_j": pc.energy.e_out,
                "passivity_active_ticks": pc.active_ticks,
                "passivity_dissipated_j": pc.dissipated_j,
                "link": self.endpoint.stats(), "events": list(self.events)}
