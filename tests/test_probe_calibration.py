"""The classifier's stated probabilities against what happens: the goodness-of-fit test of the
best candidate under the noise model, the model-error correction, an arm outside the
candidates, and the reliability read-out of simulated trials."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fieldbank.evaluate.classify import (
    FIT_LEVEL,
    classify,
    predict_all,
)
from fieldbank.evaluate.design import (
    Candidate,
    NoiseModel,
    Stroke,
    design_report,
    equilibrium,
    predict,
    severity_candidates,
)
from fieldbank.evaluate.observation import Observation, with_force_noise
from fieldbank.evaluate.reliability import calibration_error
from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic.identify import (
    Trial,
    flexor_patients,
    reliability,
    run_trials,
)
from fieldbank.haptic.probe import observation_from_trace, probe_path

LEVELS4 = ("very mild", "mild", "moderate", "severe")
GROUPS = ("shoulder", "elbow", "biarticular")


@pytest.fixture(scope="module")
def all12() -> tuple[Candidate, ...]:
    return severity_candidates(levels=LEVELS4)


def _static_observation(cands: tuple[Candidate, ...], k: int, duration_s: float = 1.0,
                        rate_hz: float = 500.0) -> tuple[Observation, np.ndarray]:
    """Candidate k's static prediction along a slow 12 cm stroke (no noise yet)."""
    stroke = Stroke(tuple(equilibrium(cands)), -110.0, 0.12, duration_s, 0.3)
    m = stroke.motion(samples=int(duration_s * rate_hz) + 1)
    f = predict(cands, m.positions_m, m.velocities_m_per_s, None)
    return Observation.from_arrays("stroke", m.times_s, m.positions_m, f[k],
                                   m.velocities_m_per_s), f


def test_the_fit_statistic_has_the_stated_mean_and_variance_under_the_noise(all12) -> None:  # type: ignore[no-untyped-def]
    """Against simulation: the truth's residual is the noise of with_force_noise (an
    Ornstein-Uhlenbeck process of time constant τ/2); over many draws Q has the mean and
    variance the classifier computes, and the test's p-value is uniform."""
    cands = tuple(c for c in all12 if c.level == "severe")  # far apart: the best is the truth
    obs, _ = _static_observation(cands, 1, duration_s=2.0)
    noise = NoiseModel(force_sd_n=2.0, correlation_s=0.05)
    preds = predict_all([obs], cands, "static")
    rng = np.random.default_rng(7)
    q, p = [], []
    for _ in range(300):
        c = classify([with_force_noise(obs, noise, rng)], cands, noise=noise,
                     predictor="static", next_probe=False, predictions=preds)
        assert c.best.name == cands[1].name
        q.append(c.fit_statistic)
        p.append(c.fit_p_value)
        expected, variance = c.fit_expected, c.fit_variance
    # n_eff = 2 s / 50 ms = 40 per axis: E[Q] = 2 × 40 (one χ² term per τ per axis) and, for
    # this noise, Var Q ≈ 2 × 40 (ρ² integrates to τ/4 each side: half a χ²'s variance)
    assert expected == pytest.approx(80.0, rel=0.01)
    assert variance == pytest.approx(80.0, rel=0.05)
    assert np.mean(q) == pytest.approx(expected, rel=0.04)
    assert np.var(q) == pytest.approx(variance, rel=0.25)
    p = np.array(p)
    assert 0.02 < np.mean(p < 0.05) < 0.09
    assert np.mean(p < FIT_LEVEL) < 0.01
    assert abs(np.mean(p) - 0.5) < 0.05


def test_model_error_tempers_the_posterior_by_the_stated_factor(all12) -> None:  # type: ignore[no-untyped-def]
    """A recording one candidate explains keeps the stated posterior; a smooth residual the
    candidates cannot produce divides the log-likelihoods by 1 + excess × n_eff."""
    cands = all12[:4]
    obs, f = _static_observation(cands, 2)
    noise = NoiseModel(force_sd_n=2.0, correlation_s=0.05)
    exact = classify([obs.replace_force(f[2] + 0.5)], cands, noise=noise,
                     predictor="static", next_probe=False)
    assert exact.temperature == 1.0 and exact.explains  # 0.5 N is inside the noise
    np.testing.assert_allclose(exact.posterior, exact.raw_posterior)
    offset = np.c_[np.full(len(obs.times_s), 3.0), np.full(len(obs.times_s), -3.0)]
    off = classify([obs.replace_force(f[2] + offset)], cands, noise=noise, predictor="static",
                   next_probe=False)
    n_eff = float(obs.weights(noise).sum())
    q = off.fit_statistic
    assert q == pytest.approx(float((-2 * off.log_likelihood).min()))
    assert off.fit_expected == pytest.approx(2 * n_eff)
    # the excess beyond 2 SD of the statistic, per unit of its mean, counted once for the
    # whole recording
    excess = (q - 2 * n_eff - 2 * math.sqrt(off.fit_variance)) / (2 * n_eff)
    assert excess > 0.5
    assert off.temperature == pytest.approx(1 + excess * n_eff)
    lp = np.log(off.prior) + off.log_likelihood / off.temperature
    want = np.exp(lp - lp.max())
    assert off.posterior == pytest.approx(want / want.sum(), rel=1e-9)
    assert off.model_error_n == pytest.approx(2.0 * math.sqrt(excess))
    # 3 N per axis beside a 2 N noise: no candidate explains the recording, and it says so
    assert not off.explains and off.fit_p_value < FIT_LEVEL
    assert "no candidate explains the recording" in off.verdict()
    doc = off.to_dict()
    assert doc["fit_test"]["p_value"] < FIT_LEVEL  # type: ignore[index]
    assert doc["calibration"]["temperature"] == pytest.approx(off.temperature, rel=1e-3)  # type: ignore[index]


def test_strong_evidence_still_names_the_group_surely(all12) -> None:  # type: ignore[no-untyped-def]
    """A severe elbow, the two designed strokes, 2 N of noise: the arm is one of the
    candidates, the correction leaves the evidence alone and the elbow is named with p ≥ 0.9
    (what a live station needs after two probes)."""
    noise = NoiseModel()
    rep = design_report(all12, criterion="information", target="group", max_probes=2,
                        stop_when_separated=False, noise=noise)
    arm = synthesize({"elbow": "severe"})
    obs = [observation_from_trace(probe_path(arm, m, seed=3 + k, wander_m=noise.wander_m)
                                  .trace, m.name) for k, m in enumerate(rep.design.motions)]
    noisy = [with_force_noise(o, noise, np.random.default_rng(5)) for o in obs]
    cl = classify(noisy, all12, noise=noise, next_probe=False)
    assert cl.explains and cl.temperature < 1.5
    assert cl.group == "elbow" and cl.group_posterior["elbow"] >= 0.9


def test_an_arm_outside_the_candidates_is_said_to_be_none_of_them(all12) -> None:  # type: ignore[no-untyped-def]
    """The shoulder flexors alone, moderate, the extensors unimpaired - no joint-group
    candidate has that arm. On the two strokes designed for 4 N the stated likelihood names
    the bi-articular group with p ≥ 0.95; the goodness-of-fit test says no candidate explains
    the trace, and the model-error correction takes the certainty away."""
    noise = NoiseModel(force_sd_n=4.0, correlation_s=0.05)
    rep = design_report(all12, criterion="information", target="group", max_probes=2,
                        stop_when_separated=False, noise=noise)
    res = run_trials({"designed": list(rep.design.motions)}, all12, groups=GROUPS,
                     levels=LEVELS4, repetitions=1, noise_draws=3, noise=noise, seed=99,
                     patients=flexor_patients(("shoulder",), ("moderate",)))
    trials = res.trials
    assert len(trials) == 3
    for t in trials:
        assert t.level == "moderate, flexors only" and t.group == "shoulder"
        assert t.raw_answer_group != "shoulder" and t.raw_group_probability >= 0.95, t
        assert not t.explains and t.fit_p_value < FIT_LEVEL, t
        assert t.group_probability < 0.9, t
    flexors = flexor_patients(("shoulder",), ("moderate",))[0].params
    assert flexors.km_n_per_m[1] == pytest.approx(600.0) and flexors.km_n_per_m[0] > 3000.0


def test_reliability_sets_stated_against_observed() -> None:
    def trial(p: float, right: bool, raw: float) -> Trial:
        return Trial("s", "elbow", "severe", 0, 0, "x", "elbow" if right else "shoulder", 0.5, p,
                     "elbow", raw)

    trials = [trial(0.95, k < 9, 0.999) for k in range(10)] + \
        [trial(0.7, k < 7, 0.999) for k in range(10)]
    bins = {(b.low, b.high): b for b in reliability(trials)}
    assert bins[(0.9, 0.99)].n == 10 and bins[(0.9, 0.99)].observed == pytest.approx(0.9)
    assert bins[(0.9, 0.99)].gap == pytest.approx(-0.05)
    assert bins[(0.6, 0.8)].observed == pytest.approx(0.7)
    assert calibration_error(reliability(trials)) == pytest.approx(0.025)
    raw = {(b.low, b.high): b for b in reliability(trials, raw=True)}
    assert raw[(0.99, 1.0)].n == 20 and raw[(0.99, 1.0)].observed == 1.0
