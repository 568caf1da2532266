"""Bad input is refused with a clear message; handle-on-arm maps are converted."""

from __future__ import annotations

import numpy as np
import pytest

from fieldbank.errors import FitError
from fieldbank.fitting import ArmFitter
from fieldbank.fitting.synthetic import impaired_params, synthetic_patient
from fieldbank.maps import FieldMap
from fieldbank.params import ArmParams

BASE = ArmParams.from_anthropometry()


@pytest.fixture(scope="module")
def patient():  # type: ignore[no-untyped-def]
    return synthetic_patient(impaired_params("elbow", "mild", BASE), seed=11)


def _with(m: FieldMap, **changes: object) -> FieldMap:
    fields = dict(kind=m.kind, positions_m=m.positions_m, values=m.values, sd=m.sd,
                  frame=m.frame, sign=m.sign, velocity_m_per_s=m.velocity_m_per_s,
                  source=m.source, metadata=dict(m.metadata))
    fields.update(changes)
    return FieldMap(**fields)  # type: ignore[arg-type]


def test_no_maps_refused() -> None:
    with pytest.raises(FitError, match="no maps to fit"):
        ArmFitter().fit([], BASE)


def test_maps_of_another_patient_refused(patient) -> None:  # type: ignore[no-untyped-def]
    maps = list(patient.maps)
    maps[2] = _with(maps[2], metadata={"patient": "P-OTHER"})
    with pytest.raises(FitError, match=r"different patients.*map 2 of 'P-OTHER'"):
        ArmFitter().fit(maps, BASE)
    with pytest.raises(FitError, match="belongs to patient 'SYN', not to 'P-007'"):
        ArmFitter().fit(patient.maps, BASE, patient="P-007")


def test_inconsistent_units_refused(patient) -> None:  # type: ignore[no-untyped-def]
    maps = list(patient.maps)
    maps[1] = _with(maps[1], metadata={"patient": "SYN", "units": "N/mm"})
    with pytest.raises(FitError, match=r"map 1 .*inconsistent units.*'N/mm'.*N/m"):
        ArmFitter().fit(maps, BASE)
    maps = list(patient.maps)
    maps[0] = _with(maps[0], metadata={"patient": "SYN", "position_unit": "mm"})
    with pytest.raises(FitError, match="positions must be in m"):
        ArmFitter().fit(maps, BASE)


def test_unreachable_position_refused_naming_map_and_index(patient) -> None:  # type: ignore[no-untyped-def]
    maps = list(patient.maps)
    pos = maps[0].positions_m.copy()
    pos[4] = (0.05, 0.9)  # 0.9 m from the shoulder: out of reach
    maps[0] = _with(maps[0], positions_m=pos)
    with pytest.raises(FitError, match=r"map 0 .*position index 4 \(0.0500, 0.9000\)"):
        ArmFitter().fit(maps, BASE)


def test_bad_options_refused(patient) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(FitError, match="unknown algorithm 'annealing'"):
        ArmFitter(algorithm="annealing").fit(patient.maps, BASE)
    with pytest.raises(FitError, match="seed must be"):
        ArmFitter(seed=-1).fit(patient.maps, BASE)
    with pytest.raises(FitError, match="cannot fit gamma"):
        ArmFitter(fit=("km", "gamma")).fit(patient.maps, BASE)
    with pytest.raises(FitError, match="bounds override 'km_xx'"):
        ArmFitter(bounds={"km_xx": (1.0, 2.0)}).fit(patient.maps, BASE)


def test_results_before_fit_raise() -> None:
    fitter = ArmFitter()
    with pytest.raises(FitError, match=r"no result 'params_' yet: call fit"):
        _ = fitter.params_
    with pytest.raises(FitError, match="call fit"):
        fitter.report()
    with pytest.raises(AttributeError):
        _ = fitter.not_a_result


def test_handle_on_arm_maps_are_converted(patient) -> None:  # type: ignore[no-untyped-def]
    flipped = [_with(m, values=-m.values, sign="handle-on-arm") for m in patient.maps]
    a = ArmFitter(seed=0).fit(patient.maps, BASE)
    b = ArmFitter(seed=0).fit(flipped, BASE)
    assert a.params_ == b.params_
    assert all(m.sign == "arm-on-handle" for m in b.maps_)


def test_bounds_override_is_respected(patient) -> None:  # type: ignore[no-untyped-def]
    fit = ArmFitter(seed=0, bounds={"km": (100.0, 1000.0)}).fit(patient.maps, BASE)
    km = np.array(fit.params_.km_n_per_m)
    assert np.all(km >= 100.0 - 1e-9) and np.all(km <= 1000.0 + 1e-9)
    assert any(name.startswith("km_") for name in fit.at_bounds_)
