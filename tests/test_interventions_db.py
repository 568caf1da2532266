"""``fieldbank whatif`` with the database: a stored patient's model in, lineage out.

Needs the storage layer (``fieldbank.storage``); runs on SQLite in a temporary directory.
"""

from __future__ import annotations

import json
from pathlib import Path

from click.testing import CliRunner

import fieldbank.storage as storage
from fieldbank.cli.main import cli
from fieldbank.evaluate.severity import synthesize
from fieldbank.interventions.plan import Plan, params_sha256


def _db(tmp_path: Path) -> str:
    return f"sqlite:///{tmp_path / 'fb.sqlite'}"


def test_patient_model_in_and_plan_with_lineage_out(tmp_path: Path) -> None:
    url = _db(tmp_path)
    fitted = synthesize({"elbow": "severe"})
    with storage.Database.open(url) as db:
        db.add_patient("P001", 75.0, 1.75, "right")
        db.add_model(synthesize({"elbow": "mild"}), "synthetic", "older", patient_code="P001")
        base = db.add_model(fitted, "fitted", "fit 1", patient_code="P001")
    r = CliRunner().invoke(cli, ["whatif", "P001", "--db", url, "--botox", "ef=200U", "--save",
                                    "--json"])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    ids = doc["saved"]
    assert ids["base_model_id"] == base.id
    assert doc["model"]["sha256"] == params_sha256(fitted)
    with storage.Database.open(url) as db:
        child = db.get_model(ids["result_model_id"])
        assert child.origin == "intervention" and child.parent_id == base.id
        assert child.patient_code == "P001"
        plan = db.get_plan(ids["plan_id"])
        assert plan.base_model_id == base.id and plan.result_model_id == child.id
        assert Plan.from_dict(plan.spec["plan"]).apply(fitted) == child.params
        assert plan.spec["child_sha256"] == params_sha256(child.params)
        lineage = db.model_lineage(child.id)
        assert [m.id for m in lineage] == [child.id, base.id]


def test_synthetic_model_is_stored_as_the_parent(tmp_path: Path) -> None:
    url = _db(tmp_path)
    r = CliRunner().invoke(cli, ["whatif", "--severity", "elbow=severe", "--lengthen", "bf=1cm",
                                    "--db", url, "--save", "--json"])
    assert r.exit_code == 0, r.output
    ids = json.loads(r.stdout)["saved"]
    with storage.Database.open(url) as db:
        parent = db.get_model(ids["base_model_id"])
        assert parent.origin == "synthetic"
        assert parent.params == synthesize({"elbow": "severe"})
        assert db.get_model(ids["result_model_id"]).parent_id == parent.id


def test_unknown_patient_and_patient_without_model(tmp_path: Path) -> None:
    url = _db(tmp_path)
    with storage.Database.open(url) as db:
        db.add_patient("P002", 70.0, 1.7, "left")
    r = CliRunner().invoke(cli, ["whatif", "P404", "--db", url, "--botox", "ef=100"])
    assert r.exit_code == 1 and "P404" in r.stderr
    r = CliRunner().invoke(cli, ["whatif", "P002", "--db", url, "--botox", "ef=100"])
    assert r.exit_code == 1 and "no fitted or synthetic model" in r.stderr
