"""The plan composer's what-if: ``fieldbank whatif`` for a page where a dose changes often.

:class:`Composer` keeps, per stored model, the model as ``whatif`` resolves it
(:mod:`fieldbank.modelsource`) and one :class:`~fieldbank.evaluate.ArmCache` that outlives the
request; each dose change is then :func:`~fieldbank.interventions.whatif.run_whatif` with that
cache, so what depends on the model before alone (its conditions and evaluation, the prior of
the held parameters, the fit's samples and their metrics) is computed once and every number is
the one ``fieldbank whatif`` prints for the same model and plan (a test compares them). The
figures are the ones ``whatif --plot`` draws, as SVG text.

A plan arrives as the command line's text forms (:func:`plan_from_fields`: ``botox``
``"ef=200U,bf=100U"``, ``lengthen`` ``"bf=1cm"``, ``weeks`` …, built by
:func:`fieldbank.interventions.spec.build_plan`, so errors have the command line's words) or as
a plan document (``plan``: the JSON of ``whatif --out``'s plan.json).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import date
from typing import Any

from fieldbank import modelsource
from fieldbank.evaluate.arms import ArmCache
from fieldbank.figures import render
from fieldbank.interventions.catalogue import KINDS
from fieldbank.interventions.defaults import DEFAULTS, DOSE_UNIT, value
from fieldbank.interventions.errors import InterventionError
from fieldbank.interventions.plan import Plan
from fieldbank.interventions.plot import comparison_page
from fieldbank.interventions.spec import build_plan
from fieldbank.interventions.whatif import (
    DoseSearch,
    SavedPlan,
    WhatIf,
    plan_label,
    run_whatif,
    save_plan,
)
from fieldbank.interventions.whatifchoices import DEFAULT_INTERVAL_SAMPLES
from fieldbank.model import Arm
from fieldbank.modelsource import ModelSource
from fieldbank.params import GROUP_NAMES, GROUPS
from fieldbank.storage import Database

#: Most models whose prepared what-if the composer keeps at once.
MAX_MODELS = 8
#: Most compiled arms kept per model (each dose change compiles one).
MAX_ARMS = 32
#: The text fields a plan may arrive as (the command line's options of the same name).
TEXT_FIELDS = ("botox", "lengthen", "tenotomy", "cast", "rhizotomy", "baclofen")


def _strings(v: object, name: str) -> tuple[str, ...]:
    if v is None or v == "":
        return ()
    if isinstance(v, str):
        return (v,)
    if isinstance(v, list) and all(isinstance(x, str) for x in v):
        return tuple(x for x in v if x)
    raise InterventionError(f"{name} must be text or a list of texts, as on the command line.")


def plan_from_fields(doc: Mapping[str, Any]) -> Plan | None:
    """The plan of a request: a ``plan`` document, or the text fields (:data:`TEXT_FIELDS`)
    and ``weeks``, as ``fieldbank whatif`` builds it; None when nothing is given."""
    weeks = doc.get("weeks")
    if weeks is not None and (isinstance(weeks, bool) or not isinstance(weeks, (int, float))):
        raise InterventionError("weeks must be a number of weeks since the injection.")
    rh, ba = (doc.get(k) for k in ("rhizotomy", "baclofen"))
    for name, v in (("rhizotomy", rh), ("baclofen", ba)):
        if v is not None and not isinstance(v, str):
            raise InterventionError(f"{name} must be text such as 'all' or 'ef,ee:0.4'.")
    if doc.get("plan") is not None:
        if any(doc.get(k) for k in TEXT_FIELDS):
            raise InterventionError("give the plan once: a plan document or the intervention "
                                    "fields, not both.")
        given = Plan.from_dict(doc["plan"], where="plan")
        return given if weeks is None else given.at_week(float(weeks))
    label = doc.get("label")
    if label is not None and not isinstance(label, str):
        raise InterventionError("label must be text.")
    plan = build_plan(plan_file=None, botox=_strings(doc.get("botox"), "botox"),
                      weeks=None if weeks is None else float(weeks),
                      lengthen=_strings(doc.get("lengthen"), "lengthen"),
                      tenotomy=_strings(doc.get("tenotomy"), "tenotomy"),
                      cast=_strings(doc.get("cast"), "cast"),
                      rhizotomy=rh or None, baclofen=ba or None)
    if plan is not None and label:
        plan = Plan(plan.steps, label=label[:200])
    return plan


def catalogue() -> dict[str, Any]:
    """What the composer offers: the muscle groups, each intervention with its unit and
    text form, the defaults with their sources."""
    return {
        "groups": [{"code": g, "name": GROUP_NAMES[g]} for g in GROUPS],
        "dose_unit": DOSE_UNIT,
        "interventions": [
            {"kind": "botulinum", "field": "botox", "unit": "U", "per_group": True,
             "text": "ef=200U,bf=100U", "max_per_group": value("botulinum.max_units_per_group"),
             "session_warning_units": value("botulinum.session_warning_units")},
            {"kind": "lengthening", "field": "lengthen", "unit": "cm", "per_group": True,
             "text": "bf=1cm"},
            {"kind": "tenotomy", "field": "tenotomy", "unit": "", "per_group": True,
             "text": "ee"},
            {"kind": "casting", "field": "cast", "unit": "mm", "per_group": True,
             "text": "ef=5mm", "default_mm": value("casting.delta_m") * 1000.0},
            {"kind": "rhizotomy", "field": "rhizotomy", "unit": "β factor", "per_group": False,
             "text": "all:0.4"},
            {"kind": "baclofen", "field": "baclofen", "unit": "β factor", "per_group": False,
             "text": "all:0.5"},
        ],
        "kinds": list(KINDS),
        "weeks_since_default": value("botulinum.weeks_since"),
        "defaults": {k: d.to_dict() for k, d in DEFAULTS.items()},
    }


def latest_model_id(db: Database, patient: str) -> int | None:
    """The model ``whatif PATIENT`` stands on (:func:`fieldbank.modelsource.latest_of_patient`:
    the latest fitted, else the latest synthetic), or None (that function says why)."""
    models = db.list_models(patient)
    for origin in ("fitted", "synthetic"):
        ids = [m.id for m in models if m.origin == origin]
        if ids:
            return max(ids)
    return None


@dataclass(eq=False)
class _Prepared:
    source: ModelSource
    arms: ArmCache
    lock: threading.Lock


class Composer:
    """What-ifs on stored models, prepared once per model (module docstring).

    Parameters
    ----------
    interval_samples : int
        Fit samples carried through each plan for the 95% intervals (``whatif``'s default).
    """

    def __init__(self, interval_samples: int = DEFAULT_INTERVAL_SAMPLES) -> None:
        self.interval_samples = interval_samples
        self._models: OrderedDict[tuple[str, int | None, int | None], _Prepared] = OrderedDict()
        self._lock = threading.Lock()

    def prepared(self, db: Database, patient: str, model_id: int | None = None) -> _Prepared:
        """The patient's latest fitted model (as ``whatif PATIENT``) or model ``model_id``,
        prepared; a model fitted since is picked up (the key is the model's id)."""
        # a stored model never changes, nor does the fit behind it: a model is resolved
        # (its fit read) once; which model "latest" means is asked each time
        wanted = model_id if model_id is not None else latest_model_id(db, patient)
        key = (patient, model_id, wanted)
        with self._lock:
            got = self._models.get(key)
        if got is None:
            if model_id is None:
                source = modelsource.latest_of_patient(db, patient)
            else:
                source = modelsource.stored(db, model_id)
                if source.patient_code != patient:
                    raise InterventionError(f"model {model_id} is not a model of patient "
                                            f"{patient}.")
            got = _Prepared(source, ArmCache(Arm.from_params(source.params), limit=MAX_ARMS),
                            threading.Lock())
            key = (patient, model_id, source.model_id)
        with self._lock:
            got = self._models.setdefault(key, got)
            self._models.move_to_end(key)
            while len(self._models) > MAX_MODELS:
                self._models.popitem(last=False)
            return got

    def whatif(self, db: Database, patient: str, plan: Plan | None, *,
               model_id: int | None = None, search: DoseSearch | None = None,
               session_limit_units: float | None = None, accept_poor_fit: bool = False,
               timecourse: bool = False) -> WhatIf:
        """:func:`run_whatif` on the prepared model (nothing is stored)."""
        p = self.prepared(db, patient, model_id)
        with p.lock:  # one computation per model at a time: the cache is filled once
            return run_whatif(p.source, plan, search=search, timecourse=timecourse,
                              session_limit_units=session_limit_units,
                              accept_poor_fit=accept_poor_fit,
                              interval_samples=self.interval_samples, arms=p.arms)

    def save(self, db: Database, patient: str, plan: Plan, *, model_id: int | None = None,
             given_on: date | None = None, accept_poor_fit: bool = False) -> SavedPlan:
        """Store the plan and its after model with lineage (as ``whatif --save``)."""
        p = self.prepared(db, patient, model_id)
        return save_plan(db, p.source, plan, given_on=given_on,
                         accept_poor_fit=accept_poor_fit)


def figure_svg(res: WhatIf) -> str:
    """The ``whatif --plot`` figures of ``res``, as SVG text."""
    g = res.guesses
    page = comparison_page(res.arm_before, res.arm_after, res.comparison, res.plan,
                           res.source.description, g.bands if g is not None else None)
    return render(page, "svg").decode("utf-8")


def whatif_document(res: WhatIf, figures: bool = True) -> dict[str, Any]:
    """The ``whatif --json`` document with what the page shows besides: the plan's label,
    the model's id and patient, and the figures."""
    doc = res.to_dict()
    doc["model"].update({"id": res.source.model_id, "patient": res.source.patient_code})
    doc["plan_label"] = plan_label(res.plan)
    if figures:
        doc["figure_svg"] = figure_svg(res)
    return doc


def groups_of(values: Sequence[object]) -> tuple[str, ...] | None:
    """Groups the optimiser may inject: None (all six) or a list of codes."""
    if not values:
        return None
    if not all(isinstance(v, str) for v in values):
        raise InterventionError("groups must be muscle group codes (sf, se, ef, ee, bf, be).")
    return tuple(str(v) for v in values)
