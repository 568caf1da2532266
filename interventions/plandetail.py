"""One stored plan with its lineage and what its prediction rests on (``plans show``).

The plan's steps in words and units, the models before and after, the fit behind the model
before, the parameters that fit did not identify and the warnings of the steps that act on them
(as ``whatif`` prints them). Apart from :mod:`fieldbank.interventions.plans` because it loads the
fit's machinery, which listing plans does not need.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from fieldbank import modelsource
from fieldbank.interventions.guesses import FitBasis, guesses, plan_warnings
from fieldbank.interventions.plans import PlanSummary, plan_of
from fieldbank.storage import Database


@dataclass(frozen=True)
class PlanDetail:
    """One stored plan with its lineage and what its prediction rests on (``plans show``).

    Attributes
    ----------
    base, result : dict
        The models before and after: id, origin, label.
    fit : dict or None
        The fit behind the model before (id, fitted model, status, verdict, reasons); None
        when the model before was not fitted (a severity or a parameter file).
    guesses : tuple of dict
        Every parameter that fit did not identify, with the reason.
    warnings : tuple of str
        Steps that act on a guessed parameter (their predictions rest on the default).
    """

    summary: PlanSummary
    base: dict[str, Any]
    result: dict[str, Any]
    fit: dict[str, Any] | None
    guesses: tuple[dict[str, Any], ...]
    warnings: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return {**self.summary.to_dict(), "base_model": self.base, "result_model": self.result,
                "fit": self.fit, "guesses": list(self.guesses), "warnings": list(self.warnings)}


def _model(db: Database, model_id: int) -> dict[str, Any]:
    m = db.get_model(model_id)
    return {"id": m.id, "origin": m.origin, "label": m.label, "patient": m.patient_code,
            "parent_id": m.parent_id}


def show_plan(db: Database, plan_id: int) -> PlanDetail:
    """Plan ``plan_id`` with its lineage, the fit behind its model before and the warnings."""
    rec = db.get_plan(plan_id)
    summary = PlanSummary.of(rec)
    source = modelsource.stored(db, rec.base_model_id)
    basis = FitBasis.of(source)
    plan = plan_of(rec)
    fit = None if basis is None else {
        "id": basis.fit_id, "fitted_model_id": basis.fitted_model_id,
        "status": basis.status, "verdict": basis.verdict, "reasons": list(basis.reasons)}
    return PlanDetail(summary, _model(db, rec.base_model_id), _model(db, rec.result_model_id),
                      fit, tuple(g.to_dict() for g in guesses(basis, source.params)),
                      plan_warnings(plan, basis, source.params))
