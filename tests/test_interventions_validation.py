"""Invalid interventions and plans are refused with messages that name the bad part."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fieldbank.interventions.catalogue import (
    Baclofen,
    Botulinum,
    Intervention,
    Lengthening,
    Rhizotomy,
    SerialCasting,
    Tenotomy,
)
from fieldbank.interventions.errors import InterventionError
from fieldbank.interventions.plan import Plan
from fieldbank.params import ArmParams


@pytest.mark.parametrize(
    ("build", "words"),
    [
        (lambda: Botulinum({"xx": 100.0}), ["botulinum", "unknown muscle group 'xx'",
                                            "sf = shoulder flexors, se = shoulder extensors"]),
        (lambda: Botulinum({"ef": -10.0}), ["botulinum", "'units[ef]'", ">= 0", "-10"]),
        (lambda: Botulinum({"ef": 100.0}, weeks_since=80.0), ["'weeks_since'", "<= 52", "80"]),
        (lambda: Botulinum({"ef": 100.0}, weeks_since=-1.0), ["'weeks_since'", ">= 0"]),
        (lambda: Botulinum({}), ["names no muscle group"]),
        (lambda: Botulinum({"ef": 900.0}), ["'units[ef]'", "<= 600"]),
        (lambda: Botulinum({"ef": 10.0}, peak_week=20.0), ["peak_week < wearoff_week"]),
        (lambda: Lengthening(group="ef", delta_m=-0.01), ["lengthening", "'delta_m'", "> 0"]),
        (lambda: Lengthening(group="hand", delta_m=0.01), ["unknown muscle group 'hand'"]),
        (lambda: Lengthening(group="ef", delta_m=0.01, alpha_factor=1.5), ["'alpha_factor'"]),
        (lambda: Tenotomy(group="ef", residual_fraction=1.0), ["'residual_fraction'", "< 1"]),
        (lambda: Rhizotomy(groups=("ef", "qq")), ["rhizotomy", "'qq'"]),
        (lambda: Baclofen(factor=2.0), ["baclofen", "'factor'", "<= 1"]),
        (lambda: SerialCasting(group="ef", km_factor=0.0), ["casting", "'km_factor'", "> 0"]),
    ],
)
def test_bad_intervention_is_refused_naming_the_field(build, words: list[str]) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(InterventionError) as info:
        build()
    for w in words:
        assert w in str(info.value)


def test_every_problem_of_one_intervention_is_listed() -> None:
    with pytest.raises(InterventionError) as info:
        Botulinum({"ef": -1.0, "zz": 5.0}, weeks_since=99.0)
    msg = str(info.value)
    assert "'units[ef]'" in msg and "'zz'" in msg and "'weeks_since'" in msg


def test_plan_names_the_bad_step() -> None:
    doc = {"steps": [
        {"kind": "lengthening", "group": "bf", "delta_m": 0.01},
        {"kind": "botulinum", "units": {"xx": 100}},
        {"kind": "botulinum", "units": {"ef": -3}, "weeks_since": 5},
        {"kind": "surgery"},
        {"kind": "tenotomy", "group": "ef", "speed": 3},
    ]}
    with pytest.raises(InterventionError) as info:
        Plan.from_dict(doc, where="plan.json")
    msg = str(info.value)
    assert msg.startswith("plan.json: 4 problems")
    assert "step 2 (botulinum): unknown muscle group 'xx'" in msg
    assert "step 3 (botulinum): 'units[ef]' must be >= 0" in msg
    assert "step 4 (surgery): unknown intervention kind 'surgery'" in msg
    assert "step 5 (tenotomy): unknown field(s) 'speed'" in msg
    assert "step 1" not in msg


def test_plan_document_shape_errors() -> None:
    with pytest.raises(InterventionError, match="'steps' must be a non-empty list"):
        Plan.from_dict({"steps": []})
    with pytest.raises(InterventionError, match="'version' 7 is not supported"):
        Plan.from_dict({"version": 7, "steps": [{"kind": "tenotomy", "group": "ef"}]})
    with pytest.raises(InterventionError, match="not valid JSON"):
        Plan.from_json("{steps: ")
    with pytest.raises(InterventionError, match="a plan needs at least one step"):
        Plan(())


def test_plan_file_errors_name_the_file(tmp_path: Path) -> None:
    f = tmp_path / "p.json"
    f.write_text(json.dumps({"steps": [{"kind": "botulinum", "units": {"ef": -1}}]}))
    with pytest.raises(InterventionError, match=r"p\.json: step 1 \(botulinum\)"):
        Plan.from_file(f)
    with pytest.raises(InterventionError, match="cannot read"):
        Plan.from_file(tmp_path / "missing.json")


def test_step_that_would_break_the_model_is_named() -> None:
    plan = Plan.of(*[Lengthening(group="ef", delta_m=0.04)] * 3)
    with pytest.raises(InterventionError, match=r"step 3 \(lengthening\).*slack_offset_m"):
        plan.apply(ArmParams.from_anthropometry())


def test_from_dict_refuses_a_kind_mismatch() -> None:
    with pytest.raises(InterventionError, match="expected kind 'tenotomy'"):
        Tenotomy.from_dict({"kind": "casting", "group": "ef"})
    with pytest.raises(InterventionError, match="expected a JSON object"):
        Intervention.from_dict([1, 2])  # type: ignore[arg-type]
    with pytest.raises(InterventionError, match="unknown intervention kind"):
        Intervention.from_dict({"kind": ["botulinum"]})
    with pytest.raises(InterventionError, match="'delta_m' must be a finite number; got '1cm'"):
        Intervention.from_dict({"kind": "lengthening", "group": "ef", "delta_m": "1cm"})


def test_docs_list_every_default_with_its_value_and_source() -> None:
    from fieldbank.interventions.defaults import DEFAULTS

    text = (Path(__file__).resolve().parents[1] / "docs" / "interventions.md").read_text()
    for name, d in DEFAULTS.items():
        row = f"| `{name}` | {d.value:.6g} | {d.unit} | {d.source} |"
        assert row in text, f"docs/interventions.md is out of date for {name}"
        assert d.source.strip()


@pytest.mark.parametrize("cls", [Botulinum, Lengthening, Tenotomy, Rhizotomy, Baclofen,
                                 SerialCasting])
def test_bounds_tables_name_fields_and_generate_the_messages(cls) -> None:  # type: ignore[no-untyped-def]
    from dataclasses import fields

    names = {f.name for f in fields(cls)}
    assert cls.BOUNDS and set(cls.BOUNDS) <= names
    assert set(cls.NO_CHANGE) <= set(cls.BOUNDS)
    for name, interval in cls.BOUNDS.items():
        if name == "units" or interval.high is None:
            continue
        kw = {"units": {"ef": 10.0}} if cls is Botulinum else (
            {"group": "ef"} if "group" in names else {})
        with pytest.raises(InterventionError) as info:
            cls(**kw, **{name: interval.high + 1.0})
        assert f"'{name}' must be <= {interval.high:g}" in str(info.value)
