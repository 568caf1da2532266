"""The distant patient as the renderer sees it: something ticked in place of a virtual arm.

The clinician's site is the ordinary renderer (:mod:`haptic.renderer`: the clinician's robot,
its safety layer, the control channel, the station, the trace) with its arms replaced
(:data:`haptic.pair.Environment`):

* :class:`RemoteArm` ticks the clinician's port of the link (:class:`~haptic.remote.ports.
  ClinicianPort`): the handle goes out, the patient's force comes back through the link's
  passivity controller. Its ``state`` is the patient's arm posture as drawn — the patient's
  handle (as last received) put through the inverse kinematics of the arm's geometry, which the
  patient's site sent (segment lengths, side, range of motion; never its muscles);
* :class:`Follower` stands where model B would: it repeats the remote arm's force and posture,
  so the renderer's A/B blend changes nothing, and a remote session refuses pushed models,
  A/B/X blocks and training (:func:`remote_environment`): the patient is the patient.

For simulations (:mod:`haptic.remote.simulate`) the same chain runs with the patient's site in
the same process (a simulated patient's robot with the model as its virtual patient), so the
training protocol and A/B/X run through a link too.
"""

from __future__ import annotations

import math

from fieldbank.errors import UnreachableError
from fieldbank.haptic.errors import CommandError
from fieldbank.haptic.pair import Environment
from fieldbank.haptic.remote.ports import ClinicianPort
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.sim import ArmSim, CouplingConfig

#: The drawn posture is recomputed every this many ticks (a display reads ≈ 60 times a second).
DRAW_EVERY = 8


class RemoteArm(ArmSim):
    """The clinician's port of the link, ticked by the renderer like a virtual arm.

    Parameters
    ----------
    port : ClinicianPort
    drawing : Arm
        The patient's arm geometry (muscles unimpaired: only the posture is drawn).
    dt_s : float, s
    """

    def __init__(self, port: ClinicianPort, drawing: Arm, dt_s: float) -> None:
        super().__init__(drawing, dt_s)
        self.port = port
        self._l1, self._l2 = drawing.l1, drawing.l2
        self._mirror = -1.0 if drawing.mirror else 1.0
        self._lo1, self._hi1 = drawing.params.shoulder_range_rad
        self._n = 0
        self.fx = self.fy = 0.0
        self.tick = self._tick

    def _tick(self, x: float, y: float, vx: float, vy: float) -> tuple[float, float]:
        fx, fy = self.port.tick(x, y, vx, vy)
        self.fx, self.fy = fx, fy
        self._n += 1
        if self._n % DRAW_EVERY == 0 and self.port.peer is not None:
            self._draw(self.port.peer.x, self.port.peer.y)
        return fx, fy

    def _draw(self, x: float, y: float) -> None:
        """Posture of the drawn arm with its hand at (x, y) (shoulder frame), elbow flexed;
        unchanged where the arm cannot reach."""
        xm = self._mirror * x
        l1, l2 = self._l1, self._l2
        c2 = (xm * xm + y * y - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
        if not -1.0 < c2 < 1.0:
            return
        q2 = math.acos(c2)
        q1 = math.atan2(y, xm) - math.atan2(l2 * math.sin(q2), l1 + l2 * math.cos(q2))
        s = self.state
        s.q1, s.q2, s.qd1, s.qd2 = q1, q2, 0.0, 0.0

    def reset_at_hand(self, x: float, y: float) -> None:
        """The renderer puts its arms at the handle; the drawn arm stays at the patient's."""
        peer = self.port.peer
        if peer is not None:
            self._draw(peer.x, peer.y)
            return
        try:
            super().reset_at_hand(x, y)
        except (UnreachableError, ValueError):
            self.reset()


class Follower(ArmSim):
    """Model B of a remote session: the remote arm's force and posture, nothing of its own."""

    def __init__(self, leader: ArmSim) -> None:
        super().__init__(leader.arm, leader.dt_s)
        self.leader = leader
        self.state = leader.state
        self.tick = self._tick

    def _tick(self, x: float, y: float, vx: float, vy: float) -> tuple[float, float]:
        del x, y, vx, vy
        lead = self.leader
        return (lead.fx, lead.fy) if isinstance(lead, RemoteArm) else (0.0, 0.0)

    def reset_at_hand(self, x: float, y: float) -> None:
        del x, y

    def reset(self, q: tuple[float, float] | None = None,
              qd: tuple[float, float] = (0.0, 0.0)) -> None:
        del q, qd


def remote_environment(port: ClinicianPort, drawing: ArmParams) -> Environment:
    """The renderer's environment for a remote session: the first model built is the link
    (:class:`RemoteArm`), the second its :class:`Follower`; any later one (a push, an A/B/X
    block, a training trial) is refused."""
    made: list[ArmSim] = []
    arm = Arm.from_params(drawing.with_unimpaired_muscles())

    def make(params: ArmParams, dt_s: float, coupling: CouplingConfig | None) -> ArmSim:
        del params, coupling
        if not made:
            made.append(RemoteArm(port, arm, dt_s))
        elif len(made) == 1:
            made.append(Follower(made[0]))
        else:
            raise CommandError("a remote session feels the patient at the patient's site; "
                               "models cannot be pushed, nor A/B/X blocks or training run "
                               "(they run through a simulated link: fieldbank haptic train "
                               "simulate --link-delay-ms)")
        return made[-1]

    return make
