"""Probing motions and the forces felt along them (seed, "Selection of specific probing motions").

The seed chose two strokes that separate hypertonic shoulder, elbow and bi-articular groups by
the orientation and size of the force felt (seed Fig. 3b, 3c):

* **pull** - from the arm's equilibrium (rest) hand position, a fast straight pull along the
  mid-sagittal line. The seed gives no direction, length or speed; here (assumption) it runs
  toward the body (-y in the shoulder frame), 15 cm in 0.3 s with a minimum-jerk profile
  (mean 0.5 m/s, peak 0.94 m/s), as a clinician pulling the hand in toward the chest.
* **semi-ellipse** - a half ellipse from the rest hand position to the same end point 15 cm
  nearer the body, bulging 8 cm laterally (+x for a right arm, -x for a left arm), in 0.6 s
  with a minimum-jerk profile along the angle (assumption: seed Fig. 3c shows the shape only).

The force felt is the model's endpoint force F(x, v) along the path with the path's velocity:
a quasi-static kinematic probe (the handle imposes the motion; the reflex sees the velocity;
the arm's inertia is left out, as the clinician's feel of tone is about the muscles).

Every motion can be handed on as a :class:`fieldbank.probepath.ProbePath`
(:meth:`ProbeMotion.path`): a name, a plain-words description and a polyline of hand positions
in the robot frame with their times - what a station draws and what the simulated operator of
:mod:`fieldbank.haptic` follows.

Joint stretches complement the strokes with the clinic's single-joint tests (Modified Ashworth,
Tardieu): one joint swept through its whole range, the other held at the rest posture, once slowly
(:data:`SLOW_STRETCH_SPEED_RAD_S`, 5°/s: BRIEF §5 "≈ 5-10°/s", Tardieu V1 "as slow as possible")
and once fast (:data:`STRETCH_SPEED_RAD_S`, 180°/s: Tardieu V3 "as fast as possible" ≈ 180°/s;
Liang et al. 2020 grade MAS at ≥ 150°/s; McPherson 2018: the reflex needs > 100°/s). The
stretch is kinematic, like the probes: the joint angle and its speed are imposed, and the torque
the muscles produce against the motion is read at each angle, per muscle group
(:class:`StretchProfile`) and summed per joint (:class:`JointStretch`):

* resisting torque at the slow and at the fast stretch (peaks over the range), N·m;
* its velocity-dependent part, fast minus slow (peak over the range), N·m. In this model that
  part is all stretch reflex (the muscles have no viscous term), where McPherson 2018 found the
  reflex to be ≈ 74% of the speed-dependent resistance measured at the elbow;
* a Tardieu-style catch (operational definition, assumption): travelling from the end of the
  range where the stretched muscles are shortest, R1 is the first joint angle at which the fast
  stretch meets a resisting torque of :data:`CATCH_FACTOR` × the unimpaired arm's largest
  slow-stretch torque over the whole range (so an unimpaired arm never catches), and R2 the
  first angle at which the slow stretch meets the same torque (the end of the slow passive
  range; the range-of-motion end when it never does). The same threshold at both speeds makes
  the distance R2 - R1 (degrees along the travel, ≥ 0) purely velocity-dependent: the
  Tardieu scale's dynamic component. Contracture moves R2 (and R1 with it); spasticity opens a
  gap between them.

Angles are joint angles of this project's convention (BRIEF §3: elbow 0° straight, flexion
positive), in degrees at the edge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fieldbank.errors import ParameterError
from fieldbank.model import Arm, FloatArray
from fieldbank.params import GROUP_LEGEND, GROUPS
from fieldbank.probepath import ProbePath

PULL_DISTANCE_M = 0.15
PULL_DURATION_S = 0.3
ELLIPSE_DEPTH_M = 0.15
ELLIPSE_BULGE_M = 0.08
ELLIPSE_DURATION_S = 0.6
PROBE_SAMPLES = 61
STRETCH_SPEED_RAD_S = math.radians(180.0)
SLOW_STRETCH_SPEED_RAD_S = math.radians(5.0)
STRETCH_SAMPLES = 121
#: Catch threshold over the unimpaired arm's peak slow-stretch torque (assumption, above).
CATCH_FACTOR = 2.0
JOINTS: tuple[str, ...] = ("shoulder", "elbow")
#: +1: the joint angle grows (flexion); -1: it falls (extension).
DIRECTION_SIGN: dict[str, float] = {"flexion": 1.0, "extension": -1.0}


def min_jerk(tau: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Minimum-jerk progress s(τ) and ds/dτ for τ in [0, 1] (any shape)."""
    s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
    ds = 30 * tau**2 - 60 * tau**3 + 30 * tau**4
    return s, ds


def _min_jerk(samples: int) -> tuple[FloatArray, FloatArray]:
    return min_jerk(np.linspace(0.0, 1.0, samples))


@dataclass(frozen=True, eq=False)
class ProbeMotion:
    """A handle path: positions (T, 2) m, velocities (T, 2) m/s, times (T,) s (shoulder frame)."""

    name: str
    times_s: FloatArray
    positions_m: FloatArray
    velocities_m_per_s: FloatArray
    description: str

    def path(self, shoulder_offset_m: tuple[float, float] = (0.0, 0.0)) -> ProbePath:
        """This motion as plain data in the robot frame (:class:`ProbePath`)."""
        ox, oy = shoulder_offset_m
        return ProbePath(self.name, self.description,
                         tuple(float(t - self.times_s[0]) for t in self.times_s),
                         tuple((float(x) + ox, float(y) + oy) for x, y in self.positions_m),
                         (float(ox), float(oy)))

    @property
    def accelerations_m_per_s2(self) -> FloatArray:
        """Hand accelerations (T, 2), m/s², differentiated from the velocities."""
        return np.asarray(np.gradient(self.velocities_m_per_s, self.times_s, axis=0,
                                      edge_order=2), dtype=float)

    @property
    def peak_speed_m_per_s(self) -> float:
        v = self.velocities_m_per_s
        return float(np.hypot(v[:, 0], v[:, 1]).max()) if len(v) else 0.0


def pull(arm: Arm, distance_m: float = PULL_DISTANCE_M, duration_s: float = PULL_DURATION_S,
         samples: int = PROBE_SAMPLES) -> ProbeMotion:
    """Fast straight pull from the rest hand position toward the body (-y)."""
    s, ds = _min_jerk(samples)
    start = arm.rest_position()
    direction = np.array([0.0, -1.0])
    pos = start + distance_m * s[:, None] * direction
    vel = (distance_m / duration_s) * ds[:, None] * direction
    return ProbeMotion("pull", np.linspace(0.0, duration_s, samples), pos, vel,
                       f"pull {distance_m * 100:g} cm toward the body in {duration_s:g} s")


def semi_ellipse(arm: Arm, depth_m: float = ELLIPSE_DEPTH_M, bulge_m: float = ELLIPSE_BULGE_M,
                 duration_s: float = ELLIPSE_DURATION_S,
                 samples: int = PROBE_SAMPLES) -> ProbeMotion:
    """Half ellipse from the rest hand position to ``depth_m`` nearer the body, bulging out."""
    s, ds = _min_jerk(samples)
    th = math.pi * s
    dth = math.pi * ds / duration_s
    lateral = -1.0 if arm.mirror else 1.0
    b = 0.5 * depth_m
    start = arm.rest_position()
    pos = np.stack([start[0] + lateral * bulge_m * np.sin(th),
                    start[1] - b * (1.0 - np.cos(th))], axis=1)
    vel = np.stack([lateral * bulge_m * np.cos(th) * dth, -b * np.sin(th) * dth], axis=1)
    return ProbeMotion("semi-ellipse", np.linspace(0.0, duration_s, samples), pos, vel,
                       f"semi-ellipse {depth_m * 100:g} cm toward the body, "
                       f"{bulge_m * 100:g} cm lateral, in {duration_s:g} s")


def lengthening_direction(arm: Arm, group: str) -> FloatArray:
    """Unit hand velocity, shape (2,), shoulder frame, that lengthens ``group`` fastest at the
    rest posture: λ̇_g = J_λ,g J_q⁻¹ v is largest over |v| = 1 for v ∝ J_q⁻ᵀ J_λ,gᵀ (the
    direction a moving field shows that group's stretch reflex in)."""
    if group not in GROUPS:
        raise ParameterError(f"unknown muscle group {group!r} (known: {GROUP_LEGEND}).")
    jq = arm.jacobian(arm.q_rest)[0]
    w = np.linalg.solve(jq.T, arm.jl[GROUPS.index(group)])
    w = w / np.hypot(w[0], w[1])
    return np.asarray(w * np.array([-1.0, 1.0]) if arm.mirror else w, dtype=float)


def standard_probes(arm: Arm) -> tuple[ProbeMotion, ...]:
    return (pull(arm), semi_ellipse(arm))


@dataclass(frozen=True, eq=False)
class ProbeProfile:
    """Force felt along a probing motion.

    Attributes
    ----------
    force_n : ndarray, shape (T, 2), N
        Force the arm exerts on the handle at each sample.
    peak_force_n : float
        Largest force magnitude.
    peak_time_s : float
    peak_direction_rad : float
        Direction of the force at the peak, from +x.
    mean_direction_rad : float
        Direction of the time-averaged force vector.
    """

    motion: ProbeMotion
    force_n: FloatArray
    peak_force_n: float
    peak_time_s: float
    peak_direction_rad: float
    mean_direction_rad: float

    def to_dict(self, with_profile: bool = False) -> dict[str, object]:
        d: dict[str, object] = {
            "motion": self.motion.name,
            "description": self.motion.description,
            "peak_force_n": self.peak_force_n,
            "peak_time_s": self.peak_time_s,
            "peak_direction_deg": math.degrees(self.peak_direction_rad),
            "mean_direction_deg": math.degrees(self.mean_direction_rad),
        }
        if with_profile:
            d["times_s"] = self.motion.times_s.tolist()
            d["positions_m"] = self.motion.positions_m.tolist()
            d["force_n"] = self.force_n.tolist()
        return d


def profile(arm: Arm, motion: ProbeMotion) -> ProbeProfile:
    """The force ``arm`` exerts on the handle along ``motion``."""
    f = arm.endpoint_force(motion.positions_m, motion.velocities_m_per_s)
    mag = np.hypot(f[:, 0], f[:, 1])
    i = int(np.argmax(mag))
    mean = f.mean(axis=0)
    return ProbeProfile(
        motion=motion,
        force_n=f,
        peak_force_n=float(mag[i]),
        peak_time_s=float(motion.times_s[i]),
        peak_direction_rad=float(math.atan2(f[i, 1], f[i, 0])),
        mean_direction_rad=float(math.atan2(mean[1], mean[0])),
    )


@dataclass(frozen=True, eq=False)
class StretchProfile:
    """One joint swept through its range, slow and fast, torque against the motion per muscle.

    Attributes
    ----------
    joint : 'shoulder' | 'elbow'; direction : 'extension' | 'flexion'
    angles_rad : ndarray, shape (T,), rad
        Joint angles in the order of travel (from the end where the stretched muscles are
        shortest).
    passive_n_m : ndarray, shape (T, 6), N·m
        Each muscle group's passive (position-dependent) torque resisting the motion.
    reflex_slow_n_m, reflex_fast_n_m : ndarray, shape (T, 6), N·m
        Each group's reflex torque resisting the motion at the slow and at the fast speed.
    slow_speed_rad_s, fast_speed_rad_s : float, rad/s
    """

    joint: str
    direction: str
    angles_rad: FloatArray
    passive_n_m: FloatArray
    reflex_slow_n_m: FloatArray
    reflex_fast_n_m: FloatArray
    slow_speed_rad_s: float
    fast_speed_rad_s: float

    @property
    def slow_n_m(self) -> FloatArray:
        """Joint torque resisting the slow stretch, shape (T,), N·m."""
        return np.asarray((self.passive_n_m + self.reflex_slow_n_m).sum(axis=1))

    @property
    def fast_n_m(self) -> FloatArray:
        """Joint torque resisting the fast stretch, shape (T,), N·m."""
        return np.asarray((self.passive_n_m + self.reflex_fast_n_m).sum(axis=1))

    @property
    def velocity_dependent_n_m(self) -> FloatArray:
        """Each group's velocity-dependent torque, fast minus slow, shape (T, 6), N·m."""
        return np.asarray(self.reflex_fast_n_m - self.reflex_slow_n_m)


def stretch_profile(arm: Arm, joint: str, direction: str,
                    fast_speed_rad_s: float = STRETCH_SPEED_RAD_S,
                    slow_speed_rad_s: float = SLOW_STRETCH_SPEED_RAD_S,
                    samples: int = STRETCH_SAMPLES,
                    hold_rad: float | None = None) -> StretchProfile:
    """Sweep ``joint`` of ``arm`` through its range in ``direction``, the other joint held at
    ``hold_rad`` (rad; default: at rest).

    The torque muscle i exerts against the motion is s · J_λ[i, j] · f_i (s = +1 for flexion,
    -1 for extension; τ = -J_λᵀ f): positive for a muscle the motion lengthens.
    """
    if joint not in JOINTS:
        raise ParameterError(f"joint must be one of {', '.join(JOINTS)}; got {joint!r}.")
    if direction not in DIRECTION_SIGN:
        raise ParameterError(f"direction must be 'flexion' or 'extension'; got {direction!r}.")
    j = JOINTS.index(joint)
    sign = DIRECTION_SIGN[direction]
    lo, hi = (arm.params.shoulder_range_rad, arm.params.elbow_range_rad)[j]
    angles = np.linspace(lo, hi, samples) if sign > 0 else np.linspace(hi, lo, samples)
    q = np.tile(arm.q_rest, (samples, 1))
    q[:, j] = angles
    if hold_rad is not None:
        q[:, 1 - j] = hold_rad
    lam = arm.muscle_lengths(q)
    lever = sign * arm.jl[:, j]  # (6,) torque per newton against the motion

    def reflex(speed: float) -> FloatArray:
        qdot = np.zeros((samples, 2))
        qdot[:, j] = sign * speed
        return np.asarray(arm.reflex_forces(lam, arm.muscle_velocities(qdot))[0] * lever)

    psi, _ = arm.passive_forces(lam)
    return StretchProfile(joint, direction, angles, psi * lever, reflex(slow_speed_rad_s),
                          reflex(fast_speed_rad_s), slow_speed_rad_s, fast_speed_rad_s)


@dataclass(frozen=True)
class JointStretch:
    """What a clinician measures on one joint stretch (module docstring), from the joint torque.

    joint : 'shoulder' | 'elbow'; direction : 'extension' | 'flexion'
    speed_deg_s, slow_speed_deg_s : the fast and the slow stretch speed, °/s
    slow_torque_n_m : largest torque opposing the slow stretch, N·m
    peak_torque_n_m : largest torque opposing the fast stretch, N·m
    peak_angle_deg : joint angle of that peak
    reflex_torque_n_m : largest velocity-dependent part (fast minus slow), N·m
    catch_threshold_n_m : the catch torque (CATCH_FACTOR × unimpaired slow peak), N·m
    catch_angle_deg : R1, where the fast stretch meets the catch torque; None: it never does
    slow_stop_angle_deg : R2, where the slow stretch meets it; None: it never does
    dynamic_range_deg : R2 - R1 along the travel, ≥ 0; None unless both R1 and R2 exist (a
        difference with an angle that was never reached would be a number the stretch did not
        measure)
    stretched : muscle groups the motion lengthens (whose parameters the read-out rests on)
    """

    joint: str
    direction: str
    speed_deg_s: float
    peak_torque_n_m: float
    peak_angle_deg: float
    reflex_torque_n_m: float
    slow_speed_deg_s: float = 0.0
    slow_torque_n_m: float = 0.0
    catch_threshold_n_m: float = 0.0
    catch_angle_deg: float | None = None
    slow_stop_angle_deg: float | None = None
    dynamic_range_deg: float | None = None
    stretched: tuple[str, ...] = ()

    @property
    def name(self) -> str:
        return f"{self.joint} {self.direction}"

    def to_dict(self) -> dict[str, object]:
        return {
            "joint": self.joint, "direction": self.direction,
            "stretched": list(self.stretched),
            "slow_speed_deg_s": self.slow_speed_deg_s, "speed_deg_s": self.speed_deg_s,
            "slow_torque_n_m": self.slow_torque_n_m,
            "peak_torque_n_m": self.peak_torque_n_m, "peak_angle_deg": self.peak_angle_deg,
            "reflex_torque_n_m": self.reflex_torque_n_m,
            "catch_threshold_n_m": self.catch_threshold_n_m,
            "catch_angle_deg": self.catch_angle_deg,
            "slow_stop_angle_deg": self.slow_stop_angle_deg,
            "dynamic_range_deg": self.dynamic_range_deg,
        }


def _first_reaching(torque: FloatArray, angles: FloatArray, threshold: float) -> float | None:
    """First angle (rad, linear between samples) where ``torque`` reaches ``threshold``."""
    hit = np.flatnonzero(torque >= threshold)
    if hit.size == 0:
        return None
    k = int(hit[0])
    if k == 0:
        return float(angles[0])
    t0, t1 = float(torque[k - 1]), float(torque[k])
    frac = (threshold - t0) / (t1 - t0)
    return float(angles[k - 1] + frac * (angles[k] - angles[k - 1]))


def unimpaired_reference(arm: Arm) -> Arm:
    """The same arm with unimpaired muscles (:meth:`ArmParams.with_unimpaired_muscles`), sharing
    ``arm``'s compiled geometry (:meth:`Arm.with_muscles`); ``arm`` itself when it already is
    that arm."""
    ref = arm.params.with_unimpaired_muscles()
    return arm if ref == arm.params else arm.with_muscles(ref)


def joint_stretch(arm: Arm, joint: str, direction: str,
                  speed_rad_s: float = STRETCH_SPEED_RAD_S,
                  samples: int = STRETCH_SAMPLES, reference: Arm | None = None,
                  slow_speed_rad_s: float = SLOW_STRETCH_SPEED_RAD_S) -> JointStretch:
    """The clinical read-outs of one joint stretch (module docstring).

    ``reference`` is the unimpaired arm that sets the catch torque (default: ``arm``'s,
    :func:`unimpaired_reference`).
    """
    ref = reference if reference is not None else unimpaired_reference(arm)
    prof = stretch_profile(arm, joint, direction, speed_rad_s, slow_speed_rad_s, samples)
    ref_prof = prof if ref is arm else stretch_profile(ref, joint, direction, speed_rad_s,
                                                       slow_speed_rad_s, samples)
    return _read_out(prof, float(ref_prof.slow_n_m.max()), arm)


Profiles = dict[tuple[str, str], StretchProfile]


def stretch_profiles(arm: Arm) -> Profiles:
    """The profiles of the four standard stretches (:data:`STRETCHES`), keyed (joint,
    direction): what the read-outs and the severity grades of one arm are computed from."""
    return {(j, d): stretch_profile(arm, j, d) for j, d in STRETCHES}


def _read_out(prof: StretchProfile, reference_slow_peak_n_m: float, arm: Arm) -> JointStretch:
    fast, slow = prof.fast_n_m, prof.slow_n_m
    i = int(np.argmax(fast))
    threshold = CATCH_FACTOR * reference_slow_peak_n_m
    r1 = _first_reaching(fast, prof.angles_rad, threshold)
    r2 = _first_reaching(slow, prof.angles_rad, threshold)
    dyn = None if r1 is None or r2 is None else abs(r2 - r1)
    j = JOINTS.index(prof.joint)
    lever = DIRECTION_SIGN[prof.direction] * arm.jl[:, j]
    stretched = tuple(g for g, v in zip(GROUPS, lever, strict=True) if v > 0)
    return JointStretch(
        joint=prof.joint, direction=prof.direction,
        speed_deg_s=math.degrees(prof.fast_speed_rad_s),
        peak_torque_n_m=float(fast[i]), peak_angle_deg=math.degrees(float(prof.angles_rad[i])),
        reflex_torque_n_m=float(np.max(fast - slow)),
        slow_speed_deg_s=math.degrees(prof.slow_speed_rad_s),
        slow_torque_n_m=float(slow.max()), catch_threshold_n_m=threshold,
        catch_angle_deg=None if r1 is None else math.degrees(r1),
        slow_stop_angle_deg=None if r2 is None else math.degrees(r2),
        dynamic_range_deg=None if dyn is None else math.degrees(dyn), stretched=stretched,
    )


STRETCHES: tuple[tuple[str, str], ...] = (
    ("elbow", "extension"), ("elbow", "flexion"), ("shoulder", "extension"),
    ("shoulder", "flexion"),
)


def standard_stretches(arm: Arm, reference: Arm | None = None,
                       profiles: Profiles | None = None,
                       reference_profiles: Profiles | None = None) -> tuple[JointStretch, ...]:
    """The four single-joint stretches (:data:`STRETCHES`) of ``arm``.

    ``profiles`` and ``reference_profiles`` (:func:`stretch_profiles` of ``arm`` and of its
    unimpaired reference) are computed when not given; a use case that grades severity too
    computes them once for both.
    """
    prof = profiles if profiles is not None else stretch_profiles(arm)
    if reference_profiles is None:
        ref = reference if reference is not None else unimpaired_reference(arm)
        reference_profiles = prof if ref is arm else stretch_profiles(ref)
    return tuple(_read_out(prof[key], float(reference_profiles[key].slow_n_m.max()), arm)
                 for key in STRETCHES)
