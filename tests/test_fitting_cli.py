"""``fieldbank fit`` and ``fieldbank models list|show`` over an in-memory FitStore."""

from __future__ import annotations

import json
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import click
import pytest
from click.testing import CliRunner

from fieldbank.cli.fit import fit, models
from fieldbank.errors import FieldbankError, FitError
from fieldbank.fitting.records import FitSubmission, ModelDetail, PatientMap, SavedFit
from fieldbank.fitting.synthetic import impaired_params, synthetic_patient
from fieldbank.params import ArmParams
from fieldbank.storage import StoredModel

BASE = ArmParams.from_anthropometry()


class MemoryStore:
    """The FitStore protocol in memory: patients, maps per session, models and fits."""

    def __init__(self) -> None:
        self.patients: dict[str, ArmParams] = {}
        self.maps: list[PatientMap] = []
        self.models: list[ModelDetail] = []
        self.fits: list[FitSubmission] = []

    def patient_params(self, patient: str) -> ArmParams:
        if patient not in self.patients:
            raise FitError(f"no patient {patient!r}")
        return self.patients[patient]

    def maps_for(self, patient: str, session: str | None = None) -> Sequence[PatientMap]:
        return [m for m in self.maps if m.patient == patient
                and (session is None or m.session == session)]

    def add_fit(self, record: FitSubmission) -> SavedFit:
        self.fits.append(record)
        model = StoredModel(len(self.models) + 1, record.patient, None, "fitted",
                            f"fit {len(self.fits)}", record.params, datetime.now(UTC))
        self.models.append(ModelDetail(model, (), dict(record.report)))
        return SavedFit(len(self.fits), model.id)

    def list_models(self, patient: str | None = None) -> Sequence[StoredModel]:
        return [d.model for d in self.models
                if patient is None or d.model.patient_code == patient]

    def get_model(self, model_id: int | str) -> ModelDetail:
        for d in self.models:
            if d.model.id == model_id:
                return d
        raise FitError(f"no model {model_id}")


@click.group()
def cli() -> None:
    pass


cli.add_command(fit)
cli.add_command(models)


@pytest.fixture(scope="module")
def store() -> MemoryStore:
    s = MemoryStore()
    s.patients["P1"] = BASE
    s.patients["P2"] = BASE
    pat = synthetic_patient(impaired_params("elbow", "moderate", BASE), seed=21, patient="P1")
    for k, m in enumerate(pat.maps):
        s.maps.append(PatientMap(100 + k, "P1", "pre", m))
    static = synthetic_patient(impaired_params("elbow", "moderate", BASE), seed=22,
                               moving=False, patient="P2")
    for k, m in enumerate(static.maps):
        s.maps.append(PatientMap(200 + k, "P2", "pre", m))
    return s


def _run(store: MemoryStore, args: list[str]) -> Any:
    runner = CliRunner()
    return runner.invoke(cli, args, obj={"fit_store": lambda url: store}, catch_exceptions=True)


def test_fit_json_stores_fit_and_model(store: MemoryStore, tmp_path: Path) -> None:
    plot = tmp_path / "fit.svg"
    res = _run(store, ["fit", "P1", "--session", "pre", "--seed", "3", "--json",
                       "--plot", str(plot)])
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    assert report["patient"] == "P1" and report["seed"] == 3
    assert report["map_ids"] == [100, 101, 102, 103]
    assert report["model_id"] == store.models[-1].model.id
    assert store.fits[-1].params == ArmParams.from_dict(report["params"])
    assert plot.read_text().lstrip().startswith("<?xml")
    assert "evaluations" in res.stderr  # progress on stderr


def test_fit_static_maps_warns_under_determined(store: MemoryStore) -> None:
    res = _run(store, ["fit", "P2"])
    assert res.exit_code == 0, res.output
    assert "status: under-determined" in res.stdout
    assert "all stiffness maps are static" in res.stdout
    assert "not identified" in res.stderr


def test_fit_refuses_no_maps_and_foreign_maps(store: MemoryStore) -> None:
    res = _run(store, ["fit", "P1", "--session", "post"])
    assert res.exit_code != 0
    assert isinstance(res.exception, FieldbankError)
    assert "no maps to fit: patient 'P1', session 'post'" in str(res.exception)
    bad = MemoryStore()
    bad.patients["P1"] = BASE
    bad.maps = [PatientMap(1, "P1", None, store.maps[0].map),
                PatientMap(2, "P9", None, store.maps[1].map)]
    bad.maps_for = lambda patient, session=None: bad.maps  # type: ignore[method-assign]
    res = _run(bad, ["fit", "P1"])
    assert "map 2 belongs to patient 'P9', not to 'P1'" in str(res.exception)
    assert bad.fits == []  # nothing stored


def test_models_list_and_show(store: MemoryStore) -> None:
    if not store.models:
        assert _run(store, ["fit", "P1"]).exit_code == 0
    res = _run(store, ["models", "list", "--json"])
    rows = json.loads(res.stdout)
    assert rows and rows[0]["origin"] == "fitted"
    res = _run(store, ["models", "list", "--patient", "P1"])
    assert "fitted" in res.stdout
    mid = str(rows[0]["id"])
    res = _run(store, ["models", "show", mid])
    assert res.exit_code == 0, res.output
    assert "ef" in res.stdout and "Km N/m" in res.stdout and "fit: mlsl+lbfgs" in res.stdout
    res = _run(store, ["models", "show", mid, "--json"])
    assert json.loads(res.stdout)["params"]["schema"] == "fieldbank.arm-params"


def test_plot_png_and_bad_extension(tmp_path: Path) -> None:
    from fieldbank.errors import ValidationError
    from fieldbank.figures import save
    from fieldbank.figures.fit import fit_figure
    from fieldbank.fitting import ArmFitter

    pat = synthetic_patient(impaired_params("shoulder", "mild", BASE), seed=5)
    f = ArmFitter().fit(pat.maps, BASE)
    fig = fit_figure(f.maps_, f.predict(f.maps_), f.r2_)
    out = save(fig, tmp_path / "a.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert save(fig, tmp_path / "a.pdf").read_bytes()[:5] == b"%PDF-"
    with pytest.raises(ValidationError, match=r"\.svg, \.png or \.pdf"):
        save(fig, tmp_path / "a.gif")
    assert not (tmp_path / "a.gif").exists()
    with pytest.raises(FitError, match="one fitted map per measured map"):
        fit_figure(f.maps_, [])
