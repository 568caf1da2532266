"""Passivity of the delayed link: an observer, an energy tank and a controller at each port.

The link between the sites is a two-port network: at the clinician's port it takes the
handle's velocity and returns a force (impedance causality); at the patient's port it takes a
force (the patient's, measured) and returns a velocity (the motion the patient's robot is told
to make: admittance causality). With delay, loss and jitter such a network can create energy,
and a link that creates energy can make the clinician's robot, the patient's arm or both
oscillate. Time-domain passivity keeps it passive at any delay:

* **observer** (Hannaford & Ryu 2002; for teleoperation Ryu, Kwon & Hannaford 2004, IEEE Trans.
  Robot. Autom. 20(2):365–373), per port and tick: the power P = F·v leaving the link there is
  split into what leaves (P > 0: E_out += P Δt) and what enters (P < 0: E_in −= P Δt);
* **energy tanks** (the passivity layer of Franken, Stramigioli, Misra, Secchi & Macchelli
  2011, IEEE Trans. Robot. 27(4):741–756): each port holds what entered through it plus what the
  other port handed over, minus what it let out and what it handed over,

      H = E_in + E_received − E_out − E_sent  ≥ 0,

  and hands everything above a reserve R to the other side (``E_sent`` is cumulative and
  travels in every STATE, so a lost datagram only delays a hand-over). The link's stored energy
  is H_clinician + H_patient + what is in flight (sent, not yet received) — every term ≥ 0 — and
  equals all that entered minus all that left: the link never creates energy, whatever the
  delay, its jitter or the datagrams lost. The clinician's port keeps a reserve (1 mJ): it
  answers the small give of a hand holding still against a force at once, instead of waiting
  a round trip for the patient's side to hand energy back (a budget that always waits makes
  every hold chatter); the patient's port keeps none and hands back at once what the patient
  returns. The reserve costs the patient's side a lag of R / F when it starts a stretch
  against a force F (0.3 mm at 1 mJ and 3 N);
* **controller**: when a tick would empty the tank, it dissipates exactly the excess:

      clinician port (force out):     F' = F − α v,  α = (E_out + F·v Δt − budget) / (‖v‖² Δt)
      patient port (velocity out):    v' = v − β F,  β = (E_out + F·v Δt − budget) / (‖F‖² Δt)

  (budget = E_in + E_received − E_sent). F' − F (v' − v) is the smallest change that brings the
  tick's output back within the tank; it removes at most the whole of the force along v (of the
  velocity along F): the tick's output is then zero, never negative, so the controller never
  pushes against the motion; an excess an earlier tick left (a site's own force limits changed
  what was sent) is dissipated on the ticks that follow.

The observer books what was actually sent (after the site's own force limits). The cost of
passivity is transparency: what the tank withholds is felt at the clinician's hand as the force
dropping while the hand gives way, and at the patient's side as the robot lagging the
clinician's motion (a position drift, pulled back as the tank allows,
:mod:`haptic.remote.ports`).
"""

from __future__ import annotations

#: Passivity modes of a link: this module's time-domain controller, or none (observer only: for
#: measuring what the link would create).
PASSIVITY_MODES: tuple[str, ...] = ("tdpa", "off")
#: Energy a port keeps before handing the rest to the other side, J (assumption; module
#: docstring).
DEFAULT_RESERVE_J = 1e-3
#: Below this speed (m/s) the force port leaves the force as it is, and below this force (N) the
#: velocity port leaves the velocity: taking off the component along a vanishing vector would
#: swing the displayed force or commanded velocity by up to its whole size from one tick to the
#: next at a standstill. What passes unchecked is at most |F| · 1e-9 m/s · dt a tick (3·10⁻¹¹ J
#: at 30 N and 1 kHz), far below what any robot's sensors resolve.
STILL = 1e-9


class PortEnergy:
    """One port's energy accounts since the session began, J."""

    __slots__ = ("e_in", "e_out", "received", "reserve", "sent")

    def __init__(self, reserve_j: float = DEFAULT_RESERVE_J) -> None:
        self.e_in = 0.0
        self.e_out = 0.0
        self.sent = 0.0          # handed to the other port (cumulative)
        self.received = 0.0      # handed over by the other port, as last received
        self.reserve = reserve_j

    def book(self, power_out_w: float, dt_s: float) -> None:
        """Account for one tick at ``power_out_w`` leaving the link (negative: entering), then
        hand everything above the reserve to the other port."""
        if power_out_w > 0.0:
            self.e_out += power_out_w * dt_s
        else:
            self.e_in -= power_out_w * dt_s
        surplus = self.tank - self.reserve
        if surplus > 0.0:
            self.sent += surplus

    def receive(self, peer_sent_j: float) -> None:
        """The other port's cumulative hand-over, as newly received (never goes back)."""
        if peer_sent_j > self.received:
            self.received = peer_sent_j

    @property
    def budget(self) -> float:
        """What this port may have let out in all, J."""
        return self.e_in + self.received - self.sent

    @property
    def tank(self) -> float:
        """Energy held here now, J (≥ 0 while the controller runs)."""
        return self.budget - self.e_out


class _Port:
    """One port's energy tank and the controller that keeps it passive: what goes out (a force
    displayed, a velocity commanded) is corrected against its conjugate (the velocity, the
    force) so that the energy let out never exceeds what the tank holds.

    ``dissipated_j`` sums what the controller withheld; ``active_ticks`` counts the ticks it
    acted on; ``last_gain`` is the last tick's correction (0: none).
    """

    __slots__ = ("active_ticks", "dissipated_j", "dt", "energy", "last_gain")

    def __init__(self, dt_s: float, reserve_j: float = DEFAULT_RESERVE_J) -> None:
        self.dt = dt_s
        self.energy = PortEnergy(reserve_j)
        self.active_ticks = 0
        self.dissipated_j = 0.0
        self.last_gain = 0.0

    def correct(self, ox: float, oy: float, cx: float, cy: float) -> tuple[float, float]:
        """What to put out instead of (ox, oy), against its conjugate (cx, cy), so that this
        port stays within its tank: the part along the conjugate that the tank cannot pay for
        is taken off (nothing below :data:`STILL`)."""
        p = ox * cx + oy * cy
        self.last_gain = 0.0
        if p <= 0.0:
            return ox, oy
        e = self.energy
        excess = e.e_out + p * self.dt - e.budget
        if excess <= 0.0:
            return ox, oy
        c2 = cx * cx + cy * cy
        if c2 <= STILL * STILL:
            return ox, oy
        g = min(excess / (c2 * self.dt), p / c2)
        self.last_gain = g
        self.active_ticks += 1
        self.dissipated_j += g * c2 * self.dt
        return ox - g * cx, oy - g * cy

    def book(self, ox: float, oy: float, cx: float, cy: float) -> None:
        """Observe what was actually put out against its conjugate for one tick."""
        self.energy.book(ox * cx + oy * cy, self.dt)


class ForcePort(_Port):
    """Passivity controller of the clinician's port (force out, velocity in):
    ``correct(fx, fy, vx, vy)`` gives the force to display; ``last_alpha`` (N·s/m) the damping
    it added on the last tick."""

    __slots__ = ()

    @property
    def last_alpha(self) -> float:
        return self.last_gain


class VelocityPort(_Port):
    """Passivity controller of the patient's port (velocity out, force in):
    ``correct(vx, vy, fx, fy)`` gives the velocity to command against the port force (the force
    the link exerts on the patient's side); ``last_beta`` (m/(N·s)) the admittance it added on
    the last tick."""

    __slots__ = ()

    @property
    def last_beta(self) -> float:
        return self.last_gain
