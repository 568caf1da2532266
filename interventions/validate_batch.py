"""``fieldbank validate --scheduler``: stored plans checked against later maps on a Dask cluster.

One task per patient (plans of no patient together): on its worker, the task checks that
patient's plans through :func:`fieldbank.interventions.validate.validate_plans` - the same
entry point the command runs in one process - and stores the checks, as JSON, in its job's
payload in the database. The command's process reads them back into the same
:class:`~fieldbank.interventions.validate.PlanValidation` values (cattrs), in the order one
process would give, and reports them as it always does. A task that fails names its patient
and leaves the others' checks done.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import cattrs

from fieldbank.engine import Done, Progress, Task, run_batch
from fieldbank.interventions.validate import (
    PlanValidation,
    ValidationReport,
    check_rule_numbers,
    plans_to_check,
    validate_plans,
)
from fieldbank.interventions.whatifchoices import CHANGE_TOLERANCE, MAX_CHANGE_SE
from fieldbank.scheduler import Scheduler
from fieldbank.storage import Database

_CONVERTER = cattrs.Converter()


def validate_tasks(db: Database, patients: Sequence[str] = (),
                   plan_ids: Sequence[int] = ()) -> tuple[list[Task], list[int]]:
    """One task per patient of the plans :func:`validate_plans` would check, and those plans'
    ids in the order it would check them."""
    records = plans_to_check(db, patients, plan_ids)
    by_patient: dict[str | None, list[int]] = {}
    for r in records:
        by_patient.setdefault(r.patient_code, []).append(r.id)
    return ([Task(code or "(no patient)", code, None, {"plan_ids": ids})
             for code, ids in by_patient.items()], [r.id for r in records])


def validate_patient(db: Database, task: Task, options: Mapping[str, Any]) -> Done:
    """One task on a worker: check its plans and store the checks (module docstring)."""
    rep = validate_plans(db, plan_ids=[int(i) for i in task.params["plan_ids"]],
                         tolerance=float(options["tolerance"]), max_se=float(options["max_se"]))
    doc = [_CONVERTER.unstructure(p) for p in rep.plans]
    return Done("done", f"{len(rep.plans)} plan(s): {rep.verdict}",
                {"verdicts": {str(p.plan_id): p.verdict for p in rep.plans}},
                json.dumps(doc).encode("utf-8"))


def validate_on_cluster(db: Database, scheduler: Scheduler | str,
                        patients: Sequence[str] = (),
                        plan_ids: Sequence[int] = (), *, tolerance: float = CHANGE_TOLERANCE,
                        max_se: float = MAX_CHANGE_SE, progress: Progress | None = None,
                        say: Callable[[str], None] | None = None
                        ) -> tuple[ValidationReport, tuple[str, ...]]:
    """The report :func:`validate_plans` gives, computed on the cluster; with it, one line per
    task that failed (patient and why; those patients' plans are missing from the report)."""
    check_rule_numbers(tolerance, max_se)
    tasks, order = validate_tasks(db, patients, plan_ids)
    res = run_batch(db, "validate", tasks, validate_patient,
                    {"tolerance": tolerance, "max_se": max_se}, scheduler=scheduler,
                    progress=progress, say=say,
                    args={"patients": list(patients), "plan_ids": list(plan_ids)})
    payloads = db.job_payloads(res.run.id)
    db.clear_payloads(res.run.id)
    checked: dict[int, PlanValidation] = {}
    for t in tasks:
        if t.key in payloads:
            for d in json.loads(payloads[t.key].decode("utf-8")):
                p = _CONVERTER.structure(d, PlanValidation)
                checked[p.plan_id] = p
    plans = tuple(checked[i] for i in order if i in checked)
    return ValidationReport(plans, tolerance, max_se), tuple(o.detail for o in res.failed)
