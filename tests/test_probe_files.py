"""Designed probes as files: one ProbePath for the design, the classifier, the station and the
training; ``fieldbank probe design --out`` writes them, instructed training reads them, a bad
file is refused naming the file and the field."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fieldbank.cli.main import cli
from fieldbank.errors import FileRefused, ParameterError, ValidationError
from fieldbank.evaluate.design import design, severity_candidates
from fieldbank.haptic.trainee import simulate
from fieldbank.haptic.training import TrainingProtocol
from fieldbank.probepath import (
    PROBES_FORMAT,
    ProbePath,
    probes_document,
    read_probes,
)


def _run(*args: str):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(cli, list(args))


@pytest.fixture(scope="module")
def probes_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("probes") / "probes.json"
    r = _run("probe", "design", "--out", str(out), "--shoulder-offset", "0.05,0.1")
    assert r.exit_code == 0, r.output
    return out


def _write(path: Path, doc: object) -> Path:
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


def test_the_designed_probes_read_back_as_written(probes_file: Path) -> None:
    probes = read_probes(probes_file)
    d = design(severity_candidates())
    assert [p.name for p in probes] == [m.name for m in d.motions]
    for got, m in zip(probes, d.motions, strict=True):
        want = m.path((0.05, 0.1))
        assert got.shoulder_offset_m == (0.05, 0.1) and got.description == want.description
        assert np.array(got.points_m) == pytest.approx(np.array(want.points_m), abs=1e-6)
        assert np.array(got.shoulder_points_m) == pytest.approx(m.positions_m, abs=1e-6)
        assert got.times_s == pytest.approx(want.times_s, abs=1e-6)
    again = probes_file.with_name("again.json")
    _write(again, probes_document(probes))
    assert read_probes(again) == probes


def test_a_probe_path_checks_its_fields() -> None:
    p = ProbePath("stroke", "a stroke", (0.0, 0.5, 1.0), ((0.1, 0.6), (0.1, 0.55), (0.1, 0.5)),
                  (0.0, 0.1))
    assert p.duration_s == 1.0 and p.shoulder_points_m[0] == pytest.approx((0.1, 0.5))
    assert p.in_shoulder_frame().points_m == p.shoulder_points_m
    assert p.at(0.25) == pytest.approx((0.1, 0.575, 0.0, -0.1))
    assert ProbePath.from_dict(p.to_dict()) == p
    with pytest.raises(ParameterError, match=r"points_m\[1\]\[0\]: must be a finite number"):
        ProbePath("bad", "", (0.0, 1.0), ((0.0, 0.5), (float("nan"), 0.5)))
    with pytest.raises(ParameterError, match="must have as many entries as times_s"):
        ProbePath("bad", "", (0.0, 1.0), ((0.0, 0.5),) * 3)
    with pytest.raises(ParameterError, match="the path must take time"):
        ProbePath("still", "", (0.0, 0.0), ((0.0, 0.5),) * 2)
    with pytest.raises(ParameterError, match="name: must be text of 1-64"):
        ProbePath("", "", (0.0, 1.0), ((0.0, 0.5),) * 2)


def test_a_bad_probes_file_names_the_file_and_every_field(probes_file: Path,
                                                          tmp_path: Path) -> None:
    good = json.loads(probes_file.read_text(encoding="utf-8"))
    first = good["probes"][0]
    bad = {**good, "probes": [
        {**first, "times_s": [*first["times_s"][:3], -1.0, *first["times_s"][4:]]},
        {k: v for k, v in first.items() if k != "points_m"},
        {**first, "name": "stroke 1", "frame": "sideways", "colour": "red"},
        first,
    ]}
    f = _write(tmp_path / "bad.json", bad)
    with pytest.raises(ValidationError) as e:
        read_probes(f)
    msg = str(e.value)
    assert msg.startswith(f"{f}: not a usable probes file")
    assert f"{f}: probes[0].times_s[3]: must be a finite number in [0, 600] s; got -1.0" in msg
    assert f"{f}: probes[1].points_m: missing" in msg
    assert f"{f}: probes[2].colour: unknown field" in msg
    assert f"{f}: probes[3].name: 'stroke 1' is the name of probes[0] too" in msg
    cases = [
        ({**good, "format": "fieldbank-plan"}, "format: must be 'fieldbank-probes'"),
        ({**good, "version": 2}, "version: 2 is newer than this fieldbank reads (1)"),
        ({**good, "probes": []}, "probes: must be a list of 1-"),
        ({**good, "probes": [{**first, "points_m": first["points_m"][:-1]}]},
         "probes[0].points_m: must have as many entries as times_s"),
        ({**good, "probes": [{**first, "frame": "shoulder"}]},
         "probes[0].shoulder_offset_m: a path in the shoulder frame has no shoulder offset"),
    ]
    for doc, words in cases:
        with pytest.raises(ValidationError) as e:
            read_probes(_write(tmp_path / "case.json", doc))
        assert f"{tmp_path / 'case.json'}: {words}" in str(e.value), str(e.value)
    (tmp_path / "text.json").write_text('{"format": "fieldbank-probes", "version": 1, '
                                        '"probes": [NaN]}', encoding="utf-8")
    with pytest.raises(ValidationError, match=r"text\.json: not JSON: NaN is not a number"):
        read_probes(tmp_path / "text.json")
    with pytest.raises(FileRefused, match="not a regular file"):
        read_probes(tmp_path)
    many = _write(tmp_path / "many.json", {**good, "probes": [
        {**first, "name": f"p{k}"} for k in range(9)]})
    with pytest.raises(ValidationError, match=r"many\.json: probes: must be a list of 1-8 probes"):
        read_probes(many, 8)


def test_simulated_training_follows_designed_probes_from_a_file(probes_file: Path) -> None:
    """The simulated trainee, instructed with only the designed probes, moves the handle along
    them: relative to the shoulder, wherever the file's robot put it."""
    probes = read_probes(probes_file)
    proto = TrainingProtocol(instruction="instructed", probes=(), extra_probes=probes,
                             familiarisation_rounds=1, assessment_repetitions=0)
    assert TrainingProtocol.from_dict(proto.to_dict()) == proto
    res = simulate(proto)
    assert not res.trace.faults
    hand = np.c_[res.trace.column("x_m"), res.trace.column("y_m")].astype(float)
    hand -= res.trace.metadata["renderer"]["shoulder_offset_m"]
    for p in probes:
        for target in (p.shoulder_points_m[len(p.points_m) // 2], p.shoulder_points_m[-1]):
            assert np.linalg.norm(hand - target, axis=1).min() < 0.02, (p.name, target)
    with pytest.raises(ParameterError, match="instructed training draws probes to follow"):
        TrainingProtocol(instruction="instructed", probes=())


def test_train_simulate_takes_a_probes_file_and_refuses_a_bad_one(probes_file: Path,
                                                                  tmp_path: Path) -> None:
    r = _run("haptic", "train", "simulate", "--probes", str(probes_file), "--no-seed-probes",
             "--familiarisation-rounds", "1", "--repetitions", "0", "--no-db", "--json")
    assert r.exit_code == 0, r.output
    proto = json.loads(r.stdout)["protocol"]
    assert proto["instruction"] == "instructed" and proto["probes"] == []
    assert [p["name"] for p in proto["extra_probes"]] == [p.name for p in
                                                          read_probes(probes_file)]
    bad = _write(tmp_path / "bad.json", {"format": PROBES_FORMAT, "version": 1, "probes": [
        {"name": "x", "times_s": [0, 1], "points_m": [[0, 0.5], [0, "far"]]}]})
    r = _run("haptic", "train", "simulate", "--probes", str(bad), "--short", "--no-db")
    assert r.exit_code == 1
    assert f"{bad}: probes[0].points_m[1][1]: must be a number" in r.output
    r = _run("haptic", "train", "simulate", "--probes", str(probes_file), "--non-instructed",
             "--short", "--no-db")
    assert r.exit_code == 2 and "needs --instructed" in r.output


def test_the_station_trains_with_designed_probes(probes_file: Path, tmp_path: Path) -> None:
    from fieldbank.cli.haptic_session import station_protocol

    proto = station_protocol("short", probes_file)
    assert proto.extra_probes == read_probes(probes_file)
    assert proto.familiarisation_rounds == 1 and proto.probes == ("pull", "semi-ellipse")
    assert station_protocol("seed", None).extra_probes == ()
    bad = _write(tmp_path / "bad.json", {"format": PROBES_FORMAT, "version": 1,
                                         "probes": [{"name": "x"}]})
    r = _run("haptic", "serve", "--robot", "sim://", "--station", "--no-db",
             "--training-probes", str(bad))
    assert r.exit_code == 1 and f"{bad}: probes[0].times_s: missing" in r.output
    r = _run("haptic", "serve", "--robot", "sim://", "--no-db", "--training-probes",
             str(probes_file))
    assert r.exit_code == 2 and "add --station" in r.output
