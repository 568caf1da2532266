"""The first hour of a new user: settings, a database never created by surprise, messages that
name what they looked in, stored plans, and the small things a first session trips over."""

from __future__ import annotations

import json
import logging
import os
import re
from collections.abc import Iterator
from pathlib import Path

import pytest
from click.testing import CliRunner, Result

from fieldbank.cli.main import cli
from fieldbank.config import setting
from fieldbank.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]


def run(*args: str, env: dict[str, str] | None = None) -> Result:
    return CliRunner().invoke(cli, list(args), env=env, catch_exceptions=False)


@pytest.fixture
def clean_env(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """No fieldbank variable set, no configuration file found; the current directory is empty."""
    for k in list(os.environ):
        if k.startswith("FIELDBANK_") and k not in ("FIELDBANK_TEST_PG_URL",
                                                   "FIELDBANK_REQUIRE_PG",
                                                   "FIELDBANK_REQUIRE_BROWSER"):
            monkeypatch.delenv(k)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg-config"))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg-data"))
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    return tmp_path


# --- settings ----------------------------------------------------------------------------------
def test_settings_come_from_flag_then_variable_then_file_then_default(
        clean_env: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert setting("scheduler").source == "default" and setting("scheduler").value is None
    user_file = clean_env / "xdg-config" / "fieldbank" / "fieldbank.toml"
    user_file.parent.mkdir(parents=True)
    user_file.write_text('scheduler = "tcp://10.0.0.5:8786"\n[report]\njobs = 3\n')
    assert setting("scheduler").source == f"file {user_file}"
    # the current directory's file comes first
    Path("fieldbank.toml").write_text('scheduler = "tcp://cluster.local:8786"\n')
    s = setting("scheduler")
    assert s.value == "tcp://cluster.local:8786" and s.source.endswith("work/fieldbank.toml")
    assert setting("report.jobs").source == "default"  # the first file found is the one read
    monkeypatch.setenv("FIELDBANK_SCHEDULER", "tcp://[::1]:8786")
    assert setting("scheduler").source == "variable FIELDBANK_SCHEDULER"
    assert setting("scheduler", "tcp://h:1").source == "flag --scheduler"
    with pytest.raises(ConfigError, match="tcp://HOST:PORT"):
        setting("scheduler", "h:8786")


def test_a_bad_file_is_refused_naming_the_file_and_the_key(clean_env: Path) -> None:
    Path("fieldbank.toml").write_text('databse = "sqlite:///x"\n')
    with pytest.raises(ConfigError, match=r"fieldbank.toml: unknown setting 'databse'"):
        setting("db")
    Path("fieldbank.toml").write_text("[report]\njobs = 0\n")
    with pytest.raises(ConfigError, match=r"report\.jobs must be a whole number"):
        setting("report.jobs")
    Path("fieldbank.toml").write_text("db = \n")
    r = run("config", "show")
    assert r.exit_code == 1 and "not valid TOML" in r.stderr and "Traceback" not in r.output


def test_config_show_prints_each_value_and_its_source_without_secrets(clean_env: Path) -> None:
    Path("fieldbank.toml").write_text(
        'db = "postgresql+psycopg://ana:s3cret@db.example/fb"\n[ingest.limits]\nmax_rows = 5\n')
    # a home deep enough that its path alone would push the row past 100 columns
    home = clean_env / "clinic-data" / ("a-directory-with-a-long-name-" * 3) / "fieldbank-home"
    assert len(str(home)) > 100
    r = run("config", "show", env={"FIELDBANK_HOME": str(home)})
    assert r.exit_code == 0
    assert "s3cret" not in r.output
    out = r.stdout.splitlines()
    assert max(len(ln) for ln in out) <= 100
    # each row's columns, with the lines a long cell wrapped onto (at the header's columns)
    at_value, at_from = out[0].index("value"), out[0].index("from")
    rows: dict[str, list[str]] = {}
    last = ""
    for ln in out[1:]:
        if not ln.startswith(" "):
            last = ln.split()[0]
            rows[last] = ["", ""]
        rows[last][0] += ln[at_value:at_from].strip()
        rows[last][1] += " " + ln[at_from:].strip()
    assert "ana:***@db.example" in rows["db"][0] and "fieldbank.toml" in rows["db"][1]
    assert "variable FIELDBANK_HOME" in " ".join(rows["home"][1].split())
    assert rows["home"][0] == str(home)  # wrapped whole, nothing cut or elided
    assert "max_rows=5" in rows["ingest.limits"][0]
    doc = json.loads(run("config", "show", "--json").stdout)
    assert doc["file"].endswith("fieldbank.toml")
    assert {s["name"] for s in doc["settings"]} >= {"db", "home", "robot", "scheduler",
                                                     "report.jobs", "ingest.limits"}


def test_ingest_limits_layer_file_then_variable_then_flag(
        clean_env: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from fieldbank.ingest.limits import IngestLimits

    Path("fieldbank.toml").write_text("[ingest.limits]\nmax_rows = 5\nmax_maps = 7\n")
    monkeypatch.setenv("FIELDBANK_INGEST_LIMITS", "max_maps=8")
    lim = IngestLimits.from_environment(["max_problems=9"])
    assert (lim.max_rows, lim.max_maps, lim.max_problems) == (5, 8, 9)


# --- a database never created by surprise -------------------------------------------------------
@pytest.mark.parametrize("args", [("patient", "list"), ("patient", "show", "SYN-001"),
                                  ("maps", "list"), ("models", "list"), ("plans", "list"),
                                  ("whatif", "SYN-001", "--botox", "ef=100U"),
                                  ("db", "current"), ("report", "--out", "rep")])
def test_reads_refuse_a_missing_database_and_create_nothing(clean_env: Path,
                                                            args: tuple[str, ...]) -> None:
    r = run(*args)
    assert r.exit_code == 1, r.output
    default = clean_env / "xdg-data" / "fieldbank" / "fieldbank.sqlite3"
    assert f"No database at {default}" in r.stderr
    assert "FIELDBANK_HOME nor FIELDBANK_DB is set" in r.stderr
    assert "fieldbank patient add" in r.stderr and "fieldbank db upgrade" in r.stderr
    assert not default.exists() and not default.parent.exists()


def test_patient_add_starts_the_database(clean_env: Path) -> None:
    home = clean_env / "h"
    env = {"FIELDBANK_HOME": str(home)}
    assert run("patient", "list", env=env).exit_code == 1 and not home.exists()
    r = run("patient", "add", "P-1", "--mass-kg", "70", "--height-m", "1.7", "--side", "left",
            env=env)
    assert r.exit_code == 0 and (home / "fieldbank.sqlite3").exists()
    r = run("patient", "list", env=env)
    assert r.exit_code == 0 and "P-1" in r.stdout and "1 patient(s) in sqlite:" in r.stderr


@pytest.fixture
def demo_like(tmp_path: Path) -> Iterator[str]:
    """A database with three patients, a fitted-like stored model and plans (fast: no fit)."""
    from fieldbank.evaluate.severity import synthesize
    from fieldbank.interventions import Botulinum, Lengthening, Plan
    from fieldbank.interventions.whatif import save_plan
    from fieldbank.modelsource import stored
    from fieldbank.storage import Database

    url = f"sqlite:///{tmp_path / 'fb.sqlite3'}"
    with Database.open(url) as db:
        for code in ("SYN-001", "SYN-002", "SYN-003"):
            db.add_patient(code, 72.0, 1.74, "right")
        db.ensure_session("SYN-001", "pre-BoNT")
        db.ensure_session("SYN-001", "post-BoNT")
        m = db.add_model(synthesize({"elbow": "severe"}), "synthetic", "elbow severe",
                         "SYN-001")
        src = stored(db, m.id)
        save_plan(db, src, Plan((Botulinum({"ef": 150.0}),), "botulinum"))
        save_plan(db, src, Plan((Lengthening("bf", 0.01),), "lengthening"))
    yield url


def test_not_found_names_the_database_and_the_nearest(demo_like: str) -> None:
    r = run("patient", "show", "SYN-01", "--db", demo_like)
    assert r.exit_code == 1
    assert "in sqlite:///" in r.stderr and "fb.sqlite3" in r.stderr
    assert "nearest: SYN-001" in r.stderr and "3 patients" in r.stderr
    r = run("fit", "SYN-001", "--session", "pre", "--db", demo_like)
    assert r.exit_code == 1 and "its sessions: 'pre-BoNT', 'post-BoNT'" in r.stderr
    r = run("models", "show", "99", "--db", demo_like)
    assert r.exit_code == 1 and "No model with id 99 in sqlite:///" in r.stderr
    assert "it holds 3 models, ids 1-3" in r.stderr
    r = run("plans", "show", "42", "--db", demo_like)
    assert r.exit_code == 1 and "it holds 2 plans, ids 1-2" in r.stderr


# --- stored plans -------------------------------------------------------------------------------
def test_plans_list_show_give(demo_like: str) -> None:
    r = run("plans", "list", "--db", demo_like)
    assert r.exit_code == 0 and "2 plan(s) in" in r.stderr
    rows = [ln for ln in r.stdout.splitlines()[1:] if ln[:5].strip().isdigit()]
    assert len(rows) == 2 and all("explored" in ln for ln in rows)
    doc = json.loads(run("plans", "list", "--db", demo_like, "--kind", "lengthening",
                         "--json").stdout)
    assert [p["id"] for p in doc] == [2] and doc[0]["kinds"] == ["lengthening"]
    assert "1 cm" in doc[0]["steps"][0]
    assert json.loads(run("plans", "list", "--db", demo_like, "--given", "--json").stdout) == []
    r = run("plans", "list", "--db", demo_like, "--kind", "surgery")
    assert r.exit_code == 1 and "not an intervention kind" in r.stderr

    r = run("plans", "give", "1", "--on", "2024-01-10", "--db", demo_like)
    assert r.exit_code == 0 and "recorded as given on 2024-01-10" in r.stderr
    r = run("plans", "give", "1", "--on", "2024-01-10", "--db", demo_like)
    assert r.exit_code == 0 and "nothing changed" in r.stderr
    r = run("plans", "give", "1", "--on", "2024-01-11", "--db", demo_like)
    assert r.exit_code == 1 and "already recorded as given on 2024-01-10" in r.stderr
    given = json.loads(run("plans", "list", "--db", demo_like, "--given", "--json").stdout)
    assert [p["given_on"] for p in given] == ["2024-01-10"]

    r = run("plans", "show", "1", "--db", demo_like)
    assert r.exit_code == 0
    assert "given: 2024-01-10" in r.stdout and "botulinum toxin A (ef 150 U" in r.stdout
    assert "model before: 1 (synthetic" in r.stdout and "fit: none" in r.stdout
    show = json.loads(run("plans", "show", "2", "--db", demo_like, "--json").stdout)
    assert show["given_on"] is None and show["base_model"]["id"] == 1
    assert show["result_model"]["origin"] == "intervention"

    # models list/show carry the plans
    models = json.loads(run("models", "list", "--db", demo_like, "--json").stdout)
    by_id = {m["id"]: m for m in models}
    assert by_id[1]["plans_from"] == [1, 2] and by_id[2]["plan_id"] == 1
    r = run("models", "show", "3", "--db", demo_like)
    assert "made by plan 2" in r.stdout and "ef elbow flexors" in r.stdout


def test_the_given_date_is_audited(demo_like: str) -> None:
    from fieldbank.storage import Database

    run("plans", "give", "2", "--on", "2024-02-01", "--db", demo_like)
    with Database.open(demo_like) as db:
        entries = [e for e in db.audit_entries() if e.action == "give"]
    assert len(entries) == 1 and entries[0].entity == "plan"


# --- inputs and outputs -------------------------------------------------------------------------
def test_an_impossible_date_says_why(demo_like: str) -> None:
    r = run("plans", "give", "1", "--on", "2024-02-30", "--db", demo_like)
    assert r.exit_code == 2 and "2024-02-30: February 2024 has 29 days" in r.stderr
    r = run("maps", "list", "--since", "2024-13-01", "--db", demo_like)
    assert r.exit_code == 2 and "there is no month 13" in r.stderr
    r = run("maps", "list", "--since", "10/01/2024", "--db", demo_like)
    assert r.exit_code == 2 and "YYYY-MM-DD" in r.stderr


def test_a_file_named_in_a_missing_directory_is_refused(tmp_path: Path) -> None:
    target = tmp_path / "no-such-dir" / "x.svg"
    r = run("whatif", "--severity", "elbow=severe", "--botox", "ef=100U", "--plot", str(target))
    assert r.exit_code == 2 and "does not exist; create it first" in r.stderr
    assert not target.parent.exists()


def test_report_out_refuses_to_overwrite_without_force(tmp_path: Path) -> None:
    from tests.report_helpers import build_batch

    batch = build_batch(tmp_path, patients=("SYN-001",))
    out = tmp_path / "rep"
    args = ("report", "--db", batch["url"], "--out", str(out), "--jobs", "1", "--no-date")
    assert run(*args).exit_code == 0
    before = (out / "report.html").read_bytes()
    (out / "report.html").write_text("kept")
    r = run(*args)
    assert r.exit_code == 1 and "already holds a report" in r.stderr and "--force" in r.stderr
    assert (out / "report.html").read_text() == "kept"
    assert run(*args, "--force").exit_code == 0
    assert (out / "report.html").read_bytes() == before


def test_group_codes_are_explained_in_help_and_errors() -> None:
    r = run("whatif", "--help")
    flat = " ".join(r.output.split())
    assert "ef = elbow flexors" in flat and "docs/glossary.md" in flat
    assert "docs/glossary.md" in " ".join(run("--help").output.split())
    r = run("whatif", "--severity", "elbow=severe", "--botox", "xx=100U")
    assert r.exit_code == 1 and "ef = elbow flexors" in r.stderr


def test_the_glossary_explains_the_terms_the_output_uses() -> None:
    text = (ROOT / "docs" / "glossary.md").read_text(encoding="utf-8")
    for term in ("**R1**", "**R2**", "**R2 − R1**", "**Catch**", "**χ²/n**", "**JND**",
                 "**Under-determined", "**Velocity-dependent part**", "**Spasticity**",
                 "**Contracture**", "`ef`", "**U**"):
        assert term in text, term


# --- database URLs and robot ports --------------------------------------------------------------
@pytest.mark.parametrize("url", [
    "postgresql+psycopg://u@h:abc/db", "postgresql+psycopg://u@h:99999/db",
    "postgresql+psycopg://u@[::1/db", "postgresql+psycopg://u:pw@h/db?sslmode=require&x",
    "postgresql+psycopg://u@h/db?password=se&cret", "sqlite:///a.db?mode=ro&&"])
def test_malformed_database_urls_are_messages_not_tracebacks(url: str) -> None:
    r = CliRunner().invoke(cli, ["patient", "list", "--db", url])
    assert r.exit_code == 1, r.output
    assert r.exception is None or isinstance(r.exception, SystemExit)
    assert "Not a database URL" in r.stderr and "Traceback" not in r.output
    assert "cret" not in r.stderr  # nothing of a password's tail is quoted


def test_a_password_with_query_characters_is_not_a_query() -> None:
    from fieldbank.storage.config import resolve_url

    u = resolve_url("postgresql+psycopg://ana:p?a&s#s@db.example/fb")
    assert u.password == "p?a&s#s" and u.host == "db.example"


def test_a_robot_device_path_is_shown_whole_and_a_url_password_never(tmp_path: Path) -> None:
    port = str(tmp_path / "ttyUSB9")
    r = run("haptic", "serve", "--robot", port, "--before-severity", "elbow=severe", "--no-db",
            "--duration-s", "0.1")
    assert r.exit_code == 1 and f"cannot open robot port '{port}'" in r.stderr
    r = run("haptic", "serve", "--robot", "socket://ana:s3cret@127.0.0.1:9", "--before-severity",
            "elbow=severe", "--no-db", "--duration-s", "0.1")
    assert r.exit_code == 1 and "s3cret" not in r.output and "ana:***@127.0.0.1" in r.stderr


def test_a_sim_url_is_shown_as_given(tmp_path: Path) -> None:
    r = run("haptic", "serve", "--robot", "sim://?mode=lockstep", "--before-severity",
            "elbow=severe", "--no-db", "--duration-s", "0.05", "--trace-dir", str(tmp_path),
            "--json", "--socket", str(tmp_path / "s.sock"))
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["robot"] == "sim://?mode=lockstep"
    assert "x0_m" not in r.output and "motion=" not in r.output


def test_abx_help_and_errors_speak_the_command_line() -> None:
    from fieldbank.haptic.commands import AbxAnswer  # noqa: F401  (the table is importable)

    text = " ".join(run("haptic", "abx", "start", "--help").output.split())
    assert "TRIALS" not in text and "--trials" in text
    src = (ROOT / "haptic" / "commands.py").read_text(encoding="utf-8")
    assert "start one with abx_start" not in src
    assert "fieldbank haptic abx start" in src


# --- the demo after the tours -------------------------------------------------------------------
def test_the_demo_clears_what_the_tours_left_and_names_anything_else(tmp_path: Path) -> None:
    from fieldbank.cli.demo import _clear_demo_home
    from fieldbank.errors import FieldbankError

    home = tmp_path / "home"
    (home / "fieldbank.sqlite3.arrays").mkdir(parents=True)
    (home / "fieldbank.sqlite3").write_bytes(b"x")
    (home / "traces").mkdir()
    (home / "traces" / "haptic-1.h5").write_bytes(b"x")
    (home / "haptic.sock").write_bytes(b"")
    (home / "fieldbank.sqlite3.backup-0003-20240101T000000Z.sqlite3").write_bytes(b"x")
    _clear_demo_home(home)
    assert list(home.iterdir()) == []
    (home / "notes.txt").write_text("mine")
    with pytest.raises(FieldbankError, match=r"notes\.txt.*fieldbank demo --out OTHER"):
        _clear_demo_home(home)
    assert (home / "notes.txt").read_text() == "mine"


# --- documents ----------------------------------------------------------------------------------
def test_the_readme_tours_write_under_demo_out_and_chromium_runs_as_root() -> None:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```sh\n(.*?)```", text, re.S)
    outputs = [m.group(2) for b in blocks for m in re.finditer(
        r"(--html|--plot|--out|--csv|-o)\s+(\S+)", b)]
    assert outputs and all(o.startswith(("demo-out", "$", '"$')) for o in outputs), outputs
    for line in re.findall(r"chromium --headless[^`]*", text):
        assert "--no-sandbox" in line, line


def test_storage_doc_names_the_head_revision_consistently() -> None:
    from fieldbank.storage import migrate

    text = (ROOT / "docs" / "storage.md").read_text(encoding="utf-8")
    assert set(re.findall(r"knows revisions up to (\d{4})", text)) == {migrate.head_revision()}
    for rev in migrate.known_revisions():
        assert re.search(rf"^\| `?{rev}`? \|", text, re.M), rev


def test_alembic_says_nothing_on_a_terminal_set_up_for_info(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    from fieldbank.storage import Database

    caplog.set_level(logging.INFO)
    with Database.open(f"sqlite:///{tmp_path / 'new.sqlite3'}"):
        pass
    assert not [r for r in caplog.records if r.name.startswith("alembic")]
