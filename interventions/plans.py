"""Stored plans: list them, show one with what it rests on, record the day one was given.

A plan is stored by ``whatif --save`` with its lineage (:func:`fieldbank.interventions.whatif.
save_plan_result`): the model before, the plan's steps, the model after and, for a plan that
was carried out, the day it was given (``given_on``), which ``fieldbank validate`` checks
against the maps measured after it. This module is what ``fieldbank plans list|show|give``
calls:

* :func:`list_plans` - every stored plan, filtered by patient, intervention kind and whether it
  was given, as :class:`PlanSummary` rows;
* :func:`fieldbank.interventions.plandetail.show_plan` - one plan with its lineage and what it
  rests on (kept apart: it loads the fit's machinery, which listing plans does not need);
* :func:`give_plan` - record that a stored plan was carried out on a day, without saving the
  plan again (audited; a different day already recorded is refused, so nothing stored is
  changed silently).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from datetime import date, datetime
from typing import TYPE_CHECKING, Any

from fieldbank.interventions.catalogue import KINDS
from fieldbank.interventions.errors import InterventionError
from fieldbank.interventions.plan import Plan
from fieldbank.stored.listing import Reads
from fieldbank.stored.records import PlanRecord

if TYPE_CHECKING:  # typing only: listing plans reads through fieldbank.stored.listing
    from fieldbank.storage import Database


@dataclass(frozen=True)
class PlanSummary:
    """One stored plan as ``plans list`` shows it.

    Attributes
    ----------
    kinds : tuple of str
        The intervention kinds of its steps, in order (botulinum, lengthening, ...).
    steps : tuple of str
        Each step in words with its units.
    given_on : date or None
        The day the plan was carried out; None for a plan only explored.
    """

    id: int
    patient_code: str | None
    label: str
    kinds: tuple[str, ...]
    steps: tuple[str, ...]
    base_model_id: int
    result_model_id: int
    given_on: date | None
    created_at: datetime
    accepted_poor_fit: str | None = None

    @classmethod
    def of(cls, rec: PlanRecord) -> PlanSummary:
        plan = plan_of(rec)
        accepted = rec.spec.get("accepted_poor_fit")
        return cls(rec.id, rec.patient_code, rec.label,
                   tuple(s.kind for s in plan.steps), tuple(s.describe() for s in plan.steps),
                   rec.base_model_id, rec.result_model_id, rec.given_on,
                   rec.created_at, str(accepted) if accepted else None)

    def to_dict(self) -> dict[str, Any]:
        return {"id": self.id, "patient": self.patient_code, "label": self.label,
                "kinds": list(self.kinds), "steps": list(self.steps),
                "base_model_id": self.base_model_id, "result_model_id": self.result_model_id,
                "given_on": None if self.given_on is None else self.given_on.isoformat(),
                "created_at": self.created_at.isoformat(),
                "accepted_poor_fit": self.accepted_poor_fit}


def plan_of(rec: PlanRecord) -> Plan:
    doc = rec.spec.get("plan")
    if not isinstance(doc, Mapping):
        raise InterventionError(f"plan {rec.id}: its stored document holds no plan.")
    return Plan.from_dict(doc, where=f"stored plan {rec.id}")


def list_plans(db: Reads, patient: str | None = None, kind: str | None = None,
               given: bool | None = None) -> list[PlanSummary]:
    """The stored plans, oldest first: of ``patient``, with a step of ``kind``, given (True)
    or only explored (False)."""
    if kind is not None and kind not in KINDS:
        raise InterventionError(f"{kind!r} is not an intervention kind (known: "
                                f"{', '.join(KINDS)}).")
    if patient is not None:
        db.get_patient(patient)  # an unknown patient is an error naming the database
    out = [PlanSummary.of(r) for r in db.list_plans(patient)]
    if kind is not None:
        out = [p for p in out if kind in p.kinds]
    if given is not None:
        out = [p for p in out if (p.given_on is not None) == given]
    return out


def give_plan(db: Database, plan_id: int, on: date) -> tuple[PlanSummary, bool]:
    """Record that plan ``plan_id`` was carried out on ``on``; returns the plan and whether
    anything changed (False: that day was already recorded)."""
    rec = db.get_plan(plan_id)
    before = PlanSummary.of(rec)
    if before.given_on == on:
        return before, False
    if before.given_on is not None:
        raise InterventionError(
            f"plan {plan_id} is already recorded as given on {before.given_on.isoformat()}; "
            "a stored record is not changed. If that day is wrong, save the plan again with "
            "'whatif ... --save --given-on DATE' (a new plan, the old one kept).")
    return PlanSummary.of(db.set_plan_given(plan_id, on)), True
