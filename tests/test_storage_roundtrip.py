"""Round trip of every stored type, on SQLite and PostgreSQL; audit log is append-only."""

from __future__ import annotations

import hashlib
from datetime import date

import numpy as np
import pytest

from fieldbank.errors import ParameterError, StorageError
from fieldbank.maps import postural_map, stiffness_map
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.storage import Database, IncomingFile, IngestOutcome


@pytest.fixture
def db(any_db_url: str, tmp_path):
    d = Database.open(any_db_url, upgrade="always", store_root=tmp_path / "arrays",
                      actor="tester")
    yield d
    d.close()


def _incoming(name, maps, text=None):
    data = (text or maps[0].to_csv()).encode()
    return IncomingFile(name, hashlib.sha256(data).hexdigest(), "csv", data, tuple(maps))


def _maps(p: ArmParams):
    arm = Arm.from_params(p)
    pos = np.array([[0.05, 0.40], [0.10, 0.35], [-0.05, 0.45]])
    post = postural_map(arm, pos, source="lab X, robot Y v1")
    sd = np.full((3, 2, 2), 3.0)
    k = stiffness_map(arm, pos, (0.0, 0.1), source="lab X")
    from fieldbank.maps import FieldMap

    stiff = FieldMap(kind="stiffness", positions_m=k.positions_m, values=k.values, sd=sd,
                     sign="handle-on-arm", velocity_m_per_s=k.velocity_m_per_s,
                     source=k.source, metadata={"operator": "A1", "note": "ünïcode"})
    return post, stiff


def test_patient_and_session_round_trip(db: Database) -> None:
    p = db.add_patient("P-001", 71.5, 1.78, "left", notes="synthetic")
    assert db.get_patient("P-001") == p
    assert db.patient_by_id(p.id) == p
    assert [x.code for x in db.list_patients()] == ["P-001"]
    s = db.ensure_session("P-001", "pre-BoNT", date(2024, 3, 1))
    assert s.session_date == date(2024, 3, 1)
    again = db.ensure_session("P-001", "pre-BoNT")
    assert again.id == s.id
    with pytest.raises(StorageError, match="dated"):
        db.ensure_session("P-001", "pre-BoNT", date(2024, 3, 2))
    with pytest.raises(StorageError, match="already exists"):
        db.add_patient("P-001", 70, 1.7, "right")


@pytest.mark.parametrize("code", ["John Smith", "", "a" * 65, "1990-01-01 Jane"])
def test_patient_code_must_be_pseudonym(db: Database, code: str) -> None:
    with pytest.raises(ParameterError):
        db.add_patient(code, 70, 1.7, "right")
    assert db.list_patients() == []


def test_map_round_trip(db: Database) -> None:
    p = db.add_patient("P-002", 80, 1.80, "right")
    post, stiff = _maps(p.arm_params())
    out = db.ingest_files("P-002", "post-BoNT", [_incoming("a.csv", [post]),
                                                 _incoming("b.csv", [stiff])],
                          session_date=date(2024, 5, 2))
    assert [o.status for o in out] == ["stored", "stored"]
    got_post = db.get_map(out[0].map_ids[0])
    got_stiff = db.get_map(out[1].map_ids[0])
    for a, b in ((post, got_post), (stiff, got_stiff)):
        assert b.kind == a.kind and b.sign == a.sign and b.frame == a.frame
        np.testing.assert_array_equal(b.positions_m, a.positions_m)
        np.testing.assert_array_equal(b.values, a.values)
        assert (b.sd is None) == (a.sd is None)
        assert b.velocity_m_per_s == a.velocity_m_per_s
        assert b.source == a.source
        assert dict(b.metadata) == dict(a.metadata)
    np.testing.assert_array_equal(got_stiff.sd, stiff.sd)
    listed = db.list_maps("P-002")
    assert [m.kind for m in listed] == ["postural", "stiffness"]
    assert listed[1].value_unit == "N/m" and listed[0].value_unit == "N"
    assert listed[0].session_date == date(2024, 5, 2)
    assert listed[0].ingested_by == "tester"
    assert db.list_maps("P-002", kind="stiffness")[0].id == out[1].map_ids[0]
    assert db.list_maps("P-002", session_label="nope") == []
    assert len(db.list_maps(since=date(2024, 5, 1), until=date(2024, 5, 3))) == 2
    assert db.list_maps(since=date(2024, 6, 1)) == []
    # the raw file comes back byte for byte
    assert db.source_bytes(out[0].sha256) == post.to_csv().encode()
    assert db.source_file(out[0].sha256).file_name == "a.csv"


def test_large_source_file_goes_to_array_store(db: Database) -> None:
    from fieldbank.storage import mapstore

    p = db.add_patient("P-003", 70, 1.7, "right")
    post, _ = _maps(p.arm_params())
    text = post.to_csv() + "# padding\n" * (mapstore.INLINE_MAX_BYTES // 10 + 10)
    inc = _incoming("big.csv", [post], text)
    db.ingest_files("P-003", "s", [inc])
    assert db.source_file(inc.sha256).in_array_store
    assert db.source_bytes(inc.sha256) == text.encode()
    assert db.check().ok


def test_duplicate_file_not_stored_twice(db: Database) -> None:
    p = db.add_patient("P-004", 70, 1.7, "right")
    post, _ = _maps(p.arm_params())
    inc = _incoming("a.csv", [post])
    first = db.ingest_files("P-004", "s", [inc, inc])
    assert [o.status for o in first] == ["stored", "duplicate"]
    second = db.ingest_files("P-004", "t", [inc])
    assert second[0].status == "duplicate"
    assert [x.label for x in db.list_sessions("P-004")] == ["s"]  # no empty session "t"
    assert len(db.list_maps()) == 1


def test_ingest_progress_reports_each_stored_file_inside_the_transaction(
        db: Database, any_db_url: str, tmp_path) -> None:
    p = db.add_patient("P-006", 70, 1.7, "right")
    post, stiff = _maps(p.arm_params())
    a, b = _incoming("a.csv", [post]), _incoming("b.csv", [post, stiff], post.to_csv() + "#\n")
    db.ingest_files("P-006", "s", [a])
    other = Database.open(any_db_url, store_root=tmp_path / "arrays")
    seen = []

    def progress(o: IngestOutcome) -> None:
        # another connection does not see the batch yet: the callback runs before the commit
        seen.append((o.file_name, o.status, o.n_maps, len(other.list_maps("P-006"))))

    out = db.ingest_files("P-006", "t", [a, b], progress=progress)
    other.close()
    assert seen == [("b.csv", "stored", 2, 1)]  # the duplicate a.csv is not reported
    assert [o.status for o in out] == ["duplicate", "stored"]
    assert len(db.list_maps("P-006")) == 3


def test_models_fits_plans_round_trip(db: Database) -> None:
    p = db.add_patient("P-005", 70, 1.7, "right")
    post, stiff = _maps(p.arm_params())
    out = db.ingest_files("P-005", "s", [_incoming("a.csv", [post]),
                                         _incoming("b.csv", [stiff])])
    base = db.add_model(p.arm_params(), "synthetic", "unimpaired default")
    assert base.patient_code is None
    fitted_params = p.arm_params().with_group("ef", km_n_per_m=3000.0)
    fitted = db.add_model(fitted_params, "fitted", "fit 1", "P-005", parent_id=base.id)
    assert db.get_model(fitted.id).params == fitted_params
    assert [m.id for m in db.model_lineage(fitted.id)] == [fitted.id, base.id]
    map_ids = [out[0].map_ids[0], out[1].map_ids[0]]
    fit = db.add_fit("P-005", fitted.id, "nlopt:GN_CRS2_LM+LN_BOBYQA", 7, 1234, 12.5, 0.031,
                     {"residuals": [0.1, 0.2], "unidentified": ["be"]}, map_ids)
    assert db.get_fit(fit.id) == fit
    assert fit.map_ids == tuple(sorted(map_ids))
    assert db.list_fits("P-005") == [fit]
    with pytest.raises(StorageError, match="not maps of patient"):
        db.add_fit("P-005", fitted.id, "x", None, 1, 1.0, 1.0, {}, [999])
    after = db.add_model(fitted_params.with_group("ef", alpha_n=50.0), "intervention",
                         "BoNT ef", "P-005", parent_id=fitted.id)
    plan = db.add_plan(fitted.id, after.id, {"steps": [{"kind": "bont", "group": "ef"}]},
                       label="BoNT", patient_code="P-005")
    assert db.get_plan(plan.id) == plan
    assert db.list_plans("P-005") == [plan]
    assert {m.origin for m in db.list_models("P-005")} == {"fitted", "intervention"}
    assert [m.id for m in db.list_models(origin="synthetic")] == [base.id]
    with pytest.raises(ParameterError):
        db.add_model(fitted_params, "guessed", "x")


def test_fitted_model_and_fit_land_together_or_not_at_all(db: Database) -> None:
    p = db.add_patient("P-006", 70, 1.7, "right")
    post, _ = _maps(p.arm_params())
    out = db.ingest_files("P-006", "s", [_incoming("a.csv", [post])])
    params = p.arm_params().with_group("ee", km_n_per_m=2500.0)
    n_audit = len(db.audit_entries())
    with pytest.raises(StorageError, match="not maps of patient"):
        db.add_fitted_model(params, "fit", "P-006", "mlsl", 1, 10, 0.1, 1.0, {}, [999])
    assert db.list_models("P-006") == [] and db.list_fits("P-006") == []
    assert len(db.audit_entries()) == n_audit
    model, fit = db.add_fitted_model(params, "fit", "P-006", "mlsl", 1, 10, 0.1, 1.0,
                                     {"cost": 1.0}, list(out[0].map_ids))
    assert db.get_model(model.id).origin == "fitted" and fit.model_id == model.id
    assert db.list_fits("P-006") == [fit]


def test_plan_and_its_result_model_land_together_or_not_at_all(db: Database) -> None:
    db.add_patient("P-007", 70, 1.7, "right")
    before = ArmParams.from_anthropometry(70, 1.7).with_group("ef", km_n_per_m=5000.0)
    after = before.with_group("ef", alpha_n=40.0)
    with pytest.raises(StorageError, match="No model with id 424242"):
        db.add_plan_result(after, {"steps": []}, "BoNT", "P-007", base_model_id=424242)
    with pytest.raises(StorageError, match="No patient"):
        db.add_plan_result(after, {"steps": []}, "BoNT", "P-404", before=before)
    assert db.list_models() == [] and db.list_plans() == []
    with pytest.raises(ParameterError, match="exactly one"):
        db.add_plan_result(after, {}, "x", base_model_id=1, before=before)
    base_id, child, plan = db.add_plan_result(after, {"steps": [1]}, "BoNT", "P-007",
                                              before=before, before_label="synthetic")
    assert db.get_model(base_id).params == before and db.get_model(base_id).origin == "synthetic"
    assert child.parent_id == base_id and child.origin == "intervention"
    assert (plan.base_model_id, plan.result_model_id) == (base_id, child.id)
    again = db.add_plan_result(after, {"steps": [2]}, "BoNT 2", "P-007", base_model_id=base_id)
    assert again[0] == base_id and len(db.list_plans("P-007")) == 2


def test_haptic_sessions_and_traces_round_trip(db: Database) -> None:
    p = db.add_patient("P-006", 70, 1.7, "right")
    a = db.add_model(p.arm_params(), "synthetic", "before", "P-006")
    b = db.add_model(p.arm_params().with_group("ef", km_n_per_m=900.0), "intervention", "after",
                     "P-006", a.id)
    hs = db.start_haptic_session(a.id, "socket://operator:hunter2@robot:7777", b.id, "P-006")
    assert "hunter2" not in hs.robot_url and hs.ended_at is None
    t = np.linspace(0, 1, 1001)
    trace = np.stack([t, np.sin(t), np.cos(t)], axis=1).astype(np.float32)
    rec = db.add_trace(hs.id, "handle_xy", trace, "m", {"rate_hz": 1000})
    assert rec.array.shape == (1001, 3) and rec.array.unit == "m"
    back = db.get_trace_array(rec.id)
    assert back.dtype == np.float32
    np.testing.assert_array_equal(back, trace)
    assert db.trace_attrs(rec.id)["provenance"]["rate_hz"] == 1000
    assert db.list_traces(hs.id) == [rec]
    ended = db.end_haptic_session(hs.id, {"ticks": 1000, "overruns": 0})
    assert ended.ended_at is not None and ended.stats == {"ticks": 1000, "overruns": 0}
    assert db.get_haptic_session(hs.id) == ended
    assert db.list_haptic_sessions("P-006") == [ended]
    with pytest.raises(StorageError, match="already ended"):
        db.end_haptic_session(hs.id, {})
    assert db.check().ok


def test_every_write_is_audited(db: Database) -> None:
    db.add_patient("P-007", 70, 1.7, "right")
    db.ensure_session("P-007", "s")
    m = db.add_model(ArmParams.from_anthropometry(), "synthetic", "m")
    entries = db.audit_entries()
    assert [(e.action, e.entity) for e in reversed(entries)] == [
        ("add", "patient"), ("add", "session"), ("add", "model")]
    assert entries[0].entity_id == str(m.id) and entries[0].actor == "tester"


def test_failed_write_leaves_no_audit_entry(db: Database) -> None:
    db.add_patient("P-008", 70, 1.7, "right")
    n = len(db.audit_entries())
    with pytest.raises(StorageError):
        db.add_model(ArmParams.from_anthropometry(), "fitted", "m", parent_id=12345)
    assert len(db.audit_entries()) == n


@pytest.mark.parametrize("sql", ["UPDATE audit_log SET actor = 'mallory'",
                                 "DELETE FROM audit_log"])
def test_audit_log_is_append_only(db: Database, sql: str) -> None:
    db.add_patient("P-009", 70, 1.7, "right")
    before = db.audit_entries()
    with pytest.raises(StorageError, match="append-only"):
        db.raw_sql(sql)
    assert db.audit_entries() == before


@pytest.mark.postgres
def test_audit_log_cannot_be_truncated_on_postgresql(pg_url: str, tmp_path) -> None:
    db = Database.open(pg_url, upgrade="always", store_root=tmp_path / "arrays")
    db.add_patient("P-010", 70, 1.7, "right")
    with pytest.raises(StorageError, match="append-only"):
        db.raw_sql("TRUNCATE audit_log")
    assert len(db.audit_entries()) == 1
    db.close()
