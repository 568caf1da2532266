"""Scores of given probes: every pair of candidates on every path, and on a set of paths,
by feel, by information and by the seed's two paradigms.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fieldbank.errors import ParameterError
from fieldbank.evaluate.design.candidates import Candidate, check_candidates, check_prior
from fieldbank.evaluate.design.config import NoiseModel, Perception, ProbeLimits
from fieldbank.evaluate.design.paths import Circle, Path
from fieldbank.evaluate.design.perception import (
    arc_fraction,
    combine_separations,
    criterion_score,
    entropy_bits,
    feature_separations,
    full_matrix,
    information_bits,
    kl_divergence,
    pair_error,
    pair_indices,
    pair_mask,
    perceived_features,
    separated_pairs,
)
from fieldbank.evaluate.design.predict import (
    execute_path,
    execution_deltas,
    path_accelerations,
    predict,
)
from fieldbank.evaluate.probing import ProbeMotion
from fieldbank.model import FloatArray
from fieldbank.probechoices import DEFAULT_TARGET, TARGETS


@dataclass
class ScoreContext:
    candidates: tuple[Candidate, ...]
    prior: FloatArray
    criterion: str
    perception: Perception
    noise: NoiseModel
    limits: ProbeLimits
    deltas: list[tuple[float, float, float]]
    labels: tuple[str, ...]
    evaluations: int = 0

    def evaluate(self, pos: FloatArray, vel: FloatArray, t: FloatArray, closed: bool,
                 robust: bool) -> tuple[dict[str, FloatArray], FloatArray]:
        """Separations (P, S) and D_KL per execution (P, S, E) of S paths (S, K, ·)."""
        frac = arc_fraction(pos)
        if robust:
            pe, ve, te = execute_path(pos, vel, t, self.deltas, closed)
        else:
            pe, ve, te = pos[:, None], vel[:, None], t[:, None]
        force = predict(self.candidates, pe, ve, self.limits.force_limit_n,
                        path_accelerations(ve, te))
        self.evaluations += pos.shape[0]
        feats = perceived_features(force, frac, self.perception)
        return (feature_separations(feats, self.perception, closed),
                kl_divergence(force, te, self.noise))


@dataclass(frozen=True)
class PathFeatures:
    """Where along a path one candidate's force is largest and smallest, and its direction
    (nominal execution; directions from +x in the shoulder frame, degrees)."""

    candidate: str
    max_force_n: float
    max_at_s: float
    max_at_m: tuple[float, float]
    max_at_fraction: float
    max_direction_deg: float
    min_force_n: float
    min_at_s: float
    min_at_m: tuple[float, float]
    min_at_fraction: float
    mean_direction_deg: float

    def to_dict(self) -> dict[str, object]:
        return {"candidate": self.candidate, "max_force_n": round(self.max_force_n, 4),
                "max_at_s": round(self.max_at_s, 4),
                "max_at_m": [round(v, 4) for v in self.max_at_m],
                "max_at_fraction": round(self.max_at_fraction, 4),
                "max_direction_deg": round(self.max_direction_deg, 2),
                "min_force_n": round(self.min_force_n, 4), "min_at_s": round(self.min_at_s, 4),
                "min_at_m": [round(v, 4) for v in self.min_at_m],
                "min_at_fraction": round(self.min_at_fraction, 4),
                "mean_direction_deg": round(self.mean_direction_deg, 2)}


def path_features(name: str, motion: ProbeMotion, force_n: FloatArray) -> PathFeatures:
    """:class:`PathFeatures` of one candidate's force (K, 2) along ``motion``."""
    mag = np.hypot(force_n[:, 0], force_n[:, 1])
    frac = arc_fraction(motion.positions_m[None])[0]
    i, k = int(np.argmax(mag)), int(np.argmin(mag))
    mean = force_n.mean(axis=0)
    p = motion.positions_m
    return PathFeatures(
        name, float(mag[i]), float(motion.times_s[i]), (float(p[i, 0]), float(p[i, 1])),
        float(frac[i]), math.degrees(math.atan2(force_n[i, 1], force_n[i, 0])),
        float(mag[k]), float(motion.times_s[k]), (float(p[k, 0]), float(p[k, 1])),
        float(frac[k]), math.degrees(math.atan2(mean[1], mean[0])))


@dataclass(frozen=True, eq=False)
class ProbeScore:
    """How one probe separates the candidates.

    Attributes
    ----------
    motion : ProbeMotion
    path : Stroke, Circle or None
        The parametrised path when the probe was designed.
    candidates : tuple of str
    force_n : ndarray, shape (n, K, 2), N
        Each candidate's predicted force along the nominal motion.
    features : tuple of PathFeatures
        Where each candidate's force is largest and smallest, and its direction.
    separations : dict of ndarray (n, n)
        'feel', 'orientation', 'minmax' in JNDs (robust to the motion noise); 'kl' D_KL, nats,
        averaged over the executions.
    kl_executions : ndarray, shape (P, E), nats
        D_KL of every pair (i < j) for each execution (nominal, then ±1 SD of each noise).
    closed : bool
        The path returns to its start (locations compare around it).
    """

    motion: ProbeMotion
    path: Path | None
    candidates: tuple[str, ...]
    force_n: FloatArray
    features: tuple[PathFeatures, ...]
    separations: dict[str, FloatArray]
    kl_executions: FloatArray
    closed: bool = False

    @property
    def name(self) -> str:
        return self.motion.name


@dataclass(frozen=True, eq=False)
class ProbeSetScore:
    """How a set of probes separates the candidates: per pair the best probe's felt, orientation
    and min-max separation (JNDs), and the sum of the probes' D_KL.

    ``labels`` says what must be told apart: with target 'candidate' every candidate is its
    own label; with 'group' only candidates of different impaired groups need separating.
    """

    probes: tuple[ProbeScore, ...]
    candidates: tuple[str, ...]
    prior: FloatArray
    perception: Perception
    noise: NoiseModel
    labels: tuple[str, ...]
    target: str = DEFAULT_TARGET

    def matrix(self, what: str) -> FloatArray:
        """(n, n): 'feel', 'orientation', 'minmax' (max over probes) or 'kl' (sum)."""
        mats = [p.separations[what] for p in self.probes]
        if not mats:
            return np.zeros((len(self.candidates),) * 2)
        return np.sum(mats, axis=0) if what == "kl" else np.max(mats, axis=0)

    def _pair_values(self, what: str) -> FloatArray:
        i, j = pair_indices(len(self.candidates))
        return self.matrix(what)[i, j]

    def _kl_combinations(self) -> FloatArray:
        """D_KL of every pair for combinations of the probes' executions, (P, C)."""
        out: tuple[dict[str, FloatArray], FloatArray] | None = None
        for p in self.probes:
            sep = {k: p.separations[k][pair_indices(len(self.candidates))][:, None]
                   for k in ("feel", "orientation", "minmax")}
            s, kl = combine_separations(sep, p.kl_executions[:, None, :], out)
            out = ({k: v[:, 0] for k, v in s.items()}, kl[:, 0])
        return out[1] if out is not None else np.zeros((len(pair_indices(len(self.candidates))[0]),
                                                         1))

    def _sep_kl(self) -> tuple[dict[str, FloatArray], FloatArray]:
        sep = {k: self._pair_values(k)[:, None] for k in ("feel", "orientation", "minmax")}
        return sep, self._kl_combinations()[:, None, :]

    @property
    def _named(self) -> tuple[str, ...] | None:
        return None if len(set(self.labels)) == len(self.labels) else self.labels

    @property
    def information_bits(self) -> float:
        """Information the set gives about the target (candidate or group), bits, averaged over
        the executions of its probes."""
        kl = self._kl_combinations()
        n = len(self.candidates)
        return float(information_bits(full_matrix(kl, n), self.prior, self._named).mean())

    @property
    def information_max_bits(self) -> float:
        """The most any recording can tell about the target, bits."""
        return entropy_bits(self.prior, self._named)

    def score(self, criterion: str) -> float:
        """The criterion's score of the set (see the module docstring; no tie-break term)."""
        sep, kl = self._sep_kl()
        return float(criterion_score(criterion, sep, kl, self.prior, self.labels,
                                     tie_break=False)[0])

    def separated(self, criterion: str = "feel") -> np.ndarray:
        """(n, n) bool: pairs the set separates by ``criterion`` (or need not separate)."""
        n = len(self.candidates)
        sep, kl = self._sep_kl()
        ok = separated_pairs(criterion, sep, kl, pair_mask(self.labels, n))[:, 0]
        out = np.eye(n, dtype=bool)
        i, j = pair_indices(n)
        out[i, j] = ok
        out[j, i] = ok
        return out

    def unseparated(self, criterion: str = "feel") -> list[tuple[str, str]]:
        s = self.separated(criterion)
        i, j = pair_indices(len(self.candidates))
        return [(self.candidates[a], self.candidates[b]) for a, b in zip(i, j, strict=True)
                if not s[a, b]]

    def separates_all(self, criterion: str = "feel") -> bool:
        return not self.unseparated(criterion)

    def pairs(self) -> list[dict[str, object]]:
        """Every pair with each measure (JNDs, nats, Bayes error) and the probe felt most."""
        out: list[dict[str, object]] = []
        i, j = pair_indices(len(self.candidates))
        kl = self.matrix("kl")
        must = pair_mask(self.labels, len(self.candidates))
        for k, (a, b) in enumerate(zip(i, j, strict=True)):
            felt = [float(p.separations["feel"][a, b]) for p in self.probes]
            best = int(np.argmax(felt)) if felt else -1
            out.append({
                "pair": [self.candidates[a], self.candidates[b]],
                "to_tell_apart": bool(must[k]),
                "felt_jnd": round(max(felt), 3) if felt else 0.0,
                "felt_best_probe": self.probes[best].name if felt else None,
                "orientation_jnd": round(float(self.matrix("orientation")[a, b]), 3),
                "minmax_jnd": round(float(self.matrix("minmax")[a, b]), 3),
                "kl_nats": round(float(kl[a, b]), 3),
                "error_probability": float(f"{float(pair_error(kl[a, b])):.3g}"),
                "felt_apart": bool(max(felt) >= 1.0) if felt else False,
            })
        return out

    def summary(self) -> dict[str, object]:
        """The headline figures: information, worst felt pair, what stays unseparated."""
        must = pair_mask(self.labels, len(self.candidates))
        felt = self._pair_values("feel")[must]
        err = pair_error(self._pair_values("kl")[must])
        return {
            "probes": len(self.probes),
            "target": self.target,
            "information_bits": round(self.information_bits, 4),
            "information_max_bits": round(self.information_max_bits, 4),
            "feel_score": round(self.score("feel"), 4),
            "worst_felt_jnd": round(float(felt.min()), 3) if felt.size else 0.0,
            "worst_error_probability": float(f"{float(err.max()):.3g}") if err.size else 0.0,
            "separates_all_by_feel": self.separates_all("feel"),
            "separates_all_statistically": self.separates_all("information"),
            "unseparated_by_feel": [list(p) for p in self.unseparated("feel")],
        }

    def to_dict(self, shoulder_offset_m: tuple[float, float] = (0.0, 0.0)
                ) -> dict[str, object]:
        return {
            "candidates": list(self.candidates),
            "prior": [round(float(p), 6) for p in self.prior],
            "summary": self.summary(),
            "probes": [{
                "name": p.name, "description": p.motion.description,
                "path": None if p.path is None else p.path.to_dict(),
                "duration_s": round(float(p.motion.times_s[-1] - p.motion.times_s[0]), 4),
                "peak_speed_m_per_s": round(p.motion.peak_speed_m_per_s, 4),
                "drawing": p.motion.path(shoulder_offset_m).to_dict(),
                "features": [f.to_dict() for f in p.features],
            } for p in self.probes],
            "pairs": self.pairs(),
            "perception": self.perception.to_dict(),
            "noise": self.noise.to_dict(),
        }


def target_labels(candidates: Sequence[Candidate], target: str) -> tuple[str, ...]:
    """What must be told apart: each candidate ('candidate') or each impaired group ('group')."""
    if target not in TARGETS:
        raise ParameterError(f"Unknown target {target!r}; known: {', '.join(TARGETS)}.")
    labels = tuple(c.name if target == "candidate" else c.label for c in candidates)
    if len(set(labels)) < 2:
        raise ParameterError(f"Every candidate has the same {target} ({labels[0]!r}); there is "
                             "nothing to tell apart.")
    return labels


def score_probes(candidates: Sequence[Candidate], motions: Sequence[ProbeMotion], *,
                 paths: Sequence[Path | None] | None = None,
                 prior: Sequence[float] | FloatArray | None = None,
                 perception: Perception | None = None, noise: NoiseModel | None = None,
                 limits: ProbeLimits | None = None,
                 closed: Sequence[bool] | None = None,
                 target: str = DEFAULT_TARGET) -> ProbeSetScore:
    """Score given probes (e.g. the seed's pull and semi-ellipse) on the candidates."""
    cands = check_candidates(candidates, 2)
    p = check_prior(prior, len(cands))
    labels = target_labels(cands, target)
    ctx = ScoreContext(cands, p, "feel", perception or Perception(), noise or NoiseModel(),
                   limits or ProbeLimits(), execution_deltas(noise or NoiseModel()), labels)
    out = []
    for k, m in enumerate(motions):
        path = paths[k] if paths is not None else None
        is_closed = closed[k] if closed is not None else isinstance(path, Circle)
        sep, kl = ctx.evaluate(m.positions_m[None], m.velocities_m_per_s[None],
                               m.times_s[None], is_closed, robust=True)
        force = predict(cands, m.positions_m, m.velocities_m_per_s, ctx.limits.force_limit_n,
                        m.accelerations_m_per_s2)
        n = len(cands)
        mats = {key: full_matrix(v, n)[0] for key, v in sep.items()}
        mats["kl"] = full_matrix(kl.mean(axis=-1), n)[0]
        feats = tuple(path_features(c.name, m, force[i]) for i, c in enumerate(cands))
        out.append(ProbeScore(m, path, tuple(c.name for c in cands), force, feats, mats,
                              kl[:, 0, :], is_closed))
    return ProbeSetScore(tuple(out), tuple(c.name for c in cands), p, ctx.perception, ctx.noise,
                         labels, target)
