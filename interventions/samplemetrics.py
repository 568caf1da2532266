"""The headline metrics of many parameter samples before and after a plan, the numbers a
prediction interval is drawn from (:mod:`fieldbank.interventions.guesses`).

Per stretch of the standard conditions: the peak resisting torque of the fast joint stretch and
its reflex (velocity-dependent) part, N·m; per probing motion, the peak force, N; per standard
speed, the RMS endpoint force, N. :func:`sample_metrics` evaluates every sample in one
vectorised pass (:class:`fieldbank.armbatch.ArmBatch`); :func:`sample_metrics_per_sample`
compiles each sample as its own arm, the reference the pass is tested against.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fieldbank.armbatch import ArmBatch
from fieldbank.errors import ParameterError
from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.batch import (
    peak_magnitude,
    probe_forces,
    rms_forces,
    standard_stretch_torques,
)
from fieldbank.evaluate.compare import Conditions
from fieldbank.evaluate.probing import (
    Profiles,
    profile,
    standard_stretches,
    stretch_profiles,
    unimpaired_reference,
)
from fieldbank.interventions.plan import Plan
from fieldbank.model import Arm, FloatArray
from fieldbank.params import ArmParams


def headline_metrics(arm: Arm, cond: Conditions,
                     curves: dict[str, FloatArray] | None = None,
                     references: dict[ArmParams, tuple[Arm, Profiles]] | None = None
                     ) -> dict[str, tuple[float, str]]:
    """The metrics given intervals: metric -> (value, unit).

    Peak resisting torque and its reflex part of each fast joint stretch, the peak force of
    each probing motion, and the RMS endpoint force of each standard speed. ``curves``, when
    given, receives each stretch's torque resisting the fast stretch along the joint angle
    (stretch name -> (T,) N·m), the curve the figures draw. ``references`` keeps the
    unimpaired reference arm and its stretch profiles (the catch threshold) per geometry, for
    callers that evaluate many arms of one geometry.
    """
    out: dict[str, tuple[float, str]] = {}
    profiles = stretch_profiles(arm)
    if curves is not None:
        curves.update({f"{j} {d}": p.fast_n_m for (j, d), p in profiles.items()})
    ref_params = arm.params.with_unimpaired_muscles()
    known = references.get(ref_params) if references is not None else None
    if known is None:
        ref = unimpaired_reference(arm)
        known = (ref, profiles if ref is arm else stretch_profiles(ref))
        if references is not None:
            references[ref_params] = known
    for s in standard_stretches(arm, known[0], profiles, known[1]):
        out[f"{s.name} peak torque"] = (s.peak_torque_n_m, "N·m")
        out[f"{s.name} reflex torque"] = (s.reflex_torque_n_m, "N·m")
    for m in cond.probes:
        out[f"{m.name} peak force"] = (profile(arm, m).peak_force_n, "N")
    for k, speed in enumerate(cond.speeds_m_per_s):
        f = arm.endpoint_force(*cond.points(k))  # the force alone: no stiffness needed
        rms = float(np.sqrt(np.mean(np.sum(f * f, axis=1))))
        out[f"RMS |F| at {speed:g} m/s"] = (rms, "N")
    return out


def headline_metrics_batch(batch: ArmBatch, cond: Conditions
                           ) -> tuple[dict[str, tuple[FloatArray, str]], dict[str, FloatArray]]:
    """:func:`headline_metrics` of every parameter set of ``batch`` in one pass: metric ->
    (values (S,), unit), in the same order, and each stretch's torque resisting the fast
    stretch along the joint angle (stretch name -> (S, T) N·m)."""
    out: dict[str, tuple[FloatArray, str]] = {}
    curves: dict[str, FloatArray] = {}
    for s in standard_stretch_torques(batch):
        curves[s.name] = s.fast_n_m
        out[f"{s.name} peak torque"] = (s.fast_n_m.max(axis=1), "N·m")
        out[f"{s.name} reflex torque"] = ((s.fast_n_m - s.slow_n_m).max(axis=1), "N·m")
    for m in cond.probes:
        out[f"{m.name} peak force"] = (peak_magnitude(probe_forces(batch, m)), "N")
    for speed, rms in zip(cond.speeds_m_per_s, rms_forces(batch, cond.grid_m, cond.velocities),
                          strict=True):
        out[f"RMS |F| at {speed:g} m/s"] = (rms, "N")
    return out, curves


@dataclass(frozen=True, eq=False)
class SampleMetrics:
    """The headline metrics of S parameter samples before and after a plan.

    ``keys`` and ``units`` in :func:`headline_metrics` order; ``before`` and ``after`` (S, K);
    ``curves``: {"before" | "after": {stretch name: (S, T) N·m}}, the fast-stretch torque.
    """

    keys: tuple[str, ...]
    units: tuple[str, ...]
    before: FloatArray
    after: FloatArray
    curves: dict[str, dict[str, FloatArray]]


def sample_metrics(samples: Sequence[ArmParams], plan: Plan, cond: Conditions,
                   geometry: Arm, memo: ArmCache | None = None) -> SampleMetrics:
    """The plan applied to each sample, every sample's metrics before and after in one
    vectorised pass (:class:`fieldbank.model.ArmBatch`: ``geometry`` compiled once, every
    muscle value free per sample). A plan that changed the geometry itself falls back to
    :func:`sample_metrics_per_sample`. ``memo``: the use case's cache, which keeps the
    metrics before (they do not depend on the plan)."""
    afters = [plan.apply(p) for p in samples]
    try:
        b = ArmBatch.from_params(samples, geometry)
        a = ArmBatch.from_params(afters, geometry)
    except ParameterError:
        return sample_metrics_per_sample(samples, plan, cond)
    mb, cb = (headline_metrics_batch(b, cond) if memo is None else memo.derived(
        ("sample metrics before", cond, tuple(samples)), lambda: headline_metrics_batch(b, cond)))
    ma, ca = headline_metrics_batch(a, cond)
    keys = tuple(mb)
    return SampleMetrics(keys, tuple(mb[k][1] for k in keys),
                         np.stack([mb[k][0] for k in keys], axis=1),
                         np.stack([ma[k][0] for k in keys], axis=1),
                         {"before": cb, "after": ca})


def sample_metrics_per_sample(samples: Sequence[ArmParams], plan: Plan,
                              cond: Conditions) -> SampleMetrics:
    """:func:`sample_metrics` one sample at a time, each compiled as its own arm: the
    reference the vectorised pass is tested against, and the path for a plan that changes
    the geometry."""
    references: dict[ArmParams, tuple[Arm, Profiles]] = {}
    rows_b, rows_a = [], []
    curves: dict[str, list[dict[str, FloatArray]]] = {"before": [], "after": []}
    keys: list[str] = []
    units: list[str] = []
    for p in samples:
        cb: dict[str, FloatArray] = {}
        ca: dict[str, FloatArray] = {}
        arm_p = Arm.from_params(p)
        after_p = plan.apply(p)
        try:  # a plan changes muscle values only: the geometry is compiled once
            arm_pa = arm_p.with_muscles(after_p)
        except ParameterError:
            arm_pa = Arm.from_params(after_p)
        mb = headline_metrics(arm_p, cond, cb, references)
        ma = headline_metrics(arm_pa, cond, ca, references)
        keys, units = list(mb), [mb[k][1] for k in mb]
        rows_b.append([mb[k][0] for k in keys])
        rows_a.append([ma[k][0] for k in keys])
        curves["before"].append(cb)
        curves["after"].append(ca)
    return SampleMetrics(
        tuple(keys), tuple(units), np.array(rows_b, dtype=float), np.array(rows_a, dtype=float),
        {when: ({name: np.stack([c[name] for c in per]) for name in per[0]} if per else {})
         for when, per in curves.items()})
