"""What a hand feels, and what a recording tells: separations in JNDs and information.

Two candidates feel different along a path where, at the same moment of the motion, their forces
differ by more than a just-noticeable difference (JND) in magnitude (Weber fraction 10 %:
7 % for matched forces, Jones 1989; 5–15 %, Pang, Tan & Durlach 1991) or in direction (25.6°
with haptics alone: Barbagli, Salisbury, Ho, Spence & Tan 2006). The two channels add as
independent cues, d = √(m² + a²) in JNDs, and a pair's separation is the largest d along the
path. Directions are judged only where both forces reach :data:`FELT_FLOOR_N` (assumption).
The operator never performs a path exactly: a pair counts as felt apart only if it stays apart
for every pair of executions within the motion noise (direction, length and speed each ±1 SD,
:class:`NoiseModel`), so a difference the clinician's own variability could produce does not
count. Free exploration uses the seed's stiffness Weber fraction 0.6 for magnitude instead
(:meth:`Perception.free_exploration`). The seed's paradigms are read the same way:
*orientation* - the directions at each candidate's peak force differ by ≥ 1 JND; *min-max* -
the places along the path of the largest or the smallest force differ by ≥ 11 % of the path's
length (distance Weber fraction of active arm movements, van Beek, Bergmann Tiest & Kappers 2014).

The recorded force is the prediction plus Gaussian noise of SD σ per axis whose samples
decorrelate over τ (assumption), so a path of duration T carries T/τ independent samples. Between
two candidates D_KL = Σ_k (Δt_k/τ)·|F_i − F_j|² / (2σ²) (averaged over the executions); a
set of paths adds. The information the path gives about which candidate it is, with prior p,
is bounded below by the pairwise-distance estimate of Kolchinsky & Tracey (2017, Entropy 19:361)
with the Bhattacharyya distance, D_KL/4 for equal covariances:
I ≥ −Σ_i p_i log₂ Σ_j p_j exp(−D_ij/4) bits (at most log₂ n). Pairwise, the Bayes error of
telling two candidates apart is Φ(−√(2 D_ij)/2).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.special import erf, ndtr

from fieldbank.evaluate.design.config import (
    MAX_COMBINATIONS,
    SEPARATED_ERROR,
    TIE_BREAK,
    NoiseModel,
    Perception,
)
from fieldbank.model import FloatArray


def pair_indices(n: int) -> tuple[np.ndarray, np.ndarray]:
    i, j = np.triu_indices(n, 1)
    return i, j


@dataclass(frozen=True)
class Features:
    """Per candidate, path and execution: log magnitude, direction, felt mask, and the places
    of the peak and the trough (fractions of the path length) with the peak's direction."""

    logmag: FloatArray      # (n, S, E, K)
    angle: FloatArray       # (n, S, E, K) rad
    felt: np.ndarray        # (n, S, E, K) bool
    peak_angle: FloatArray  # (n, S, E)
    peak_felt: np.ndarray   # (n, S, E) bool
    at_max: FloatArray      # (n, S, E) fraction of the path
    at_min: FloatArray      # (n, S, E)


def perceived_features(force: FloatArray, frac: FloatArray, perception: Perception) -> Features:
    """``force`` (n, S, E, K, 2); ``frac`` (S, K) arc-length fraction of each sample."""
    mag = np.hypot(force[..., 0], force[..., 1])
    ang = np.arctan2(force[..., 1], force[..., 0])
    imax = np.argmax(mag, axis=-1)
    imin = np.argmin(mag, axis=-1)
    peak_mag = np.take_along_axis(mag, imax[..., None], -1)[..., 0]
    peak_ang = np.take_along_axis(ang, imax[..., None], -1)[..., 0]
    s_idx = np.arange(frac.shape[0])[None, :, None]
    return Features(np.log(np.maximum(mag, perception.floor_n)), ang,
                     mag >= perception.floor_n, peak_ang, peak_mag >= perception.floor_n,
                     frac[s_idx, imax], frac[s_idx, imin])


def _wrap(a: FloatArray) -> FloatArray:
    return np.abs((a + np.pi) % (2.0 * np.pi) - np.pi)


def feature_separations(f: Features, perception: Perception, closed: bool
                        ) -> dict[str, FloatArray]:
    """Robust felt, orientation and min-max separations in JNDs for every pair, shape (P, S):
    the smallest over every pair of executions (e of the first candidate, e' of the second)."""
    n = f.logmag.shape[0]
    i, j = pair_indices(n)
    lm_i, lm_j = f.logmag[i][:, :, :, None], f.logmag[j][:, :, None, :]
    mag = np.abs(lm_i - lm_j) / math.log1p(perception.force_jnd)
    both = f.felt[i][:, :, :, None] & f.felt[j][:, :, None, :]
    dang = np.where(both, _wrap(f.angle[i][:, :, :, None] - f.angle[j][:, :, None, :]), 0.0)
    dang /= math.radians(perception.direction_jnd_deg)
    felt = np.sqrt(mag * mag + dang * dang).max(axis=-1).min(axis=(2, 3))
    pboth = f.peak_felt[i][:, :, :, None] & f.peak_felt[j][:, :, None, :]
    orient = np.where(pboth, _wrap(f.peak_angle[i][:, :, :, None]
                                   - f.peak_angle[j][:, :, None, :]), 0.0)
    orient = (orient / math.radians(perception.direction_jnd_deg)).min(axis=(2, 3))
    dmax = np.abs(f.at_max[i][:, :, :, None] - f.at_max[j][:, :, None, :])
    dmin = np.abs(f.at_min[i][:, :, :, None] - f.at_min[j][:, :, None, :])
    if closed:
        dmax = np.minimum(dmax, 1.0 - dmax)
        dmin = np.minimum(dmin, 1.0 - dmin)
    minmax = (np.maximum(dmax, dmin) / perception.location_jnd).min(axis=(2, 3))
    return {"feel": felt, "orientation": orient, "minmax": minmax}


def felt_jnd(force_a_n: FloatArray, force_b_n: FloatArray,
             perception: Perception | None = None) -> float:
    """How far apart two force profiles (K, 2) sampled at the same moments feel, in JNDs: the
    largest √(m² + a²) along them (magnitude and direction JNDs, module docstring)."""
    f = np.stack([np.asarray(force_a_n, dtype=float), np.asarray(force_b_n, dtype=float)])
    k = f.shape[1]
    feats = perceived_features(f[:, None, None], np.linspace(0.0, 1.0, k)[None],
                               perception or Perception())
    return float(feature_separations(feats, perception or Perception(), False)["feel"][0, 0])


def kl_divergence(force: FloatArray, times_s: FloatArray, noise: NoiseModel) -> FloatArray:
    """D_KL between every pair for every execution (P, S, E); ``force`` (n, S, E, K, 2),
    ``times_s`` (S, E, K)."""
    dt = np.diff(times_s, axis=-1)
    w = np.zeros(times_s.shape)
    w[..., 1:] += 0.5 * dt
    w[..., :-1] += 0.5 * dt
    w /= noise.correlation_s
    i, j = pair_indices(force.shape[0])
    d = force[i] - force[j]
    sq = (d * d).sum(axis=-1)
    return (sq * w[None]).sum(axis=-1) / (2.0 * noise.force_sd_n ** 2)


def full_matrix(pairs: FloatArray, n: int) -> FloatArray:
    """(P, ...) pairwise values → (..., n, n) symmetric with a zero diagonal."""
    i, j = pair_indices(n)
    out = np.zeros((*pairs.shape[1:], n, n))
    out[..., i, j] = np.moveaxis(pairs, 0, -1)
    out[..., j, i] = np.moveaxis(pairs, 0, -1)
    return out


def information_bits(kl_nats: FloatArray, prior: FloatArray,
                     labels: Sequence[str] | None = None) -> FloatArray:
    """Information (bits) a recording gives about which candidate it is - or, with ``labels``,
    about which label (group) - from the pairwise D_KL (..., n, n) under equal-covariance
    Gaussian noise.

    The pairwise-distance estimate of Kolchinsky & Tracey (2017) with the Bhattacharyya
    distance (D_KL / 4): for candidates, I ≥ −Σ_i p_i log₂ Σ_j p_j e^{−D_ij/4}, a lower bound;
    for labels, the estimate of H(Y) minus that of H(Y | label),
    Σ_i p_i log₂ [Σ_{j ~ i} p_j e^{−D_ij/4} / (p_label(i) Σ_j p_j e^{−D_ij/4})], which is 0
    when nothing is told apart and H(label) when the labels are.
    """
    k = prior * np.exp(-kl_nats / 4.0)
    total = k.sum(axis=-1)
    if labels is None:
        return -(prior * np.log2(total)).sum(axis=-1)
    lab = np.asarray(labels)
    same = lab[:, None] == lab[None, :]
    p_label = (prior[None, :] * same).sum(axis=-1)
    own = (k * same).sum(axis=-1)
    return (prior * np.log2(own / (p_label * total))).sum(axis=-1)


def entropy_bits(prior: FloatArray, labels: Sequence[str] | None = None) -> float:
    """H of the candidates (or of their labels) under ``prior``, bits: the most any recording
    can tell."""
    if labels is None:
        q = prior
    else:
        q = np.array([prior[[k for k, lab in enumerate(labels) if lab == u]].sum()
                      for u in dict.fromkeys(labels)])
    q = q[q > 0]
    return float(-(q * np.log2(q)).sum())


def pair_error(kl_nats: FloatArray) -> FloatArray:
    """Bayes error of telling two equal-covariance Gaussians apart with equal priors."""
    return ndtr(-np.sqrt(2.0 * np.maximum(kl_nats, 0.0)) / 2.0)


def pair_mask(labels: Sequence[str], n: int) -> np.ndarray:
    """Pairs (i < j) that must be told apart: those with different labels."""
    i, j = pair_indices(n)
    lab = np.asarray(labels)
    return np.asarray(lab[i] != lab[j])


def _pair_weights(prior: FloatArray, mask: np.ndarray) -> FloatArray:
    i, j = pair_indices(len(prior))
    w = prior[i] * prior[j] * mask
    return w / w.sum() if w.sum() > 0 else mask / max(int(mask.sum()), 1)


def criterion_score(criterion: str, sep: Mapping[str, FloatArray], kl: FloatArray,
                    prior: FloatArray, labels: Sequence[str], tie_break: bool = True) -> FloatArray:
    """The criterion's score of each of S paths (or sets): ``sep`` (P, S), ``kl`` (P, S, E)
    → (S,).

    information: the information about the labels, bits, averaged over the executions E of the
    motion noise; the others: the prior-weighted mean
    over the pairs to tell apart of erf(d/2), the chance above guessing that a two-alternative
    comparison tells the pair apart for a separation of d JNDs (0 … 1). ``tie_break`` adds
    10⁻³·log(1 + the worst pair to tell apart).
    """
    mask = pair_mask(labels, len(prior))
    named = None if len(set(labels)) == len(labels) else labels
    if criterion == "information":
        # information is concave in D: average it over the executions, not D
        out = information_bits(full_matrix(kl, len(prior)), prior, named).mean(axis=-1)
        worst = kl.mean(axis=-1)[mask].min(axis=0)
    else:
        s = sep[criterion]
        out = (_pair_weights(prior, mask)[:, None] * erf(s / 2.0)).sum(axis=0)
        worst = s[mask].min(axis=0)
    return out + TIE_BREAK * np.log1p(worst) if tie_break else out


def separated_pairs(criterion: str, sep: Mapping[str, FloatArray], kl: FloatArray,
                    mask: np.ndarray) -> np.ndarray:
    """Per pair (P, S): separated by ``criterion``, or not one to tell apart (``mask`` False)."""
    if criterion == "information":
        ok = np.asarray(pair_error(kl.mean(axis=-1)) <= SEPARATED_ERROR)
    else:
        ok = np.asarray(sep[criterion] >= 1.0)
    return ok | ~mask.reshape((-1,) + (1,) * (ok.ndim - 1))


def combine_separations(sep: dict[str, FloatArray], kl: FloatArray,
                        prev: tuple[dict[str, FloatArray], FloatArray] | None
                        ) -> tuple[dict[str, FloatArray], FloatArray]:
    """A set so far (``prev``: separations (P,), D_KL per execution combination (P, C)) with
    each of S new paths (``sep`` (P, S), ``kl`` (P, S, E)): felt separations take the best
    path, D_KL adds over every combination of executions (at most :data:`MAX_COMBINATIONS`,
    a fixed stride through them beyond)."""
    if prev is None:
        return sep, kl
    psep, pkl = prev
    both = (pkl[:, None, :, None] + kl[:, :, None, :]).reshape(kl.shape[0], kl.shape[1], -1)
    if both.shape[-1] > MAX_COMBINATIONS:
        both = both[..., np.linspace(0, both.shape[-1] - 1, MAX_COMBINATIONS).astype(int)]
    return {k: np.maximum(psep[k][:, None], v) for k, v in sep.items()}, both



def arc_fraction(pos: FloatArray) -> FloatArray:
    """Arc length from the start as a fraction of the path's length, (S, K, 2) → (S, K)."""
    seg = np.hypot(*np.moveaxis(np.diff(pos, axis=1), -1, 0))
    arc = np.concatenate([np.zeros((pos.shape[0], 1)), np.cumsum(seg, axis=1)], axis=1)
    total = np.maximum(arc[:, -1:], 1e-12)
    return arc / total
