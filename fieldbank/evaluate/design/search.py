"""The search for the most informative probes.

For one path: every point of a coarse grid of the family is scored on its nominal execution in
one vectorised evaluation per candidate; the best few distinct ones are polished with nlopt
(Sbplx, derivative-free) on the robust score. A set is built greedily: each next path maximises
the score of the set with it, until every pair is separated (felt apart by ≥ 1 JND, or a
Bayes error ≤ 5 % for the information criterion), the score stops improving, or n − 1 paths.
Scores saturate when every pair is far apart; a term 10⁻³·log(1 + worst pair) breaks the tie
toward the path that separates the closest pair most.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import nlopt
import numpy as np

from fieldbank.errors import ParameterError
from fieldbank.evaluate.design.candidates import (
    Candidate,
    check_candidates,
    check_prior,
    equilibrium,
)
from fieldbank.evaluate.design.config import (
    DESIGN_SAMPLES,
    LIMIT_SAMPLES,
    MIN_GAIN,
    POLISH_EVALS,
    POLISH_STARTS,
    NoiseModel,
    Perception,
    ProbeLimits,
)
from fieldbank.evaluate.design.coverage import coverage_strokes
from fieldbank.evaluate.design.paths import FAMILIES, Family, Path
from fieldbank.evaluate.design.perception import (
    combine_separations,
    criterion_score,
    pair_mask,
    separated_pairs,
)
from fieldbank.evaluate.design.predict import execute_path, execution_deltas, feasible
from fieldbank.evaluate.design.score import ProbeSetScore, ScoreContext, score_probes, target_labels
from fieldbank.evaluate.probing import PROBE_SAMPLES, ProbeMotion
from fieldbank.model import FloatArray
from fieldbank.probechoices import CRITERIA, DEFAULT_CRITERION, DEFAULT_TARGET


@dataclass(frozen=True, eq=False)
class ProbeDesign:
    """A designed set of probes and how it was found.

    Attributes
    ----------
    paths : tuple of Stroke or Circle
    score : ProbeSetScore
        The set scored at report resolution (robust to the motion noise).
    criterion, family : str
    search_s : float, s
        Wall time of the search.
    evaluations : int
        Paths evaluated (each on every candidate; robust ones once per execution).
    limits : ProbeLimits
    """

    paths: tuple[Path, ...]
    score: ProbeSetScore
    criterion: str
    family: str
    search_s: float
    evaluations: int
    limits: ProbeLimits

    @property
    def motions(self) -> tuple[ProbeMotion, ...]:
        return tuple(p.motion for p in self.score.probes)

    def to_dict(self, shoulder_offset_m: tuple[float, float] = (0.0, 0.0)
                ) -> dict[str, object]:
        return {"criterion": self.criterion, "family": self.family, "target": self.score.target,
                "search_s": round(self.search_s, 4), "evaluations": self.evaluations,
                "limits": self.limits.to_dict(), **self.score.to_dict(shoulder_offset_m)}


def _polish(ctx: ScoreContext, fam: Family, start: FloatArray, x0: FloatArray,
            prev: tuple[dict[str, FloatArray], FloatArray] | None,
            evals: int) -> tuple[FloatArray, float]:
    """nlopt Sbplx from ``x0`` on the robust score; returns the best point seen and its score."""
    lo, hi = fam.bounds(ctx.limits)
    if fam.name == "stroke":  # direction: a local window, the grid chose the neighbourhood
        lo, hi = lo.copy(), hi.copy()
        lo[0], hi[0] = x0[0] - 20.0, x0[0] + 20.0
    idx = list(fam.polish)
    best_x, best_val = x0.copy(), -np.inf

    def f(x: Sequence[float], grad: FloatArray) -> float:
        nonlocal best_x, best_val
        v = x0.copy()
        v[idx] = x
        val = float(_robust_score(ctx, fam, start, v[None], prev)[0])
        if val > best_val:
            best_x, best_val = v, val
        return val

    opt = nlopt.opt(nlopt.LN_SBPLX, len(idx))
    opt.set_lower_bounds(lo[idx].tolist())
    opt.set_upper_bounds(hi[idx].tolist())
    opt.set_max_objective(f)
    opt.set_maxeval(evals)
    opt.set_xtol_rel(1e-3)
    opt.set_initial_step(((hi[idx] - lo[idx]) / 8.0).tolist())
    x_start = np.clip(x0[idx], lo[idx], hi[idx])
    try:
        opt.optimize(x_start.tolist())
    except (nlopt.RoundoffLimited, ValueError, RuntimeError):
        pass  # the best point seen is kept
    return best_x, best_val



def _within_limits(ctx: ScoreContext, fam: Family, start: FloatArray, v: FloatArray,
                   samples: int = LIMIT_SAMPLES) -> np.ndarray:
    """Which of S paths (rows of v) keep every limit in every execution of the motion noise,
    sampled at ``samples`` points: mask (S,).

    At :data:`LIMIT_SAMPLES` the check holds for every point of the drawn polyline and of the
    search; at :data:`DESIGN_SAMPLES` (points among those) it is a cheap necessary condition.
    """
    pos, vel, t = fam.make(start, v, samples)
    pe, ve, _ = execute_path(pos, vel, t, ctx.deltas, fam.closed)
    return feasible(ctx.candidates, pe, ve, ctx.limits)


def _robust_score(ctx: ScoreContext, fam: Family, start: FloatArray, v: FloatArray,
                  prev: tuple[dict[str, FloatArray], FloatArray] | None) -> FloatArray:
    """Score of S paths (rows of v) added to the set ``prev``; paths that break a limit score
    −1 (a feasible path scores ≥ 0)."""
    ok = _within_limits(ctx, fam, start, v)
    pos, vel, t = fam.make(start, v, DESIGN_SAMPLES)
    out = np.full(v.shape[0], -1.0)
    if ok.any():
        sep, kl = ctx.evaluate(pos[ok], vel[ok], t[ok], fam.closed, robust=True)
        sep, kl = combine_separations(sep, kl, prev)
        out[ok] = criterion_score(ctx.criterion, sep, kl, ctx.prior, ctx.labels)
    return out


def _search_one(ctx: ScoreContext, fam: Family, start: FloatArray,
                prev: tuple[dict[str, FloatArray], FloatArray] | None,
                starts: int, evals: int) -> tuple[FloatArray | None, float]:
    grid = fam.grid(ctx.limits)
    pos, vel, t = fam.make(start, grid, DESIGN_SAMPLES)
    # the coarse check filters the grid; a start is checked at full resolution before polish
    ok = _within_limits(ctx, fam, start, grid, DESIGN_SAMPLES)
    if not ok.any():
        return None, -np.inf
    grid = grid[ok]
    sep, kl = ctx.evaluate(pos[ok], vel[ok], t[ok], fam.closed, robust=False)
    sep, kl = combine_separations(sep, kl, prev)
    order = np.argsort(-criterion_score(ctx.criterion, sep, kl, ctx.prior, ctx.labels),
                       kind="stable")
    chosen: list[FloatArray] = []
    for k in order:
        g = grid[k]
        if fam.name == "stroke" and any(
                abs(((g[0] - c[0]) + 180.0) % 360.0 - 180.0) < 30.0 for c in chosen):
            continue
        if not _within_limits(ctx, fam, start, g[None])[0]:
            continue
        chosen.append(g)
        if len(chosen) == starts:
            break
    best_v: FloatArray | None = None
    best = -np.inf
    for g in chosen:
        v, val = _polish(ctx, fam, start, g, prev, evals) if evals > 0 else \
            (g, float(_robust_score(ctx, fam, start, g[None], prev)[0]))
        if val > best:
            best_v, best = v, val
    if best < 0.0:  # no start kept every limit
        return None, -np.inf
    if best_v is not None and fam.name == "stroke":
        best_v = best_v.copy()
        best_v[0] = ((best_v[0] + 180.0) % 360.0) - 180.0
    return best_v, best


def design(candidates: Sequence[Candidate], *, criterion: str = DEFAULT_CRITERION,
           family: str = "stroke", target: str = DEFAULT_TARGET, max_probes: int | None = None,
           prior: Sequence[float] | FloatArray | None = None,
           perception: Perception | None = None, noise: NoiseModel | None = None,
           limits: ProbeLimits | None = None, start_m: Sequence[float] | None = None,
           stop_when_separated: bool = True, polish_starts: int = POLISH_STARTS,
           polish_evals: int = POLISH_EVALS, names: Sequence[str] | None = None,
           cover: bool = False) -> ProbeDesign:
    """The set of at most ``max_probes`` (default n − 1) paths that best separates the candidates.

    Parameters
    ----------
    candidates : sequence of Candidate
    criterion : {'feel', 'information', 'orientation', 'minmax'}
        What is maximised: felt separation (JNDs), information (bits), or one of the seed's
        paradigms alone.
    family : {'stroke', 'circle'}
    target : {'candidate', 'group'}
        Tell every candidate apart, or only candidates of different impaired groups.
    max_probes : int, optional
    prior : sequence of float, optional
        Prior probability of each candidate (uniform by default).
    start_m : (x, y), m, optional
        Where strokes start / circles are centred (default: the candidates' equilibrium).
    stop_when_separated : bool
        Stop adding paths once every pair is separated (else go on while the score improves).
    polish_starts, polish_evals : int
        Grid points polished with nlopt and the evaluations each may use.
    names : sequence of str, optional
        Names of the probes (default "stroke 1", "stroke 2", …).
    cover : bool
        Start the set with a stroke along the direction that lengthens each group in which the
        candidates differ (:func:`fieldbank.evaluate.design.coverage.coverage_strokes`), so
        that no difference goes unstretched; the search adds strokes after them up to
        ``max_probes`` (strokes only).
    """
    t0 = time.perf_counter()
    cands = check_candidates(candidates, 2)
    if criterion not in CRITERIA:
        raise ParameterError(f"Unknown criterion {criterion!r}; known: {', '.join(CRITERIA)}.")
    if family not in FAMILIES:
        raise ParameterError(f"Unknown path family {family!r}; known: {', '.join(FAMILIES)}.")
    n = len(cands)
    limit = n - 1 if max_probes is None else int(max_probes)
    if limit < 1:
        raise ParameterError(f"max_probes must be at least 1; got {max_probes!r}.")
    fam = FAMILIES[family]
    noise = noise or NoiseModel()
    labels = target_labels(cands, target)
    ctx = ScoreContext(cands, check_prior(prior, n), criterion, perception or Perception(), noise,
                   limits or ProbeLimits(), execution_deltas(noise), labels)
    mask = pair_mask(labels, n)
    start = equilibrium(cands) if start_m is None else np.asarray(start_m, dtype=float)
    chosen: list[FloatArray] = []
    prev: tuple[dict[str, FloatArray], FloatArray] | None = None
    last = -np.inf
    if cover and family == "stroke":
        for s in coverage_strokes(cands, ctx.limits, noise, (float(start[0]), float(start[1]))):
            cv = np.array(s.values, dtype=float)
            chosen.append(cv)
            pos, vel, t = fam.make(start, cv[None], DESIGN_SAMPLES)
            sep, kl = ctx.evaluate(pos, vel, t, fam.closed, robust=True)
            sep, kl = combine_separations(sep, kl, prev)
            prev = ({k: x[:, 0] for k, x in sep.items()}, kl[:, 0])
        limit = max(limit, len(chosen))
    while len(chosen) < limit:
        v, val = _search_one(ctx, fam, start, prev, polish_starts, polish_evals)
        if v is None or (chosen and val < last + MIN_GAIN):
            break
        chosen.append(v)
        last = val
        pos, vel, t = fam.make(start, v[None], DESIGN_SAMPLES)
        sep, kl = ctx.evaluate(pos, vel, t, fam.closed, robust=True)
        sep, kl = combine_separations(sep, kl, prev)
        prev = ({k: s[:, 0] for k, s in sep.items()}, kl[:, 0])
        if stop_when_separated and separated_pairs(
                criterion, {k: s[:, None] for k, s in prev[0].items()}, prev[1][:, None, :],
                mask).all():
            break
    if not chosen:
        raise ParameterError(
            f"No {family} within the limits (peak speed ≤ {ctx.limits.max_speed_m_per_s:g} m/s, "
            f"{ctx.limits.rom_margin_deg:g}° inside every candidate's range of motion"
            + ("" if ctx.limits.workspace_m is None else ", inside the workspace box")
            + ") starts at the equilibrium; relax the limits or check the candidates.")
    side = "left" if cands[0].arm.mirror else "right"
    paths = tuple(fam.build(start, v) for v in chosen)
    titles = list(names) if names is not None else [f"{family} {k + 1}" for k in range(len(paths))]
    motions = [p.motion(PROBE_SAMPLES, titles[k], side) for k, p in enumerate(paths)]
    score = score_probes(cands, motions, paths=paths, prior=ctx.prior,
                         perception=ctx.perception, noise=noise, limits=ctx.limits,
                         closed=[fam.closed] * len(paths), target=target)
    return ProbeDesign(paths, score, criterion, family, time.perf_counter() - t0,
                       ctx.evaluations, ctx.limits)
