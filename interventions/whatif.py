"""The what-if use case: a model and a plan in, what the plan changes out.

:func:`run_whatif` is what ``fieldbank whatif`` does, in order:

1. optionally search the botulinum split closest to the unimpaired reference
   (:class:`DoseSearch`, :func:`fieldbank.interventions.inverse.optimise_botulinum`); its plan is
   the plan when none is given;
2. apply the plan with its lineage (:meth:`fieldbank.interventions.plan.Plan.derive`) and
   compare before with after on the standard conditions of the model before
   (:func:`fieldbank.evaluate.compare`; severity grades name the parameters the model's fit
   did not identify), and warn about a botulinum session above the session limit
   (:func:`fieldbank.interventions.plan.dose_warnings`);
3. say what the prediction rests on (:mod:`fieldbank.interventions.guesses`): a model from a
   poor fit is refused unless accepted; the parameters the fit did not identify are listed,
   steps that act on them warned about, and the fit's uncertainty carried through the plan as
   95% intervals of the headline metrics;
4. optionally follow the metrics week by week after the injection
   (:func:`fieldbank.interventions.course.time_course`);
5. optionally draw the figure, write ``plan.json``, ``after.json`` and ``lineage.json``, and
   store the after model and the plan with lineage (:func:`save_plan_result`; a plan that was
   carried out records its date, ``given_on``, which ``fieldbank validate`` checks against the
   maps measured after it).

One :class:`fieldbank.evaluate.ArmCache` lives for the whole use case, so each distinct model
(before, after, every week, every dose split tried, the unimpaired reference) is compiled
exactly once. Everything here is a model prediction, not treatment advice.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from datetime import date
from pathlib import Path
from typing import Any

from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.compare import (
    Comparison,
    Conditions,
    compare_evaluations,
    evaluate_arm,
)
from fieldbank.files import to_json, write_atomic
from fieldbank.interventions.course import TimeCourse, time_course
from fieldbank.interventions.defaults import value
from fieldbank.interventions.errors import InterventionError
from fieldbank.interventions.guesses import (
    FitBasis,
    Guesses,
    check_fit,
    examine,
)
from fieldbank.interventions.inverse import DoseSplitResult, optimise_botulinum
from fieldbank.interventions.plan import Derivation, Plan, dose_warnings, params_sha256
from fieldbank.interventions.plot import plot_comparison
from fieldbank.interventions.summary import WhatIfSummary, summarise
from fieldbank.interventions.whatifchoices import DEFAULT_INTERVAL_SAMPLES
from fieldbank.model import Arm
from fieldbank.modelsource import DatabaseOpener, ModelSource
from fieldbank.params import ArmParams
from fieldbank.storage import Database

#: Files ``out_dir`` receives.
OUT_FILES = ("plan.json", "after.json", "lineage.json")


@dataclass(frozen=True)
class DoseSearch:
    """A request for the inverse what-if (``--optimize``).

    Parameters
    ----------
    total_units : float, U
        Dose limit over all groups.
    groups : tuple of str, optional
        Groups the search may inject (default all six).
    weeks_since : float, weeks
        When the injection is seen.
    """

    total_units: float
    groups: tuple[str, ...] | None = None
    weeks_since: float = value("botulinum.weeks_since")


@dataclass(frozen=True)
class SavedPlan:
    """Database ids of a stored plan result: the model before, the model after, the plan."""

    base_model_id: int
    result_model_id: int
    plan_id: int

    def to_dict(self) -> dict[str, int]:
        return {"base_model_id": self.base_model_id, "result_model_id": self.result_model_id,
                "plan_id": self.plan_id}


@dataclass(frozen=True, eq=False)
class WhatIf:
    """What :func:`run_whatif` computed and wrote.

    ``plot`` and ``out_dir`` are the paths as given; ``saved`` the ids when stored.
    """

    source: ModelSource
    plan: Plan
    arm_before: Arm
    arm_after: Arm
    derivation: Derivation
    comparison: Comparison
    course: TimeCourse | None = None
    inverse: DoseSplitResult | None = None
    plot: str | None = None
    out_dir: str | None = None
    saved: SavedPlan | None = None
    #: Warnings about the plan itself (a botulinum session above the session limit).
    warnings: tuple[str, ...] = ()
    guesses: Guesses | None = None

    def all_warnings(self) -> list[str]:
        """What the prediction rests on that the reader must know (poor fit accepted, steps
        acting on guessed parameters), then warnings about the plan itself."""
        first = list(self.guesses.warnings) if self.guesses is not None else []
        return first + list(self.warnings)

    def summary(self) -> WhatIfSummary:
        """The three lines a clinician reads first (:mod:`fieldbank.interventions.summary`)."""
        return summarise(self.comparison, self.guesses, self.all_warnings())

    @property
    def before(self) -> ArmParams:
        return self.arm_before.params

    @property
    def after(self) -> ArmParams:
        return self.arm_after.params

    def to_dict(self) -> dict[str, Any]:
        """The ``whatif --json`` document (without what the command line adds)."""
        doc: dict[str, Any] = {"model": {**self.source.to_dict(),
                                         "sha256": params_sha256(self.before)},
                               "summary": self.summary().to_dict()}
        if self.inverse is not None:
            doc["inverse"] = self.inverse.to_dict()
        doc["plan"] = self.plan.to_dict()
        doc["plan_steps"] = self.plan.describe()
        doc["lineage"] = self.derivation.to_dict()
        doc["comparison"] = self.comparison.to_dict()
        if self.guesses is not None:
            doc.update(self.guesses.to_dict())
        doc["warnings"] = self.all_warnings()
        if self.course is not None:
            doc["timecourse"] = self.course.to_dict()
        if self.plot is not None:
            doc["plot"] = self.plot
        if self.out_dir is not None:
            doc["out"] = str(Path(self.out_dir))
        if self.saved is not None:
            doc["saved"] = self.saved.to_dict()
        return doc


def plan_label(plan: Plan) -> str:
    """The plan's label, else its steps described in one line (the stored label)."""
    return plan.label or "; ".join(s.describe() for s in plan.steps)


def record_extras(given_on: date | None = None,
                  accepted_poor_fit: str | None = None) -> dict[str, Any]:
    """What a stored plan records beside its lineage: the day it was carried out
    (``given_on``, ISO date; absent for a plan only explored) and an accepted poor fit."""
    extra: dict[str, Any] = {}
    if given_on is not None:
        extra["given_on"] = given_on.isoformat()
    if accepted_poor_fit:
        extra["accepted_poor_fit"] = accepted_poor_fit
    return extra


def save_plan_result(db: Database, source: ModelSource, after: ArmParams,
                     derivation: Derivation,
                     extra: Mapping[str, Any] | None = None) -> SavedPlan:
    """Store the after model (origin 'intervention', parent = the model before) and the plan
    with its lineage, in one transaction.

    A model before that is not stored yet (a parameter file, a severity) is stored first as a
    synthetic model named by ``source.description``, so the lineage always has both ends.
    ``extra`` (:func:`record_extras`) is stored in the plan's document beside the lineage.
    """
    stored = source.model_id is not None
    base_id, child, rec = db.add_plan_result(
        after, {**derivation.to_dict(), **(extra or {})}, plan_label(derivation.plan),
        patient_code=source.patient_code, base_model_id=source.model_id,
        before=None if stored else source.params, before_label=source.description)
    return SavedPlan(int(base_id), int(child.id), int(rec.id))


def save_plan(db: Database, source: ModelSource, plan: Plan, *, given_on: date | None = None,
              accept_poor_fit: bool = False) -> SavedPlan:
    """Apply ``plan`` to the model of ``source`` and store the result (:func:`save_plan_result`).

    A model from a poor fit is refused unless ``accept_poor_fit``
    (:func:`fieldbank.interventions.guesses.check_fit`); ``given_on``: the day the plan was
    carried out.
    """
    accepted = check_fit(FitBasis.of(source), accept_poor_fit)
    after, derivation = plan.derive(source.params)
    return save_plan_result(db, source, after, derivation, record_extras(given_on, accepted))


def run_whatif(source: ModelSource, plan: Plan | None, *, search: DoseSearch | None = None,
               timecourse: bool = False, plot_path: str | None = None,
               out_dir: str | None = None,
               save_to: DatabaseOpener | None = None,
               session_limit_units: float | None = None, accept_poor_fit: bool = False,
               interval_samples: int = DEFAULT_INTERVAL_SAMPLES,
               given_on: date | None = None, arms: ArmCache | None = None) -> WhatIf:
    """Apply ``plan`` (or the plan ``search`` finds) to the model of ``source`` and compare.

    Parameters
    ----------
    source : ModelSource
        The model before (:mod:`fieldbank.modelsource`).
    plan : Plan or None
        None only with ``search``, whose best split becomes the plan.
    search : DoseSearch, optional
        Run the inverse what-if as well.
    timecourse : bool
        Add the metrics week by week (the plan needs a botulinum step).
    plot_path : str, optional
        Write the before / after / difference figure here (.png or .svg).
    out_dir : str, optional
        Write :data:`OUT_FILES` into this directory.
    save_to : callable () -> Database, optional
        Store the result in this database (:func:`save_plan_result`).
    session_limit_units : float, optional
        Botulinum units (onabotulinumtoxinA) per session above which the result warns
        (default ``botulinum.session_warning_units``, 400 U).
    accept_poor_fit : bool
        Run on a model from a poor fit anyway (recorded in the result and the stored plan).
    interval_samples : int
        Fit samples carried through the plan for the intervals (0: none).
    given_on : date, optional
        With ``save_to``: the day the plan was carried out.
    arms : ArmCache, optional
        A cache that outlives the call (the workspace's composer keeps one per model): what
        depends on the model before alone - its conditions, its evaluation, the prior, the
        fit's samples and their metrics - is computed once in it, the rest as usual.
    """
    if plan is None and search is None:
        raise InterventionError("what-if: give a plan or a dose search.")
    if given_on is not None and save_to is None:
        raise InterventionError("what-if: a date the plan was given is stored with the plan; "
                                "it needs --save.")
    basis = FitBasis.of(source)
    check_fit(basis, accept_poor_fit)  # before any work or writing
    arms = arms if arms is not None else ArmCache()
    arm_b = arms(source.params)  # the model before, compiled once: every step below takes it
    cond = arms.derived(("conditions", source.params), lambda: Conditions.standard(arm_b))
    inverse = None
    if search is not None:
        inverse = optimise_botulinum(arm_b, search.total_units, search.groups,
                                     weeks_since=search.weeks_since, conditions=cond, arms=arms)
        if plan is None:
            plan = inverse.plan
    assert plan is not None
    after, derivation = plan.derive(source.params)
    arm_a = arms(after)
    unid = source.unidentified
    before_ev = arms.derived(("evaluation", cond, unid),
                             lambda: evaluate_arm(arm_b, cond, unid))
    comparison = compare_evaluations(before_ev, evaluate_arm(arm_a, cond, unid))
    guesses = examine(basis, arm_b, plan, cond, arms, accept_poor_fit=accept_poor_fit,
                      n_samples=interval_samples)
    course = time_course(arm_b, plan, conditions=cond, arms=arms) if timecourse else None
    if plot_path:
        plot_comparison(arm_b, arm_a, comparison, plan, plot_path, title=source.description,
                        bands=guesses.bands)
    if out_dir:
        d = Path(out_dir)
        write_atomic(d / "plan.json", plan.to_json() + "\n")
        write_atomic(d / "after.json", after.to_json() + "\n")
        write_atomic(d / "lineage.json", to_json(derivation) + "\n")
    res = WhatIf(source, plan, arm_b, arm_a, derivation, comparison, course, inverse,
                 plot_path or None, out_dir or None, None,
                 tuple(dose_warnings(plan, session_limit_units)), guesses)
    if save_to is not None:
        with save_to() as db:
            res = store_whatif(db, res, given_on)
    return res


def store_whatif(db: Database, res: WhatIf, given_on: date | None = None) -> WhatIf:
    """Store what ``res`` computed (:func:`save_plan_result`: the after model and the plan,
    with the day it was given and an accepted poor fit); ``res`` with the ids."""
    if given_on is not None and given_on > date.today():
        raise InterventionError(f"what-if: {given_on.isoformat()} is in the future; a plan is "
                                "recorded as given on the day it was carried out.")
    accepted = check_fit(FitBasis.of(res.source),
                         res.guesses is not None and res.guesses.accepted_poor_fit)
    saved = save_plan_result(db, res.source, res.after, res.derivation,
                             record_extras(given_on, accepted))
    return replace(res, saved=saved)
