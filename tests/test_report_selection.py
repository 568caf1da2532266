"""The report's selection reads a cohort set-based: the same cases, the same report bytes as
reading each record on its own, in a number of queries that does not grow with the cohort."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import event

from fieldbank.interventions.report import Selection, build_report, select_cases
from fieldbank.interventions.report import select as select_module
from fieldbank.interventions.report.trust import interval_key_of
from fieldbank.storage import Database
from tests.report_helpers import build_batch

FILES = ("report.html", "metrics.csv", "metrics.json")


@pytest.fixture(scope="module")
def batch(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    return build_batch(tmp_path_factory.mktemp("report-select"))


@contextmanager
def counted(db: Database) -> Iterator[list[str]]:
    """The SQL statements ``db`` runs inside the block."""
    seen: list[str] = []

    def note(conn: Any, cursor: Any, statement: str, *args: Any) -> None:
        seen.append(statement)

    event.listen(db.engine, "before_cursor_execute", note)
    try:
        yield seen
    finally:
        event.remove(db.engine, "before_cursor_execute", note)


def _record_by_record(monkeypatch: pytest.MonkeyPatch) -> None:
    """The old path: nothing read ahead, every record asked of the database on its own."""
    monkeypatch.setattr(select_module._CohortReads, "read_records", lambda self, plans: None)
    monkeypatch.setattr(select_module._CohortReads, "read_checks", lambda self, plans: None)


def test_the_report_is_the_same_bytes_read_set_based_or_record_by_record(
        batch: dict[str, Any], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with Database.open(batch["url"]) as db:
        with counted(db) as fast:
            build_report(db, Selection(), tmp_path / "set-based")
        with monkeypatch.context() as m:
            _record_by_record(m)
            with counted(db) as slow:
                build_report(db, Selection(), tmp_path / "by-record")
    for name in FILES:
        assert ((tmp_path / "set-based" / name).read_bytes()
                == (tmp_path / "by-record" / name).read_bytes()), name
    # the checks against later maps are in the bytes compared
    assert b'"validation"' in (tmp_path / "set-based" / "metrics.json").read_bytes()
    assert len(fast) < len(slow)


def test_the_selection_asks_as_many_queries_for_one_plan_as_for_the_cohort(
        batch: dict[str, Any]) -> None:
    with Database.open(batch["url"]) as db:
        every = select_cases(db, Selection())
        assert len(every) >= 3
        with counted(db) as one:
            select_cases(db, Selection(plan_ids=(every[0].plan_id,)))
        with counted(db) as all_:
            select_cases(db, Selection(plan_ids=tuple(c.plan_id for c in every)))
        with counted(db) as listed:
            select_cases(db, Selection())
    assert len(all_) == len(one)
    assert len(listed) == len(one)


def test_the_set_based_reads_return_what_the_record_reads_return(
        batch: dict[str, Any], tmp_path: Path) -> None:
    with Database.open(batch["url"]) as db:
        build_report(db, Selection(), tmp_path / "keeps-intervals")
        codes = [p.code for p in db.list_patients()]
        plans = db.list_plans()
        assert db.get_plans([p.id for p in plans][::-1]) == plans[::-1]
        assert db.patients_by_code([*codes, "NOBODY"]) == {c: db.get_patient(c) for c in codes}
        assert db.fits_of(codes) == {c: db.list_fits(c) for c in codes}
        assert any(db.fits_of(codes).values())
        assert db.maps_of(codes) == [m for c in sorted(codes) for m in db.list_maps(c)]
        assert db.sessions_of(codes) == db.list_sessions()
        models = db.list_models()
        assert db.get_models([m.id for m in models] + [10**6]) == {
            m.id: db.get_model(m.id) for m in models}
        maps = db.list_maps()
        got = db.maps_by_id([m.id for m in maps] + [10**6])
        assert sorted(got) == sorted(m.id for m in maps)
        for m, fm in zip(maps, db.get_maps([m.id for m in maps]), strict=True):
            assert got[m.id].kind == fm.kind
            assert (got[m.id].values == fm.values).all()
            assert (got[m.id].positions_m == fm.positions_m).all()
        keys = [k for c in select_cases(db, Selection()) if (k := interval_key_of(c))]
        assert keys
        kept = db.fit_documents(keys)
        assert kept
        assert kept == {k: d for k in keys if (d := db.fit_document(*k)) is not None}


def test_an_unknown_plan_is_named_as_before(batch: dict[str, Any]) -> None:
    from fieldbank.errors import StorageError

    with Database.open(batch["url"]) as db:
        plan = db.list_plans()[0].id
        with pytest.raises(StorageError, match="No plan with id 999999"):
            select_cases(db, Selection(plan_ids=(plan, 999999)))


@pytest.mark.parametrize(("n", "sizes"), [(1, [1]), (5, [1] * 5), (20, [3] * 6 + [2]),
                                          (64, [8] * 8), (100, [8] * 12 + [4])])
def test_a_cluster_report_is_cut_into_tasks_of_up_to_eight_plans(n: int,
                                                                 sizes: list[int]) -> None:
    from types import SimpleNamespace
    from typing import cast

    from fieldbank.interventions.report.remote import report_tasks
    from fieldbank.interventions.report.select import CaseSpec

    cases = [cast(CaseSpec, SimpleNamespace(plan_id=i + 1, patient_code=f"P{i // 2:03d}"))
             for i in range(n)]
    tasks = report_tasks(cases)
    assert [len(t.params["plan_ids"]) for t in tasks] == sizes
    assert [i for t in tasks for i in t.params["plan_ids"]] == list(range(1, n + 1))


@pytest.mark.parametrize(("codes", "whose"), [
    (["P1"], "P1"), (["P1", "P2"], "P1, P2"),
    ([f"FIT-C{i:04d}" for i in range(8)], "FIT-C0000 and 7 more"),
    (["A" * 64, "B" * 64], "2 patients")])
def test_a_task_names_its_patients_within_what_its_job_record_keeps(
        codes: list[str], whose: str) -> None:
    from types import SimpleNamespace
    from typing import cast

    from fieldbank.interventions.report.remote import WHOSE_MAX, _whose, report_tasks
    from fieldbank.interventions.report.select import CaseSpec

    assert _whose(codes) == whose
    # a cohort of one plan per patient: eight patients to a task
    cases = [cast(CaseSpec, SimpleNamespace(plan_id=i + 1, patient_code=f"FIT-C{i:04d}"))
             for i in range(100)]
    tasks = report_tasks(cases)
    assert tasks[0].patient == "FIT-C0000 and 7 more"
    assert all(len(t.patient) <= WHOSE_MAX for t in tasks)
