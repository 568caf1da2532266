"""The default fit's evaluation - over β alone - compiled, with what stays fixed kept.

In a fit of Km, α and β (the default: neither the rest posture nor the slack length fitted)
only β moves between evaluations: the passive columns of the design matrix, the Gram matrix
among the free passive columns, and the reflex terms of every muscle that does not lengthen
at a measured point (a static map, a shortening muscle) are the same at every one of a fit's
some 5,000 evaluations. :class:`BetaPath` builds them once per problem
(:meth:`BetaPath.of`) and evaluates in one compiled call each:

* :meth:`BetaPath.project` - the best Km and α at β
  (:func:`fieldbank.fitting.kernels.project_reflex`);
* :meth:`BetaPath.cost_grad` - the same with the projected cost's gradient over the fitted β
  (:func:`fieldbank.fitting.kernels.project_reflex_grad`).

Where a bound binds and the compiled active-set method gives up, the bounded least squares of
:func:`fieldbank.fitting.reference.bounded_solve` finishes, as for every other evaluation.
What it keeps is computed with the kernels' own operations in their order, so the numbers are
those of the evaluation that recomputes everything (``tests/test_fitting_kernels.py`` holds
both to the numpy reference).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from fieldbank.fitting import kernels
from fieldbank.fitting.reference import bounded_solve
from fieldbank.fitting.space import ParamSpace
from fieldbank.model import FloatArray


class FitProblem(Protocol):
    """What :meth:`BetaPath.of` reads of a :class:`fieldbank.fitting.problem.FitProblem`."""

    space: ParamSpace
    row_pt: np.ndarray
    cf: FloatArray
    cl: FloatArray
    cd: FloatArray
    lam_above_min: FloatArray
    c: FloatArray
    dc: FloatArray

    def consts(self) -> dict[str, Any]: ...

    def passive_columns(self) -> FloatArray: ...

#: Central-difference step of the gradient over β (as :meth:`FitProblem.design_derivatives`).
H_BETA = 1e-6


@dataclass(frozen=True, eq=False)
class BetaPath:
    """What a problem's evaluations over β read, fixed for the problem (module docstring)."""

    project_fn: Callable[..., bool]
    grad_fn: Callable[..., bool]
    #: the kernels' arguments after β: geometry, kept terms, data, free columns
    head: tuple[Any, ...]
    #: after the solved vector: the prior of the free linear entries and their bounds
    prior: tuple[Any, ...]
    #: after the buffers: the kept Gram block and its size
    fixed: tuple[Any, ...]
    #: after those, for the gradient: β's bounds, the step and the fitted β
    grad_tail: tuple[Any, ...]
    base: FloatArray
    nl: np.ndarray
    rows: int
    n_free: int
    #: the prior cost over every fitted entry: indices, means, SDs, weight
    fitted: np.ndarray
    prior_mean: FloatArray
    prior_sd: FloatArray
    prior_weight: float
    #: the prior's gradient over the fitted β: indices into the full vector, 2·weight, mean, SD²
    beta_idx: np.ndarray
    two_pw: float
    beta_mean: FloatArray
    beta_sd2: FloatArray

    @classmethod
    def of(cls, problem: FitProblem) -> BetaPath:
        """The fixed part of ``problem``'s evaluations (a fit over β alone)."""
        kern = kernels.load()
        k = problem.consts()
        xkm = np.ascontiguousarray(problem.passive_columns(), dtype=float)
        free = k["free"]
        n_fixed = int(np.count_nonzero(free < 6))
        gram0 = np.zeros((free.size, free.size))
        kern["passive_gram"](xkm, k["w"], free, n_fixed, gram0)
        s = problem.space
        fitted_beta = k["beta_fitted"]
        idx = fitted_beta + 12
        fitted = np.flatnonzero(s.fitted)
        return cls(
            kern["project_reflex"], kern["project_reflex_grad"],
            (k["kk"], problem.lam_above_min, k["ell"], problem.c, problem.dc, k["row_pt"],
             problem.cf, problem.cl, problem.cd, k["still"], k["gam0"], k["e0"], xkm, k["y"],
             k["w"], free),
            (float(k["pw"]), k["mu"], k["sdp"], k["lo"], k["hi"]), (gram0, n_fixed),
            (k["b_lo"], k["b_hi"], H_BETA, fitted_beta), s.base.copy(), k["nl"],
            problem.row_pt.size, free.size, fitted, s.prior_mean[fitted],
            s.prior_sd[fitted], float(s.prior_weight), idx, 2.0 * s.prior_weight,
            s.prior_mean[idx], s.prior_sd[idx] ** 2)

    def prior_cost(self, theta: FloatArray) -> float:
        """:meth:`FitProblem.prior_cost` of ``theta``."""
        z = (theta[self.fitted] - self.prior_mean) / self.prior_sd
        return float(self.prior_weight * (z @ z))

    def _fallback(self, theta: FloatArray, a: FloatArray, rhs: FloatArray) -> FloatArray:
        """The bounded solve where the compiled one gave up: the Km and α into ``theta``,
        the residuals returned."""
        pw, mu, sdp, lo, hi = self.prior
        sol = bounded_solve(a, rhs, pw, mu, sdp, lo, hi)
        theta[self.head[-1]] = sol
        return np.asarray(rhs - a @ sol, dtype=float)

    def project(self, theta_nl: FloatArray) -> tuple[float, FloatArray, FloatArray]:
        """(cost, the full vector with the best Km and α, the whitened residuals) at the β
        of ``theta_nl``."""
        theta = np.array(theta_nl, dtype=float)
        r = np.empty(self.rows)
        a = np.empty((self.rows, self.n_free))
        rhs = np.empty(self.rows)
        if not self.project_fn(theta[12:18], *self.head, theta[:12], *self.prior, a, rhs, r,
                               *self.fixed):
            r = self._fallback(theta, a, rhs)
        return float(r @ r) + self.prior_cost(theta), theta, r

    def cost_grad(self, phi: FloatArray
                  ) -> tuple[float, FloatArray, FloatArray, FloatArray]:
        """(cost, full vector, residuals, the cost's gradient over the fitted β) at the
        fitted entries ``phi``."""
        theta = self.base.copy()
        theta[self.nl] = phi
        grad = np.empty(self.beta_idx.size)
        r = np.empty(self.rows)
        a = np.empty((self.rows, self.n_free))
        rhs = np.empty(self.rows)
        if not self.grad_fn(theta[12:18], *self.head, theta[:12], *self.prior, a, rhs, r,
                            *self.fixed, *self.grad_tail, grad):
            r = self._fallback(theta, a, rhs)
            b_lo, b_hi, h, fitted_beta = self.grad_tail
            kernels.load()["reflex_gradient"](
                np.ascontiguousarray(theta[12:18]), b_lo, b_hi, h, *self.head[:12],
                np.ascontiguousarray(theta[6:12]), r, self.head[14], fitted_beta, grad)
        grad += self.two_pw * (theta[self.beta_idx] - self.beta_mean) / self.beta_sd2
        return float(r @ r) + self.prior_cost(theta), theta, r, grad
