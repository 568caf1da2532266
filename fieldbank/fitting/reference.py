"""The fit's inner evaluation in numpy: the reference the compiled kernels are held to.

:class:`~fieldbank.fitting.problem.FitProblem` evaluates its variable-projected cost with the
compiled kernels (:mod:`fieldbank.fitting.kernels`). The same formulas written in numpy stay
here, for two uses: ``tests/test_fitting_kernels.py`` holds the compiled path to them (one
evaluation to rounding, whole fits to the same optimum and intervals), and
``benchmarks/bench_fit_cost.py`` takes them as its same-run baseline. A problem built inside
:func:`reference_kernels` evaluates with them (its ``compiled`` is False):

* :func:`reflex_basis` - the reflex (α) columns of the design matrix X(β, q_rest);
* :func:`project` - the best Km and α at fixed β, q_rest and slack offsets: the whitened
  normal equations with the prior by ``np.linalg.solve``, and :func:`bounded_solve` where a
  bound binds.

:func:`bounded_solve` (scipy's NNLS, or BVLS when an upper bound binds) is also the compiled
path's fallback when its own active-set method gives up.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Protocol

import numpy as np

from fieldbank.fitting.space import ParamSpace
from fieldbank.model import Arm, FloatArray


class FitProblem(Protocol):
    """What the reference reads of a :class:`fieldbank.fitting.problem.FitProblem`."""

    arm: Arm
    space: ParamSpace
    y: FloatArray
    row_pt: np.ndarray
    cf: FloatArray
    cl: FloatArray
    cd: FloatArray
    lam_above_min: FloatArray
    c: FloatArray
    dc: FloatArray

    @property
    def w(self) -> FloatArray: ...

    def kk(self, q_rest: FloatArray) -> FloatArray: ...

    def split(self, theta: FloatArray
              ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]: ...

    def design(self, beta: FloatArray, q_rest: FloatArray,
               slack: FloatArray | None = None) -> FloatArray: ...

#: Whether problems built now evaluate on this path (:func:`reference_kernels`).
_ACTIVE = [False]


@contextmanager
def reference_kernels() -> Iterator[None]:
    """Problems built inside evaluate with the numpy formulas of this module, not the
    compiled kernels (the tests hold the two together; the benchmark's baseline)."""
    old = _ACTIVE[0]
    _ACTIVE[0] = True
    try:
        yield
    finally:
        _ACTIVE[0] = old


def active() -> bool:
    """Problems built now take this path (inside :func:`reference_kernels`)."""
    return _ACTIVE[0]


def reflex_basis(problem: FitProblem, beta: FloatArray, q_rest: FloatArray) -> FloatArray:
    """The reflex columns of the design matrix, shape (M, 6): the values per unit α of each
    group at reflex gains ``beta`` and rest posture ``q_rest``."""
    arm = problem.arm
    kk = problem.kk(q_rest)
    u = beta * problem.c
    ell = arm.excursion
    gam = problem.lam_above_min / ell - kk * (1.0 - u)
    e = np.exp(-gam * gam)
    h = u * gam * e
    one = 1.0 - 2.0 * gam * gam
    dh_dlam = u * e * one / ell
    dh_du = gam * e + u * e * one * kk
    on = (h > 0) | ((h == 0) & (dh_du > 0))
    rf = np.where(h > 0, h, 0.0)[problem.row_pt]
    rl = np.where(on, dh_dlam, 0.0)[problem.row_pt]
    rd = np.where(on, dh_du * beta * problem.dc, 0.0)[problem.row_pt]
    return problem.cf * rf + problem.cl * rl + problem.cd * rd


def project(problem: FitProblem, theta_nl: FloatArray, x: FloatArray | None
            ) -> tuple[FloatArray, FloatArray]:
    """The best Km and α for the nonlinear entries of ``theta_nl`` (a full vector; its linear
    part kept where not fitted), with ``x`` the design matrix when already built: (the full
    vector with the solved Km and α, the whitened data residuals)."""
    s = problem.space
    lin, beta, q_rest, slack = problem.split(theta_nl)
    if x is None:
        x = problem.design(beta, q_rest, slack)
    free = s.fitted[:12]
    w = problem.w
    lin = lin.copy()
    rhs = (problem.y - x[:, ~free] @ lin[~free]) * w
    a = x[:, free] * w[:, None]
    if free.any():
        pw = s.prior_weight
        mu = s.prior_mean[:12][free]
        sdp = s.prior_sd[:12][free]
        lo = s.lower[:12][free]
        hi = s.upper[:12][free]
        gram = a.T @ a + np.diag(pw / sdp**2)
        rhs_n = a.T @ rhs + pw * mu / sdp**2
        sol: FloatArray | None
        try:
            sol = np.linalg.solve(gram, rhs_n)
        except np.linalg.LinAlgError:
            sol = None
        if sol is None or np.any(sol < lo) or np.any(sol > hi):
            sol = bounded_solve(a, rhs, pw, mu, sdp, lo, hi)
        lin[free] = sol
    theta = theta_nl.copy()
    theta[:12] = lin
    r = rhs - a @ lin[free] if free.any() else rhs
    return theta, r


def bounded_solve(a: FloatArray, rhs: FloatArray, pw: float, mu: FloatArray, sdp: FloatArray,
                  lo: FloatArray, hi: FloatArray) -> FloatArray:
    """The projection's linear least squares with the prior, inside [lo, hi]."""
    sq = np.sqrt(pw) / sdp
    aa = np.vstack([a, np.diag(sq)])
    bb = np.concatenate([rhs, sq * mu])
    # Lower bounds are what binds (α >= 0 of quiet groups): NNLS on x - lo is ~15x
    # faster than BVLS and solves the same strictly convex problem; BVLS only when
    # an upper bound binds as well.
    from scipy.optimize import lsq_linear, nnls  # heavy: where it solves

    shifted, _ = nnls(aa, bb - aa @ lo)
    sol = np.asarray(shifted + lo, dtype=float)
    if np.any(sol > hi):
        sol = np.asarray(lsq_linear(aa, bb, bounds=(lo, hi), method="bvls").x, dtype=float)
    return sol
