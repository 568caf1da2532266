"""Field-change metrics between two compiled arms ("before" and "after" an intervention plan).

Both arms are evaluated on the same standard conditions, set by the *before* arm so the
two are compared at identical positions and velocities:

* a workspace grid, :func:`fieldbank.maps.workspace_grid` with n = :data:`GRID_N` (the
  reachable points of a 15 × 15 box), without the near-straight-elbow postures
  (:data:`MIN_ELBOW_RAD`);
* endpoint velocities: static (0) and every speed of :data:`SPEEDS_M_PER_S` in
  :data:`N_DIRECTIONS` directions evenly spread around the circle (the reflex acts only on
  lengthening muscles, so one direction would see only some groups);
* the seed's probing motions and the single-joint fast stretches
  (:mod:`fieldbank.evaluate.probing`).

Reported (:class:`Comparison`):

* per velocity condition - RMS and maximum of |F_after - F_before| and where the maximum is;
  stiffness-ellipse changes (median area ratio, mean absolute orientation change, median shape
  ratio before and after; :func:`fieldbank.maps.ellipse`);
* the passive potential U: mean, RMS and largest change over the grid;
* severity per muscle group and direction before and after, passive (position-dependent) and
  dynamic (velocity-dependent) (:func:`fieldbank.evaluate.severity.classify`), each grade naming the
  parameters it rests on that the model's fit did not identify;
* probing-motion profiles: peak force, its direction, mean direction, before and after;
* the clinic's joint stretches per joint and direction: resisting torque at the slow and the
  fast stretch, its velocity-dependent part, the Tardieu catch (R1, R2, R2 - R1).
"""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import dataclass
from typing import Any

import numpy as np

from fieldbank.errors import ParameterError
from fieldbank.evaluate.probing import (
    JointStretch,
    ProbeMotion,
    ProbeProfile,
    Profiles,
    profile,
    standard_probes,
    standard_stretches,
    stretch_profiles,
    unimpaired_reference,
)
from fieldbank.evaluate.severity import GroupSeverity, classify, severity_dict
from fieldbank.maps import ellipse, workspace_grid
from fieldbank.model import Arm, FloatArray
from fieldbank.params import ArmParams

GRID_N = 15
#: Grid postures with the elbow within this angle of straight are left out: there the endpoint
#: Jacobian is near-singular and endpoint forces at speed reflect geometry, not the muscles.
MIN_ELBOW_RAD = math.radians(15.0)
#: Moving conditions (assumption): 0.3 m/s, a brisk clinical hand speed, in 8 directions.
SPEEDS_M_PER_S: tuple[float, ...] = (0.3,)
N_DIRECTIONS = 8


def standard_grid(arm: Arm, grid_n: int = GRID_N) -> FloatArray:
    """The workspace grid of the standard conditions: :func:`fieldbank.maps.workspace_grid`
    without the postures whose elbow is within :data:`MIN_ELBOW_RAD` of straight, (N, 2), m."""
    grid = workspace_grid(arm, grid_n)
    return grid[arm.ik(grid)[:, 1] >= MIN_ELBOW_RAD]


@dataclass(frozen=True, eq=False)
class Conditions:
    """Standard evaluation conditions: grid (N, 2) m; velocity sets per condition."""

    grid_m: FloatArray
    speeds_m_per_s: tuple[float, ...]
    velocities: tuple[FloatArray, ...]  # per condition, (D, 2) m/s; static is [[0, 0]]
    probes: tuple[ProbeMotion, ...]
    #: The unimpaired arm of this geometry and its stretch profiles (severity and catch
    #: reference), computed once for every arm evaluated on these conditions.
    reference: Arm | None = None
    reference_profiles: Profiles | None = None

    @classmethod
    def standard(cls, arm: Arm, grid_n: int = GRID_N,
                 speeds_m_per_s: tuple[float, ...] = SPEEDS_M_PER_S,
                 n_directions: int = N_DIRECTIONS) -> Conditions:
        th = 2 * np.pi * np.arange(n_directions) / n_directions
        dirs = np.stack([np.cos(th), np.sin(th)], axis=1)
        vels = [np.zeros((1, 2))] + [s * dirs for s in speeds_m_per_s]
        grid = standard_grid(arm, grid_n)
        ref = unimpaired_reference(arm)
        return cls(grid, (0.0, *speeds_m_per_s), tuple(vels), standard_probes(arm), ref,
                   stretch_profiles(ref))

    def points(self, k: int) -> tuple[FloatArray, FloatArray]:
        """Positions and velocities of condition k, each (N·D, 2)."""
        v = self.velocities[k]
        n, d = self.grid_m.shape[0], v.shape[0]
        return np.repeat(self.grid_m, d, axis=0), np.tile(v, (n, 1))


@dataclass(frozen=True, eq=False)
class Evaluation:
    """One compiled arm on the standard conditions.

    Attributes
    ----------
    arm : Arm
    conditions : Conditions
    force_n : tuple of ndarray, each shape (N·D, 2), N
        Endpoint force at each condition's points (:meth:`Conditions.points`).
    stiffness_n_per_m : tuple of ndarray, each shape (N·D, 2, 2), N/m
    potential_j : ndarray, shape (N,), J
        Passive potential on the grid.
    probes, stretches : probing-motion profiles and the slow/fast joint stretches
    severity : dict muscle group -> GroupSeverity (passive and dynamic grade)
    profiles : the torque-angle profiles of the four joint stretches the read-outs and the
        grades come from (:func:`fieldbank.evaluate.probing.stretch_profiles`; figures draw
        them)
    """

    arm: Arm
    conditions: Conditions
    force_n: tuple[FloatArray, ...]
    stiffness_n_per_m: tuple[FloatArray, ...]
    potential_j: FloatArray
    probes: tuple[ProbeProfile, ...]
    stretches: tuple[JointStretch, ...]
    severity: dict[str, GroupSeverity]
    profiles: Profiles | None = None

    @property
    def params(self) -> ArmParams:
        return self.arm.params


def fields_per_velocity(
    arm: Arm, cond: Conditions
) -> tuple[tuple[FloatArray, ...], tuple[FloatArray, ...]]:
    """Force (N, 2) and stiffness (N, 2, 2) on the grid at each of the conditions' velocities."""
    forces, stiff = [], []
    for k in range(len(cond.velocities)):
        x, v = cond.points(k)
        f, kk, _ = arm.field(x, v)
        forces.append(f)
        stiff.append(kk)
    return tuple(forces), tuple(stiff)


def evaluate_arm(arm: Arm, conditions: Conditions | None = None,
                 unidentified: Collection[str] = ()) -> Evaluation:
    """Evaluate ``arm`` on ``conditions`` (default: its own standard conditions).

    ``unidentified`` names the fitted parameters the model's maps did not identify; the
    severity grades that rest on them say so.
    """
    cond = conditions if conditions is not None else Conditions.standard(arm)
    forces, stiff = fields_per_velocity(arm, cond)
    reference, ref_profiles = cond.reference, cond.reference_profiles
    if reference is None or ref_profiles is None or \
            reference.params != arm.params.with_unimpaired_muscles():
        reference = unimpaired_reference(arm)
        ref_profiles = stretch_profiles(reference)
    profiles = stretch_profiles(arm)
    return Evaluation(
        arm=arm,
        conditions=cond,
        force_n=forces,
        stiffness_n_per_m=stiff,
        potential_j=arm.potential(cond.grid_m),
        probes=tuple(profile(arm, m) for m in cond.probes),
        stretches=standard_stretches(arm, reference, profiles, ref_profiles),
        severity=classify(arm, unidentified, reference, profiles=profiles,
                          reference_profiles=ref_profiles),
        profiles=profiles,
    )


@dataclass(frozen=True)
class FieldChange:
    """Change of the force and stiffness field at one speed (all grid points × directions)."""

    speed_m_per_s: float
    force_rms_before_n: float
    force_rms_after_n: float
    diff_rms_n: float
    diff_max_n: float
    diff_max_at_m: tuple[float, float]
    diff_max_velocity_m_per_s: tuple[float, float]
    area_ratio_median: float
    orientation_change_deg_mean: float
    shape_ratio_before_median: float
    shape_ratio_after_median: float

    def to_dict(self) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}


@dataclass(frozen=True)
class PotentialChange:
    mean_j: float
    rms_j: float
    max_abs_j: float
    max_at_m: tuple[float, float]

    def to_dict(self) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}


@dataclass(frozen=True, eq=False)
class Comparison:
    """Before/after metrics of one plan (see the module docstring)."""

    before: Evaluation
    after: Evaluation
    fields: tuple[FieldChange, ...]
    potential: PotentialChange

    def probe_rows(self) -> list[tuple[str, ProbeProfile, ProbeProfile]]:
        return [(b.motion.name, b, a) for b, a in zip(self.before.probes, self.after.probes,
                                                       strict=True)]

    def stretch_rows(self) -> list[tuple[str, JointStretch, JointStretch]]:
        return [(b.name, b, a) for b, a in zip(self.before.stretches, self.after.stretches,
                                                strict=True)]

    def severity_rows(self) -> list[tuple[str, GroupSeverity, GroupSeverity]]:
        return [(g, self.before.severity[g], self.after.severity[g])
                for g in self.before.severity]

    def to_dict(self, with_profiles: bool = False) -> dict[str, Any]:
        return {
            "grid_points": int(self.before.conditions.grid_m.shape[0]),
            "directions_per_speed": int(self.before.conditions.velocities[-1].shape[0]),
            "fields": [f.to_dict() for f in self.fields],
            "potential_change": self.potential.to_dict(),
            "severity": {"before": severity_dict(self.before.severity),
                         "after": severity_dict(self.after.severity)},
            "probes": {n: {"before": b.to_dict(with_profiles), "after": a.to_dict(with_profiles)}
                       for n, b, a in self.probe_rows()},
            "stretches": {n: {"before": b.to_dict(), "after": a.to_dict()}
                          for n, b, a in self.stretch_rows()},
        }


def _wrap_axis_deg(d: FloatArray) -> FloatArray:
    """Absolute difference of ellipse axis angles, in [0, 90] degrees (axes are ±π periodic)."""
    a = np.abs((d + np.pi / 2) % np.pi - np.pi / 2)
    return np.asarray(np.degrees(a), dtype=float)


def _field_change(speed: float, x: FloatArray, v: FloatArray, fb: FloatArray, fa: FloatArray,
                  kb: FloatArray, ka: FloatArray) -> FieldChange:
    diff = np.hypot(*(fa - fb).T)
    i = int(np.argmax(diff))
    eb, ea = ellipse(kb), ellipse(ka)
    ok = (eb.area > 0) & (ea.area > 0)
    nan = float("nan")
    ratio = float(np.median(ea.area[ok] / eb.area[ok])) if np.any(ok) else nan
    orient = float(np.mean(_wrap_axis_deg(ea.orientation_rad - eb.orientation_rad)))
    return FieldChange(
        speed_m_per_s=speed,
        force_rms_before_n=float(np.sqrt(np.mean(np.sum(fb * fb, axis=1)))),
        force_rms_after_n=float(np.sqrt(np.mean(np.sum(fa * fa, axis=1)))),
        diff_rms_n=float(np.sqrt(np.mean(diff * diff))),
        diff_max_n=float(diff[i]),
        diff_max_at_m=(float(x[i, 0]), float(x[i, 1])),
        diff_max_velocity_m_per_s=(float(v[i, 0]), float(v[i, 1])),
        area_ratio_median=ratio,
        orientation_change_deg_mean=orient,
        shape_ratio_before_median=float(np.median(eb.shape_ratio[ok])) if np.any(ok) else nan,
        shape_ratio_after_median=float(np.median(ea.shape_ratio[ok])) if np.any(ok) else nan,
    )


def compare_evaluations(before: Evaluation, after: Evaluation) -> Comparison:
    """Metrics from two evaluations on the same conditions."""
    cond = before.conditions
    if after.conditions is not cond:
        raise ParameterError("before and after must be evaluated on the same Conditions object.")
    changes = []
    for k, speed in enumerate(cond.speeds_m_per_s):
        x, v = cond.points(k)
        changes.append(_field_change(speed, x, v, before.force_n[k], after.force_n[k],
                                     before.stiffness_n_per_m[k], after.stiffness_n_per_m[k]))
    du = after.potential_j - before.potential_j
    j = int(np.argmax(np.abs(du)))
    pot = PotentialChange(
        mean_j=float(du.mean()), rms_j=float(math.sqrt(float(np.mean(du * du)))),
        max_abs_j=float(abs(du[j])),
        max_at_m=(float(cond.grid_m[j, 0]), float(cond.grid_m[j, 1])),
    )
    return Comparison(before, after, tuple(changes), pot)


def compare(arm_before: Arm, arm_after: Arm, conditions: Conditions | None = None,
            unidentified: Collection[str] = ()) -> Comparison:
    """All before/after metrics of two compiled arms on the standard conditions of the first.

    Parameters
    ----------
    arm_before, arm_after : Arm
    conditions : Conditions, optional
        Default: :meth:`Conditions.standard` of ``arm_before``.
    unidentified : collection of str
        Parameters of the model before that its fit did not identify (they stay guesses in
        the model after); the severity grades resting on them say so.
    """
    cond = conditions if conditions is not None else Conditions.standard(arm_before)
    return compare_evaluations(evaluate_arm(arm_before, cond, unidentified),
                               evaluate_arm(arm_after, cond, unidentified))
