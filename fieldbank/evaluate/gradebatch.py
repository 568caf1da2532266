"""Severity scores of many parameter sets of one arm in one pass.

A fit grades its model and, for the range of each grade, every one of its parameter samples
(held parameters drawn from their prior range): forty-odd sets that differ only in muscle
values. :func:`fieldbank.evaluate.severity.classify` grades one compiled arm at a time - six
stretch profiles and the tone measures in Python per set. Here the sets are one
:class:`~fieldbank.armbatch.ArmBatch`: each standard stretch and each bi-articular group's own
stretch is swept once for all of them (:func:`fieldbank.evaluate.batch.group_stretch`), and the
measures of :mod:`fieldbank.evaluate.tone` - what each group adds to its graded stretch over the
unimpaired arm, the larger over its stretches - and the continuous score of
:class:`~fieldbank.evaluate.severity.SeverityScale` run over the sample axis.

:func:`scores` gives, per (group, component), the score of every set: what ``classify`` of
each set's own arm gives, to rounding (``tests/test_severity_batch.py`` holds the two
together on impaired, contracted and unimpaired arms).
"""

from __future__ import annotations

import math

import numpy as np

from fieldbank.armbatch import ArmBatch
from fieldbank.evaluate.batch import GroupStretch, group_stretch
from fieldbank.evaluate.probing import (
    Profiles,
    StretchProfile,
    stretch_profiles,
)
from fieldbank.evaluate.severity import SCALE, SeverityScale
from fieldbank.evaluate.tone import (
    GRADED_STRETCH,
    POSITIONED_STRETCH,
    positioned_hold_rad,
    positioned_profiles,
)
from fieldbank.model import Arm, FloatArray
from fieldbank.params import GROUP_INDEX, GROUPS


def _ratio(torque: FloatArray, torque_ref: FloatArray, reference_peak: float) -> FloatArray:
    """The ratio of one component for every set (:func:`fieldbank.evaluate.tone._added`):
    ``torque`` (S, T) against the unimpaired ``torque_ref`` (T,)."""
    extra = torque - torque_ref
    peak = extra.max(axis=1)
    below = (torque_ref + extra).max(axis=1) / reference_peak
    return np.asarray(np.where(peak > 0.0, 1.0 + peak / reference_peak, below), dtype=float)


def score_array(ratio: FloatArray, component: str, scale: SeverityScale = SCALE) -> FloatArray:
    """:meth:`SeverityScale.score` of every ratio of ``ratio``."""
    vm = scale.level_ratio("very mild", component)
    r = np.asarray(ratio, dtype=float)
    safe = np.maximum(r, 1.0)
    low = np.log(safe) / math.log(vm)
    high = 1.0 + np.log(safe / vm) / math.log(1.0 + scale.weber_fraction)
    return np.asarray(np.where(r <= 1.0, 0.0, np.where(r < vm, low, high)), dtype=float)


def ratios(batch: ArmBatch, reference: Arm, reference_profiles: Profiles | None = None,
           reference_positioned: dict[str, StretchProfile] | None = None
           ) -> dict[tuple[str, str], FloatArray]:
    """Per (group, component), the ratio to unimpaired of every set of ``batch``, (S,): what
    :func:`fieldbank.evaluate.tone.group_tone` gives each set against ``reference`` (the
    unimpaired arm; its profiles when already computed)."""
    ref_prof = reference_profiles if reference_profiles is not None else \
        stretch_profiles(reference)
    ref_own = reference_positioned if reference_positioned is not None else \
        positioned_profiles(reference)
    swept: dict[tuple[str, str], GroupStretch] = {}
    own: dict[str, GroupStretch] = {}
    out: dict[tuple[str, str], FloatArray] = {}
    for g in GROUPS:
        i = GROUP_INDEX[g]
        key = GRADED_STRETCH[g]
        if key not in swept:
            swept[key] = group_stretch(batch, *key)
        pairs = [(swept[key], ref_prof[key])]
        if g in POSITIONED_STRETCH:
            own[g] = group_stretch(batch, *key, hold_rad=positioned_hold_rad(batch.geometry, g))
            pairs.append((own[g], ref_own[g]))
        passive: FloatArray | None = None
        dynamic: FloatArray | None = None
        for a, r in pairs:
            p_ref = r.passive_n_m[:, i]
            v_ref = r.velocity_dependent_n_m[:, i]
            pr = _ratio(a.passive_n_m[:, :, i], p_ref, float(np.max(p_ref)))
            dyn_ref = p_ref + v_ref
            dr = _ratio(p_ref + a.velocity_dependent_n_m[:, :, i], dyn_ref,
                        float(np.max(dyn_ref)))
            # each component on the stretch that shows it more
            passive = pr if passive is None else np.maximum(passive, pr)
            dynamic = dr if dynamic is None else np.maximum(dynamic, dr)
        assert passive is not None and dynamic is not None
        out[(g, "passive")] = passive
        out[(g, "dynamic")] = dynamic
    return out


def scores(batch: ArmBatch, reference: Arm, scale: SeverityScale = SCALE,
           reference_profiles: Profiles | None = None,
           reference_positioned: dict[str, StretchProfile] | None = None
           ) -> dict[tuple[str, str], FloatArray]:
    """Per (group, component), the continuous severity score (0 unimpaired … 4 severe) of
    every set of ``batch``, (S,): the ``score`` of :func:`fieldbank.evaluate.severity.classify`
    of each set's arm against ``reference``."""
    return {(g, c): score_array(r, c, scale)
            for (g, c), r in ratios(batch, reference, reference_profiles,
                                    reference_positioned).items()}
