"""The plan composer's routes in the workspace (a :class:`fieldbank.web.routes.RouteProvider`).

The catalogue, the what-if as a dose changes (:class:`~fieldbank.interventions.composer.
Composer`: the numbers of ``fieldbank whatif``), the dose optimiser, saving a plan and marking
it given, a patient's plans with what they rest on and how they were checked, validation
against the maps measured later - and "Feel it": the pair pushed to the robot through the
:class:`~fieldbank.web.robot.RobotSeam` the command line hands in (this package never imports
the haptic wing). Every read of a patient's plans is recorded; every write is audited as the
logged-in account.
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import UTC, date, datetime
from typing import Any

from aiohttp import web

from fieldbank.interventions.composer import (
    Composer,
    catalogue,
    groups_of,
    plan_from_fields,
    whatif_document,
)
from fieldbank.interventions.defaults import value
from fieldbank.interventions.errors import InterventionError
from fieldbank.interventions.plandetail import show_plan
from fieldbank.interventions.plans import give_plan, list_plans
from fieldbank.interventions.report.build import report_page
from fieldbank.interventions.report.select import Selection
from fieldbank.interventions.validate import validate_plans
from fieldbank.interventions.whatif import DoseSearch, plan_label
from fieldbank.sanitize import file_component
from fieldbank.storage import Database
from fieldbank.web.robot import FeelPair, RobotSeam
from fieldbank.web.routes import ApiError, Asset, Call, Param, Route, need, optional

PLAN_FIELDS = {
    "patient": {"type": "string"},
    "model_id": {"type": ["integer", "null"], "description": "default: the latest fitted"},
    "botox": {"type": "string", "examples": ["ef=200U,bf=100U"]},
    "weeks": {"type": "number", "description": "weeks since the injection (default 5)"},
    "lengthen": {"type": "string", "examples": ["bf=1cm"]},
    "tenotomy": {"type": "array", "items": {"type": "string"}},
    "cast": {"type": "array", "items": {"type": "string"}, "examples": [["ef=5mm"]]},
    "rhizotomy": {"type": "string", "examples": ["all:0.4"]},
    "baclofen": {"type": "string", "examples": ["ef,ee:0.5"]},
    "plan": {"type": "object", "description": "a plan document instead of the fields"},
    "label": {"type": "string"},
    "session_limit": {"type": "number", "description": "U per session before a warning"},
    "accept_poor_fit": {"type": "boolean"},
}
PLAN_BODY = {"type": "object", "required": ["patient"], "properties": PLAN_FIELDS}


def _given_on(text: object) -> date | None:
    if text is None:
        return None
    if not isinstance(text, str):
        raise ApiError(400, "given_on must be a date, YYYY-MM-DD")
    try:
        return date.fromisoformat(text)
    except ValueError:
        raise ApiError(400, f"given_on must be a date, YYYY-MM-DD; got {text!r}") from None


def patient_plans(db: Database, code: str) -> list[dict[str, Any]]:
    """The patient's plans, oldest first, each with what it rests on (warnings, guesses, the
    fit) and, for a plan that was given, how it was checked against the later maps."""
    out = [show_plan(db, p.id).to_dict() for p in list_plans(db, code)]
    if any(p["given_on"] for p in out):
        checks = {c.plan_id: c.to_dict() for c in validate_plans(db, [code]).plans}
        for p in out:
            p["check"] = checks.get(p["id"])
    return out


def plans_key(db: Database, code: str) -> tuple[Any, ...]:
    """Everything :func:`patient_plans` depends on that can change: the plans and the days
    they were given, the patient's maps and models (a fit stores a model). Stored records
    are otherwise never changed, so the same key means the same answer."""
    return (tuple((p.id, p.spec.get("given_on")) for p in db.list_plans(code)),
            tuple(m.id for m in db.list_maps(code)), tuple(m.id for m in db.list_models(code)))


class ComposerRoutes:
    """The composer's routes; ``robot``: where "Feel it" pushes (None: no robot here)."""

    name = "composer"

    def __init__(self, composer: Composer | None = None, robot: RobotSeam | None = None) -> None:
        self.composer = composer or Composer()
        self.robot = robot
        #: a patient's plans with their checks, by patient: (plans_key, answer)
        self._plans: dict[str, tuple[tuple[Any, ...], list[dict[str, Any]]]] = {}

    def assets(self) -> Sequence[Asset]:
        return (Asset("fieldbank.interventions", "composer.js", "script"),)

    def routes(self) -> Sequence[Route]:
        t = ("plans",)
        plan_id = Param("id", type="integer", description="plan id")
        return [
            Route("GET", "/api/catalogue", self.catalogue, "read",
                  "The interventions with their units, the muscle groups, the defaults and "
                  "their sources", tags=t),
            Route("POST", "/api/whatif", self.whatif, "read",
                  "What-if: the plan applied to the patient's model - summary, grades, "
                  "warnings, 95% intervals, figures (SVG): the numbers of 'fieldbank whatif'",
                  body=PLAN_BODY, tags=t),
            Route("POST", "/api/whatif/optimise", self.optimise, "plan",
                  "The botulinum split closest to unimpaired within a dose limit (as "
                  "'whatif --optimize'), with its what-if",
                  body={"type": "object", "required": ["patient", "total_units"],
                        "properties": {"patient": {"type": "string"},
                                       "model_id": {"type": ["integer", "null"]},
                                       "total_units": {"type": "number"},
                                       "groups": {"type": "array", "items": {"type": "string"}},
                                       "weeks": {"type": "number"}}}, tags=t),
            Route("POST", "/api/whatif/feel", self.feel, "robot",
                  "Feel it: push before (A) and after (B) to the robot's renderer (a "
                  "simulated robot when none is configured); answers the robot view's path",
                  body={**PLAN_BODY, "properties": {**PLAN_FIELDS, "plan_id": {
                      "type": "integer", "description": "the stored plan, when saved"}}},
                  tags=("robot",)),
            Route("POST", "/api/plans", self.save, "plan",
                  "Save the plan with its after model and lineage (as 'whatif --save')",
                  body={**PLAN_BODY, "properties": {**PLAN_FIELDS, "given_on": {
                      "type": "string", "format": "date"}}}, tags=t),
            Route("GET", "/api/plans/{id}", self.plan, "read",
                  "One stored plan with its lineage and what it rests on (as 'plans show')",
                  (plan_id,), tags=t),
            Route("POST", "/api/plans/{id}/give", self.give, "plan",
                  "Record the day a stored plan was given (as 'plans give')", (plan_id,),
                  body={"type": "object", "required": ["on"],
                        "properties": {"on": {"type": "string", "format": "date"}}}, tags=t),
            Route("GET", "/api/patients/{code}/plans", self.plans, "read",
                  "A patient's plans: given or not, what each rests on, how a given one was "
                  "checked against later maps (recorded as a read)",
                  (Param("code", description="patient code"),), tags=t),
            Route("GET", "/api/patients/{code}/report.html", self.report, "read",
                  "The report of a patient's plans (the page 'fieldbank report --patient' "
                  "writes), as a file to keep (recorded as a read)",
                  (Param("code", description="patient code"),),
                  response={"type": "string", "format": "html"}, tags=t),
            Route("POST", "/api/validate", self.validate, "read",
                  "Stored plans that were given, checked against the maps measured after "
                  "them (as 'fieldbank validate')",
                  body={"type": "object", "properties": {
                      "patients": {"type": "array", "items": {"type": "string"}},
                      "plans": {"type": "array", "items": {"type": "integer"}}}}, tags=t),
        ]

    async def catalogue(self, call: Call) -> Any:
        return catalogue()

    async def _plan_and_model(self, call: Call) -> tuple[dict[str, Any], str, int | None]:
        body = await call.json()
        patient = need(body, "patient", str)
        return body, patient, optional(body, "model_id", int)

    async def whatif(self, call: Call) -> Any:
        body, patient, model_id = await self._plan_and_model(call)
        limit = optional(body, "session_limit", (int, float))
        accept = bool(optional(body, "accept_poor_fit", bool, False))

        def work() -> dict[str, Any]:
            plan = plan_from_fields(body)
            if plan is None:
                raise InterventionError(
                    "No intervention given: use --botox, --lengthen, --tenotomy, --cast, "
                    "--rhizotomy, --baclofen, --plan or --optimize.")
            res = self.composer.whatif(call.db, patient, plan, model_id=model_id,
                                       session_limit_units=limit, accept_poor_fit=accept)
            call.record_read(patient, f"what-ifs on model {res.source.model_id} (first: "
                                      f"{plan_label(res.plan)})",
                             once=f"what-if {res.source.model_id}")
            return whatif_document(res)

        return await call.run(work)

    async def optimise(self, call: Call) -> Any:
        body, patient, model_id = await self._plan_and_model(call)
        total = need(body, "total_units", (int, float), "the dose limit, U")
        weeks = optional(body, "weeks", (int, float))
        groups = groups_of(optional(body, "groups", list, []))

        def work() -> dict[str, Any]:
            search = DoseSearch(float(total), groups,
                                value("botulinum.weeks_since") if weeks is None else weeks)
            res = self.composer.whatif(call.db, patient, None, model_id=model_id,
                                       search=search)
            call.record_read(patient, f"dose search on model {res.source.model_id}")
            return whatif_document(res)

        return await call.run(work)

    async def save(self, call: Call) -> Any:
        body, patient, model_id = await self._plan_and_model(call)
        given = _given_on(body.get("given_on"))
        accept = bool(optional(body, "accept_poor_fit", bool, False))

        def work() -> dict[str, Any]:
            plan = plan_from_fields(body)
            if plan is None:
                raise InterventionError("No intervention given: nothing to save.")
            saved = self.composer.save(call.db, patient, plan, model_id=model_id,
                                       given_on=given, accept_poor_fit=accept)
            return {**saved.to_dict(), "label": plan_label(plan)}

        return await call.run(work)

    async def plan(self, call: Call) -> Any:
        pid = call.match_int("id")

        def work() -> dict[str, Any]:
            d = show_plan(call.db, pid).to_dict()
            if d.get("patient"):
                call.record_read(d["patient"], f"plan {pid}")
            return d

        return await call.run(work)

    async def give(self, call: Call) -> Any:
        pid = call.match_int("id")
        body = await call.json()
        on = _given_on(need(body, "on", str, "the day the plan was given"))
        assert on is not None
        if on > date.today():
            raise ApiError(400, f"the day a plan was given cannot be in the future; got "
                                f"{on.isoformat()}")
        p, changed = await call.run(lambda: give_plan(call.db, pid, on))
        return {**p.to_dict(), "changed": changed}

    async def plans(self, call: Call) -> Any:
        code = call.match("code")

        def work() -> dict[str, Any]:
            call.db.get_patient(code)  # an unknown patient: the usual error
            key = plans_key(call.db, code)
            known = self._plans.get(code)
            out = known[1] if known is not None and known[0] == key else None
            if out is None:  # validation is the slow part: done again only when data changed
                out = patient_plans(call.db, code)
                if len(self._plans) > 256:
                    self._plans.clear()
                self._plans[code] = (key, out)
            call.record_read(code, "plans and their checks")
            return {"plans": out}

        return await call.run(work)

    async def report(self, call: Call) -> web.StreamResponse:
        code = call.match("code")

        def work() -> str:
            call.db.get_patient(code)
            page = report_page(call.db, Selection(patients=(code,)),
                               stamp=datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"))
            call.record_read(code, "report of its plans")
            return page

        page = await call.run(work)
        resp = web.Response(text=page, content_type="text/html")
        # a file to keep and print: downloaded, never run inside the workspace's origin
        resp.headers["Content-Disposition"] = (
            f'attachment; filename="report-{file_component(code)}.html"')
        return resp

    async def validate(self, call: Call) -> Any:
        body = await call.json()
        patients = optional(body, "patients", list, [])
        ids = optional(body, "plans", list, [])
        if not all(isinstance(p, str) for p in patients) or not all(
                isinstance(i, int) and not isinstance(i, bool) for i in ids):
            raise ApiError(400, "patients must be codes and plans ids")

        def work() -> dict[str, Any]:
            report = validate_plans(call.db, patients, ids)
            for code in {p.patient for p in report.plans if p.patient}:
                call.record_read(code, "validation of its given plans")
            return report.to_dict()

        return await call.run(work)

    async def feel(self, call: Call) -> Any:
        robot = self.robot
        if robot is None:
            raise ApiError(503, "this workspace was started without a robot")
        body, patient, model_id = await self._plan_and_model(call)
        plan_id = optional(body, "plan_id", int)
        actor = call.user.name

        def work() -> dict[str, Any]:
            plan = plan_from_fields(body)
            if plan is None:
                raise InterventionError("No intervention given: nothing to feel.")
            p = self.composer.prepared(call.db, patient, model_id)
            after, _ = plan.derive(p.source.params)
            after_id = None
            if plan_id is not None:
                rec = call.db.get_plan(plan_id)
                if rec.base_model_id != p.source.model_id or rec.patient_code != patient:
                    raise InterventionError(f"plan {plan_id} was not made on this model.")
                after_id = rec.result_model_id
            text = plan_label(plan)
            pair = FeelPair(p.source.params, after, (p.source.model_id, after_id), patient,
                            (p.source.description, f"what-if result on "
                             f"{p.source.description}"), text, plan_id, actor)
            return robot.feel(pair)

        return await call.run(work)

