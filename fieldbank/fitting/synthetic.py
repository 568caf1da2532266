"""Synthetic patients: a known arm, its maps with measurement noise, and held-out maps.

Used to show that the fitter recovers what it should. A patient has one joint group
(``fieldbank.params.JOINT_GROUPS``) made hypertonic at a severity level of the one scale,
:func:`fieldbank.evaluate.severity.synthesize`.

Maps: a postural map at ``n_postural`` positions and stiffness maps at ``n_stiffness``
positions, each measured static and moving (at ``±speed`` along :data:`MOVE_DIRECTION`, so that
the stretch reflex of flexors and of extensors is seen). Positions are scattered over a
wide part of the range of motion. Noise: each value gets Gaussian noise with SD ``noise`` (5% by
default) × the size of the force or stiffness at its position (:func:`relative_scale`), and that
SD is stored in the map.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fieldbank.errors import ParameterError
from fieldbank.evaluate import severity
from fieldbank.fitting.problem import relative_scale
from fieldbank.maps import FieldMap, postural_map, stiffness_map
from fieldbank.model import Arm, FloatArray
from fieldbank.params import JOINT_GROUPS, ArmParams

#: The impaired levels, most severe first.
LEVELS: tuple[str, ...] = tuple(reversed(severity.LEVELS[1:]))
#: Unit direction of the moving stiffness measurements (shoulder frame).
MOVE_DIRECTION = (-0.6, 0.8)
DEFAULT_SPEED_M_PER_S = 1.0
#: Joint-angle box (deg) the synthetic positions are drawn from.
SHOULDER_DEG = (-10.0, 120.0)
ELBOW_DEG = (20.0, 140.0)


def impaired_params(group: str, level: str, base: ArmParams | None = None) -> ArmParams:
    """A patient with ``group`` (a joint group) hypertonic at ``level``."""
    if group not in JOINT_GROUPS:
        raise ParameterError(f"unknown joint group {group!r}; known: {', '.join(JOINT_GROUPS)}.")
    base = base or ArmParams.from_anthropometry()
    return severity.synthesize({group: level}, base)


def scattered_positions(arm: Arm, n: int, rng: np.random.Generator) -> FloatArray:
    """``n`` hand positions (n, 2), m, from postures drawn uniformly in the comfortable box."""
    q = np.column_stack([
        rng.uniform(math.radians(SHOULDER_DEG[0]), math.radians(SHOULDER_DEG[1]), size=n),
        rng.uniform(math.radians(ELBOW_DEG[0]), math.radians(ELBOW_DEG[1]), size=n),
    ])
    return arm.fk(q)


@dataclass(frozen=True)
class SyntheticPatient:
    truth: ArmParams
    maps: tuple[FieldMap, ...]
    held_out: tuple[FieldMap, ...]


def _noisy(m: FieldMap, noise: float, rng: np.random.Generator, patient: str) -> FieldMap:
    sd = np.broadcast_to(relative_scale(m.values)[(...,) + (None,) * (m.values.ndim - 1)],
                         m.values.shape) * noise
    values = m.values + rng.normal(size=m.values.shape) * sd
    return FieldMap(kind=m.kind, positions_m=m.positions_m, values=values, sd=sd,
                    velocity_m_per_s=m.velocity_m_per_s,
                    source=f"synthetic patient, {100 * noise:g}% noise",
                    metadata={"patient": patient})


def model_maps(
    arm: Arm, postural_pos: FloatArray, stiffness_pos: FloatArray,
    velocities: Sequence[tuple[float, float]],
) -> list[FieldMap]:
    """The arm's postural map and one stiffness map per velocity (noise-free)."""
    out = [postural_map(arm, postural_pos)]
    out += [stiffness_map(arm, stiffness_pos, v) for v in velocities]
    return out


def default_velocities(speed_m_per_s: float = DEFAULT_SPEED_M_PER_S,
                       moving: bool = True) -> list[tuple[float, float]]:
    """Static, and (when ``moving``) ±speed along :data:`MOVE_DIRECTION`."""
    vels = [(0.0, 0.0)]
    if moving:
        ux, uy = MOVE_DIRECTION
        norm = math.hypot(ux, uy)
        vx, vy = speed_m_per_s * ux / norm, speed_m_per_s * uy / norm
        vels += [(vx, vy), (-vx, -vy)]
    return vels


def synthetic_patient(
    truth: ArmParams,
    seed: int = 0,
    n_postural: int = 25,
    n_stiffness: int = 9,
    noise: float = 0.05,
    moving: bool = True,
    n_held_out: int = 30,
    patient: str = "SYN",
) -> SyntheticPatient:
    """Noisy maps of ``truth`` and noise-free maps at held-out positions.

    Parameters
    ----------
    truth : ArmParams
    seed : int
        Seeds the positions and the noise (numpy Generator).
    n_postural, n_stiffness : int
        Positions of the postural map and of the stiffness maps.
    noise : float
        Noise SD as a fraction of each map's RMS value.
    moving : bool
        Also measure stiffness while moving (else static maps only: the reflex is unseen).
    n_held_out : int
        Positions of the held-out maps (postural and stiffness at the same velocities).
    """
    rng = np.random.default_rng(seed)
    arm = Arm.from_params(truth)
    vels = default_velocities(moving=moving)
    pp = scattered_positions(arm, n_postural, rng)
    ps = scattered_positions(arm, n_stiffness, rng)
    maps = [_noisy(m, noise, rng, patient) for m in model_maps(arm, pp, ps, vels)]
    hp = scattered_positions(arm, n_held_out, rng)
    held = model_maps(arm, hp, hp, vels)
    return SyntheticPatient(truth, tuple(maps), tuple(held))
