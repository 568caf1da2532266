"""The fit's inner evaluation compiled (numba): the reflex columns, the projection, the gradient.

A fit evaluates the variable-projected cost (:meth:`fieldbank.fitting.problem.FitProblem.
project`) some 5,000 times: the search, the hold of what the maps leave open, the bootstrap's
40 refits. Each evaluation is small (≈ 160 measured values, 12 linear unknowns), so in numpy
its cost was the interpreter's and numpy's fixed cost per call (≈ 300 µs over some 40 array
operations), not arithmetic. Here the same formulas run as compiled calls:

* :func:`reflex_columns` - the reflex columns of the design matrix X (the α columns: the
  tension per unit α at each measured value), :func:`fieldbank.fitting.reference.reflex_basis`'s
  formulas in the same order;
* :func:`solve_normal` - the whitened system and its normal equations with the prior (a
  Cholesky factorisation of the 12×12 Gram matrix in place of ``np.linalg.solve``) and the
  residuals; where a bound binds (α ≥ 0 of a quiet group), the same strictly convex problem
  by an active-set method on the Gram matrix already built (:func:`_box_qp`) in place of
  scipy's NNLS/BVLS on the stacked least squares, which stay as its fallback;
* :func:`reflex_gradient` - the projected cost's gradient over β by the envelope theorem,
  from central differences of the reflex columns alone, as :meth:`FitProblem.
  design_derivatives` takes them.

The numpy formulas stay in :mod:`fieldbank.fitting.reference` as the reference
(:func:`~fieldbank.fitting.reference.reference_kernels`); ``tests/test_fitting_kernels.py``
holds the two together (columns and costs to 1e-12 relative, optima and intervals of whole
fits to 1e-6). IEEE double without fast-math; the machine code is cached on disk like the
haptic tick's (:mod:`fieldbank.armkernel`); numba loads and compiles at the first evaluation
(:func:`load`), not on import.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: The kernels, in the order numba compiles them (each calls only those before it).
KERNELS = ("still_terms", "reflex_columns", "_cholesky_solve", "_box_qp", "solve_normal",
           "passive_gram", "reflex_gradient", "project_reflex", "project_reflex_grad")
_LOADED: dict[str, Any] = {}


def load() -> dict[str, Any]:
    """The compiled kernels by name, compiled (or loaded from numba's disk cache) at the first
    call: numba's import costs ≈ 0.2 s CPU, which everything that imports the fitting package
    without fitting (stored fits, reports, what-ifs) does not pay. The module's functions
    become numba dispatchers, so a kernel calling another calls it compiled."""
    if not _LOADED:
        from numba import njit  # heavy: only when a fit evaluates

        names = globals()
        for name in KERNELS:
            names[name] = njit(cache=True, nogil=True)(names[name])
            _LOADED[name] = names[name]
    return _LOADED


def still_terms(kk: np.ndarray, lam_above_min: np.ndarray, ell: np.ndarray, c: np.ndarray,
                still: np.ndarray, gam0: np.ndarray, e0: np.ndarray) -> None:
    """Where a muscle does not lengthen at a measured point (``c`` = 0: a static map, or a
    muscle shortening), u = β·c is 0 whatever β: Γ and e^(-Γ²) of :func:`reflex_columns` do
    not change during a fit (``kk`` fixed). Marks those entries in ``still`` and keeps their Γ
    and e^(-Γ²) in ``gam0`` and ``e0`` (N, 6), computed with the same operations, so that
    :func:`reflex_columns` reading them gives the same numbers to the last bit."""
    for n in range(c.shape[0]):
        for i in range(6):
            if c[n, i] == 0.0:
                u = 0.0
                gam = lam_above_min[n, i] / ell[i] - kk[i] * (1.0 - u)
                still[n, i] = True
                gam0[n, i] = gam
                e0[n, i] = math.exp(-gam * gam)
            else:
                still[n, i] = False


def reflex_columns(beta: np.ndarray, kk: np.ndarray, lam_above_min: np.ndarray,
                   ell: np.ndarray, c: np.ndarray, dc: np.ndarray, row_pt: np.ndarray,
                   cf: np.ndarray, cl: np.ndarray, cd: np.ndarray, still: np.ndarray,
                   gam0: np.ndarray, e0: np.ndarray, out: np.ndarray, col0: int) -> None:
    """Write the reflex columns for ``beta`` (6,) into ``out[:, col0:col0 + 6]``.

    ``kk`` (6,) is λ_rest/λ_max at the fit's rest posture; ``lam_above_min``, ``c``, ``dc``
    (N, 6) per measured point; ``cf``, ``cl``, ``cd`` (M, 6) per measured value and
    ``row_pt`` (M,) its point (see :class:`~fieldbank.fitting.problem.FitProblem`);
    ``still``, ``gam0``, ``e0`` what does not depend on β (:func:`still_terms`; ``still``
    all False when ``kk`` is not the one they were computed with).
    """
    n_pts = lam_above_min.shape[0]
    rf = np.empty((n_pts, 6))
    rl = np.empty((n_pts, 6))
    rd = np.empty((n_pts, 6))
    for n in range(n_pts):
        for i in range(6):
            u = beta[i] * c[n, i]
            if still[n, i]:
                gam = gam0[n, i]
                e = e0[n, i]
            else:
                gam = lam_above_min[n, i] / ell[i] - kk[i] * (1.0 - u)
                e = math.exp(-gam * gam)
            h = u * gam * e
            one = 1.0 - 2.0 * gam * gam
            dh_dlam = u * e * one / ell[i]
            dh_du = gam * e + u * e * one * kk[i]
            on = (h > 0) or ((h == 0) and (dh_du > 0))
            rf[n, i] = h if h > 0 else 0.0
            rl[n, i] = dh_dlam if on else 0.0
            rd[n, i] = dh_du * beta[i] * dc[n, i] if on else 0.0
    for m in range(row_pt.shape[0]):
        p = row_pt[m]
        for i in range(6):
            out[m, col0 + i] = cf[m, i] * rf[p, i] + cl[m, i] * rl[p, i] + cd[m, i] * rd[p, i]


def _cholesky_solve(g: np.ndarray, b: np.ndarray, out: np.ndarray) -> bool:
    """Solve g x = b for a symmetric positive definite ``g`` (Cholesky); False when ``g`` is
    not positive definite to working precision."""
    k = g.shape[0]
    low = np.zeros((k, k))
    for j in range(k):
        s = g[j, j]
        for p in range(j):
            s -= low[j, p] * low[j, p]
        if not s > 0.0:
            return False
        d = math.sqrt(s)
        low[j, j] = d
        for i in range(j + 1, k):
            t = g[i, j]
            for p in range(j):
                t -= low[i, p] * low[j, p]
            low[i, j] = t / d
    z = np.empty(k)
    for i in range(k):
        t = b[i]
        for p in range(i):
            t -= low[i, p] * z[p]
        z[i] = t / low[i, i]
    for i in range(k - 1, -1, -1):
        t = z[i]
        for p in range(i + 1, k):
            t -= low[p, i] * out[p]
        out[i] = t / low[i, i]
    return True


#: Iterations of :func:`_box_qp` before it gives up (each adds or frees one bound; 12 unknowns).
BOX_QP_ITERATIONS = 100


def _box_qp(g: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray,
            x: np.ndarray) -> bool:
    """Minimise ½ xᵀ g x − bᵀ x inside [lo, hi] for a positive definite ``g``; ``x`` holds the
    unbounded minimiser on entry and the bounded one on return.

    The primal active-set method for bound constraints (Nocedal & Wright, *Numerical
    Optimization*, 2nd ed., §16.5): from the clipped point, solve for the free entries with
    the bound ones fixed; step toward that solution as far as the bounds allow and fix the
    entry that blocks, or, at the solution, free the bound entry whose multiplier has the
    wrong sign (the largest). The problem is strictly convex, so its minimiser is unique: the
    one scipy's NNLS/BVLS find on the same least squares. False when it has not finished in
    :data:`BOX_QP_ITERATIONS` steps.
    """
    k = g.shape[0]
    state = np.zeros(k, dtype=np.int64)  # 0 free, -1 at lo, +1 at hi
    for j in range(k):
        if x[j] <= lo[j]:
            x[j] = lo[j]
            state[j] = -1
        elif x[j] >= hi[j]:
            x[j] = hi[j]
            state[j] = 1
    for _ in range(BOX_QP_ITERATIONS):
        nfree = 0
        for j in range(k):
            if state[j] == 0:
                nfree += 1
        cand = np.empty(k)
        for j in range(k):
            cand[j] = x[j]
        if nfree > 0:
            idx = np.empty(nfree, dtype=np.int64)
            n = 0
            for j in range(k):
                if state[j] == 0:
                    idx[n] = j
                    n += 1
            gf = np.empty((nfree, nfree))
            bf = np.empty(nfree)
            for p in range(nfree):
                t = b[idx[p]]
                for j in range(k):
                    if state[j] != 0:
                        t -= g[idx[p], j] * x[j]
                bf[p] = t
                for q in range(nfree):
                    gf[p, q] = g[idx[p], idx[q]]
            sf = np.empty(nfree)
            if not _cholesky_solve(gf, bf, sf):
                return False
            for p in range(nfree):
                cand[idx[p]] = sf[p]
        # step toward the candidate as far as the bounds allow
        step = 1.0
        block = -1
        for j in range(k):
            if state[j] != 0:
                continue
            d = cand[j] - x[j]
            if cand[j] < lo[j] and d < 0:
                t = (lo[j] - x[j]) / d
                if t < step:
                    step, block = t, j
            elif cand[j] > hi[j] and d > 0:
                t = (hi[j] - x[j]) / d
                if t < step:
                    step, block = t, j
        if block >= 0:
            for j in range(k):
                if state[j] == 0:
                    x[j] += step * (cand[j] - x[j])
            x[block] = lo[block] if cand[block] < lo[block] else hi[block]
            state[block] = -1 if cand[block] < lo[block] else 1
            continue
        for j in range(k):
            x[j] = cand[j]
        # at the minimiser over the free entries: the multipliers of the bound ones
        worst = 0.0
        release = -1
        for j in range(k):
            if state[j] == 0:
                continue
            grad = -b[j]
            for q in range(k):
                grad += g[j, q] * x[q]
            # at lo the gradient must not be negative, at hi not positive
            viol = -grad if state[j] < 0 else grad
            if viol > worst:
                worst, release = viol, j
        if release < 0:
            return True
        state[release] = 0
    return False


def solve_normal(x: np.ndarray, y: np.ndarray, w: np.ndarray, free: np.ndarray,
                 lin: np.ndarray, pw: float, mu: np.ndarray, sdp: np.ndarray,
                 lo: np.ndarray, hi: np.ndarray, a: np.ndarray, rhs: np.ndarray,
                 r: np.ndarray, gram0: np.ndarray, n_fixed: int) -> bool:
    """The unbounded projection at a fixed design ``x`` (M, 12).

    ``gram0`` (F, F) holds the data part of the Gram matrix among the first ``n_fixed`` free
    columns when those do not change between calls (:func:`passive_gram`: the passive
    columns of a fit over β alone), summed as here; the rest of it is summed here, skipping
    the zero entries (the reflex columns are zero wherever the reflex is off - some nine in
    ten of them): adding a product with a zero changes no sum, so the numbers are those of
    the dense sums.

    Fills ``a`` (M, F) = the whitened free columns and ``rhs`` (M,) = the whitened data less
    the held linear terms; solves the normal equations with the prior (``mu``, ``sdp``: the
    prior mean and SD of the F free entries, ``pw`` its weight) inside [``lo``, ``hi``]
    (:func:`_box_qp` when the unbounded solution leaves them) into ``lin[free]`` and the
    whitened residuals into ``r``. Returns False - ``lin`` and ``r`` then unset - when the
    Gram matrix is not positive definite or the bounded solve does not finish: the caller
    solves the bounded problem from ``a`` and ``rhs`` (scipy).
    """
    m_rows = x.shape[0]
    nf = free.shape[0]
    held = np.ones(12, dtype=np.bool_)
    for j in range(nf):
        held[free[j]] = False
    for m in range(m_rows):
        t = y[m]
        for j in range(12):
            if held[j]:
                t -= x[m, j] * lin[j]
        rhs[m] = t * w[m]
        for j in range(nf):
            a[m, j] = x[m, free[j]] * w[m]
    if nf == 0:
        for m in range(m_rows):
            r[m] = rhs[m]
        return True
    gram = np.zeros((nf, nf))
    for j in range(n_fixed):
        for k in range(j + 1):
            gram[j, k] = gram0[j, k]
    bn = np.zeros(nf)
    for m in range(m_rows):
        for j in range(nf):
            aj = a[m, j]
            bn[j] += aj * rhs[m]
        for j in range(n_fixed, nf):
            aj = a[m, j]
            if aj == 0.0:  # most reflex entries: the reflex is off at most points
                continue
            for k in range(j + 1):
                gram[j, k] += aj * a[m, k]
    for j in range(nf):
        for k in range(j):
            gram[k, j] = gram[j, k]
        gram[j, j] += pw / (sdp[j] * sdp[j])
        bn[j] += pw * mu[j] / (sdp[j] * sdp[j])
    sol = np.empty(nf)
    if not _cholesky_solve(gram, bn, sol):
        return False
    inside = True
    for j in range(nf):
        if sol[j] < lo[j] or sol[j] > hi[j]:
            inside = False
    if not inside and not _box_qp(gram, bn, lo, hi, sol):
        return False
    for j in range(nf):
        lin[free[j]] = sol[j]
    for m in range(m_rows):
        t = rhs[m]
        for j in range(nf):
            if a[m, j] != 0.0:
                t -= a[m, j] * sol[j]
        r[m] = t
    return True


def passive_gram(xkm: np.ndarray, w: np.ndarray, free: np.ndarray, n_fixed: int,
                 gram0: np.ndarray) -> None:
    """The Gram matrix of the first ``n_fixed`` free (passive) columns of ``xkm`` whitened by
    ``w``, into ``gram0``'s lower triangle: what :func:`solve_normal` would sum for them, in
    the same order, kept for the fit's evaluations in which they do not change."""
    for j in range(n_fixed):
        for k in range(j + 1):
            gram0[j, k] = 0.0
    for m in range(xkm.shape[0]):
        for j in range(n_fixed):
            aj = xkm[m, free[j]] * w[m]
            for k in range(j + 1):
                gram0[j, k] += aj * (xkm[m, free[k]] * w[m])


def reflex_gradient(beta: np.ndarray, b_lo: np.ndarray, b_hi: np.ndarray, h: float,
                    kk: np.ndarray, lam_above_min: np.ndarray, ell: np.ndarray, c: np.ndarray,
                    dc: np.ndarray, row_pt: np.ndarray, cf: np.ndarray, cl: np.ndarray,
                    cd: np.ndarray, still: np.ndarray, gam0: np.ndarray, e0: np.ndarray,
                    alpha: np.ndarray, r: np.ndarray, w: np.ndarray, fitted: np.ndarray,
                    grad: np.ndarray) -> None:
    """-2 rᵀ W (∂X/∂β_i) θ_lin for each fitted β_i (``fitted``: indices 0-5), into ``grad``:
    the data part of the projected cost's gradient, ∂X/∂β_i by central differences of step
    ``h`` kept inside [``b_lo``, ``b_hi``]."""
    m_rows = row_pt.shape[0]
    bp = np.empty(6)
    bm = np.empty(6)
    for i in range(6):
        bp[i] = min(beta[i] + h, b_hi[i])
        bm[i] = max(beta[i] - h, b_lo[i])
    xp = np.empty((m_rows, 6))
    xm = np.empty((m_rows, 6))
    reflex_columns(bp, kk, lam_above_min, ell, c, dc, row_pt, cf, cl, cd, still, gam0, e0, xp,
                   0)
    reflex_columns(bm, kk, lam_above_min, ell, c, dc, row_pt, cf, cl, cd, still, gam0, e0, xm,
                   0)
    for n in range(fitted.shape[0]):
        i = fitted[n]
        step = bp[i] - bm[i]
        t = 0.0
        for m in range(m_rows):
            t += r[m] * ((xp[m, i] - xm[m, i]) / step * alpha[i] * w[m])
        grad[n] = -2.0 * t


def project_reflex(beta: np.ndarray, kk: np.ndarray, lam_above_min: np.ndarray,
                   ell: np.ndarray, c: np.ndarray, dc: np.ndarray, row_pt: np.ndarray,
                   cf: np.ndarray, cl: np.ndarray, cd: np.ndarray, still: np.ndarray,
                   gam0: np.ndarray, e0: np.ndarray, xkm: np.ndarray, y: np.ndarray,
                   w: np.ndarray, free: np.ndarray, lin: np.ndarray, pw: float, mu: np.ndarray,
                   sdp: np.ndarray, lo: np.ndarray, hi: np.ndarray, a: np.ndarray,
                   rhs: np.ndarray, r: np.ndarray, gram0: np.ndarray, n_fixed: int) -> bool:
    """:func:`reflex_columns` beside the fixed passive columns ``xkm`` (M, 6), then
    :func:`solve_normal`, in one call: the evaluation when only β varies (the default fit)."""
    m_rows = row_pt.shape[0]
    x = np.empty((m_rows, 12))
    for m in range(m_rows):
        for j in range(6):
            x[m, j] = xkm[m, j]
    reflex_columns(beta, kk, lam_above_min, ell, c, dc, row_pt, cf, cl, cd, still, gam0, e0,
                   x, 6)
    return solve_normal(x, y, w, free, lin, pw, mu, sdp, lo, hi, a, rhs, r, gram0, n_fixed)


def project_reflex_grad(beta: np.ndarray, kk: np.ndarray, lam_above_min: np.ndarray,
                        ell: np.ndarray, c: np.ndarray, dc: np.ndarray, row_pt: np.ndarray,
                        cf: np.ndarray, cl: np.ndarray, cd: np.ndarray, still: np.ndarray,
                        gam0: np.ndarray, e0: np.ndarray, xkm: np.ndarray, y: np.ndarray,
                        w: np.ndarray, free: np.ndarray, lin: np.ndarray, pw: float,
                        mu: np.ndarray, sdp: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                        a: np.ndarray, rhs: np.ndarray, r: np.ndarray, gram0: np.ndarray,
                        n_fixed: int, b_lo: np.ndarray, b_hi: np.ndarray, h: float,
                        fitted: np.ndarray, grad: np.ndarray) -> bool:
    """:func:`project_reflex`, then :func:`reflex_gradient` at the solved α, in one call (the
    search's and the refits' evaluation with its gradient). False as :func:`solve_normal`:
    nothing solved, ``grad`` unset."""
    if not project_reflex(beta, kk, lam_above_min, ell, c, dc, row_pt, cf, cl, cd, still,
                          gam0, e0, xkm, y, w, free, lin, pw, mu, sdp, lo, hi, a, rhs, r,
                          gram0, n_fixed):
        return False
    reflex_gradient(beta, b_lo, b_hi, h, kk, lam_above_min, ell, c, dc, row_pt, cf, cl, cd,
                    still, gam0, e0, lin[6:12], r, w, fitted, grad)
    return True
