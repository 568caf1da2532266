"""What a fit holds at the unimpaired value, what the maps make it release, and a reflex the
maps cannot place on one group rather than its partner - on synthetic patients whose truth is
known (a lab's patient: another body size, Km and α raised together, β 0.8; 25 postural and
9 stiffness positions, static and moving, 5% noise)."""

from __future__ import annotations

import numpy as np
import pytest

from fieldbank.evaluate.severity import classify
from fieldbank.fitting import ArmFitter
from fieldbank.fitting.prior import Prior
from fieldbank.fitting.synthetic import synthetic_patient
from fieldbank.fitting.uncertainty import reduced_problem, refit_local
from fieldbank.model import Arm
from fieldbank.params import ArmParams


def _patient(mass: float, height: float, groups: tuple[str, ...], factor: float
             ) -> tuple[ArmParams, ArmParams]:
    base = ArmParams.from_anthropometry(mass, height)
    truth = base
    for g in groups:
        truth = truth.with_group(g, km_n_per_m=base.group_value("km_n_per_m", g) * factor,
                                 alpha_n=base.group_value("alpha_n", g) * factor, beta=0.8)
    return base, truth


def _chi2(fit: ArmFitter, theta: np.ndarray) -> float:
    r = fit.problem_.residuals(theta)
    return float(r @ r)


@pytest.fixture(scope="module")
def flexors() -> tuple[ArmParams, ArmFitter]:
    """Elbow flexors: Km and α × 2.39, β 0.8."""
    base, truth = _patient(68.14354813590305, 1.8638953520004766, ("ef",), 2.385286623873146)
    pat = synthetic_patient(truth, seed=1007, n_postural=25, n_stiffness=9)
    return truth, ArmFitter(seed=7).fit(list(pat.maps), base)


def test_a_reflex_the_search_left_silent_is_released_not_held(
        flexors: tuple[ArmParams, ArmFitter]) -> None:
    # The global search ends where α_ef is not identified; holding it at 100 N would cost
    # the maps Δχ² ≈ 88 - they rule it out.
    truth, fit = flexors
    test = fit.hold_test_
    assert test is not None and test["accepted"]
    released = {tuple(r["names"]): r for r in test["released"]}
    assert ("alpha_ef",) in released
    row = released[("alpha_ef",)]
    assert row["delta_chi2"] > row["threshold"] > 3.84  # Bonferroni over the units tested
    assert "alpha_ef" not in fit.held_
    # the test's Δχ² is what the maps say: α_ef held at 100 N (the others as fitted, the
    # free parameters refitted) fits them worse by more than the threshold
    k = fit.space_.names.index("alpha_ef")
    theta = fit.theta_.copy()
    theta[k] = 100.0
    red = reduced_problem(fit.problem_, theta, [*fit.held_, "alpha_ef"])
    held_theta, _ = refit_local(red, red.y, theta)
    assert _chi2(fit, held_theta) - fit.chi2_ > row["threshold"]
    # the released reflex is graded as the truth's (α and β trade off; the resistance they
    # add to a fast stretch is what the maps fix)
    want = classify(Arm.from_params(truth))["ef"].dynamic
    got = fit.severity_["ef"]["dynamic"]
    assert got["level"] == want.level != "unimpaired"
    assert got["ratio"] == pytest.approx(want.ratio, rel=0.25)
    # α_ef still trades off with β_ef: it stays reported as not identified, saying why it
    # is fitted rather than held
    reason = {u.name: u.reason for u in fit.unidentified_}["alpha_ef"]
    assert "the maps reject holding alpha_ef at the unimpaired value" in reason
    # a neighbour that only stood in for the missing reflex is not released with it
    assert not any(n.endswith("_se") for names in released for n in names)
    assert fit.severity_["se"]["dynamic"]["level"] == "unimpaired"


def test_a_reflex_the_maps_cannot_place_is_flagged_on_both_groups() -> None:
    # both elbow groups: Km and α × 5.02, β 0.8. The moving maps see a reflex resisting elbow
    # extension but do not tell the elbow flexors' from the bi-articular flexors': the fit
    # puts it on bf, and moving it to ef costs the maps nothing.
    base, truth = _patient(81.22486702011531, 1.6003599050760486, ("ef", "ee"),
                           5.020183793321987)
    pat = synthetic_patient(truth, seed=1010, n_postural=25, n_stiffness=9)
    fit = ArmFitter(seed=10).fit(list(pat.maps), base)
    attr = {(a["group"], a["partner"]): a for a in fit.attribution_}
    assert ("bf", "ef") in attr
    a = attr[("bf", "ef")]
    assert a["delta_chi2"] <= a["threshold"]
    reasons = {u.name: u.reason for u in fit.unidentified_}
    for n in ("alpha_bf", "beta_bf", "alpha_ef", "beta_ef"):
        assert "do not tell the stretch reflex of bf from that of ef" in reasons[n], n
    # the grades say so: the bi-articular reflex rests on what the maps did not identify
    assert fit.severity_["bf"]["dynamic"]["level"] != "unimpaired"
    assert set(fit.severity_["bf"]["dynamic"]["unidentified"]) == {"alpha_bf", "beta_bf"}
    assert fit.report()["attribution"][0]["partner"] == "ef"


def test_the_maps_cap_a_held_reflex_they_partly_see(
        flexors: tuple[ArmParams, ArmFitter]) -> None:
    # the moving maps see some held reflexes well enough to rule out a severe one, though not
    # well enough to identify them: their range stops below the top of the scale, where the
    # maps allow (Δχ² at the cap within the threshold, above it at the top)
    _, fit = flexors
    capped = [r for r in fit.prior_ranges_ if r.limited_by_maps]
    assert capped, [r.to_dict() for r in fit.prior_ranges_]
    prior = Prior.for_arm(Arm.from_params(fit.params_))
    red = reduced_problem(fit.problem_, fit.theta_, fit.held_)
    chi0 = float(red.project(fit.theta_).r @ red.project(fit.theta_).r)
    for r in capped:
        assert r.delta_chi2_at_top is not None and r.threshold is not None
        assert r.delta_chi2_at_top > r.threshold
        theta = fit.theta_.copy()
        for n, v in prior.values(r.group, r.component, np.array([r.score_high])).items():
            if n in r.names:
                theta[fit.space_.names.index(n)] = float(v[0])
        rr = red.project(theta).r
        assert float(rr @ rr) - chi0 <= r.threshold + 1e-6
        # the fit's interval of the held parameter is the capped range
        for n in r.names:
            iv = fit.intervals_[n]
            assert iv["basis"] == "prior" and iv["high"] == pytest.approx(
                prior.interval(r)[n][1])
