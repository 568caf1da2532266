"""The headline metrics of a what-if's intervals one parameter set at a time: each set
compiled as its own arm (:meth:`fieldbank.model.Arm.from_params`) and read out by the one-arm
read-outs (:mod:`fieldbank.evaluate.probing`, :meth:`fieldbank.model.Arm.endpoint_force`) - the
reference the vectorised pass (:func:`fieldbank.interventions.samplemetrics.sample_metrics`,
one :class:`fieldbank.armbatch.ArmBatch`) is tested against.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fieldbank.errors import ParameterError
from fieldbank.evaluate.compare import Conditions
from fieldbank.evaluate.probing import (
    Profiles,
    profile,
    standard_stretches,
    stretch_profiles,
    unimpaired_reference,
)
from fieldbank.interventions.plan import Plan
from fieldbank.interventions.samplemetrics import SampleMetrics
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




def sample_metrics_per_sample(samples: Sequence[ArmParams], plan: Plan,
                              cond: Conditions) -> SampleMetrics:
    """``sample_metrics`` one sample at a time, each compiled as its own arm: the reference
    the vectorised pass is tested against."""
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
