"""Optimisers: nlopt global search then local polish, and scipy's dual annealing baseline.

nlopt algorithms run on the variable-projected cost (:meth:`FitProblem.projected_cost_grad`):
the search space is β (and q_rest) only, with Km and α solved inside. The pipeline: the global
search, a local polish from its best point, one-dimensional grid scans of each coordinate
(:func:`_coordinate_sweeps`: the reflex's flat regions hide improvements from local searches),
and a last polish when a scan improved the point. ``dual_annealing`` is the
seed's method and runs, as the seed did, over the full parameter vector with the same cost
(:meth:`FitProblem.cost`) and bounds; it is kept as the baseline to compare against.

Every run is deterministic for a seed: ``nlopt.srand(seed)`` before each nlopt run, the seed
passed to ``dual_annealing``, and MLSL uses its low-discrepancy sequence.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fieldbank.errors import FitError
from fieldbank.fitchoices import ALGORITHMS
from fieldbank.fitting.problem import FitProblem
from fieldbank.model import FloatArray

#: Default evaluation budgets: the global stage of nlopt, the polish, and dual annealing.
DEFAULT_GLOBAL_EVALS = 600
POLISH_EVALS = 400
#: Global-stage budget of the refit with unidentified parameters held (see ArmFitter).
HOLD_EVALS = 100
#: Restarts of a global run that a failed local search aborted.
MAX_RESTARTS = 3
#: Coordinate scans after the polish: grid points per parameter and passes over all of them.
SWEEP_POINTS = 41
SWEEP_PASSES = 2
DEFAULT_ANNEALING_EVALS = 200_000

Progress = Callable[[int, float], None]
_RESULT_NAMES = {1: "success", 2: "stopval reached", 3: "ftol reached", 4: "xtol reached",
                 5: "maxeval reached", 6: "maxtime reached"}


@dataclass(frozen=True)
class SearchResult:
    theta: FloatArray
    cost: float
    n_evals: int
    stop_reason: str


class _Tracker:
    """Wraps an objective: counts evaluations, keeps the best point, reports progress."""

    def __init__(self, progress: Progress | None, every: int = 50) -> None:
        self.best_cost = np.inf
        self.best_x: FloatArray | None = None
        self.n = 0
        self.progress = progress
        self.every = every

    def seen(self, x: FloatArray, cost: float) -> None:
        self.n += 1
        if cost < self.best_cost:
            self.best_cost = cost
            self.best_x = np.array(x, dtype=float)
        if self.progress is not None and self.n % self.every == 0:
            self.progress(self.n, float(self.best_cost))


def nlopt_run(
    algorithm: int,
    local: int | None,
    f: Callable[[FloatArray, FloatArray], float],
    x0: FloatArray,
    lo: FloatArray,
    hi: FloatArray,
    max_evals: int,
    seed: int,
) -> str:
    """One nlopt run (``local``: MLSL's local optimiser) minimising ``f`` from ``x0``; returns
    why it stopped. nlopt's failures are caught: the caller keeps its best point."""
    import nlopt

    nlopt.srand(seed)
    opt = nlopt.opt(algorithm, x0.size)
    opt.set_lower_bounds(lo)
    opt.set_upper_bounds(hi)
    opt.set_min_objective(f)
    opt.set_maxeval(max_evals)
    if local is not None:
        sub = nlopt.opt(local, x0.size)
        sub.set_ftol_rel(1e-6)
        sub.set_xtol_rel(1e-5)
        sub.set_maxeval(max(50, max_evals // 8))
        opt.set_local_optimizer(sub)
    else:
        opt.set_ftol_rel(1e-12)
        opt.set_xtol_rel(1e-9)
    try:
        opt.optimize(np.clip(x0, lo, hi))
        code = int(opt.last_optimize_result())
        return _RESULT_NAMES.get(code, f"nlopt result {code}")
    except nlopt.RoundoffLimited:
        return "roundoff limited (best point kept)"
    except (ValueError, RuntimeError, nlopt.exception) as exc:  # nlopt failure codes
        return f"stopped: {exc or 'nlopt failure'} (best point kept)"


def run_nlopt(
    problem: FitProblem,
    name: str,
    seed: int,
    max_evals: int | None,
    progress: Progress | None = None,
) -> SearchResult:
    """Global search over the nonlinear parameters, then a local polish from the best point."""
    import nlopt

    glob, loc = (getattr(nlopt, a) for a in ALGORITHMS[name])
    idx = problem.nonlinear_index()
    tracker = _Tracker(progress)
    start = problem.n_evals
    if idx.size == 0:
        pr = problem.project(problem.space.base.copy())
        return SearchResult(pr.theta, pr.cost, problem.n_evals - start, "linear only")
    lo = problem.space.lower[idx]
    hi = problem.space.upper[idx]
    x0 = problem.space.base[idx]
    needs_grad = loc == nlopt.LD_LBFGS

    def f(x: FloatArray, grad: FloatArray) -> float:
        if grad.size:
            cost, g, _ = problem.projected_cost_grad(x)
            grad[:] = g
        else:
            cost = problem.project(problem.full_from_nonlinear(x)).cost
        tracker.seen(x, cost)
        return cost

    evals = DEFAULT_GLOBAL_EVALS if max_evals is None else max_evals
    # A local search can fail on a kink of the cost (the reflex's max(0, ·) and clip); nlopt
    # then aborts the whole global run. Restart it on the remaining budget, from the best point
    # so far, with the next seed (deterministic), at most MAX_RESTARTS times.
    reasons = []
    for attempt in range(MAX_RESTARTS + 1):
        budget = evals - tracker.n
        if budget < 10:
            break
        start_x = x0 if tracker.best_x is None else tracker.best_x
        reason = nlopt_run(glob, loc if glob == nlopt.G_MLSL_LDS else None, f, start_x, lo, hi,
                            budget, seed + attempt)
        reasons.append(reason)
        if not reason.startswith("stopped"):
            break
    reason = " / ".join(reasons)
    if tracker.best_x is None:
        raise FitError(f"{name}: the global search evaluated no point ({reason}).")
    polish = loc if needs_grad or loc == nlopt.LN_BOBYQA else nlopt.LN_BOBYQA
    reason2 = _polish(polish, f, tracker, lo, hi, seed)
    improved = _coordinate_sweeps(problem, f, tracker, lo, hi)
    reason3 = "none"
    if improved:
        reason3 = _polish(polish, f, tracker, lo, hi, seed)
    best = problem.project(problem.full_from_nonlinear(tracker.best_x))
    return SearchResult(best.theta, best.cost, problem.n_evals - start,
                        f"global: {reason}; polish: {reason2}; sweeps improved {improved} "
                        f"time(s), polish: {reason3}")


def _polish(
    algorithm: int,
    f: Callable[[FloatArray, FloatArray], float],
    tracker: _Tracker,
    lo: FloatArray,
    hi: FloatArray,
    seed: int,
) -> str:
    """Local search from the best point; after a gradient search stopped on a kink of the
    cost, finish without gradients (BOBYQA)."""
    import nlopt

    assert tracker.best_x is not None
    reason = nlopt_run(algorithm, None, f, tracker.best_x, lo, hi, POLISH_EVALS, seed)
    if reason.startswith("stopped") and algorithm != nlopt.LN_BOBYQA:
        reason += "; then bobyqa: " + nlopt_run(nlopt.LN_BOBYQA, None, f, tracker.best_x, lo,
                                                 hi, POLISH_EVALS, seed)
    return reason


def _coordinate_sweeps(
    problem: FitProblem,
    f: Callable[[FloatArray, FloatArray], float],
    tracker: _Tracker,
    lo: FloatArray,
    hi: FloatArray,
) -> int:
    """One-dimensional grid scans of each nonlinear parameter from the best point.

    The reflex φ = max(0, ·) is exactly zero over whole ranges of β where it never fires at a
    measured point; there the cost is flat and a local search cannot see that a larger β
    would make it fire and fit better. A scan over a grid of each coordinate (others fixed,
    Km and α re-solved) finds such steps for a few hundred cheap evaluations. Returns how many
    scans improved the best point.
    """
    assert tracker.best_x is not None
    improved = 0
    empty = np.empty(0)
    for _ in range(SWEEP_PASSES):
        changed = False
        for k in range(tracker.best_x.size):
            base_x = tracker.best_x.copy()
            base_cost = tracker.best_cost
            for v in np.linspace(lo[k], hi[k], SWEEP_POINTS):
                x = base_x.copy()
                x[k] = v
                f(x, empty)
            if tracker.best_cost < base_cost - 1e-9 * max(1.0, abs(base_cost)):
                improved += 1
                changed = True
        if not changed:
            break
    return improved


def run_dual_annealing(
    problem: FitProblem,
    seed: int,
    max_evals: int | None,
    progress: Progress | None = None,
    target_cost: float | None = None,
    maxiter: int = 1000,
) -> SearchResult:
    """scipy's dual annealing over every fitted parameter (the seed's method), same cost.

    ``target_cost``: stop as soon as the cost reaches it (used by the benchmark to time how
    long the baseline needs to match another fit). ``maxiter``: annealing iterations (scipy's
    default 1000).
    """
    from scipy.optimize import dual_annealing

    s = problem.space
    idx = np.flatnonzero(s.fitted)
    tracker = _Tracker(progress, every=2000)
    start = problem.n_evals
    theta = s.base.copy()

    def f(x: FloatArray) -> float:
        theta[idx] = x
        cost = problem.cost(theta)
        tracker.seen(x, cost)
        return cost

    def cb(x: FloatArray, fval: float, context: int) -> bool:
        return target_cost is not None and fval <= target_cost

    res = dual_annealing(
        f,
        bounds=list(zip(s.lower[idx], s.upper[idx], strict=True)),
        seed=np.random.default_rng(seed),
        maxfun=DEFAULT_ANNEALING_EVALS if max_evals is None else max_evals,
        maxiter=maxiter,
        x0=np.clip(s.base[idx], s.lower[idx], s.upper[idx]),
        callback=cb,
    )
    best = s.base.copy()
    best[idx] = tracker.best_x if tracker.best_x is not None else res.x
    return SearchResult(best, float(tracker.best_cost), problem.n_evals - start,
                        "; ".join(res.message) if isinstance(res.message, list)
                        else str(res.message))
