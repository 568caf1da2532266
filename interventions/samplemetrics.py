"""The headline metrics of many parameter samples before and after a plan, the numbers a
prediction interval is drawn from (:mod:`fieldbank.interventions.guesses`).

Per stretch of the standard conditions: the peak resisting torque of the fast joint stretch and
its reflex (velocity-dependent) part, N·m; per probing motion, the peak force, N; per standard
speed, the RMS endpoint force, N. :func:`sample_metrics` evaluates every sample in one
vectorised pass (:class:`fieldbank.armbatch.ArmBatch`); the tests hold it against each sample
compiled as its own arm and read out by the one-arm read-outs (:mod:`fieldbank.evaluate.probing`).
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
from fieldbank.interventions.plan import Plan
from fieldbank.model import Arm, FloatArray
from fieldbank.params import ArmParams


def headline_metrics_batch(batch: ArmBatch, cond: Conditions
                           ) -> tuple[dict[str, tuple[FloatArray, str]], dict[str, FloatArray]]:
    """The metrics given intervals, of every parameter set of ``batch`` in one pass: metric
    -> (values (S,), unit), and each stretch's torque resisting the fast stretch along the
    joint angle (stretch name -> (S, T) N·m). In order: the peak resisting torque and its
    reflex part of each fast joint stretch, the peak force of each probing motion, and the
    RMS endpoint force of each standard speed."""
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

    ``keys`` and ``units`` in :func:`headline_metrics_batch` order; ``before`` and ``after`` (S, K);
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
    vectorised pass (:class:`fieldbank.armbatch.ArmBatch`: ``geometry``, the model before,
    compiled once, every muscle value free per sample). A plan that changed the geometry
    itself has its own geometry compiled once (in ``memo`` when given). ``memo``: the use
    case's cache, which keeps the metrics before (they do not depend on the plan).

    Raises
    ------
    ParameterError
        The samples do not share the geometry of ``geometry`` (nor the plan's results one).
    """
    afters = [plan.apply(p) for p in samples]
    b = ArmBatch.from_params(samples, geometry)
    try:
        a = ArmBatch.from_params(afters, geometry)
    except ParameterError:  # the plan moved the geometry: every sample's the same way
        a = ArmBatch.from_params(afters, (memo or Arm.from_params)(afters[0]))
    mb, cb = (headline_metrics_batch(b, cond) if memo is None else memo.derived(
        ("sample metrics before", cond, tuple(samples)), lambda: headline_metrics_batch(b, cond)))
    ma, ca = headline_metrics_batch(a, cond)
    keys = tuple(mb)
    return SampleMetrics(keys, tuple(mb[k][1] for k in keys),
                         np.stack([mb[k][0] for k in keys], axis=1),
                         np.stack([ma[k][0] for k in keys], axis=1),
                         {"before": cb, "after": ca})
