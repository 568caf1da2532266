"""The ``fieldbank whatif`` command end to end (click's runner, real library underneath)."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from collections import Counter
from pathlib import Path

import pytest
from click.testing import CliRunner

from fieldbank.cli.main import cli
from fieldbank.evaluate.severity import synthesize
from fieldbank.interventions.catalogue import Botulinum
from fieldbank.interventions.errors import InterventionError
from fieldbank.interventions.inverse import unimpaired_reference
from fieldbank.interventions.plan import Plan, params_sha256
from fieldbank.interventions.spec import parse_length, parse_units
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from tests.report_helpers import svg_paths

#: Built before any test counts compilations (synthesis compiles the arm it starts from).
SEVERE_ELBOW = synthesize({"elbow": "severe"})


def run(*args: str) -> tuple[int, str, str]:
    r = CliRunner().invoke(cli, ["whatif", *args])
    return r.exit_code, r.stdout, r.stderr


def test_table_shows_before_and_after() -> None:
    code, out, _ = run("--severity", "elbow=severe", "--botox", "ef=200U", "--weeks", "5")
    assert code == 0, out
    assert ("botulinum toxin A (ef 200 U; onabotulinumtoxinA (Botox®) units), 5 weeks after "
            "injection") in out
    assert "elbow extension" in out and "Severity" in out
    # a summary first, every line within 100 columns; the rest with --detail
    assert out.splitlines()[3] == "Summary" and "Most change: " in out
    assert max(len(x) for x in out.splitlines()) <= 100
    assert "Probing motion" not in out
    code, detail, _ = run("--severity", "elbow=severe", "--botox", "ef=200U", "--detail")
    assert code == 0 and "Probing motion" in detail and "Field change" in detail
    assert max(len(x) for x in detail.splitlines()) <= 100
    line = next(x for x in out.splitlines() if x.strip().startswith("elbow extension"))
    # slow stretch unchanged, fast stretch and its velocity-dependent part lower
    cells = line.split()
    assert float(cells[2]) == pytest.approx(float(cells[4]), rel=0.01)
    assert float(cells[7]) < float(cells[5])


def test_json_output_is_complete_and_parsable() -> None:
    code, out, _ = run("--severity", "elbow=severe", "--lengthen", "bf=1cm", "--tenotomy", "ee",
                       "--json")
    assert code == 0
    doc = json.loads(out)
    kinds = [s["kind"] for s in doc["plan"]["steps"]]
    assert kinds == ["lengthening", "tenotomy"]
    assert doc["plan"]["steps"][0]["delta_m"] == 0.01
    c = doc["comparison"]
    assert set(c) >= {"fields", "potential_change", "severity", "probes", "stretches"}
    assert c["fields"][0]["diff_rms_n"] > 0
    assert doc["lineage"]["parent_sha256"] == doc["model"]["sha256"]


def test_params_file_plan_file_and_out_dir(tmp_path: Path) -> None:
    p = ArmParams.from_anthropometry(80.0, 1.8)
    pf = tmp_path / "arm.json"
    pf.write_text(p.to_json())
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps({"label": "test", "steps": [
        {"kind": "casting", "group": "ef"}, {"kind": "botulinum", "units": {"ee": 50}}]}))
    out = tmp_path / "out"
    code, stdout, _ = run("--params", str(pf), "--plan", str(plan), "--rhizotomy", "ef,ee:0.4",
                          "--out", str(out))
    assert code == 0, stdout
    after = ArmParams.from_file(out / "after.json")
    lineage = json.loads((out / "lineage.json").read_text())
    saved = Plan.from_file(out / "plan.json")
    assert [s.kind for s in saved.steps] == ["casting", "botulinum", "rhizotomy"]
    assert saved.apply(p) == after
    assert lineage["parent_sha256"] == params_sha256(p)
    assert lineage["child_sha256"] == params_sha256(after)


def test_timecourse_and_optimize() -> None:
    code, out, _ = run("--severity", "elbow=severe", "--optimize", "--total-units", "200",
                       "--groups", "ef,ee", "--timecourse", "--json")
    assert code == 0
    doc = json.loads(out)
    assert sum(doc["inverse"]["units"].values()) <= 200
    assert "not a treatment recommendation" in doc["inverse"]["notice"]
    assert len(doc["timecourse"]["weeks"]) == 25


def test_plot_is_written(tmp_path: Path) -> None:
    png = tmp_path / "f.png"
    code, _, err = run("--severity", "elbow=severe", "--botox", "ef=100", "--plot", str(png))
    assert code == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    code, _, err = run("--severity", "elbow=severe", "--botox", "ef=100", "--plot",
                       str(tmp_path / "f.jpg"))
    assert code == 1 and ".svg, .png or .pdf" in err


@pytest.mark.parametrize(("group", "changed", "unchanged"), [
    ("ef", "elbow extension", "elbow flexion"), ("ee", "elbow flexion", "elbow extension")])
def test_plot_shows_what_botulinum_changes(tmp_path: Path, group: str, changed: str,
                                           unchanged: str) -> None:
    """The what-if figure is the report's: the fast stretch that lengthens the injected group
    drops in the figure's own curve data, the other direction and the slow stretch do not."""
    svg = tmp_path / "w.svg"
    code, _, err = run("--severity", "elbow=severe", "--botox", f"{group}=150U", "--plot",
                       str(svg))
    assert code == 0, err
    text = svg.read_text(encoding="utf-8")
    ET.fromstring(text.split("?>", 1)[1])  # well-formed
    assert 'data-figure="whatif"' in text

    def peak(stretch: str, curve: str) -> float:
        (path,) = svg_paths(text, stretch=stretch, curve=curve)
        return float(-min(p[:, 1].min() for p in path))  # y down: the highest point

    assert peak(changed, "fast after") < peak(changed, "fast before") - 5.0  # px
    assert peak(unchanged, "fast after") == peak(unchanged, "fast before")
    assert abs(peak(changed, "slow after") - peak(changed, "slow before")) < 1.5
    assert f"treated: {group}" in text
    # botulinum leaves the static field alone: said in words instead of an empty figure
    assert "Static (passive, position-dependent) field, potential and stiffness: no change" \
        in text
    moving = float(text.split('data-moving-field-change-max-n="', 1)[1].split('"', 1)[0])
    assert moving > 0.1  # N: the moving field in the direction that stretches the group


def test_bad_input_is_refused_with_a_clear_message(tmp_path: Path) -> None:
    code, _, err = run("--severity", "elbow=severe", "--botox", "xx=100")
    assert code == 1 and "'xx' is not a muscle group" in err
    code, _, err = run("--severity", "elbow=severe", "--botox", "ef=lots")
    assert code == 1 and "--botox 'ef=lots'" in err
    code, _, err = run("--severity", "elbow=severe", "--botox", "ef=100", "--weeks", "99")
    assert code == 1 and "the weeks since the injection must be from 0 to 52 weeks" in err
    assert "weeks_since" not in err
    code, _, err = run("--severity", "elbow=severe", "--lengthen", "bf=1inch")
    assert code == 1 and "--lengthen" in err
    code, _, err = run("--severity", "elbow=severe")
    assert code == 2 and "No intervention given" in err
    code, _, err = run("--botox", "ef=100")
    assert code == 2 and "Give exactly one model" in err
    bad_db = tmp_path / "no-such-dir" / "sub" / "x.sqlite3"
    (tmp_path / "no-such-dir").write_text("a file where a directory should be")
    code, _, err = run("--severity", "elbow=severe", "--botox", "ef=100", "--save",
                       "--db", f"sqlite:///{bad_db}")
    assert code == 1 and "no-such-dir" in err
    code, _, err = run("P001", "--botox", "ef=100")
    assert code == 1 and "database" in err
    out = tmp_path / "never"
    code, _, err = run("--severity", "elbow=severe", "--botox", "ef=-4", "--out", str(out))
    assert code == 1 and not out.exists()


def test_option_parsers() -> None:
    assert parse_units(("ef=200U,ee=50", "bf=10 units")) == {"ef": 200.0, "ee": 50.0,
                                                              "bf": 10.0}
    assert parse_length("1cm", "--x") == 0.01
    assert parse_length("5 mm", "--x") == 0.005
    assert parse_length("0.02m", "--x") == 0.02
    # a bare number is refused, not read as metres (--botox's bare numbers are units of toxin)
    with pytest.raises(InterventionError, match=r"give the unit, e\.g\. 1cm"):
        parse_length("1", "--lengthen bf=1")


@pytest.fixture
def compiled(monkeypatch: pytest.MonkeyPatch) -> Counter[ArmParams]:
    """How often each distinct parameter set is compiled (Arm.from_params calls)."""
    calls: Counter[ArmParams] = Counter()
    real = Arm.from_params.__func__  # type: ignore[attr-defined]

    def counting(cls: type[Arm], p: ArmParams) -> Arm:
        calls[p] += 1
        return real(cls, p)  # type: ignore[no-any-return]

    monkeypatch.setattr(Arm, "from_params", classmethod(counting))
    return calls


def test_timecourse_compiles_each_model_once(compiled: Counter[ArmParams]) -> None:
    code, out, _ = run("--severity", "elbow=severe", "--botox", "ef=200U", "--timecourse",
                       "--json")
    assert code == 0, out
    before = SEVERE_ELBOW
    plan = Plan.of(Botulinum({"ef": 200.0}))
    weeks = {plan.at_week(float(w)).apply(before) for w in range(25)}
    # week 0 is the model before and week 5 (the default) the model after: 25 models in all,
    # and the unimpaired arm the synthesis of the model before starts from
    start = ArmParams.from_anthropometry()
    assert set(compiled) == weeks | {before, plan.apply(before), start}
    assert len(compiled) == 26
    assert all(n == 1 for n in compiled.values()), compiled.most_common(1)


def test_optimize_compiles_each_model_once(compiled: Counter[ArmParams]) -> None:
    code, out, _ = run("--severity", "elbow=severe", "--optimize", "--total-units", "200",
                       "--groups", "ef,ee", "--timecourse", "--json")
    assert code == 0, out
    before = SEVERE_ELBOW
    after = Plan.from_dict(json.loads(out)["plan"]).apply(before)
    assert {before, after, unimpaired_reference(before)} <= set(compiled)
    assert all(n == 1 for n in compiled.values()), compiled.most_common(1)


def test_session_above_the_label_maximum_warns_in_text_and_json() -> None:
    code, out, _ = run("--severity", "elbow=severe", "--botox", "ef=300U,ee=200U")
    assert code == 0, out
    text = " ".join(out.split())  # the warning's wrapped lines as one
    warning = text[text.index("WARNING: "):]
    assert "500 U" in warning and "400 U" in warning and "onabotulinumtoxinA" in warning
    code, out, _ = run("--severity", "elbow=severe", "--botox", "ef=300U,ee=200U", "--json")
    doc = json.loads(out)
    assert len(doc["warnings"]) == 1 and "500 U" in doc["warnings"][0]
    # a configurable limit; at or below it nothing is said
    code, out, _ = run("--severity", "elbow=severe", "--botox", "ef=300U,ee=200U",
                       "--session-limit", "500", "--json")
    assert json.loads(out)["warnings"] == []
    code, out, _ = run("--severity", "elbow=severe", "--botox", "ef=150U")
    assert code == 0 and "WARNING" not in out and "Warnings: none." in out
    # the doses name their unit wherever they are shown
    assert "onabotulinumtoxinA (Botox®) units" in out


def test_other_toxins_units_are_refused() -> None:
    with pytest.raises(InterventionError, match="not interchangeable"):
        Botulinum({"ef": 300.0}, toxin="abobotulinumtoxinA")
    doc = Plan.of(Botulinum({"ef": 100.0})).to_dict()
    assert doc["steps"][0]["toxin"] == "onabotulinumtoxinA"
    # a plan stored before the toxin was named reads as onabotulinumtoxinA, and one stored
    # with β scaled reproduces its after model
    old = {"kind": "botulinum", "units": {"ef": 100.0}, "scale_beta": True}
    step = Plan.from_dict({"steps": [old]}).steps[0]
    assert isinstance(step, Botulinum) and step.toxin == "onabotulinumtoxinA" and step.scale_beta
