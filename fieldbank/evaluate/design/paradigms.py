"""The seed's min-max and orientation paradigms read on given paths, the seed's pull and
semi-ellipse from the candidates' equilibrium, and a designed set beside them
(:class:`DesignReport`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fieldbank.evaluate.design.candidates import Candidate, check_candidates, equilibrium
from fieldbank.evaluate.design.config import NoiseModel, Perception, ProbeLimits
from fieldbank.evaluate.design.perception import pair_indices
from fieldbank.evaluate.design.score import ProbeSetScore, score_probes
from fieldbank.evaluate.design.search import ProbeDesign, design
from fieldbank.evaluate.probing import ProbeMotion, pull, semi_ellipse


@dataclass(frozen=True)
class Paradigms:
    """The seed's two paradigms read on given paths: for every path, where each candidate's
    force is largest and smallest and its direction; which pairs each paradigm separates; and a
    greedy set of at most n − 1 of the paths that separates every pair, if one exists."""

    score: ProbeSetScore
    minmax_set: tuple[str, ...]
    orientation_set: tuple[str, ...]
    minmax_complete: bool
    orientation_complete: bool

    def to_dict(self) -> dict[str, object]:
        d = self.score.to_dict()
        d["minmax_set"] = {"paths": list(self.minmax_set), "separates_all": self.minmax_complete}
        d["orientation_set"] = {"paths": list(self.orientation_set),
                                "separates_all": self.orientation_complete}
        return d


def _greedy_cover(score: ProbeSetScore, what: str, limit: int) -> tuple[tuple[str, ...], bool]:
    """At most ``limit`` probes whose union separates the most pairs (≥ 1 JND), greedily."""
    n = len(score.candidates)
    i, j = pair_indices(n)
    covers = [p.separations[what][i, j] >= 1.0 for p in score.probes]
    todo = np.ones(len(i), dtype=bool)
    chosen: list[str] = []
    while todo.any() and len(chosen) < limit:
        gains = [int((c & todo).sum()) for c in covers]
        k = int(np.argmax(gains)) if gains else 0
        if not gains or gains[k] == 0:
            break
        chosen.append(score.probes[k].name)
        todo &= ~covers[k]
    return tuple(chosen), not todo.any()


def paradigms(candidates: Sequence[Candidate], motions: Sequence[ProbeMotion], *,
              closed: Sequence[bool] | None = None, perception: Perception | None = None,
              noise: NoiseModel | None = None, limits: ProbeLimits | None = None) -> Paradigms:
    """Read the min-max and orientation paradigms on ``motions``; pick ≤ n − 1 of them."""
    score = score_probes(candidates, motions, perception=perception, noise=noise,
                         limits=limits, closed=closed)
    limit = len(score.candidates) - 1
    mm, mm_ok = _greedy_cover(score, "minmax", limit)
    orient, orient_ok = _greedy_cover(score, "orientation", limit)
    return Paradigms(score, mm, orient, mm_ok, orient_ok)


def seed_probes(candidates: Sequence[Candidate]) -> list[ProbeMotion]:
    """The seed's pull and semi-ellipse (:mod:`fieldbank.evaluate.probing`) from the
    candidates' equilibrium."""
    cands = check_candidates(candidates, 1)
    arm = cands[0].arm
    shift = equilibrium(cands) - arm.rest_position()
    return [ProbeMotion(m.name, m.times_s, m.positions_m + shift, m.velocities_m_per_s,
                        m.description) for m in (pull(arm), semi_ellipse(arm))]


@dataclass(frozen=True, eq=False)
class DesignReport:
    """A designed set of probes next to the seed's pull and semi-ellipse on the same
    candidates, measured the same way."""

    design: ProbeDesign
    seed: ProbeSetScore

    def to_dict(self, shoulder_offset_m: tuple[float, float] = (0.0, 0.0)
                ) -> dict[str, object]:
        return {**self.design.to_dict(shoulder_offset_m),
                "seed_probes": self.seed.to_dict(shoulder_offset_m)}


def design_report(candidates: Sequence[Candidate], **options: object) -> DesignReport:
    """:func:`design` with ``options``, and the seed's probes scored on the same candidates with
    the same perception, noise, limits, prior and target."""
    d = design(candidates, **options)  # type: ignore[arg-type]
    s = score_probes(candidates, seed_probes(candidates), prior=d.score.prior,
                     perception=d.score.perception, noise=d.score.noise, limits=d.limits,
                     target=d.score.target)
    return DesignReport(d, s)
