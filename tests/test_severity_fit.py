"""A reflex-only spastic elbow end to end: synthesized, measured as maps (static and moving),
written as lab CSV files, ingested, fitted, and graded on the severity scale."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import pytest
from click.testing import CliRunner

from fieldbank import storage
from fieldbank.cli.fit import fit
from fieldbank.cli.ingest import ingest
from fieldbank.cli.main import cli
from fieldbank.evaluate.severity import synthesize
from fieldbank.fitting.synthetic import synthetic_patient
from fieldbank.maps import FieldMap
from fieldbank.params import ArmParams

#: Stiffness positions per map (each static and at ±1 m/s), as the recovery tests use.
N_STIFFNESS = 16


def _ingested(tmp_path: Path, maps: Sequence[FieldMap], patient: str) -> str:
    """The maps written as lab CSV files and ingested through the CLI into a new database of
    ``patient``, session "pre"; the database URL."""
    files = []
    for k, m in enumerate(maps):
        path = tmp_path / f"map{k}.csv"
        path.write_text(m.to_csv(), encoding="utf-8")
        files.append(str(path))
    url = f"sqlite:///{tmp_path / 'fieldbank.sqlite3'}"
    storage.Database.open(url).add_patient(patient, 75.0, 1.75, "right")
    res = CliRunner().invoke(ingest, ["--db", url, "--patient", patient, "--session", "pre",
                                      *files])
    assert res.exit_code == 0, res.output
    return url


@pytest.mark.parametrize("level", ["severe", "moderate"])
def test_reflex_only_elbow_is_graded_dynamic_after_ingest_and_fit(tmp_path: Path,
                                                                    level: str) -> None:
    base = ArmParams.from_anthropometry()
    truth = synthesize({"elbow:dynamic": level}, base)
    assert truth.km_n_per_m == base.km_n_per_m
    patient = synthetic_patient(truth, seed=4, n_stiffness=N_STIFFNESS, patient="SPAS")
    kinds = [m.kind for m in patient.maps]
    assert "postural" in kinds and any(m.velocity_m_per_s != (0.0, 0.0) for m in patient.maps)
    url = _ingested(tmp_path, patient.maps, "SPAS")
    runner = CliRunner()
    res = runner.invoke(fit, ["SPAS", "--db", url, "--json"])
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    sev = report["severity"]
    for g in ("ef", "ee"):
        assert sev[g]["dynamic"]["level"] == level, sev[g]
        assert sev[g]["passive"]["level"] == "unimpaired", sev[g]
        assert not sev[g]["dynamic"]["unidentified"]
    for g in ("sf", "se", "bf", "be"):
        assert sev[g]["passive"]["level"] == sev[g]["dynamic"]["level"] == "unimpaired"
    # the text read-out says the same, per muscle group
    res = runner.invoke(fit, ["SPAS", "--db", url])
    line = next(x for x in res.stdout.splitlines() if x.strip().startswith("elbow flexors"))
    assert line.split()[2:] == ["unimpaired", level]
    # a what-if on the fitted patient carries the grades (and would flag guesses)
    res = runner.invoke(cli, ["whatif", "SPAS", "--db", url, "--botox", "ef=150U", "--json"])
    assert res.exit_code == 0, res.output
    before = json.loads(res.stdout)["comparison"]["severity"]["before"]
    assert before["ef"]["dynamic"]["level"] == level


def test_postural_only_fit_flags_the_reflex_grades(tmp_path: Path) -> None:
    truth = synthesize({"elbow": "moderate"})
    patient = synthetic_patient(truth, seed=2, moving=False, patient="STAT")
    url = _ingested(tmp_path, patient.maps, "STAT")
    runner = CliRunner()
    report = json.loads(runner.invoke(fit, ["STAT", "--db", url, "--json"]).stdout)
    ef = report["severity"]["ef"]
    assert ef["passive"]["level"] == "moderate" and not ef["passive"]["unidentified"]
    assert set(ef["dynamic"]["unidentified"]) == {"alpha_ef", "beta_ef"}
    res = runner.invoke(cli, ["whatif", "STAT", "--db", url, "--botox", "ef=150U", "--json"])
    assert res.exit_code == 0, res.output
    before = json.loads(res.stdout)["comparison"]["severity"]["before"]
    assert set(before["ef"]["dynamic"]["unidentified"]) == {"alpha_ef", "beta_ef"}
    res = runner.invoke(cli, ["whatif", "STAT", "--db", url, "--botox", "ef=150U"])
    line = next(x for x in res.stdout.splitlines() if x.strip().startswith("elbow flexors"))
    assert "*" in line and "alpha_ef" in res.stdout
