"""Build a report: select the cases, compute them (over worker processes for batches), draw
the cohort figures, write ``report.html``, ``metrics.csv`` and ``metrics.json`` into the output
directory.

Determinism: cases are ordered by patient code and plan id, results are collected in that
order whatever the number of workers, figures carry no dates, and the page states the inputs
(title, selection, number of cases) and the time of writing (``stamp``; the command line
leaves it out only when asked, so that reruns can be byte-identical).
The database's URL is never embedded (a report travels; the URL may carry a host, a user or a
password). Text cells of ``metrics.csv`` are neutralised against formula injection
(:func:`fieldbank.sanitize.csv_cell`). The files are written together into a temporary
directory beside ``--out`` and renamed into place once all are complete
(:func:`fieldbank.files.write_directory`), so a failed run - a full disk - leaves nothing
behind and its rerun is not refused.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import os
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fieldbank.engine import progress_bar
from fieldbank.errors import FileRefused
from fieldbank.figures import svg
from fieldbank.files import DISK_FULL_ERRNOS, disk_full_message, write_directory
from fieldbank.interventions.errors import SelectionError
from fieldbank.interventions.report.compute import ALL_COLUMNS, CaseResult, compute_case
from fieldbank.interventions.report.figures.cohort import (
    CohortPoint,
    cohort_change_figure,
    validation_figure,
)
from fieldbank.interventions.report.html import case_stretches, render
from fieldbank.interventions.report.remote import compute_on_cluster
from fieldbank.interventions.report.select import CaseSpec, Selection, select_cases
from fieldbank.interventions.report.trust import (
    TRUST_COLUMNS,
    keep_intervals,
    with_known_intervals,
)
from fieldbank.sanitize import csv_cell
from fieldbank.scheduler import Scheduler
from fieldbank.storage import Database

SCHEMA = "fieldbank.report"
VERSION = 1
#: Below this many cases per worker a process pool costs more than it saves (measured with
#: benchmarks/bench_report.py: starting a worker and shipping results ≈ 0.1 s).
MIN_CASES_PER_JOB = 2
FILES = ("report.html", "metrics.csv", "metrics.json")
#: Columns of metrics.csv and metrics.json: the metrics, then what they rest on and the check.
TABLE_COLUMNS = ALL_COLUMNS + TRUST_COLUMNS


@dataclass(frozen=True)
class ReportOutput:
    out_dir: Path
    html: Path
    csv: Path
    json: Path
    n_cases: int
    #: Local worker processes used (0: computed on a Dask cluster).
    jobs_used: int


def compute_all(cases: list[CaseSpec], jobs: int,
                wrap: Callable[[Iterable[CaseResult], int], Iterable[CaseResult]] | None = None
                ) -> tuple[list[CaseResult], int]:
    """Compute every case, in order; returns the results and the number of processes used."""
    jobs = max(1, min(jobs, len(cases) // MIN_CASES_PER_JOB or 1))
    it: Iterator[CaseResult]
    if jobs == 1:
        it = map(compute_case, cases)
        return list(wrap(it, len(cases)) if wrap else it), 1
    chunk = max(1, len(cases) // (jobs * 8))
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        # the workers send back what they computed, not the case (its models, plan and later
        # maps): the parent has it already
        parts = pool.map(_computed, cases, chunksize=chunk)
        it = (dataclasses.replace(p, spec=c) for c, p in zip(cases, parts, strict=True))
        return list(wrap(it, len(cases)) if wrap else it), jobs


def _computed(spec: CaseSpec) -> CaseResult:
    """:func:`compute_case` in a worker, its result without the case spec."""
    return dataclasses.replace(compute_case(spec), spec=_NO_SPEC)


#: Stands in for the case spec in a worker's result (the parent puts the real one back).
_NO_SPEC: Any = None


def metrics_csv(results: Iterable[CaseResult]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([k for k, _ in TABLE_COLUMNS])
    for r in results:
        w.writerow(["" if r.row.get(k) is None else repr(r.row[k])
                    if isinstance(r.row[k], float) else csv_cell(r.row[k])
                    for k, _ in TABLE_COLUMNS])
    return buf.getvalue()


def metrics_json(results: Iterable[CaseResult], inputs: dict[str, Any]) -> str:
    doc = {"schema": SCHEMA, "version": VERSION, "inputs": inputs,
           "columns": [k for k, _ in TABLE_COLUMNS],
           "cases": [{"metrics": r.row, **r.detail} for r in results]}
    return json.dumps(doc, indent=1, ensure_ascii=False, allow_nan=False) + "\n"


def cohort_points(results: Iterable[CaseResult]) -> list[CohortPoint]:
    """Per case and treated group: the change (%) of the peak torque resisting the fast and
    the slow stretch the group is graded on."""
    out = []
    for r in results:
        row = r.row
        kinds = "+".join(r.spec.kinds) or "plan"
        for g in str(row.get("treated_groups") or "").split():
            (j, d), = case_stretches({"treated_groups": g})
            vals = [row.get(f"{j}_{d}_{stem}_{when}") for stem in ("fast_n_m", "slow_n_m")
                    for when in ("before", "after")]
            if not all(isinstance(v, float) for v in vals):
                continue
            fb, fa, sb, sa = (float(v) for v in vals)  # type: ignore[arg-type]
            if fb <= 0 or sb <= 0:
                continue
            out.append(CohortPoint(f"{kinds} · {g}",
                                   f"{r.spec.patient_code or '-'} plan {r.spec.plan_id}",
                                   100.0 * (fa - fb) / fb, 100.0 * (sa - sb) / sb))
    return out


def cohort_figures(results: list[CaseResult]) -> list[tuple[str, str, str]]:
    """The summary's figures (key, caption, SVG) of a batch of two or more cases: the change
    per kind and treated group, and the predictions checked against later maps."""
    if len(results) < 2:
        return []
    out = []
    points = cohort_points(results)
    if points:
        out.append(("cohort-change",
                    "Change per intervention kind and treated muscle group: the peak torque "
                    "resisting the fast stretch (velocity-dependent: spasticity) and the slow "
                    "stretch (position-dependent: contracture) of the stretch each treated "
                    "group is graded on, after against before; one dot per case and group, "
                    "bar: median.",
                    svg.write(cohort_change_figure(points), "cohort1")))
    checks = [c for r in results for c in r.checks]
    if checks:
        n = len({c.case for c in checks})
        out.append(("cohort-validation",
                    f"Predictions checked against maps measured after the plan ({n} plan"
                    f"{'s' if n != 1 else ''}): per map, the RMS of the measured change against "
                    "the RMS of the predicted change (on the dashed identity line the change "
                    "came as predicted), and the measured change along the predicted one "
                    "(realised fraction, ±1 SE) against the check's tolerance.",
                    svg.write(validation_figure(checks, "Predicted against measured change, "
                                                "across patients"), "cohort2")))
    return out


def checked_cases(db: Database, selection: Selection, accept_poor_fit: bool = False,
                  checks: bool = True) -> list[CaseSpec]:
    """The selected cases (``checks``: :func:`select_cases`); SelectionError for none, and for
    a case whose model comes from a poor fit unless ``accept_poor_fit`` (then each case
    records it)."""
    cases = select_cases(db, selection, checks)
    poor = [c for c in cases if (c.fit_report or {}).get("status") == "poor"]
    if poor and not accept_poor_fit:
        raise SelectionError(
            "the model before of " + ", ".join(f"plan {c.plan_id} ({c.patient_code})"
                                               for c in poor)
            + " comes from a poor fit; its predictions would not describe the patient. "
            "Narrow the selection, refit, or give --accept-poor-fit (recorded in the report).")
    if accept_poor_fit:
        cases = [dataclasses.replace(c, accept_poor_fit=True) for c in cases]
    return cases


def report_page(db: Database, selection: Selection, stamp: str | None = None) -> str:
    """The report's page (``report.html``) of ``selection``, computed in this process and
    returned as text, not written (the workspace's download of a patient's report); the
    intervals are read from, and kept with, the fits as :func:`build_report` does."""
    cases = with_known_intervals(db, checked_cases(db, selection))
    results, _ = compute_all(cases, 1)
    keep_intervals(db, cases, [r.intervals for r in results])
    return render(results, page_inputs(cases, selection, None, stamp), cohort_figures(results))


def page_inputs(cases: list[CaseSpec], selection: Selection, title: str | None,
                stamp: str | None) -> dict[str, Any]:
    """What the page states it was made from: title, selection, cases, when (``stamp``)."""
    if title is None:
        title = (f"fieldbank report: {cases[0].title}" if len(cases) == 1 else
                 f"fieldbank report: {len(cases)} cases")
    inputs: dict[str, Any] = {"title": title, "selection": selection.describe(),
                              "cases": len(cases)}
    if stamp:
        inputs["generated"] = stamp
    return inputs


def build_report(db: Database, selection: Selection, out_dir: str | Path, jobs: int = 1,
                 progress: bool = False, stamp: str | None = None,
                 title: str | None = None, accept_poor_fit: bool = False,
                 force: bool = False, scheduler: Scheduler | str | None = None,
                 say: Callable[[str], None] | None = None) -> ReportOutput:
    """Select, compute and write the report; raises SelectionError for an empty selection,
    and for cases whose model comes from a poor fit unless ``accept_poor_fit`` (then each such
    case records it); FileRefused when ``out_dir`` already holds report files, unless
    ``force`` (checked first: nothing is computed for a report that would be refused). With
    ``scheduler`` the cases are computed on that Dask cluster
    (:mod:`~fieldbank.interventions.report.remote`), else in ``jobs`` local processes; the
    files are the same bytes either way."""
    there = [f for f in FILES if os.path.lexists(Path(out_dir) / f)]
    if there and not force:
        raise FileRefused(f"{out_dir} already holds a report ({', '.join(there)}); give --force "
                          "to replace it, or choose another --out.")
    cases = checked_cases(db, selection, accept_poor_fit, checks=not scheduler)
    wrap = None
    if progress:
        from tqdm import tqdm

        def wrap(it: Iterable[CaseResult], n: int) -> Iterable[CaseResult]:
            return tqdm(it, total=n, unit="case", desc="report", leave=False, disable=None)

    if scheduler:
        results = compute_on_cluster(db, cases, scheduler, accept_poor_fit=accept_poor_fit,
                                     progress=progress_bar("report") if progress else None,
                                     say=say)
        used = 0
    else:
        cases = with_known_intervals(db, cases)
        results, used = compute_all(cases, jobs, wrap)
        keep_intervals(db, cases, [r.intervals for r in results])
    inputs = page_inputs(cases, selection, title, stamp)
    out = Path(out_dir)
    paths = [out / f for f in FILES]
    json_inputs = {**inputs, "selection": selection.to_dict()}
    files = {FILES[1]: metrics_csv(results), FILES[2]: metrics_json(results, json_inputs),
             FILES[0]: render(results, inputs, cohort_figures(results))}
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        write_directory(out, files)
    except OSError as exc:
        if exc.errno in DISK_FULL_ERRNOS:
            raise FileRefused(disk_full_message(out, exc)) from None
        raise FileRefused(f"cannot write the report into {out}: {exc.strerror or exc}; "
                          "nothing was written.") from None
    return ReportOutput(out, paths[0], paths[1], paths[2], len(cases), used)
