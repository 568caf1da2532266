"""The fit and models commands on the real field database (SQLite).

Runs where the storage layer (fieldbank.storage) is installed with the fitter.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

import fieldbank.storage as storage
from fieldbank.cli.fit import fit, models
from fieldbank.fitting import ArmFitter
from fieldbank.fitting.dbstore import DatabaseFitStore
from fieldbank.fitting.records import fit_patient
from fieldbank.fitting.synthetic import impaired_params, synthetic_patient
from fieldbank.params import ArmParams


@click.group()
def cli() -> None:
    pass


cli.add_command(fit)
cli.add_command(models)


def test_fit_stored_patient_end_to_end(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'db' / 'fieldbank.sqlite3'}"
    db = storage.Database.open(url)
    db.add_patient("P-1", 75.0, 1.75, "right")
    base = ArmParams.from_anthropometry()
    pat = synthetic_patient(impaired_params("elbow", "severe", base), seed=1, patient="P-1")
    files = []
    for k, m in enumerate(pat.maps):
        data = m.to_csv().encode()
        files.append(storage.IncomingFile(f"m{k}.csv", hashlib.sha256(data).hexdigest(), "csv",
                                          data, (m,)))
    db.ingest_files("P-1", "pre", files)
    store = DatabaseFitStore(db)
    out = fit_patient(store, "P-1", "pre", ArmFitter(seed=0))
    detail = store.get_model(out.saved.model_id)
    model = detail.model
    assert model.origin == "fitted" and model.patient_code == "P-1"
    assert model.params == out.fitter.params_
    assert detail.fit is not None and detail.fit["map_ids"] == list(out.record.map_ids)
    assert model.params.km_n_per_m[2] == pytest.approx(
        pat.truth.km_n_per_m[2], rel=0.15)

    res = CliRunner().invoke(cli, ["fit", "P-1", "--db", url, "--json"])
    assert res.exit_code == 0, res.output
    mid = json.loads(res.stdout)["model_id"]
    res = CliRunner().invoke(cli, ["models", "show", str(mid), "--db", url])
    assert res.exit_code == 0 and "fit: mlsl+lbfgs" in res.stdout
    res = CliRunner().invoke(cli, ["models", "list", "--db", url, "--json"])
    rows = json.loads(res.stdout)
    assert len(rows) == 2
    assert list(rows[0]) == ["id", "patient", "origin", "label", "parent_id", "created_at",
                             "plan_id", "plans_from"]
    res = CliRunner().invoke(cli, ["models", "show", str(mid), "--db", url, "--json"])
    shown = json.loads(res.stdout)
    assert list(shown) == [*rows[0], "params", "lineage", "fit"]
    assert shown["id"] == mid and shown["patient"] == "P-1" and shown["lineage"] == []
    assert shown["fit"]["algorithm"] == "mlsl+lbfgs" and shown["fit"]["seed"] == 0
    res = CliRunner().invoke(cli, ["fit", "P-404", "--db", url])
    assert res.exit_code != 0 and "P-404" in str(res.exception)
