"""The model a what-if stands on is named in its first lines: the fitted model, the session
and date its maps were measured, and - when that session came after a plan given to the
patient - that the arm is already under that plan. ``--session`` chooses another; a later fit
that changes which model a patient's code stands for says so."""

from __future__ import annotations

import json
from datetime import date
from pathlib import Path

import pytest
from click.testing import CliRunner, Result

from fieldbank.cli.main import cli


def run(*args: str) -> Result:
    return CliRunner().invoke(cli, list(args))


@pytest.fixture
def two_sessions(tmp_path: Path, sample_dir: Path) -> str:
    """SYN-001's sample maps of both sessions ingested; the pre-BoNT maps fitted (model 1,
    stored as a fit without running the fitter: the model is the sample's own); a botulinum
    plan on it given on 2024-01-12, between the two sessions."""
    from fieldbank.interventions import Botulinum, Plan
    from fieldbank.interventions.whatif import save_plan
    from fieldbank.modelsource import stored
    from fieldbank.params import ArmParams
    from fieldbank.storage import Database

    url = f"sqlite:///{tmp_path / 'fb.sqlite3'}"
    with Database.open(url) as db:
        db.add_patient("SYN-001", 72.0, 1.74, "right")
    root = sample_dir / "SYN-001"
    for session, day in (("pre-BoNT", "2024-01-10"), ("post-BoNT", "2024-02-21")):
        r = run("ingest", *map(str, sorted((root / session).iterdir())), "--patient",
                "SYN-001", "--session", session, "--date", day, "--db", url)
        assert r.exit_code == 0, r.output
    with Database.open(url) as db:
        pre = [m.id for m in db.list_maps("SYN-001", "pre-BoNT")]
        params = ArmParams.from_file(root / "params-pre-BoNT.json")
        m, _ = db.add_fitted_model(params, "fit of the pre-BoNT maps", "SYN-001", "mlsl", 0,
                                   1, 0.0, 1.0, {"status": "good"}, pre,
                                   session_label="pre-BoNT")
        save_plan(db, stored(db, m.id), Plan((Botulinum({"ef": 150.0}),), "botulinum"),
                  given_on=date(2024, 1, 12))
    return url


def _fit_post(url: str, sample_dir: Path) -> int:
    from fieldbank.params import ArmParams
    from fieldbank.storage import Database

    with Database.open(url) as db:
        post = [m.id for m in db.list_maps("SYN-001", "post-BoNT")]
        params = ArmParams.from_file(sample_dir / "SYN-001" / "params-post-BoNT.json")
        m, _ = db.add_fitted_model(params, "fit of the post-BoNT maps", "SYN-001", "mlsl", 0,
                                   1, 0.0, 1.0, {"status": "good"}, post,
                                   session_label="post-BoNT")
    return int(m.id)


def test_whatif_names_the_model_its_session_and_date_and_a_plan_already_given(
        two_sessions: str, sample_dir: Path) -> None:
    from fieldbank.modelsource import default_changes, patient_defaults
    from fieldbank.storage import Database

    args = ("whatif", "SYN-001", "--botox", "ef=100U", "--interval-samples", "0",
            "--db", two_sessions)
    first = run(*args).stdout.splitlines()[:3]
    assert first[0] == "Model: patient SYN-001, fitted model 1"
    assert first[1] == "  fitted (fit 1) to the maps of session pre-BoNT, 2024-01-10"
    assert not any("already under" in line for line in first)

    with Database.open(two_sessions) as db:
        before = patient_defaults(db, ["SYN-001"])
    post = _fit_post(two_sessions, sample_dir)
    with Database.open(two_sessions) as db:
        (line,) = default_changes(db, before)
    assert f"now starts from model {post} (session post-BoNT, 2024-02-21; already under plan 1)" \
        in line
    assert "not model 1 (session pre-BoNT, 2024-01-10): --session pre-BoNT chooses it" in line

    text = run(*args).stdout
    head = " ".join(" ".join(text.splitlines()[:6]).split())
    assert head.startswith(f"Model: patient SYN-001, fitted model {post} fitted (fit 2) to the "
                           "maps of session post-BoNT, 2024-02-21")
    assert "already under plan 1 (given 2024-01-12: botulinum)" in head
    assert "other fitted sessions: pre-BoNT (model 1); --session LABEL chooses" in head
    doc = json.loads(run(*args, "--json").stdout)["model"]
    assert doc["model_id"] == post and doc["fitted_on"]["measured_on"] == "2024-02-21"
    assert [p["plan_id"] for p in doc["fitted_on"]["under_plans"]] == [1]

    chosen = run(*args, "--session", "pre-BoNT").stdout.splitlines()[0]
    assert chosen == "Model: patient SYN-001, fitted model 1"
    r = run(*args, "--session", "post")
    assert r.exit_code == 1
    assert ("no model fitted to session 'post'; fitted: pre-BoNT (model 1), post-BoNT (model "
            f"{post})") in r.stderr
    r = run("whatif", "--severity", "elbow=severe", "--botox", "ef=100U", "--session", "x")
    assert r.exit_code == 2 and "give PATIENT" in r.stderr


def test_fit_says_when_it_changes_the_model_a_patient_stands_for(two_sessions: str) -> None:
    r = run("fit", "SYN-001", "--session", "post-BoNT", "--fit", "km", "--max-evals", "10",
            "--uncertainty", "gauss-newton", "--db", two_sessions)
    assert r.exit_code == 0, r.output
    said = " ".join(r.stderr.split())
    assert ("SYN-001: 'fieldbank whatif SYN-001' (every command naming the patient) now starts "
            "from model 3 (session post-BoNT, 2024-02-21; already under plan 1), not model 1 "
            "(session pre-BoNT, 2024-01-10): --session pre-BoNT chooses it.") in said
    # a refit of the same maps changes nothing a command uses: nothing said
    r = run("fit", "SYN-001", "--session", "pre-BoNT", "--fit", "km", "--max-evals", "10",
            "--uncertainty", "gauss-newton", "--db", two_sessions)
    assert r.exit_code == 0 and "now starts from" not in r.stderr
