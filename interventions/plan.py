"""Plans: ordered lists of interventions, applied to an immutable model, with lineage.

A :class:`Plan` is a tuple of catalogue interventions applied in order; ``plan.apply(params)``
returns a new :class:`fieldbank.params.ArmParams` and leaves the input as it was.
:meth:`Plan.derive` also returns a :class:`Derivation`: the parent model's SHA-256, the plan,
the child model and its SHA-256, the record the database keeps so that every "after" model
can be traced to the model and the plan it came from.

The JSON document::

    {"schema": "fieldbank.intervention-plan", "version": 1, "label": "...",
     "steps": [{"kind": "botulinum", "units": {"ef": 200}, "weeks_since": 5}, ...]}

Reading a document checks every step and reports every bad one at once, each as
``step N (kind): what is wrong``.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from fieldbank.files import JsonDocument
from fieldbank.interventions.catalogue import Botulinum, Intervention
from fieldbank.interventions.defaults import DOSE_UNIT, value
from fieldbank.interventions.errors import InterventionError
from fieldbank.params import ArmParams

PLAN_SCHEMA = "fieldbank.intervention-plan"
PLAN_VERSION = 1


def params_sha256(params: ArmParams) -> str:
    """SHA-256 of the canonical JSON of a parameter set (sorted keys, no whitespace)."""
    import hashlib  # OpenSSL: loaded when a hash is taken, not when 'plans list' reads a plan

    text = json.dumps(params.to_dict(), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


@dataclass(frozen=True)
class Plan(JsonDocument):
    """An ordered list of interventions.

    Parameters
    ----------
    steps : tuple of Intervention
    label : str
        Free text shown in reports.
    """

    document_name = "plan"
    document_error = InterventionError

    steps: tuple[Intervention, ...]
    label: str = ""

    def __post_init__(self) -> None:
        steps = tuple(self.steps)
        problems = [
            f"step {i} must be an intervention; got {type(s).__name__}"
            for i, s in enumerate(steps, 1) if not isinstance(s, Intervention)
        ]
        if not steps:
            problems.append("a plan needs at least one step")
        if problems:
            raise InterventionError("plan: " + "; ".join(problems) + ".")
        object.__setattr__(self, "steps", steps)

    # --- application ------------------------------------------------------------------------
    def apply(self, params: ArmParams) -> ArmParams:
        """The model after every step, in order; ``params`` is not changed."""
        out = params
        for i, step in enumerate(self.steps, 1):
            try:
                out = step.apply(out)
            except InterventionError as exc:
                raise InterventionError(f"step {i} ({step.kind}): {_strip_kind(exc, step)}") \
                    from None
        return out

    def derive(self, params: ArmParams) -> tuple[ArmParams, Derivation]:
        """The after model and its lineage record."""
        after = self.apply(params)
        return after, Derivation(
            parent_sha256=params_sha256(params), plan=self, child_sha256=params_sha256(after)
        )

    def at_week(self, weeks: float) -> Plan:
        """The plan seen ``weeks`` after its most recent botulinum injection.

        Every botulinum step keeps its spacing to the most recent one; other steps are
        unchanged. A plan without botulinum is returned as it is.
        """
        bots = [s for s in self.steps if isinstance(s, Botulinum)]
        if not bots:
            return self
        latest = min(s.weeks_since for s in bots)
        steps = tuple(
            s.at_week(s.weeks_since - latest + weeks) if isinstance(s, Botulinum) else s
            for s in self.steps
        )
        return Plan(steps, self.label)

    def describe(self) -> list[str]:
        return [f"{i}. {s.describe()}" for i, s in enumerate(self.steps, 1)]

    # --- JSON ---------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return {
            "schema": PLAN_SCHEMA,
            "version": PLAN_VERSION,
            "label": self.label,
            "steps": [s.to_dict() for s in self.steps],
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2)

    def sha256(self) -> str:
        import hashlib  # as in params_sha256

        text = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode("utf-8")).hexdigest()

    @classmethod
    def of(cls, *steps: Intervention, label: str = "") -> Plan:
        return cls(tuple(steps), label)

    @classmethod
    def from_dict(cls, data: Any, where: str = "plan") -> Plan:
        """Read the JSON form; every bad step is reported, each with its number and kind."""
        if isinstance(data, list):  # a bare list of steps is accepted too
            data = {"schema": PLAN_SCHEMA, "version": PLAN_VERSION, "steps": data}
        if not isinstance(data, Mapping):
            raise InterventionError(f"{where}: expected a JSON object; got {type(data).__name__}.")
        problems: list[str] = []
        if data.get("schema", PLAN_SCHEMA) != PLAN_SCHEMA:
            problems.append(f"'schema' must be {PLAN_SCHEMA!r}; got {data.get('schema')!r}")
        if data.get("version", PLAN_VERSION) != PLAN_VERSION:
            problems.append(f"'version' {data.get('version')!r} is not supported "
                            f"(this program reads version {PLAN_VERSION})")
        unknown = sorted(set(data) - {"schema", "version", "label", "steps"})
        if unknown:
            problems.append(f"unknown key(s) {', '.join(map(repr, unknown))}")
        raw_steps = data.get("steps")
        steps: list[Intervention] = []
        if not isinstance(raw_steps, list) or not raw_steps:
            problems.append("'steps' must be a non-empty list of interventions")
            raw_steps = []
        for i, raw in enumerate(raw_steps, 1):
            kind = raw.get("kind", "?") if isinstance(raw, Mapping) else "?"
            try:
                steps.append(Intervention.from_dict(raw))
            except InterventionError as exc:
                problems.append(f"step {i} ({kind}): {_strip_kind_text(str(exc), str(kind))}")
        label = data.get("label", "")
        if not isinstance(label, str):
            problems.append(f"'label' must be text; got {label!r}")
            label = ""
        if len(problems) == 1:
            raise InterventionError(f"{where}: {problems[0].rstrip('.')}.")
        if problems:
            lines = "\n".join(f"  {p.rstrip('.')}." for p in problems)
            raise InterventionError(f"{where}: {len(problems)} problems:\n{lines}")
        return cls(tuple(steps), label)



@dataclass(frozen=True)
class Derivation:
    """Lineage of an after model: which model, which plan, which result.

    Attributes
    ----------
    parent_sha256, child_sha256 : str
        :func:`params_sha256` of the model before and after.
    plan : Plan
    origin : str
        'intervention' (the storage layer's model origin for derived models).
    """

    parent_sha256: str
    plan: Plan
    child_sha256: str
    origin: str = "intervention"
    notes: tuple[str, ...] = field(default_factory=tuple)

    def to_dict(self) -> dict[str, Any]:
        return {
            "origin": self.origin,
            "parent_sha256": self.parent_sha256,
            "plan_sha256": self.plan.sha256(),
            "plan": self.plan.to_dict(),
            "child_sha256": self.child_sha256,
            "notes": list(self.notes),
        }


def _strip_kind_text(msg: str, kind: str) -> str:
    prefix = f"{kind}: "
    return msg[len(prefix):] if msg.startswith(prefix) else msg


def _strip_kind(exc: Exception, step: Intervention) -> str:
    return _strip_kind_text(str(exc), step.kind)


def botulinum_sessions(plan: Plan) -> list[tuple[float, float]]:
    """(weeks since the injection, total units) of each botulinum session of ``plan``, in
    onabotulinumtoxinA (Botox®) units: steps seen the same number of weeks after their
    injection were given on the same day and make one session."""
    totals: dict[float, float] = {}
    for s in plan.steps:
        if isinstance(s, Botulinum):
            totals[s.weeks_since] = totals.get(s.weeks_since, 0.0) + s.total_units()
    return sorted(totals.items(), reverse=True)


def dose_warnings(plan: Plan, session_limit_units: float | None = None) -> list[str]:
    """A warning for each botulinum session of ``plan`` above ``session_limit_units`` (default
    ``botulinum.session_warning_units``, 400 U: the adult upper-limb label maximum)."""
    limit = (value("botulinum.session_warning_units") if session_limit_units is None
             else float(session_limit_units))
    out = []
    for weeks, total in botulinum_sessions(plan):
        if total > limit:
            out.append(
                f"botulinum session {weeks:g} weeks before the model: {total:g} U in total "
                f"exceeds the session limit of {limit:g} U ({DOSE_UNIT}; the adult upper-limb "
                "label maximum per session is 400 U)")
    return out


def plan_of(steps: Iterable[Intervention], label: str = "") -> Plan:
    """A plan from any iterable of interventions."""
    return Plan(tuple(steps), label)
