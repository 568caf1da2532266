"""Arm parameters: Winter fractions, JSON round trip and validation messages."""

from __future__ import annotations

import dataclasses
import json
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fieldbank.errors import ParameterError
from fieldbank.params import ArmParams


def test_winter_fractions():
    p = ArmParams.from_anthropometry(80.0, 1.80)
    assert p.upper_arm_length_m == pytest.approx(0.186 * 1.80)
    assert p.forearm_length_m == pytest.approx(0.146 * 1.80 + 0.5 * 0.108 * 1.80)
    assert p.upper_arm_mass_kg == pytest.approx(0.028 * 80)
    assert p.forearm_mass_kg == pytest.approx(0.022 * 80)
    assert p.forearm_com_m == pytest.approx(0.682 * 0.146 * 1.80)
    assert p.upper_arm_inertia_kg_m2 == pytest.approx(0.028 * 80 * (0.322 * 0.186 * 1.80) ** 2)
    assert p.q_rest_rad == pytest.approx((math.radians(45), math.radians(70)))


def test_json_round_trip_is_exact():
    p = ArmParams.from_anthropometry(62.5, 1.63, "left").with_group("ef", km_n_per_m=4321.5)
    q = ArmParams.from_json(p.to_json())
    assert q == p
    assert json.loads(p.to_json())["schema"] == "fieldbank.arm-params"


def test_params_are_immutable():
    p = ArmParams.from_anthropometry()
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.height_m = 2.0  # type: ignore[misc]


@pytest.mark.parametrize(
    "override, pattern",
    [
        ({"km_n_per_m": (600.0, -5.0, 600.0, 600.0, 600.0, 600.0)},
         r"'km_n_per_m\[1\] \(se\)' parameter must be a finite number in \[0, 1e\+06\] N/m; "
         r"got -5.0"),
        ({"beta": (0.1, 0.1, 1.5, 0.1, 0.1, 0.1)},
         r"'beta\[2\] \(ef\)' parameter must be a finite number in \[0, 1\]; got 1.5"),
        ({"alpha_n": (100.0, 100.0, 100.0, float("nan"), 100.0, 100.0)},
         r"'alpha_n\[3\] \(ee\)' parameter must be a finite number in \[0, 1e\+06\] N; got nan"),
        ({"km_n_per_m": (600.0,) * 5}, r"'km_n_per_m' parameter must have 6 entries; got 5"),
        ({"passive_smoothing_m": "wide"}, r"'passive_smoothing_m' parameter must be a number"),
        ({"q_rest_rad": (0.7, 3.0)}, r"'q_rest_rad\[1\]' parameter must lie in the range"),
        ({"side": "middle"}, r"'side' parameter must be 'right' or 'left'"),
        ({"stiffness": 3.0}, r"Unknown arm parameter\(s\) stiffness"),
    ],
)
def test_bad_parameters_name_the_parameter_and_range(override, pattern):
    with pytest.raises(ParameterError, match=pattern):
        ArmParams.from_anthropometry(**override)


def test_from_dict_refuses_missing_and_unknown_fields():
    d = ArmParams.from_anthropometry().to_dict()
    del d["beta"]
    d["colour"] = "blue"
    with pytest.raises(ParameterError, match=r"missing field\(s\) beta; unknown field\(s\) colour"):
        ArmParams.from_dict(d, where="arm.json")
    with pytest.raises(ParameterError, match=r"arm\.json: not valid JSON"):
        ArmParams.from_json("{", where="arm.json")


@given(km=st.floats(allow_nan=True, allow_infinity=True), beta=st.floats(allow_nan=True))
def test_property_validation_accepts_exactly_the_bounds(km, beta):
    ok = math.isfinite(km) and 0 <= km <= 1e6 and math.isfinite(beta) and 0 <= beta <= 1
    try:
        p = ArmParams.from_anthropometry().with_group("bf", km_n_per_m=km, beta=beta)
    except ParameterError:
        assert not ok
    else:
        assert ok and p.km_n_per_m[4] == km
