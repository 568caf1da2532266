"""A virtual patient holding the simulated robot's handle.

The simulated robot (:mod:`haptic.simrobot`) can have an arm attached to its handle instead of
the scripted operator: ``sim://?patient=SPEC`` with SPEC

* a stored model id (``patient=12``): that model, read from the default database
  (``FIELDBANK_DB``, else the embedded database of ``FIELDBANK_HOME``);
* a parameter file (``patient=file:arm.json``, schema ``fieldbank.arm-params``);
* a severity on the scale of :mod:`fieldbank.evaluate.severity` (``patient=elbow=severe``,
  ``patient=ef:dynamic=moderate,shoulder=mild``) on the default body, or ``unimpaired``.

The arm is the six-muscle model of :class:`fieldbank.sim.ArmSim`, relaxed (no voluntary
force), its hand held to the handle by a stiff grip (a spring–damper, default 1e6 N/m and
400 N·s/m: stiff enough that the handle measures the arm, not the grip — a 10 N hold moves the
hand 0.01 mm off the handle, a 2,000 N/m arm measures 0.2 % softer — and stable at the device's
250 µs substep). Each substep the
handle's position and velocity (robot frame, minus the patient's shoulder position
``patient_x_m``, ``patient_y_m``) drive the arm, and the grip force the arm puts on the handle
comes back: that is what the handle's force sensor reads, and what moves the handle.

Sensor noise (robot side, so every consumer of the link sees it): Gaussian, white per sample,
``force_noise_n`` on each force-sensor component and ``position_noise_m`` on each reported
position coordinate, seeded by the robot's ``seed``. With a patient attached the defaults are
0.2 N (lab force sensors: 0.1–0.5 N, BRIEF §16) and 0.02 mm (encoders: ≪ 1 mm); without one
they are 0 (the bare simulated robot stays noise-free for rendering tests).

The same object serves any process that needs a simulated arm on a handle (a patient-side
robot of a remote assessment, a device process at a higher rate): build it with
:meth:`VirtualPatient.from_spec` and call :meth:`VirtualPatient.force` each substep.
"""

from __future__ import annotations

from dataclasses import dataclass

from fieldbank.errors import ParameterError
from fieldbank.model import Arm
from fieldbank.modelsource import ModelSource, from_file, stored, synthetic
from fieldbank.params import ArmParams
from fieldbank.sim import ArmSim, CouplingConfig
from fieldbank.storage import Database
from fieldbank.validation import Interval, check_fields

#: Grip between hand and handle (assumption; see the module docstring).
GRIP_N_PER_M = 1.0e6
GRIP_N_S_PER_M = 400.0
#: Sensor noise with a patient attached (BRIEF §16: force 0.1–0.5 N, position ≪ 1 mm).
DEFAULT_FORCE_NOISE_N = 0.2
DEFAULT_POSITION_NOISE_M = 2.0e-5


def resolve_patient(spec: str) -> ModelSource:
    """The arm named by a ``patient=`` spec (see the module docstring)."""
    text = spec.strip()
    if not text:
        raise ParameterError("sim:// patient is empty: give a stored model id, file:PATH or a "
                             "severity such as elbow=severe")
    if text.isdigit():
        with Database.open(None) as db:
            return stored(db, int(text))
    if text.startswith("file:"):
        return from_file(text.removeprefix("file:"))
    if text == "unimpaired":
        return synthetic(())
    return synthetic([s for s in text.split(",") if s.strip()])


#: Allowed range of each coordinate of :class:`PatientPlacement`.
PLACEMENT_BOUNDS: dict[str, Interval] = {
    "shoulder_x_m": Interval(None, None, "m"),
    "shoulder_y_m": Interval(None, None, "m"),
}


@dataclass(frozen=True)
class PatientPlacement:
    """Where the patient sits: the shoulder's position in robot coordinates, m (finite)."""

    shoulder_x_m: float = 0.0
    shoulder_y_m: float = 0.0

    def __post_init__(self) -> None:
        check_fields(self, PLACEMENT_BOUNDS, what="patient placement")


class VirtualPatient:
    """A relaxed arm gripping the handle; :meth:`force` is the force its hand puts on it.

    Parameters
    ----------
    params : ArmParams
        The patient's arm (any model the product can build or store).
    placement : PatientPlacement
        Shoulder position in robot coordinates.
    dt_s : float
        Substep of the device physics, s.
    description : str
        What the arm is, in words (for read-outs).
    """

    def __init__(self, params: ArmParams, placement: PatientPlacement, dt_s: float,
                 description: str = "") -> None:
        self.params = params
        self.description = description or "virtual patient"
        self.placement = placement
        self.arm = Arm.from_params(params)
        self.sim = ArmSim(self.arm, dt_s, CouplingConfig(GRIP_N_PER_M, GRIP_N_S_PER_M))
        self._tick = self.sim.tick
        self._sx = placement.shoulder_x_m
        self._sy = placement.shoulder_y_m

    @classmethod
    def from_spec(cls, spec: str, placement: PatientPlacement, dt_s: float) -> VirtualPatient:
        src = resolve_patient(spec)
        return cls(src.params, placement, dt_s, src.description)

    def grasp(self, x_m: float, y_m: float) -> None:
        """Put the relaxed hand on the handle at (x, y), robot frame; ParameterError when the
        arm cannot reach it."""
        hx, hy = x_m - self._sx, y_m - self._sy
        if not bool(self.arm.reachable([[hx, hy]])[0]):
            raise ParameterError(
                f"the virtual patient cannot reach the handle at ({x_m:.3f}, {y_m:.3f}) m "
                f"(shoulder at ({self._sx:.3f}, {self._sy:.3f}) m): move the handle (x0_m, "
                "y0_m) or the shoulder (patient_x_m, patient_y_m)")
        self.sim.reset_at_hand(hx, hy)

    def force(self, x: float, y: float, vx: float, vy: float) -> tuple[float, float]:
        """Advance the arm one substep with the handle at (x, y) moving at (vx, vy), robot
        frame; return the force of the hand on the handle, N."""
        return self._tick(x - self._sx, y - self._sy, vx, vy)
