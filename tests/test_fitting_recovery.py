"""Recovery of synthetic patients, the under-determined case, determinism and algorithms."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fieldbank.fitchoices import ALGORITHMS
from fieldbank.fitting import ArmFitter
from fieldbank.fitting.synthetic import LEVELS, impaired_params, synthetic_patient
from fieldbank.params import GROUP_INDEX, JOINT_GROUPS, ArmParams

BASE = ArmParams.from_anthropometry()
#: 16 stiffness positions (each static and at ±1 m/s): with 9, the sparse stretch reflex is
#: sometimes not seen well enough to predict it at new positions (see the benchmark).
N_STIFFNESS = 16


@pytest.mark.parametrize("level", LEVELS)
@pytest.mark.parametrize("group", list(JOINT_GROUPS))
def test_recovers_impaired_group(group: str, level: str) -> None:
    truth = impaired_params(group, level, BASE)
    patient = synthetic_patient(truth, seed=1, n_stiffness=N_STIFFNESS, noise=0.05)
    fit = ArmFitter(seed=0).fit(patient.maps, BASE)
    for g in JOINT_GROUPS[group]:
        i = GROUP_INDEX[g]
        assert fit.params_.km_n_per_m[i] == pytest.approx(truth.km_n_per_m[i], rel=0.15), g
    held = fit.score(patient.held_out)
    assert min(held) >= 0.95, held
    assert len(fit.r2_) == len(patient.maps)
    assert min(fit.r2_) > 0.95
    # with sd = the true noise the whitened χ² is near its expectation (number of values)
    m = fit.problem_.y.size
    assert 0.5 * m < fit.chi2_ < 1.5 * m


def test_static_maps_only_are_reported_under_determined() -> None:
    truth = impaired_params("elbow", "moderate", BASE)
    patient = synthetic_patient(truth, seed=2, moving=False)
    fit = ArmFitter(seed=0).fit(patient.maps, BASE)
    assert fit.status_ == "under-determined"
    flagged = {u.name: u.reason for u in fit.unidentified_}
    for g in ("sf", "se", "ef", "ee", "bf", "be"):
        for kind in ("alpha", "beta"):
            assert f"{kind}_{g}" in flagged
            assert "static" in flagged[f"{kind}_{g}"] and "reflex" in flagged[f"{kind}_{g}"]
    # the passive stiffness is still determined by static maps
    assert not any(name.startswith("km_e") for name in flagged)
    i = GROUP_INDEX["ef"]
    assert fit.params_.km_n_per_m[i] == pytest.approx(truth.km_n_per_m[i], rel=0.15)
    # the unseen reflex parameters stay at the prior (unimpaired), not at arbitrary values
    assert np.allclose(fit.params_.beta, 0.1, atol=1e-6)
    report = fit.report()
    assert report["status"] == "under-determined"
    assert len(report["unidentified"]) >= 12


def test_moving_maps_identify_the_impaired_reflex() -> None:
    truth = impaired_params("elbow", "severe", BASE)
    patient = synthetic_patient(truth, seed=1, n_stiffness=N_STIFFNESS)
    fit = ArmFitter(seed=0).fit(patient.maps, BASE)
    names = {u.name for u in fit.unidentified_}
    assert "km_ef" not in names and "km_ee" not in names
    assert fit.relative_sd_["km_ef"] < 0.05
    # the uncertainty is a positive SD, small against the value for a well-determined Km
    assert 0 < fit.uncertainty_["km_ef"] < 0.1 * fit.params_.km_n_per_m[GROUP_INDEX["ef"]]


def test_same_seed_same_fit_and_report_is_json() -> None:
    truth = impaired_params("shoulder", "mild", BASE)
    patient = synthetic_patient(truth, seed=3)
    for algorithm in ("mlsl+lbfgs", "crs2+bobyqa"):
        a = ArmFitter(algorithm=algorithm, seed=7).fit(patient.maps, BASE)
        b = ArmFitter(algorithm=algorithm, seed=7).fit(patient.maps, BASE)
        assert a.params_ == b.params_
        assert a.cost_ == b.cost_
        assert a.n_evals_ == b.n_evals_
    report = json.loads(json.dumps(a.report()))
    assert report["algorithm"] == "crs2+bobyqa" and report["seed"] == 7
    assert report["n_evals"] > 0 and report["time_s"] > 0
    assert ArmParams.from_dict(report["params"]) == a.params_
    assert [m["n"] for m in report["maps"]] == [m.n for m in patient.maps]


@pytest.mark.parametrize("algorithm", [a for a in ALGORITHMS if a != "mlsl+lbfgs"])
def test_every_algorithm_fits(algorithm: str) -> None:
    truth = impaired_params("biarticular", "moderate", BASE)
    patient = synthetic_patient(truth, seed=4, n_stiffness=N_STIFFNESS)
    ours = ArmFitter(seed=0).fit(patient.maps, BASE)
    max_evals = 20_000 if algorithm == "dual_annealing" else None
    fit = ArmFitter(algorithm=algorithm, seed=0, max_evals=max_evals).fit(patient.maps, BASE)
    assert fit.algorithm_ == algorithm
    assert np.isfinite(fit.cost_)
    # the same cost function: ours evaluates the other's optimum consistently
    assert fit.problem_.cost(fit.theta_) == pytest.approx(fit.cost_)
    if algorithm != "dual_annealing":
        assert fit.cost_ <= 1.05 * ours.cost_
        assert min(fit.r2_) > 0.95


def test_fitting_the_rest_posture() -> None:
    truth = impaired_params("elbow", "moderate", BASE).replace(q_rest_rad=(0.70, 1.35))
    patient = synthetic_patient(truth, seed=5, n_stiffness=N_STIFFNESS)
    fit = ArmFitter(seed=0, fit=("km", "alpha", "beta", "q_rest")).fit(patient.maps, BASE)
    assert np.allclose(fit.params_.q_rest_rad, truth.q_rest_rad, atol=np.radians(3.0))
    assert fit.params_.km_n_per_m[2] == pytest.approx(truth.km_n_per_m[2], rel=0.15)
    assert "q_rest_shoulder" in fit.uncertainty_


@pytest.mark.parametrize("group", list(JOINT_GROUPS))
def test_fitted_model_gets_the_synthesized_severity(group: str) -> None:
    truth = impaired_params(group, "moderate", BASE)
    patient = synthetic_patient(truth, seed=1, n_stiffness=N_STIFFNESS)
    fit = ArmFitter(seed=0).fit(patient.maps, BASE)
    assert fit.severity_ is not None
    for g in GROUP_INDEX:
        want = "moderate" if g in JOINT_GROUPS[group] else "unimpaired"
        for component in ("passive", "dynamic"):
            grade = fit.severity_[g][component]
            # every grade's 95% range over the fit's samples holds the truth
            assert want in _levels_between(*grade["level_range"]), (g, component, grade)
            if grade["level"] == want:
                continue
            # A reflex the maps barely see can be fitted slightly above unimpaired: a grade
            # is unimpaired only while what the group adds stays within one force JND (10%)
            # of the unimpaired resistance, and 5% map noise does not resolve that. Such a
            # grade must stay below the first Weber step (the old nearest-level boundary,
            # √2.44 ≈ 1.56), and its range over the fit's samples reach unimpaired.
            assert want == "unimpaired" and component == "dynamic", (g, component, grade)
            assert grade["level"] == "very mild" and grade["ratio"] < 1.56, grade
            assert grade["level_range"][0] == "unimpaired", grade


def _levels_between(low: str, high: str) -> list[str]:
    levels = ["unimpaired", *reversed(LEVELS)]
    return levels[levels.index(low):levels.index(high) + 1]


def test_unidentified_parameters_are_held_at_unimpaired_unless_rejected() -> None:
    truth = impaired_params("elbow", "severe", BASE)
    patient = synthetic_patient(truth, seed=2)
    free = ArmFitter(seed=0, hold_unidentified=False).fit(patient.maps, BASE)
    held = ArmFitter(seed=0).fit(patient.maps, BASE)
    assert free.held_ == [] and free.hold_test_ is None
    assert held.held_, "this design leaves some reflex parameters open"
    test = held.hold_test_
    assert test is not None and test["accepted"] and test["delta_chi2"] <= test["threshold"]
    unimpaired = {"alpha": 100.0, "beta": 0.1, "km": 600.0}
    for name in held.held_:
        k = held.space_.names.index(name)
        assert held.theta_[k] == pytest.approx(unimpaired[name.split("_")[0]])
    # the held parameters stay reported as not identified, with the test in the reason
    reasons = {u.name: u.reason for u in held.unidentified_}
    assert all("held at the unimpaired value" in reasons[n] for n in held.held_)
    # holding costs little data fit and does not spoil the identified Km
    assert held.chi2_ - free.chi2_ == pytest.approx(test["delta_chi2"], abs=1e-6)
    assert held.params_.km_n_per_m[2] == pytest.approx(truth.km_n_per_m[2], rel=0.15)
