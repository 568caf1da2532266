"""A contracture the fit can see: the slack length fitted per group (``--fit ...,slack``).

A patient whose shoulder flexors are four times stiffer and 10 mm short (a body of its own, a
left arm, 3 % noise) is not described by Km, α and β alone - the fit is poor - and is described
within the noise once the slack length is fitted, with the truth inside its 95 % interval, the
grade and a lengthening what-if resting on the fitted value.
"""

from __future__ import annotations

import pytest

from fieldbank.evaluate.severity import classify
from fieldbank.fitting import ArmFitter
from fieldbank.fitting.space import SLACK_RANGE_M
from fieldbank.fitting.synthetic import synthetic_patient
from fieldbank.interventions.catalogue import Lengthening
from fieldbank.model import Arm
from fieldbank.params import GROUP_INDEX, ArmParams

BASE = ArmParams.from_anthropometry(62.0, 1.63, "left")
SLACK_M = -0.010
TRUTH = BASE.with_group("sf", km_n_per_m=2400.0, slack_offset_m=SLACK_M)


@pytest.fixture(scope="module")
def maps() -> tuple:
    return synthetic_patient(TRUTH, seed=41, n_postural=20, n_stiffness=8, noise=0.03,
                             patient="CON-1").maps


def test_a_contracture_fits_within_the_noise_with_the_slack_interval_holding_the_truth(
        maps: tuple) -> None:
    fit = ArmFitter(seed=0, fit=("km", "alpha", "beta", "slack"), replicates=20).fit(maps, BASE)
    gof = fit.goodness_
    assert fit.status_ != "poor", gof.reasons
    for m in gof.maps:  # every map within its poor-fit limit
        assert m.chi2_per_value <= m.chi2_limit, m
    # with 3 % noise and ~200 values χ²/dof stays near 1 (its SD is ≈ 0.1)
    assert gof.chi2_per_dof < 1.5
    iv = fit.intervals_["slack_sf"]
    assert iv["low"] <= SLACK_M <= iv["high"], iv
    assert iv["high"] - iv["low"] < 0.004  # identified to a few mm, not the prior's range
    assert "slack_sf" not in {u.name for u in fit.unidentified_}
    assert SLACK_RANGE_M[0] <= iv["low"] and iv["high"] <= SLACK_RANGE_M[1]
    fitted = fit.params_.slack_offset_m[GROUP_INDEX["sf"]]
    assert fitted == pytest.approx(SLACK_M, abs=0.0015)
    # the grade rests on the fitted value: the fitted model graded as it is
    graded = classify(Arm.from_params(fit.params_))["sf"].passive
    assert fit.severity_["sf"]["passive"]["ratio"] == pytest.approx(graded.ratio, rel=1e-4)
    assert graded.level != "unimpaired"
    # and a 10 mm lengthening acts on it: the slack length comes back near none
    after = Lengthening("sf", 0.010).apply(fit.params_)
    assert after.slack_offset_m[GROUP_INDEX["sf"]] == pytest.approx(fitted + 0.010)
    assert abs(after.slack_offset_m[GROUP_INDEX["sf"]]) < 0.0015


def test_without_the_slack_the_same_patient_is_a_poor_fit(maps: tuple) -> None:
    """The test above is not vacuous: Km, α and β alone cannot describe the contracture."""
    fit = ArmFitter(seed=0, uncertainty="gauss-newton").fit(maps, BASE)
    assert fit.status_ == "poor"
    assert fit.goodness_.chi2_per_dof > 5.0
