"""What a report case rests on, and whether its prediction held: the columns and JSON parts.

For each case (:func:`case_trust`): the status of the fit behind the model before, the
parameters it did not identify, the warnings of :mod:`fieldbank.interventions.guesses` (a step
acting on a guessed parameter; an accepted poor fit), 95% intervals of the headline metrics
(the fit's samples through the plan; for every joint stretch, the probing motions), and - when
the plan was given and the patient has maps
measured after it - the check of :mod:`fieldbank.interventions.validate` per later session.
The intervals are kept with the fit (:func:`with_known_intervals` reads them,
:func:`keep_intervals` stores new ones): a report that meets the same fit, model and plan
again reads them back, exactly, instead of computing them.
The metrics table gets :data:`TRUST_COLUMNS`; the case's JSON gets everything.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.compare import Conditions
from fieldbank.evaluate.probing import STRETCHES
from fieldbank.fitchoices import MODEL_VERSION
from fieldbank.interventions.guesses import (
    FitBasis,
    Guesses,
    IntervalSet,
    examine,
    interval_key,
)
from fieldbank.interventions.report.select import CaseSpec
from fieldbank.interventions.validate import PlanValidation, check_plan
from fieldbank.interventions.whatifchoices import DEFAULT_INTERVAL_SAMPLES
from fieldbank.storage import Database

#: Headline metrics with interval columns: metric of
#: :func:`fieldbank.interventions.samplemetrics.headline_metrics_batch` -> (column stem,
#: heading, unit).
_INTERVALS: tuple[tuple[str, str, str, str], ...] = (
    ("pull peak force", "pull_peak", "pull peak", "N"),
    ("semi-ellipse peak force", "semi_ellipse_peak", "semi-ellipse peak", "N"),
    *((f"{j} {d} {what} torque", f"{j}_{d}_{what}", f"{j} {d} {label}", "N·m")
      for j, d in STRETCHES
      for what, label in (("peak", "fast-stretch peak"), ("reflex", "reflex"))))
#: Interval columns: headline metric -> (low column, high column).
_INTERVAL_COLUMNS = {
    metric: (f"{stem}_after_low_{'n' if unit == 'N' else 'n_m'}",
             f"{stem}_after_high_{'n' if unit == 'N' else 'n_m'}")
    for metric, stem, _, unit in _INTERVALS}
#: Columns after the metrics: (key, heading).
TRUST_COLUMNS: tuple[tuple[str, str], ...] = (
    ("fit_status", "fit status"),
    ("unidentified", "not identified by the fit"),
    *((col, f"{head} after, 95% {side} ({unit})")
      for metric, _, head, unit in _INTERVALS
      for col, side in zip(_INTERVAL_COLUMNS[metric], ("low", "high"), strict=True)),
    ("validation", "prediction check"),
    ("validation_sessions", "checked against sessions"),
    ("validation_chi2_per_value_max", "check: largest χ²/n"),
    ("validation_r2_min", "check: lowest R²"),
    ("realised_change_fraction", "measured / predicted change"),
)


@dataclass(frozen=True, eq=False)
class CaseTrust:
    """A case's :data:`TRUST_COLUMNS` values (``row``), its JSON parts (``detail``), and for
    the figures the guesses (intervals, curve bands) and the check against later maps."""

    row: dict[str, Any]
    detail: dict[str, Any]
    guesses: Guesses | None
    validation: PlanValidation | None


def basis_of(spec: CaseSpec) -> FitBasis | None:
    """The fit behind a case's model before, from what the selection read."""
    if spec.fit_report is None or spec.fit_id is None or spec.fitted_model_id is None:
        return None
    return FitBasis.from_report(spec.fit_id, spec.fitted_model_id,
                                spec.fitted_model_id == spec.base_model_id, spec.fit_report)


def interval_key_of(spec: CaseSpec) -> tuple[int, str] | None:
    """(fit id, :func:`~fieldbank.interventions.guesses.interval_key`) of a case whose
    intervals can be kept with its fit; None when it has none to keep (no fit, no samples, a
    model derived from the fitted one, no readable plan)."""
    basis = basis_of(spec)
    if basis is None or spec.plan is None or basis.samples is None or not basis.same_model:
        return None
    return basis.fit_id, interval_key(basis, spec.before, spec.plan, DEFAULT_INTERVAL_SAMPLES)


def with_known_intervals(db: Database, cases: list[CaseSpec]) -> list[CaseSpec]:
    """The cases, each with its intervals when its fit keeps them already."""
    keys = [interval_key_of(c) for c in cases]
    kept = db.fit_documents([k for k in keys if k is not None])
    out = []
    for c, at in zip(cases, keys, strict=True):
        found = kept.get(at) if at is not None else None
        out.append(c if found is None else
                   dataclasses.replace(c, intervals=IntervalSet.from_document(*found)))
    return out


def keep_intervals(db: Database, specs: list[CaseSpec],
                   computed: list[IntervalSet | None]) -> int:
    """Keep the intervals computed for cases that had none with their fits; returns how
    many were stored (two processes storing the same one store it once)."""
    n = 0
    for spec, iv in zip(specs, computed, strict=True):
        at = interval_key_of(spec)
        if at is None or iv is None or spec.intervals is not None or iv.n_samples == 0:
            continue
        doc, arrays = iv.to_document()
        n += db.put_fit_document(at[0], at[1], MODEL_VERSION, doc, arrays)
    return n


def case_trust(spec: CaseSpec, cond: Conditions, arms: ArmCache) -> CaseTrust:
    """The case's :data:`TRUST_COLUMNS` values and its JSON parts (``fit``,
    ``unidentified``, ``warnings``, ``intervals``, ``validation``)."""
    row: dict[str, Any] = dict.fromkeys(k for k, _ in TRUST_COLUMNS)
    detail: dict[str, Any] = {}
    basis = basis_of(spec)
    g = v = None
    if spec.plan is not None:
        g = examine(basis, arms(spec.before), spec.plan, cond, arms,
                    accept_poor_fit=spec.accept_poor_fit, known=spec.intervals)
        detail.update(g.to_dict())
        row["fit_status"] = (basis.status + (" (accepted)" if g.accepted_poor_fit else "")
                             if basis is not None else "not fitted")
        row["unidentified"] = " ".join(x.name for x in g.guesses)
        by_metric = {i.metric: i for i in g.intervals}
        for metric, (lo, hi) in _INTERVAL_COLUMNS.items():
            if metric in by_metric:
                row[lo], row[hi] = by_metric[metric].after_low, by_metric[metric].after_high
    if spec.checks is not None:
        v = check_plan(spec.checks)
        detail["validation"] = v.to_dict()
        row["validation"] = v.verdict
        row["validation_sessions"] = " ".join(s.session for s in v.sessions)
        if v.sessions:
            row["validation_chi2_per_value_max"] = max(s.worst_chi2_per_value
                                                       for s in v.sessions)
            row["validation_r2_min"] = min(s.lowest_r2 for s in v.sessions)
            fr = [s.realised_fraction for s in v.sessions if s.realised_fraction is not None]
            row["realised_change_fraction"] = fr[0] if len(fr) == 1 else (
                None if not fr else math.fsum(fr) / len(fr))
    return CaseTrust(row, detail, g, v)
