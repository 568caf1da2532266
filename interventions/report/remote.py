"""A report's cases computed on a Dask cluster (``fieldbank report --scheduler``).

The cases are split into tasks of a few plans each (:data:`CASES_PER_TASK`, at least
:data:`MIN_TASKS` tasks while there are cases for them). A task runs on a
worker (:func:`report_cases`): it selects its plans from the database itself (the same
:func:`~fieldbank.interventions.report.select.select_cases` the report's own process ran),
computes each case, keeps newly computed prediction intervals with their fits, and writes the
cases - metrics row, JSON detail, figures as SVG text, the checks against later maps - as one
JSON document into its job's payload. Nothing but a line of status goes back through the
scheduler. The report's process reads the payloads back (:func:`compute_on_cluster`) and writes
the files exactly as one process would: JSON keeps every number to the last bit, so the files
are the same bytes.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Mapping
from typing import Any

import cattrs

from fieldbank.engine import Done, Progress, Task, run_batch
from fieldbank.interventions.errors import InterventionError
from fieldbank.interventions.report.compute import CaseResult, Figure, compute_case
from fieldbank.interventions.report.figures.cohort import CheckPoint
from fieldbank.interventions.report.select import CaseSpec, Selection, select_cases
from fieldbank.interventions.report.trust import keep_intervals, with_known_intervals
from fieldbank.scheduler import Scheduler
from fieldbank.storage import Database

#: Most plans per task: a task's own cost - its job's marks, its selection (a few queries
#: whatever its number of plans), reading the kept intervals, writing its payload - is paid
#: once for all its cases (≈ 0.1 s each), and a cohort still spreads over the workers.
CASES_PER_TASK = 8
#: A report is cut into at least this many tasks while it has cases for them (a small report
#: still spreads over several workers; below that, tasks of fewer cases).
MIN_TASKS = 8


def report_tasks(cases: list[CaseSpec], per_task: int = CASES_PER_TASK) -> list[Task]:
    """Tasks of up to ``per_task`` consecutive cases (cases are ordered by patient); fewer per
    task for a small report, so that its cases still spread over :data:`MIN_TASKS` tasks."""
    per_task = max(1, min(per_task, -(-len(cases) // MIN_TASKS)))
    tasks = []
    for k in range(0, len(cases), per_task):
        part = cases[k:k + per_task]
        codes = sorted({c.patient_code or "-" for c in part})
        tasks.append(Task(f"plans {', '.join(str(c.plan_id) for c in part)}",
                          _whose(codes), None, {"plan_ids": [c.plan_id for c in part]}))
    return tasks


#: Longest name of a task's patients (the job record keeps up to 64 characters).
WHOSE_MAX = 64


def _whose(codes: list[str]) -> str:
    """A task's patients in at most :data:`WHOSE_MAX` characters: their codes, else the first
    and how many more, else how many (the job's key names its plans)."""
    for text in (", ".join(codes), f"{codes[0]} and {len(codes) - 1} more",
                 f"{len(codes)} patients"):
        if len(text) <= WHOSE_MAX:
            return text
    return f"{len(codes)} patients"


def report_cases(db: Database, task: Task, options: Mapping[str, Any]) -> Done:
    """One task on a worker: select, compute and store its cases (module docstring)."""
    ids = tuple(int(i) for i in task.params["plan_ids"])
    cases = select_cases(db, Selection(plan_ids=ids))
    if options.get("accept_poor_fit"):
        cases = [dataclasses.replace(c, accept_poor_fit=True) for c in cases]
    cases = with_known_intervals(db, cases)
    results = [compute_case(c) for c in cases]
    kept = keep_intervals(db, cases, [r.intervals for r in results])
    doc = [_case_doc(r) for r in results]
    return Done("done", f"{len(results)} case(s), {kept} interval set(s) kept",
                {"plan_ids": list(ids)},
                json.dumps(doc, ensure_ascii=False).encode("utf-8"))


def compute_on_cluster(db: Database, cases: list[CaseSpec], scheduler: Scheduler | str, *,
                       accept_poor_fit: bool = False, progress: Progress | None = None,
                       say: Callable[[str], None] | None = None) -> list[CaseResult]:
    """Every case computed on the cluster, in order, read back from the database.

    Raises
    ------
    InterventionError
        A task failed (the message names its patients and plans and why); the run's
        other tasks are done and ``fieldbank jobs RUN`` lists them.
    """
    tasks = report_tasks(cases)
    res = run_batch(db, "report", tasks, report_cases, {"accept_poor_fit": accept_poor_fit},
                    scheduler=scheduler, progress=progress, say=say,
                    args={"plans": [c.plan_id for c in cases]})
    if res.failed:
        raise InterventionError(
            f"report: {len(res.failed)} of {len(tasks)} task(s) failed (run {res.run.id}; "
            "'fieldbank jobs " + str(res.run.id) + "' lists them): "
            + "; ".join(o.detail for o in res.failed))
    by_plan: dict[int, dict[str, Any]] = {}
    for payload in db.job_payloads(res.run.id).values():
        for d in json.loads(payload.decode("utf-8")):
            by_plan[int(d["plan_id"])] = d
    db.clear_payloads(res.run.id)
    missing = [c.plan_id for c in cases if c.plan_id not in by_plan]
    if missing:
        raise InterventionError(f"report: run {res.run.id} stored no result for plans "
                                f"{missing}; run the report again.")
    return [_case_result(c, by_plan[c.plan_id]) for c in cases]


#: Frozen dataclasses to plain JSON values and back (cattrs).
_CONVERTER = cattrs.Converter()


def _case_doc(r: CaseResult) -> dict[str, Any]:
    return {"plan_id": r.spec.plan_id, "row": r.row, "detail": r.detail,
            "figures": _CONVERTER.unstructure(r.figures),
            "checks": _CONVERTER.unstructure(r.checks)}


def _case_result(spec: CaseSpec, d: Mapping[str, Any]) -> CaseResult:
    return CaseResult(spec, dict(d["row"]), dict(d["detail"]),
                      _CONVERTER.structure(d["figures"], tuple[Figure, ...]),
                      _CONVERTER.structure(d["checks"], tuple[CheckPoint, ...]))
