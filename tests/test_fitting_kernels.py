"""The compiled evaluation of the fit (fieldbank.fitting.kernels) held to the numpy reference.

Two levels, each with its stated tolerance:

* one evaluation - the design matrix, the projection (unbounded and bounded branches) and the
  projected gradient - agrees to rounding: 1e-12 of the column's size for X, 1e-10 relative
  for the cost, 1e-7 of the largest Km/α for the solved linear parameters, 1e-6 relative for
  the gradient (a central difference of step 1e-6 multiplies rounding by 1e6);
* a whole default fit on virtual patients: the search, its polish and the bootstrap's refits
  follow evaluations that differ by rounding, so the optimiser's path can part at a kink of
  the cost; the fits must still land on the same optimum - the same cost to 1e-3 relative, the
  same parameters to 0.1 of their SD, the same held parameters, status and uncertainty method
  - and the same intervals: SDs within 15 % and interval ends within 0.2 of the interval's
  width. Both are set by the bootstrap's own Monte-Carlo error with 40 replicates: ≈ 11 % for
  an SD, and ≈ 0.11 of the width for a 2.5 or 97.5 percentile (≈ 0.15 for the difference of
  two independent ones). The two paths draw the same noise, so most agree far closer; the
  tolerance allows a replicate's refit to land elsewhere at a kink.
"""

from __future__ import annotations

import numpy as np
import pytest

from fieldbank.fitting import ArmFitter
from fieldbank.fitting.problem import FitProblem
from fieldbank.fitting.reference import reference_kernels
from fieldbank.fitting.space import ParamSpace
from fieldbank.fitting.synthetic import impaired_params, synthetic_patient
from fieldbank.model import Arm
from fieldbank.params import ArmParams

BASE = ArmParams.from_anthropometry()


def _pair(kinds: tuple[str, ...], seed: int = 0) -> tuple[FitProblem, FitProblem]:
    """The same patient's problem on the reference and on the compiled path."""
    truth = impaired_params("elbow", "severe", BASE)
    maps = list(synthetic_patient(truth, seed=seed).maps)
    arm = Arm.from_params(BASE)
    space = ParamSpace.build(BASE, kinds)
    with reference_kernels():
        ref = FitProblem.from_maps([m.as_arm_on_handle() for m in maps], arm, space)
    new = FitProblem.from_maps([m.as_arm_on_handle() for m in maps], arm, space)
    assert not ref.compiled and new.compiled
    return ref, new


def _random_theta(p: FitProblem, rng: np.random.Generator) -> np.ndarray:
    s = p.space
    theta = s.base.copy()
    nl = np.flatnonzero(s.fitted)
    nl = nl[nl >= 12]
    theta[nl] = rng.uniform(s.lower[nl], s.upper[nl])
    return theta


KIND_SETS = [("km", "alpha", "beta"), ("km", "alpha", "beta", "q_rest"),
             ("km", "alpha", "beta", "slack"), ("km", "beta")]


@pytest.mark.parametrize("kinds", KIND_SETS)
def test_design_and_projection_agree(kinds: tuple[str, ...]) -> None:
    ref, new = _pair(kinds)
    rng = np.random.default_rng(7)
    branches = set()
    for _ in range(40):
        theta = _random_theta(ref, rng)
        _, beta, q_rest, slack = ref.split(theta)
        x_ref = ref.design(beta, q_rest, slack)
        x_new = new.design(beta, q_rest, slack)
        scale = np.maximum(np.abs(x_ref).max(axis=0), 1e-300)
        assert np.all(np.abs(x_new - x_ref) <= 1e-12 * scale)
        p_ref, p_new = ref.project(theta), new.project(theta)
        assert p_new.cost == pytest.approx(p_ref.cost, rel=1e-10)
        big = np.abs(p_ref.theta[:12]).max()
        np.testing.assert_allclose(p_new.theta, p_ref.theta, rtol=0, atol=1e-7 * big)
        np.testing.assert_allclose(p_new.r, p_ref.r, rtol=0,
                                   atol=1e-7 * np.abs(p_ref.r).max())
        free = ref.space.fitted[:12]
        bound = np.isclose(p_ref.theta[:12][free], ref.space.lower[:12][free])
        branches.add(bool(bound.any()))
    # the points reach the bounded fallback (α = 0 binds, where α is fitted); with the default
    # kinds also the unbounded solve
    assert True in branches or "alpha" not in kinds
    if kinds == KIND_SETS[0]:
        assert branches == {True, False}
    assert new.n_evals == ref.n_evals == 40


@pytest.mark.parametrize("kinds", KIND_SETS)
def test_projected_gradient_agrees(kinds: tuple[str, ...]) -> None:
    ref, new = _pair(kinds, seed=1)
    rng = np.random.default_rng(11)
    idx = ref.nonlinear_index()
    np.testing.assert_array_equal(new.nonlinear_index(), idx)
    for _ in range(20):
        phi = _random_theta(ref, rng)[idx]
        c_ref, g_ref, _ = ref.projected_cost_grad(phi)
        c_new, g_new, _ = new.projected_cost_grad(phi)
        assert c_new == pytest.approx(c_ref, rel=1e-10)
        np.testing.assert_allclose(g_new, g_ref, rtol=1e-6,
                                   atol=1e-6 * max(1.0, float(np.abs(g_ref).max())))


def test_jacobian_agrees() -> None:
    ref, new = _pair(("km", "alpha", "beta"), seed=2)
    theta = _random_theta(ref, np.random.default_rng(3))
    theta = ref.project(theta).theta
    j_ref, j_new = ref.jacobian(theta), new.jacobian(theta)
    np.testing.assert_allclose(j_new, j_ref, rtol=0, atol=1e-6 * np.abs(j_ref).max())


@pytest.mark.parametrize(("group", "level", "seed"),
                         [("elbow", "severe", 0), ("shoulder", "moderate", 1),
                          ("elbow", "mild", 2)])
def test_default_fit_same_optimum_and_intervals(group: str, level: str, seed: int) -> None:
    patient = synthetic_patient(impaired_params(group, level, BASE), seed=seed)
    with reference_kernels():
        old = ArmFitter(seed=seed).fit(patient.maps, BASE)
    new = ArmFitter(seed=seed).fit(patient.maps, BASE)
    assert not old.problem_.compiled and new.problem_.compiled
    assert new.cost_ == pytest.approx(old.cost_, rel=1e-3)
    assert new.held_ == old.held_
    assert new.status_ == old.status_
    assert new.uncertainty_detail_.method == old.uncertainty_detail_.method
    io, inew = old.intervals_, new.intervals_
    assert set(io) == set(inew) and len(io) >= 18
    for name, a in io.items():
        b = inew[name]
        width = a["high"] - a["low"]
        assert abs(b["value"] - a["value"]) <= 0.1 * a["sd"], name
        assert abs(b["low"] - a["low"]) <= 0.2 * width, name
        assert abs(b["high"] - a["high"]) <= 0.2 * width, name
        assert b["sd"] == pytest.approx(a["sd"], rel=0.15), name


def test_what_the_beta_path_keeps_changes_no_number() -> None:
    """The evaluation over β alone keeps what does not move with β - the reflex terms of the
    muscles that do not lengthen at a point, the Gram matrix of the passive columns - and
    skips the zero entries of the reflex columns; it gives the numbers of the evaluation that
    recomputes everything, to the bit."""
    from fieldbank.fitting import kernels

    _, new = _pair(("km", "alpha", "beta"), seed=4)
    k = new.consts()
    assert k["still"].mean() > 0.5  # most (point, muscle) pairs do not lengthen
    reflex_columns = kernels.load()["reflex_columns"]
    rng = np.random.default_rng(5)
    for _ in range(20):
        theta = _random_theta(new, rng)
        beta = np.ascontiguousarray(theta[12:18])
        kept = np.empty((new.row_pt.size, 6))
        fresh = np.empty((new.row_pt.size, 6))
        reflex_columns(beta, k["kk"], new.lam_above_min, k["ell"], new.c, new.dc, k["row_pt"],
                       new.cf, new.cl, new.cd, k["still"], k["gam0"], k["e0"], kept, 0)
        reflex_columns(beta, k["kk"], new.lam_above_min, k["ell"], new.c, new.dc, k["row_pt"],
                       new.cf, new.cl, new.cd, np.zeros_like(k["still"]), k["gam0"], k["e0"],
                       fresh, 0)
        np.testing.assert_array_equal(kept, fresh)
        # the β path against the general compiled solve on the whole design matrix
        x = new.design(theta[12:18], new.arm.q_rest, new.base_slack)
        fast, full = new.project(theta), new.project(theta, x)
        assert fast.cost == full.cost
        np.testing.assert_array_equal(fast.theta, full.theta)
        np.testing.assert_array_equal(fast.r, full.r)
        # the gradient's call gives the projection's numbers too
        cost, _, pr = new.projected_cost_grad(theta[new.nonlinear_index()])
        assert cost == fast.cost
        np.testing.assert_array_equal(pr.theta, fast.theta)
