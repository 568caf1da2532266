"""The fitter's precomputed cost equals the model, and its gradient equals finite differences."""

from __future__ import annotations

import numpy as np
import pytest

from fieldbank.fitting.problem import FitProblem
from fieldbank.fitting.space import ParamSpace
from fieldbank.fitting.synthetic import scattered_positions
from fieldbank.maps import postural_map, stiffness_map
from fieldbank.model import Arm
from fieldbank.params import ArmParams

VELOCITIES = [(0.0, 0.0), (-0.6, 0.8), (0.6, -0.8), (2.0, 1.5)]  # the last one saturates λ̇


def _patient(side: str = "right", contracture: bool = False) -> ArmParams:
    p = ArmParams.from_anthropometry(side=side, q_rest_rad=(0.75, 1.3))
    p = p.with_group("ef", km_n_per_m=5200.0, alpha_n=900.0, beta=0.9)
    p = p.with_group("be", km_n_per_m=1500.0, alpha_n=400.0, beta=0.6)
    if contracture:  # ef 12 mm short, sf 6 mm, ee lengthened by 4 mm
        p = p.replace(slack_offset_m=(-0.006, 0.0, -0.012, 0.004, 0.0, 0.0))
    return p


def _theta(p: ArmParams, with_q: bool, with_slack: bool = False) -> np.ndarray:
    parts = [p.km_n_per_m, p.alpha_n, p.beta] + ([p.q_rest_rad] if with_q else []) \
        + ([p.slack_offset_m] if with_slack else [])
    return np.concatenate([np.asarray(x, dtype=float) for x in parts])


@pytest.mark.parametrize(("fit_q_rest", "fit_slack"), [(False, False), (True, False),
                                                       (False, True), (True, True)])
def test_fast_prediction_equals_arm_field(fit_q_rest: bool, fit_slack: bool) -> None:
    truth = _patient(contracture=fit_slack)
    arm = Arm.from_params(truth)
    pos = scattered_positions(arm, 20, np.random.default_rng(3))
    maps = [postural_map(arm, pos)] + [stiffness_map(arm, pos, v) for v in VELOCITIES]
    # The problem is built around another rest posture when q_rest is fitted: the prediction
    # must follow the q_rest in the parameter vector, not the base's.
    # Likewise the slack offsets: the base has none, the truth a contracture.
    base = truth.replace(q_rest_rad=(0.6, 1.5)) if fit_q_rest else truth
    if fit_slack:
        base = base.replace(slack_offset_m=(0.0,) * 6)
    kinds = ("km", "alpha", "beta") + (("q_rest",) if fit_q_rest else ()) \
        + (("slack",) if fit_slack else ())
    prob = FitProblem.from_maps(maps, Arm.from_params(base), ParamSpace.build(base, kinds))
    pred = prob.predict(_theta(truth, fit_q_rest, fit_slack))
    for m, rows in zip(maps, prob.map_rows, strict=True):
        scale = np.abs(m.values).max()
        np.testing.assert_allclose(pred[rows], m.values.ravel(), rtol=0, atol=1e-10 * scale)
    assert np.abs(prob.y).max() > 100.0  # the comparison is not between zeros


def test_left_arm_prediction_matches_finite_differences_of_force() -> None:
    truth = _patient("left")
    arm = Arm.from_params(truth)
    pos = scattered_positions(arm, 6, np.random.default_rng(4))
    vel = (0.5, -0.4)
    post = postural_map(arm, pos)
    stiff = stiffness_map(arm, pos, vel)
    prob = FitProblem.from_maps([post, stiff], arm, ParamSpace.build(truth))
    pred = prob.predict(_theta(truth, False))
    np.testing.assert_allclose(pred[prob.map_rows[0]], post.values.ravel(), atol=1e-9)
    h = 1e-6
    k_fd = np.empty((pos.shape[0], 2, 2))
    for j in range(2):
        e = np.zeros(2)
        e[j] = h
        k_fd[:, :, j] = -(arm.endpoint_force(pos + e, vel) - arm.endpoint_force(pos - e, vel)) / (
            2 * h)
    np.testing.assert_allclose(pred[prob.map_rows[1]].reshape(-1, 2, 2), k_fd, rtol=1e-5,
                               atol=1e-4)


@pytest.mark.parametrize(("fit_q_rest", "fit_slack"), [(False, False), (True, False),
                                                       (True, True)])
def test_projected_gradient_matches_finite_differences(fit_q_rest: bool,
                                                        fit_slack: bool) -> None:
    truth = _patient(contracture=fit_slack)
    arm = Arm.from_params(truth)
    pos = scattered_positions(arm, 15, np.random.default_rng(5))
    maps = [postural_map(arm, pos)] + [stiffness_map(arm, pos, v) for v in VELOCITIES[:3]]
    kinds = ("km", "alpha", "beta") + (("q_rest",) if fit_q_rest else ()) \
        + (("slack",) if fit_slack else ())
    base = ArmParams.from_anthropometry()
    prob = FitProblem.from_maps(maps, Arm.from_params(base), ParamSpace.build(base, kinds))
    phi = np.array([0.3, 0.5, 0.7, 0.4, 0.55, 0.65] + ([0.8, 1.25] if fit_q_rest else [])
                   + ([-0.008, 0.003, -0.011, 0.002, -0.004, 0.001] if fit_slack else []))
    _, grad, _ = prob.projected_cost_grad(phi)
    fd = np.empty_like(phi)
    for k in range(phi.size):
        e = np.zeros_like(phi)
        e[k] = 1e-6
        fd[k] = (prob.projected_cost_grad(phi + e)[0] - prob.projected_cost_grad(phi - e)[0]) / 2e-6
    np.testing.assert_allclose(grad, fd, rtol=2e-3, atol=1e-3 * np.abs(fd).max())


def test_projection_minimises_over_km_and_alpha() -> None:
    truth = _patient()
    arm = Arm.from_params(truth)
    pos = scattered_positions(arm, 15, np.random.default_rng(6))
    maps = [postural_map(arm, pos), stiffness_map(arm, pos, VELOCITIES[1])]
    base = ArmParams.from_anthropometry()
    prob = FitProblem.from_maps(maps, Arm.from_params(base), ParamSpace.build(base))
    theta = _theta(base, False)
    theta[12:18] = truth.beta
    best = prob.project(theta)
    assert best.cost == pytest.approx(prob.cost(best.theta), rel=1e-9)
    rng = np.random.default_rng(0)
    for _ in range(20):
        other = best.theta.copy()
        other[:12] = np.clip(other[:12] * np.exp(0.05 * rng.normal(size=12)), 50.0, None)
        assert prob.cost(other) >= best.cost
