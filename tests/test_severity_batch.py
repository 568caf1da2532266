"""The severity scores of many parameter sets graded as arrays (fieldbank.evaluate.gradebatch)
held to the one-arm-at-a-time grading (fieldbank.evaluate.severity.classify), and a fit's grade
ranges held to the per-sample path they replaced.

Tolerance: 1e-9 on the score (a score is a log of a torque ratio; the batch evaluates the same
equations over a sample axis, so the two differ by rounding only - measured ≈ 1e-15).
"""

from __future__ import annotations

import numpy as np
import pytest

from fieldbank.armbatch import ArmBatch
from fieldbank.errors import ParameterError
from fieldbank.evaluate.gradebatch import score_array, scores
from fieldbank.evaluate.probing import stretch_profiles, unimpaired_reference
from fieldbank.evaluate.severity import COMPONENTS, SCALE, classify, synthesize
from fieldbank.fitting import ArmFitter
from fieldbank.fitting.fitter import GRADE_PERCENTILES
from fieldbank.fitting.prior import draw
from fieldbank.fitting.synthetic import impaired_params, synthetic_patient
from fieldbank.fitting.uncertainty import FitSamples
from fieldbank.model import Arm
from fieldbank.params import GROUPS, ArmParams

BASE = ArmParams.from_anthropometry()
TOL = 1e-9


def _one_by_one(arm: Arm, sets: list[ArmParams]) -> dict[tuple[str, str], np.ndarray]:
    """The scores of each set by classify on its own arm (the path the batch replaced)."""
    ref = unimpaired_reference(arm)
    ref_prof = stretch_profiles(ref)
    out: dict[tuple[str, str], list[float]] = {}
    for p in sets:
        try:
            trial = arm.with_muscles(p)
        except ParameterError:  # a set with its own rest posture
            trial = Arm.from_params(p)
        for g, sev in classify(trial, reference=ref, reference_profiles=ref_prof).items():
            for c in COMPONENTS:
                out.setdefault((g, c), []).append(sev.component(c).score)
    return {k: np.array(v) for k, v in out.items()}


def _random_sets(centre: ArmParams, n: int, seed: int, q_rest: bool = False
                 ) -> dict[str, np.ndarray]:
    """``n`` sets around ``centre``: Km, α, β and the slack offsets spread over the severity
    scale and beyond (α = 0, β at its bounds, contractures and lengthenings)."""
    rng = np.random.default_rng(seed)
    km = np.array(centre.km_n_per_m) * np.exp(rng.normal(0.0, 0.8, (n, 6)))
    alpha = np.array(centre.alpha_n) * np.exp(rng.normal(0.0, 1.0, (n, 6)))
    alpha[0, 2] = 0.0
    beta = np.clip(np.array(centre.beta) + rng.normal(0.0, 0.3, (n, 6)), 0.0, 1.0)
    beta[1] = 1.0
    beta[2, 3] = 0.0
    slack = rng.uniform(-0.02, 0.02, (n, 6))
    out = {"km_n_per_m": km, "alpha_n": alpha, "beta": beta, "slack_offset_m": slack}
    if q_rest:
        q = np.array(centre.q_rest_rad) + rng.normal(0.0, 0.1, (n, 2))
        out["q_rest_rad"] = q
    return out


def _as_params(centre: ArmParams, arrays: dict[str, np.ndarray]) -> list[ArmParams]:
    n = next(iter(arrays.values())).shape[0]
    return [centre.replace(**{f: tuple(a[k].tolist()) for f, a in arrays.items()})
            for k in range(n)]


CENTRES = {
    "elbow severe": impaired_params("elbow", "severe", BASE),
    "shoulder moderate": impaired_params("shoulder", "moderate", BASE),
    "contracture": BASE.with_group("ef", slack_offset_m=-0.015),
    "unimpaired": BASE,
    "left arm, small": synthesize({"biarticular": "mild"},
                                  ArmParams.from_anthropometry(52.0, 1.55, "left")),
}


@pytest.mark.parametrize("name", sorted(CENTRES))
def test_batch_scores_equal_classify_of_each_arm(name: str) -> None:
    centre = CENTRES[name]
    arm = Arm.from_params(centre)
    arrays = _random_sets(centre, 24, seed=len(name))
    batch = ArmBatch.from_arrays(arm, 24, **arrays)
    got = scores(batch, unimpaired_reference(arm))
    want = _one_by_one(arm, _as_params(centre, arrays))
    assert set(got) == set(want) == {(g, c) for g in GROUPS for c in COMPONENTS}
    spread = 0.0
    for key, w in want.items():
        np.testing.assert_allclose(got[key], w, rtol=0, atol=TOL, err_msg=str(key))
        spread = max(spread, float(np.ptp(w)))
    assert spread > 1.0  # the sets reach across levels, not one grade repeated


def test_batch_scores_with_the_rest_posture_per_set() -> None:
    centre = CENTRES["elbow severe"]
    arm = Arm.from_params(centre)
    arrays = _random_sets(centre, 12, seed=5, q_rest=True)
    batch = ArmBatch.from_arrays(arm, 12, **arrays)
    assert not batch.muscles.same_lengths
    got = scores(batch, unimpaired_reference(arm))
    want = _one_by_one(arm, _as_params(centre, arrays))
    for key, w in want.items():
        np.testing.assert_allclose(got[key], w, rtol=0, atol=TOL, err_msg=str(key))


def test_score_array_is_the_scale_score() -> None:
    ratios = np.array([0.3, 1.0, 1.0 + 1e-12, 1.05, 1.2, 1.5, 2.44, 2.5, 4.0, 9.99, 10.0,
                       15.0, 1e4])
    for c in COMPONENTS:
        want = [SCALE.score(float(r), c) for r in ratios]
        np.testing.assert_allclose(score_array(ratios, c), want, rtol=1e-14, atol=0)


def test_from_arrays_checks_values_once_with_the_records_messages() -> None:
    arm = Arm.from_params(BASE)
    beta = np.full((3, 6), 0.5)
    beta[2, 4] = 1.5
    with pytest.raises(ParameterError, match=r"parameter set 2: The 'beta\[4\] \(bf\)' "
                                             r"parameter must be a finite number in \[0, 1\]"):
        ArmBatch.from_arrays(arm, 3, beta=beta)
    km = np.full((2, 6), 600.0)
    km[1, 0] = np.nan
    with pytest.raises(ParameterError, match=r"parameter set 1: .*km_n_per_m\[0\] \(sf\)"):
        ArmBatch.from_arrays(arm, 2, km_n_per_m=km)
    with pytest.raises(ParameterError, match=r"parameter set 0: the 'q_rest_rad\[1\]' parameter "
                                             r"must lie in the range of motion"):
        ArmBatch.from_arrays(arm, 1, q_rest_rad=np.array([[0.5, -0.2]]))
    with pytest.raises(ParameterError, match="cannot differ"):
        ArmBatch.from_arrays(arm, 1, upper_arm_length_m=np.array([[0.3]]))
    with pytest.raises(ParameterError, match="shape"):
        ArmBatch.from_arrays(arm, 2, beta=np.full((3, 6), 0.5))


def _ranges_one_by_one(fitter: ArmFitter) -> dict[tuple[str, str], list[float]]:
    """The fit's grade ranges as the per-sample path computed them: each drawn sample's own
    arm graded by classify, the percentiles widened to hold the model's own score."""
    unc = fitter.uncertainty_detail_
    samples = draw(FitSamples(unc.names, unc.samples), fitter.prior_ranges_, fitter.prior_,
                   seed=fitter.seed_)
    per = _one_by_one(Arm.from_params(fitter.params_), samples.params(fitter.params_))
    out = {}
    for (g, c), vals in per.items():
        point = float(fitter.severity_[g][c]["score"])
        lo, hi = (float(v) for v in np.percentile(vals, list(GRADE_PERCENTILES)))
        out[(g, c)] = [round(min(lo, point), 4), round(max(hi, point), 4)]
    return out


@pytest.mark.parametrize(("truth", "kinds"), [
    (impaired_params("elbow", "severe", BASE), ("km", "alpha", "beta")),
    (BASE, ("km", "alpha", "beta")),
    (BASE.with_group("sf", km_n_per_m=2400.0, slack_offset_m=-0.010),
     ("km", "alpha", "beta", "slack")),
], ids=["elbow severe", "unimpaired", "contracture with the slack fitted"])
def test_a_fits_grade_ranges_equal_the_per_sample_grades(truth: ArmParams,
                                                         kinds: tuple[str, ...]) -> None:
    patient = synthetic_patient(truth, seed=3, n_postural=12, n_stiffness=6)
    fitter = ArmFitter(seed=3, fit=kinds, replicates=20).fit(patient.maps, BASE)
    want = _ranges_one_by_one(fitter)
    for (g, c), rng in want.items():
        assert fitter.severity_[g][c]["score_range"] == pytest.approx(rng, abs=2e-4), (g, c)
    # the ranges are not all one point: the samples spread
    assert any(r[1] > r[0] for r in want.values())
