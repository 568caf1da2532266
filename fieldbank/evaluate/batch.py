"""Read-outs of many parameter sets of one arm in one pass (:class:`fieldbank.model.ArmBatch`).

A fit's uncertainty is a set of parameter samples that differ from the fitted model only in
muscle values (Km, α, β, slack offsets, rest lengths, the rest posture). Evaluating each as its
own :class:`~fieldbank.model.Arm` compiles and validates the same geometry once per sample and
loops in Python; here the geometry is compiled once and every read-out runs over a leading
sample axis:

* :func:`stretch_torques` - the slow and fast joint stretches of
  :func:`fieldbank.evaluate.probing.stretch_profile`, the torque resisting each, per sample;
  :func:`group_stretch` - the same stretch per muscle group (what the severity grades of
  many samples rest on, :mod:`fieldbank.evaluate.gradebatch`);
* :func:`probe_forces` - the force felt along a probing motion
  (:func:`fieldbank.evaluate.probing.profile`), per sample;
* :func:`rms_forces` - the RMS endpoint force over a grid, for sets of velocities.

Each equals the one-arm function applied to each sample in turn (``tests/test_intervals.py``
checks it to 1e-12 relative against those functions).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fieldbank.armbatch import ArmBatch
from fieldbank.errors import ParameterError
from fieldbank.evaluate.probing import (
    DIRECTION_SIGN,
    JOINTS,
    SLOW_STRETCH_SPEED_RAD_S,
    STRETCH_SAMPLES,
    STRETCH_SPEED_RAD_S,
    STRETCHES,
    ProbeMotion,
)
from fieldbank.model import FloatArray


@dataclass(frozen=True, eq=False)
class StretchTorques:
    """One joint stretch of every set of a batch.

    angles_rad : (T,) rad, in the order of travel (shared: the range of motion is geometry)
    slow_n_m, fast_n_m : (S, T) N·m, the joint torque resisting the slow and the fast stretch
    """

    joint: str
    direction: str
    angles_rad: FloatArray
    slow_n_m: FloatArray
    fast_n_m: FloatArray

    @property
    def name(self) -> str:
        return f"{self.joint} {self.direction}"


@dataclass(frozen=True, eq=False)
class GroupStretch:
    """One joint stretch of every set of a batch, per muscle group (N·m against the motion,
    as :class:`fieldbank.evaluate.probing.StretchProfile` holds it for one arm).

    angles_rad : (T,) rad, in the order of travel
    passive_n_m : (S, T, 6) each group's passive torque
    reflex_slow_n_m, reflex_fast_n_m : (S, T, 6) each group's reflex torque at each speed
    """

    joint: str
    direction: str
    angles_rad: FloatArray
    passive_n_m: FloatArray
    reflex_slow_n_m: FloatArray
    reflex_fast_n_m: FloatArray

    @property
    def velocity_dependent_n_m(self) -> FloatArray:
        """Each group's velocity-dependent torque, fast minus slow, (S, T, 6), N·m."""
        return np.asarray(self.reflex_fast_n_m - self.reflex_slow_n_m)


def group_stretch(batch: ArmBatch, joint: str, direction: str,
                  fast_speed_rad_s: float = STRETCH_SPEED_RAD_S,
                  slow_speed_rad_s: float = SLOW_STRETCH_SPEED_RAD_S,
                  samples: int = STRETCH_SAMPLES,
                  hold_rad: float | None = None) -> GroupStretch:
    """:func:`fieldbank.evaluate.probing.stretch_profile` of every set, per muscle group:
    ``joint`` swept through its range in ``direction``, the other joint held at ``hold_rad``
    (default: each set's rest posture)."""
    if joint not in JOINTS:
        raise ParameterError(f"joint must be one of {', '.join(JOINTS)}; got {joint!r}.")
    if direction not in DIRECTION_SIGN:
        raise ParameterError(f"direction must be 'flexion' or 'extension'; got {direction!r}.")
    geo, m = batch.geometry, batch.muscles
    j = JOINTS.index(joint)
    sign = DIRECTION_SIGN[direction]
    lo, hi = (geo.params.shoulder_range_rad, geo.params.elbow_range_rad)[j]
    angles = np.linspace(lo, hi, samples) if sign > 0 else np.linspace(hi, lo, samples)
    # the other joint at each set's rest posture (one posture when the sets share it)
    q = np.repeat(m.q_rest[:1 if m.same_lengths else None, None, :], samples, axis=1)
    q[:, :, j] = angles
    if hold_rad is not None:
        q[:, :, 1 - j] = hold_rad
    lam = m.lengths(q[0] if m.same_lengths else q, geo.jl)
    lever = sign * geo.jl[:, j]

    def reflex(speed: float) -> FloatArray:
        qdot = np.zeros((samples, 2))
        qdot[:, j] = sign * speed
        return np.asarray(m.reflex(lam, geo.muscle_velocities(qdot)) * lever)

    # the groups this joint moves: the others add exactly 0 N·m (a zero lever)
    moved = np.flatnonzero(lever)
    passive = np.zeros_like(lam)
    passive[..., moved] = m.passive(m.columns(lam, moved), moved) * lever[moved]
    return GroupStretch(joint, direction, angles, passive, reflex(slow_speed_rad_s),
                        reflex(fast_speed_rad_s))


def stretch_torques(batch: ArmBatch, joint: str, direction: str,
                    fast_speed_rad_s: float = STRETCH_SPEED_RAD_S,
                    slow_speed_rad_s: float = SLOW_STRETCH_SPEED_RAD_S,
                    samples: int = STRETCH_SAMPLES,
                    hold_rad: float | None = None) -> StretchTorques:
    """:func:`fieldbank.evaluate.probing.stretch_profile` of every set: ``joint`` swept
    through its range in ``direction``, the other joint held at ``hold_rad`` (default: each
    set's rest posture); the groups' torques summed (:func:`group_stretch`)."""
    g = group_stretch(batch, joint, direction, fast_speed_rad_s, slow_speed_rad_s, samples,
                      hold_rad)
    slow = (g.passive_n_m + g.reflex_slow_n_m).sum(axis=-1)
    fast = (g.passive_n_m + g.reflex_fast_n_m).sum(axis=-1)
    return StretchTorques(joint, direction, g.angles_rad, slow, fast)


def standard_stretch_torques(batch: ArmBatch) -> tuple[StretchTorques, ...]:
    """The four standard stretches (:data:`fieldbank.evaluate.probing.STRETCHES`), in order."""
    return tuple(stretch_torques(batch, j, d) for j, d in STRETCHES)


def probe_forces(batch: ArmBatch, motion: ProbeMotion) -> FloatArray:
    """The force every set's arm exerts on the handle along ``motion``, (S, T, 2), N."""
    return batch.endpoint_force(motion.positions_m, motion.velocities_m_per_s)


def peak_magnitude(force_n: FloatArray) -> FloatArray:
    """Largest force magnitude along the last-but-one axis: (S, T, 2) -> (S,), N."""
    return np.asarray(np.hypot(force_n[..., 0], force_n[..., 1]).max(axis=-1))


def rms_forces(batch: ArmBatch, grid_m: FloatArray,
               velocities: Sequence[FloatArray]) -> list[FloatArray]:
    """RMS endpoint force magnitude per set, (S,) N, for each velocity set of ``velocities``
    (each (D, 2), m/s) over every point of ``grid_m`` (N, 2): the N·D points of
    :meth:`fieldbank.evaluate.compare.Conditions.points`, in that order. The passive force
    on the grid is computed once for every velocity set."""
    sizes = [len(v) for v in velocities]
    f = batch.grid_force(grid_m, np.concatenate(velocities, axis=0))
    out = []
    for lo, hi in itertools.pairwise(np.cumsum([0, *sizes])):
        part = np.ascontiguousarray(f[:, :, lo:hi]).reshape(f.shape[0], -1, 2)
        out.append(np.asarray(np.sqrt(np.mean(np.sum(part * part, axis=-1), axis=-1))))
    return out
