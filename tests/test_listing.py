"""The light listing (fieldbank.stored.listing) reads what the ORM reads, on SQLite and
PostgreSQL, and the list commands say the same through it as through the ORM.

* :func:`~fieldbank.stored.location.locate` reads every URL form it accepts as SQLAlchemy does
  (file, connection arguments of the psycopg dialect, masked text) and declines the rest;
* on a database holding the awkward cases (patients out of order, a session without a date, a
  model and a plan without a patient, a chain of plans, runs of several kinds with tasks in
  every state) every listing equals :class:`fieldbank.storage.Database`'s, filters included,
  and so do the "not found" errors;
* each list command's ``--json`` output, text and errors are the same through the light path
  and with the light path refused (the ORM's), and the light path is the one taken;
* a database behind head, made by a newer fieldbank or missing is handled as before: migrated,
  refused or refused in the same words.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterator
from datetime import date
from pathlib import Path

import pytest
from click.testing import CliRunner
from sqlalchemy import create_engine, text

from fieldbank.cli.main import cli
from fieldbank.errors import DatabaseMissing, StorageError
from fieldbank.fitting.synthetic import impaired_params, synthetic_patient
from fieldbank.interventions import Botulinum, Plan, Tenotomy
from fieldbank.interventions.whatif import save_plan
from fieldbank.modelsource import stored, synthetic
from fieldbank.params import ArmParams
from fieldbank.redact import mask_url, quote_password
from fieldbank.storage import Database, IncomingFile, migrate, resolve_url
from fieldbank.stored import listing as listing_module
from fieldbank.stored.listing import Listing, open_listing
from fieldbank.stored.location import locate
from fieldbank.stored.records import model_summary

# --- URLs ---------------------------------------------------------------------------------------

READ = [
    "sqlite:////tmp/x/fieldbank.sqlite3",
    "sqlite:///relative/db.sqlite3",
    "sqlite:////tmp/with space/and+plus/é/db.sqlite3",
    "sqlite:////tmp/a%20b/db.sqlite3",
    "sqlite:////tmp/at@sign:colon/db.sqlite3",
    "postgresql+psycopg://postgres@127.0.0.1:55432/postgres",
    "postgresql+psycopg://ana:s3cret@db.example/fieldbank",
    "postgresql+psycopg://ana:p@ss/w:rd?x#y@db.example:5433/fb",
    "postgresql+psycopg://ana:%40pct@db.example/fb",
    "postgresql+psycopg://ana@db.example/fb?sslmode=require&application_name=fb+cli",
    "postgresql+psycopg://ana@db.example/fb?password=x&connect_timeout=5",
    "postgresql+psycopg://ana:@db.example/fb",
    "postgresql+psycopg://@db.example/fb",
    "postgresql+psycopg://db.example",
    "postgresql+psycopg://db.example/",
    "postgresql+psycopg://db.example/f%C3%A9b",
    "postgresql+psycopg://ana@db.example/fb?a=",               # a blank item is dropped
]
DECLINED = [
    "sqlite://",
    "sqlite:///:memory:",
    "sqlite:///x.db?mode=ro",
    "postgresql://ana@db.example/fb",            # psycopg2 is SQLAlchemy's choice here
    "postgresql+psycopg://ana@/fb?host=/run/postgresql",
    "postgresql+psycopg://ana@[::1]:5432/fb",
    "postgresql+psycopg://ana@h1,h2/fb",
    "postgresql+psycopg://ana@db.example:0/fb",
    "postgresql+psycopg://ana@db.example:70000/fb",
    "postgresql+psycopg://ana@db.example/fb?sslmode",
    "postgresql+psycopg://ana@db.example/fb?a=1&a=2",
    "mysql://ana@db.example/fb",
]


@pytest.mark.parametrize("url", READ)
def test_a_url_it_reads_is_read_as_sqlalchemy_reads_it(url: str) -> None:
    where = locate(url)
    assert where is not None
    sa = resolve_url(url)
    assert where.masked == mask_url(sa)
    assert where.text == url
    if where.backend == "sqlite":
        assert where.path == Path(str(sa.database)) and not where.connect
    else:
        assert where.backend == "postgresql" and where.path is None
        _, kwargs = create_engine(sa).dialect.create_connect_args(sa)
        kwargs.pop("context", None)
        assert dict(where.connect) == kwargs


@pytest.mark.parametrize("url", DECLINED)
def test_other_url_forms_are_left_to_sqlalchemy(url: str) -> None:
    assert locate(url) is None


def test_the_embedded_default_is_read_as_sqlalchemy_reads_it(tmp_path: Path,
                                                              monkeypatch: pytest.MonkeyPatch,
                                                              ) -> None:
    monkeypatch.setenv("FIELDBANK_HOME", str(tmp_path / "a home with é"))
    where = locate(None)
    assert where is not None and where.path == Path(str(resolve_url(None).database))
    assert where.masked == mask_url(resolve_url(None))
    monkeypatch.setenv("FIELDBANK_DB", "postgresql+psycopg://u:pw@h/db")
    env = locate(None)
    assert env is not None and env.connect["password"] == "pw" and "pw" not in env.masked
    assert quote_password("postgresql+psycopg://u:p@w@h/db").count("@") == 1


# --- the same records ---------------------------------------------------------------------------

def _fill(url: str) -> dict[str, int]:
    """A database holding the cases a listing can get wrong; returns ids the tests name."""
    base = ArmParams.from_anthropometry()
    with Database.open(url, upgrade="always") as db:
        for code, mass in (("P-2", 70.0), ("P-10", 64.5), ("P-1", 81.25), ("q-3", 50.0)):
            db.add_patient(code, mass, 1.72, "left" if code == "P-2" else "right",
                           "notes: é ü" if code == "P-1" else "")
        for k, (code, label, day) in enumerate((("P-1", "pre", date(2024, 1, 10)),
                                                ("P-1", "post", date(2024, 3, 20)),
                                                ("P-2", "pre", None),
                                                ("P-10", "pre", date(2023, 12, 31)))):
            truth = impaired_params("elbow", "moderate", base)
            files = []
            for j, m in enumerate(synthetic_patient(truth, seed=k, patient=code).maps[:2]):
                data = m.to_csv().encode()
                files.append(IncomingFile(f"{code}-{label}-{j}.csv",
                                          hashlib.sha256(data).hexdigest(), "csv", data, (m,)))
            db.ingest_files(code, label, files, session_date=day)
        first = db.add_model(impaired_params("shoulder", "mild", base), "synthetic",
                             "P-1's model", patient_code="P-1")
        loose = db.add_model(base, "synthetic", "nobody's model")
        plan1 = save_plan(db, stored(db, first.id), Plan((Botulinum({"ef": 100.0}),)),
                          given_on=date(2024, 1, 10))
        plan2 = save_plan(db, stored(db, plan1.result_model_id),
                          Plan((Tenotomy("ee", 0.5),)))
        save_plan(db, stored(db, first.id), Plan((Botulinum({"bf": 50.0}),)))
        save_plan(db, synthetic(["elbow=severe"]), Plan((Botulinum({"ef": 60.0}),)))
        fit = db.start_run("fit", "local processes (2)", {"all": True},
                           [("P-1/pre", "P-1", "pre"), ("P-1/post", "P-1", "post"),
                            ("P-2/pre", "P-2", "pre"), ("P-10/pre", "P-10", "pre")])
        db.finish_job(fit.id, "P-1/pre", "done", {"model_id": 7},
                      attempt=db.start_job(fit.id, "P-1/pre", "w1").attempts)
        db.finish_job(fit.id, "P-1/post", "failed", error="no maps: ‘post’",
                      attempt=db.start_job(fit.id, "P-1/post", "w2").attempts)
        db.start_job(fit.id, "P-2/pre", "w1")
        db.finish_run(fit.id)
        report = db.start_run("report", "tcp://10.0.0.5:8786", {"plans": [1, 2]},
                              [("cases-1", None, None), ("cases-2", None, None)])
        db.finish_job(report.id, "cases-1", "skipped",
                      attempt=db.start_job(report.id, "cases-1", "w3").attempts)
        db.give_up_job(report.id, "cases-2", "the scheduler went away")
    return {"fit_run": fit.id, "report_run": report.id, "loose_model": loose.id,
            "plan2": plan2.plan_id}


@pytest.fixture
def filled(any_db_url: str) -> Iterator[tuple[str, dict[str, int]]]:
    yield any_db_url, _fill(any_db_url)


def _same(listing: Listing, db: Database, name: str, *args: object) -> object:
    """Call ``name`` on both; the results, or the errors' messages, must be equal."""
    def call(obj: object) -> object:
        try:
            return getattr(obj, name)(*args)
        except StorageError as exc:
            return ("error", type(exc).__name__, str(exc))

    light, orm = call(listing), call(db)
    if name == "list_models" and isinstance(light, list) and isinstance(orm, list):
        light = [model_summary(m) for m in light]
        orm = [model_summary(m) for m in orm]
    assert light == orm, name
    return light


def test_every_listing_is_the_orm_s(filled: tuple[str, dict[str, int]]) -> None:
    url, ids = filled
    listing = open_listing(url)
    assert isinstance(listing, Listing)  # the light path is taken on both backends
    with listing, Database.open(url, create=False) as db:
        assert listing.url_masked == db.url_masked
        patients = _same(listing, db, "list_patients")
        assert [p.code for p in patients] == sorted(["P-2", "P-10", "P-1", "q-3"])  # type: ignore[attr-defined]
        for code in ("P-1", "q-3", "P-3", "nobody"):
            _same(listing, db, "get_patient", code)
        maps = _same(listing, db, "list_maps")
        assert len(maps) == 8  # type: ignore[arg-type]
        for args in (("P-1",), (None, "pre"), (None, None, "stiffness"),
                     (None, None, None, date(2024, 1, 10)),
                     (None, None, None, None, date(2024, 1, 10)),
                     ("P-1", "post", "postural", date(2024, 1, 1), date(2024, 12, 31)),
                     ("nobody",)):
            _same(listing, db, "list_maps", *args)
        models = _same(listing, db, "list_models")
        assert any(m["patient"] is None for m in models)  # type: ignore[attr-defined]
        assert any(m["plans_from"] and m["plan_id"] for m in models)  # type: ignore[attr-defined]
        for code in ("P-1", "P-2", "nobody"):
            _same(listing, db, "list_models", code)
        plans = _same(listing, db, "list_plans")
        assert len(plans) == 4 and plans[-1].patient_code is None  # type: ignore[arg-type,index]
        for code in ("P-1", "q-3"):
            _same(listing, db, "list_plans", code)
        runs = _same(listing, db, "list_runs")
        assert [r.kind for r in runs] == ["report", "fit"]  # type: ignore[attr-defined]
        for args in (("fit",), ("validate",), (None, 1), ("report", 5)):
            _same(listing, db, "list_runs", *args)
        for run_id in (ids["fit_run"], ids["report_run"], 999):
            _same(listing, db, "get_run", run_id)
            _same(listing, db, "list_jobs", run_id)
            _same(listing, db, "list_jobs", run_id, ["failed", "running"])
            _same(listing, db, "list_jobs", run_id, [])


# --- the commands -------------------------------------------------------------------------------

COMMANDS = [
    "patient list", "patient list --json",
    "maps list --json", "maps list", "maps list --patient P-1 --kind postural --json",
    "maps list --since 2024-01-10 --until 2024-12-31 --json",
    "models list", "models list --json", "models list --patient P-1 --json",
    "plans list", "plans list --json", "plans list --patient P-1 --given --json",
    "plans list --kind tenotomy --json", "plans list --patient P-9 --json",
    "jobs", "jobs --json", "jobs --kind fit --json", "jobs 1 --json", "jobs 1",
    "jobs 1 --state failed --json", "jobs 99 --json",
]


def _invoke(url: str, command: str, light: bool,
            monkeypatch: pytest.MonkeyPatch) -> tuple[int, str, str, bool]:
    taken: list[bool] = []

    def spy(db_url: str | None = None) -> Listing | None:
        found = real(db_url) if light else None
        taken.append(found is not None)
        return found

    real = listing_module.open_listing
    with monkeypatch.context() as m:
        m.setattr(listing_module, "open_listing", spy)
        res = CliRunner().invoke(cli, [*command.split(), "--db", url])
    assert not isinstance(res.exception, Exception) or isinstance(res.exception, SystemExit), \
        res.exception
    return res.exit_code, res.stdout, res.stderr, taken == [True]


def test_each_list_command_says_the_same_through_either_path(
        filled: tuple[str, dict[str, int]], monkeypatch: pytest.MonkeyPatch) -> None:
    url, _ = filled
    for command in COMMANDS:
        code, out, err, taken = _invoke(url, command, True, monkeypatch)
        assert taken, f"{command}: the light path was not taken"
        assert (code, out, err)[:3] == _invoke(url, command, False, monkeypatch)[:3], command
        assert code == (1 if command.endswith(("P-9 --json", "99 --json")) else 0), (command, err)


def test_a_missing_database_is_refused_in_the_same_words(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'nowhere' / 'fieldbank.sqlite3'}"
    with pytest.raises(DatabaseMissing) as light:
        open_listing(url)
    with pytest.raises(DatabaseMissing) as orm:
        Database.open(url, create=False)
    assert str(light.value) == str(orm.value)
    assert not (tmp_path / "nowhere").exists()
    res = CliRunner().invoke(cli, ["patient", "list", "--db", url])
    assert res.exit_code == 1 and str(orm.value).split(" (")[0] in res.stderr


def test_a_database_behind_head_is_migrated_first(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'old.sqlite3'}"
    engine = create_engine(url)
    migrate.upgrade(engine, migrate.known_revisions()[-2])
    engine.dispose()
    assert open_listing(url) is None  # not the schema its SELECTs are written against
    res = CliRunner().invoke(cli, ["patient", "list", "--db", url])
    assert res.exit_code == 0 and "0 patient(s)" in res.stderr
    listing = open_listing(url)
    assert isinstance(listing, Listing)
    listing.close()


def test_a_database_made_by_a_newer_fieldbank_is_refused_as_before(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'new.sqlite3'}"
    Database.open(url).close()
    engine = create_engine(url)
    with engine.begin() as conn:
        conn.execute(text("UPDATE alembic_version SET version_num = '9999'"))
    engine.dispose()
    assert open_listing(url) is None
    with pytest.raises(StorageError) as orm:
        Database.open(url, create=False)
    res = CliRunner().invoke(cli, ["jobs", "--db", url])
    assert res.exit_code == 1 and "created by a newer fieldbank" in str(orm.value)
    assert str(orm.value) in " ".join(res.stderr.split())


def test_a_file_that_is_not_a_database_goes_to_sqlalchemy(tmp_path: Path) -> None:
    junk = tmp_path / "junk.sqlite3"
    junk.write_bytes(b"not a database" * 100)
    assert open_listing(f"sqlite:///{junk}") is None
    res = CliRunner().invoke(cli, ["maps", "list", "--db", f"sqlite:///{junk}"])
    assert res.exit_code == 1 and "not a database" in res.stderr
    assert junk.read_bytes() == b"not a database" * 100


@pytest.mark.postgres
def test_a_server_that_does_not_answer_is_reported_as_before() -> None:
    url = "postgresql+psycopg://nobody:secret-pw@127.0.0.1:1/none"
    assert open_listing(url) is None
    res = CliRunner().invoke(cli, ["patient", "list", "--db", url])
    assert res.exit_code == 1 and "secret-pw" not in res.stderr
    assert "127.0.0.1" in res.stderr
