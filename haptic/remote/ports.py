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

Each port keeps its own safety (:class:`~haptic.remote.supervision.LinkPort`): it engages only
once its robot has been ready and its loop on time for ``ready_s``; it uses only the peer's
STATEs that :mod:`haptic.remote.plausible` accepts (the first it refuses is a fault of the link:
the force ramps to zero and stays there); a **watchdog** (no STATE from the peer for
``watchdog_s`` → the link is lost: the force ramps to zero over ``ramp_s``, raised cosine, and
the patient's robot stops following; when STATEs have flowed again for ``resume_s`` it ramps
back in); the peer's BYE or silence ramps the force to zero before the session ends. Then the
**passivity** controller of :mod:`haptic.remote.passivity` (an energy tank per port, topped up
by what the other port hands over), and — in the site that owns the robot — the robot's own
limits (:mod:`haptic.safety`). Every tick is one row of a
:class:`~haptic.remote.linklog.LinkLog` (energy per tick included).

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

import math
from collections.abc import Callable

from fieldbank.haptic.remote.channel import Endpoint
from fieldbank.haptic.remote.config import LinkConfig
from fieldbank.haptic.remote.linklog import CLINICIAN_COLUMNS, PATIENT_COLUMNS
from fieldbank.haptic.remote.passivity import ForcePort, VelocityPort
from fieldbank.haptic.remote.plausible import Plausibility
from fieldbank.haptic.remote.supervision import LinkPort
from fieldbank.haptic.remote.tap import TapWriter
from fieldbank.haptic.remote.wire import FLAG_ARMED, State


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


class ClinicianPort(LinkPort):
    """The clinician's end: handle in, force out (shoulder frame of the patient).

    ``commanded``: the force the robot was actually commanded on the previous tick (after the
    site's limits), booked by the observer in place of what the port asked for.
    """

    role = "clinician"
    peer_name = "the patient's site"
    displays_peer_force = True
    columns = CLINICIAN_COLUMNS

    def __init__(self, endpoint: Endpoint, config: LinkConfig, dt_s: float,
                 plausibility: Plausibility | None = None) -> None:
        super().__init__(endpoint, config, dt_s, plausibility)
        self.pc = ForcePort(dt_s, config.reserve_j)
        self.commanded: Callable[[], tuple[float, float]] | None = None
        self.offset = (0.0, 0.0)
        self.engaged = False
        self._pending: tuple[float, float, float, float] | None = None
        self.fx = self.fy = 0.0
        #: mirrors every log row for another process (the station), when set
        self.tap: TapWriter | None = None
        #: sent before the first STATE: the CONFIRM of the handshake, so that the patient's
        #: site starts its loop (and arms its robot) when this one starts
        self.greeting: bytes | None = None

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
        if self.greeting is not None:
            self.endpoint.transport.send(self.greeting)
            self.greeting = None
        self._local(t)
        self._receive(t)
        peer = self.peer
        engaged = (self.may_render(self.engaged) and self.link_ok and peer is not None
                   and not self.link_fault and not self.closing)
        if engaged and not self.engaged:
            assert peer is not None
            self.offset = (peer.x - x, peer.y - y)  # the clutch: start where the patient is
            self._event("engaged", t, f"engaged at t = {t:.2f} s: the patient's hand is felt",
                        clutch_m=[round(v, 6) for v in self.offset])
        elif self.engaged and not engaged:
            self._event("disengaged", t, link_ok=self.link_ok, fit=self.fit)
        self.engaged = engaged
        g = self._gain(engaged and bool(self.peer_flags & FLAG_ARMED), t)
        wx = wy = 0.0
        if peer is not None:
            b = self.config.damping_n_s_per_m
            wx, wy = g * (peer.fx - b * vx), g * (peer.fy - b * vy)
            pc.energy.receive(peer.e_sent)
        fx, fy = wx, wy
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


class PatientPort(LinkPort):
    """The patient's end: the patient's handle and its force in, the servo force out."""

    role = "patient"
    peer_name = "the clinician's site"
    columns = PATIENT_COLUMNS

    def __init__(self, endpoint: Endpoint, config: LinkConfig, dt_s: float,
                 plausibility: Plausibility | None = None) -> None:
        super().__init__(endpoint, config, dt_s, plausibility)
        self.pc = VelocityPort(dt_s, config.patient_reserve_j)
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
        self._local(t)
        self._receive(t)
        if self.new_state:
            self._peer_at = t
        peer = self.peer
        want = (self.may_render(self.engaged) and self.link_ok and peer is not None
                and bool(self.peer_flags & FLAG_ARMED) and not self.link_fault
                and not self.closing)
        if want and not self.engaged:
            self.cmd = (x, y)
            self._event("engaged", t, f"engaged at t = {t:.2f} s: the robot follows the "
                        "clinician's hand")
        elif self.engaged and not want:
            self._event("disengaged", t, link_ok=self.link_ok, fit=self.fit)
        if want:
            self.engaged = True
        g = self._gain(want, t)
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
