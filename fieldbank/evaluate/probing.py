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

Every motion can be handed on as a :class:`ProbePath` (:meth:`ProbeMotion.path`): a name, a
plain-words description and a polyline of hand positions in the robot frame with their times —
what a station draws and what the simulated operator of :mod:`fieldbank.haptic` follows.

Joint stretches complement the strokes with the clinic's single-joint test (Tardieu): one joint
swept through its range at 180°/s (fast stretch ≥ 150°/s in Liang et al. 2020) with the other at
rest, reporting the peak torque resisting the motion and its velocity-dependent part.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fieldbank.model import Arm, FloatArray

PULL_DISTANCE_M = 0.15
PULL_DURATION_S = 0.3
ELLIPSE_DEPTH_M = 0.15
ELLIPSE_BULGE_M = 0.08
ELLIPSE_DURATION_S = 0.6
PROBE_SAMPLES = 61
STRETCH_SPEED_RAD_S = math.radians(180.0)
STRETCH_SAMPLES = 121


def min_jerk(tau: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Minimum-jerk progress s(τ) and ds/dτ for τ in [0, 1] (any shape)."""
    s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
    ds = 30 * tau**2 - 60 * tau**3 + 30 * tau**4
    return s, ds


def _min_jerk(samples: int) -> tuple[FloatArray, FloatArray]:
    return min_jerk(np.linspace(0.0, 1.0, samples))


@dataclass(frozen=True)
class ProbePath:
    """A probe as plain data: a polyline of hand positions with timing, in the robot frame.

    Attributes
    ----------
    name : str
        Short name ("pull", "stroke 1").
    description : str
        What to do, in words.
    times_s : tuple of float, s
        Time of each point from the start of the motion (increasing, first 0).
    points_m : tuple of (x, y), m
        Hand positions in the robot frame (shoulder frame + ``shoulder_offset_m``).
    shoulder_offset_m : (x, y), m
        Where the shoulder is in robot coordinates.
    """

    name: str
    description: str
    times_s: tuple[float, ...]
    points_m: tuple[tuple[float, float], ...]
    shoulder_offset_m: tuple[float, float] = (0.0, 0.0)

    @property
    def duration_s(self) -> float:
        return self.times_s[-1] if self.times_s else 0.0

    def to_dict(self) -> dict[str, object]:
        return {"name": self.name, "description": self.description, "frame": "robot",
                "shoulder_offset_m": list(self.shoulder_offset_m),
                "times_s": [round(t, 6) for t in self.times_s],
                "points_m": [[round(x, 6), round(y, 6)] for x, y in self.points_m]}


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


@dataclass(frozen=True)
class JointStretch:
    """Resistance to one joint swept through its range (the other joint at rest).

    joint : 'shoulder' | 'elbow'; direction : 'extension' | 'flexion'
    peak_torque_n_m : largest torque opposing the motion at the fast speed, N·m
    peak_angle_deg : joint angle of that peak
    reflex_torque_n_m : largest velocity-dependent part (fast minus static torque), N·m
    """

    joint: str
    direction: str
    speed_deg_s: float
    peak_torque_n_m: float
    peak_angle_deg: float
    reflex_torque_n_m: float

    @property
    def name(self) -> str:
        return f"{self.joint} {self.direction}"

    def to_dict(self) -> dict[str, object]:
        return {
            "joint": self.joint, "direction": self.direction, "speed_deg_s": self.speed_deg_s,
            "peak_torque_n_m": self.peak_torque_n_m, "peak_angle_deg": self.peak_angle_deg,
            "reflex_torque_n_m": self.reflex_torque_n_m,
        }


def joint_stretch(arm: Arm, joint: str, direction: str,
                  speed_rad_s: float = STRETCH_SPEED_RAD_S,
                  samples: int = STRETCH_SAMPLES) -> JointStretch:
    """Sweep ``joint`` through its range at ``speed_rad_s``; torque opposing the motion."""
    j = {"shoulder": 0, "elbow": 1}[joint]
    sign = {"flexion": 1.0, "extension": -1.0}[direction]
    lo, hi = (arm.params.shoulder_range_rad, arm.params.elbow_range_rad)[j]
    angles = np.linspace(lo, hi, samples)
    q = np.tile(arm.q_rest, (samples, 1))
    q[:, j] = angles
    qdot = np.zeros((samples, 2))
    qdot[:, j] = sign * speed_rad_s
    fast = -sign * arm.joint_torque(q, qdot)[:, j]  # torque against the motion
    static = -sign * arm.joint_torque(q)[:, j]
    i = int(np.argmax(fast))
    return JointStretch(joint, direction, math.degrees(speed_rad_s), float(fast[i]),
                        math.degrees(float(angles[i])), float(np.max(fast - static)))


STRETCHES: tuple[tuple[str, str], ...] = (
    ("elbow", "extension"), ("elbow", "flexion"), ("shoulder", "extension"),
    ("shoulder", "flexion"),
)


def standard_stretches(arm: Arm) -> tuple[JointStretch, ...]:
    return tuple(joint_stretch(arm, j, d) for j, d in STRETCHES)
