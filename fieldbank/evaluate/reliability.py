"""Are the classifier's probabilities right? Seeded arm families, simulated probes, and the
stated probability against how often the answer was right.

Families of arms (:func:`family_arms`), each arm a body of its own (45-100 kg, 1.50-1.95 m,
either side), none of them on the candidates' steps:

* **between severities** - one muscle group, passive, reflex or both, at a severity score
  uniform in [0.5, 4.5] (between and around the scale's steps);
* **two groups** - two groups at once, each with its own component and score in [1, 4.5];
* **reflex only** - one group's reflex: along the scale's path at a score in [0.5, 4.5], or α
  alone raised 6-20 fold at the unimpaired gain, or β alone raised to 0.5-1;
* **contracture only** - one group's slack length 4-20 mm short, Km unimpaired;
* **outside the candidates** - three groups at once, one group beyond severe (score 5-6.5), one
  group with a contracture of 10-20 mm and a moderate to severe reflex, or a rest posture
  10-20° from the one assumed with a group impaired.

The truth of an arm is the set of groups whose grade is not unimpaired
(:func:`truth_label`, :func:`fieldbank.evaluate.severity.classify`): a change a hand would not
feel is not an impairment to name. A trial (:func:`run_trials`): each probe performed with the
operator's motion noise (:func:`fieldbank.evaluate.design.draw_execution`), sampled at 1 kHz,
the true arm's force through the virtual coupling for the executed motion
(:func:`fieldbank.evaluate.replay.replay_forces`, the force a renderer would send), sensor
noise drawn (:func:`fieldbank.evaluate.observation.with_force_noise`), and the classifier's
answer - the most probable set of impaired groups, or none of the candidates - with the
probability it states. :func:`reliability_bins` sets the stated probability against how often
such answers were right; :func:`calibration_error` is the trial-weighted mean gap.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fieldbank.errors import ParameterError
from fieldbank.evaluate.classify import FIT_LEVEL, classify
from fieldbank.evaluate.design import NoiseModel, draw_execution, severity_candidates
from fieldbank.evaluate.design.coverage import stretch_noise, stretch_set
from fieldbank.evaluate.observation import Observation, with_force_noise
from fieldbank.evaluate.opencalibration import Calibration, counting_outside, outside_share
from fieldbank.evaluate.openset import (
    NONE_OF_THEM,
    OpenClassification,
    OpenSet,
    OpenTrace,
    classify_open,
    predict,
    yardstick,
)
from fieldbank.evaluate.openstates import KINDS, SET_COUNT_PRIOR, label_counts
from fieldbank.evaluate.replay import replay_forces
from fieldbank.evaluate.severity import LEVELS, ratio_of_score, synthesize_ratios
from fieldbank.evaluate.severity import classify as grade
from fieldbank.evaluate.statements import Statement, state
from fieldbank.model import Arm, FloatArray
from fieldbank.params import GROUPS, JOINT_GROUPS, ArmParams

FAMILIES: tuple[str, ...] = ("between severities", "two groups", "reflex only",
                             "contracture only", "outside the candidates")
OUTSIDE = "outside the candidates"
#: Sample period of the simulated recordings, s (the renderer's 1 kHz).
SAMPLE_S = 1e-3
#: Bins of the stated probability (the last closed at 1).
BINS: tuple[tuple[float, float], ...] = ((0.0, 0.6), (0.6, 0.8), (0.8, 0.9), (0.9, 0.95),
                                         (0.95, 0.99), (0.99, 1.0))

Progress = Callable[[int, int], None]


@dataclass(frozen=True)
class TrialArm:
    """One simulated patient: its family, how it was made, its parameters and its truth."""

    family: str
    name: str
    params: ArmParams
    truth: str


def truth_label(params: ArmParams) -> str:
    """The groups whose passive or dynamic grade is not unimpaired, 'ef+bf' style in the
    model's order, or 'unimpaired'."""
    graded = grade(Arm.from_params(params))
    hit = [g for g in GROUPS if graded[g].passive.level != "unimpaired"
           or graded[g].dynamic.level != "unimpaired"]
    return "+".join(hit) if hit else "unimpaired"


def _body(rng: np.random.Generator) -> ArmParams:
    return ArmParams.from_anthropometry(float(rng.uniform(45.0, 100.0)),
                                        float(rng.uniform(1.50, 1.95)),
                                        "left" if rng.uniform() < 0.4 else "right")


def _one(family: str, rng: np.random.Generator) -> tuple[str, ArmParams]:
    base = _body(rng)
    comps = ("passive", "dynamic")
    if family == "between severities":
        g = GROUPS[int(rng.integers(6))]
        comp = ("passive", "dynamic", "both")[int(rng.integers(3))]
        s = float(rng.uniform(0.5, 4.5))
        targets = {f"{g}:{c}": ratio_of_score(s, c) for c in comps if comp in (c, "both")}
        return f"{g} {comp} score {s:.2f}", synthesize_ratios(targets, base)
    if family == "two groups":
        a, b = (GROUPS[int(k)] for k in rng.choice(6, 2, replace=False))
        targets, words = {}, []
        for g in (a, b):
            comp = ("passive", "dynamic", "both")[int(rng.integers(3))]
            s = float(rng.uniform(1.0, 4.5))
            targets.update({f"{g}:{c}": ratio_of_score(s, c) for c in comps
                            if comp in (c, "both")})
            words.append(f"{g} {comp} {s:.2f}")
        return " + ".join(words), synthesize_ratios(targets, base)
    if family == "reflex only":
        g = GROUPS[int(rng.integers(6))]
        kind = int(rng.integers(3))
        if kind == 0:
            s = float(rng.uniform(0.5, 4.5))
            return f"{g} reflex score {s:.2f}", synthesize_ratios(
                {f"{g}:dynamic": ratio_of_score(s, "dynamic")}, base)
        if kind == 1:
            k = float(rng.uniform(6.0, 20.0))
            return f"{g} α ×{k:.1f}", base.with_group(g, alpha_n=k * base.group_value(
                "alpha_n", g))
        gain = float(rng.uniform(0.5, 1.0))
        return f"{g} β {gain:.2f}", base.with_group(g, beta=gain)
    if family == "contracture only":
        g = GROUPS[int(rng.integers(6))]
        d = float(rng.uniform(0.004, 0.020))
        return f"{g} {d * 1000:.0f} mm short", base.with_group(g, slack_offset_m=-d)
    if family == "outside the candidates":
        kind = int(rng.integers(4))
        if kind == 0:
            gs = [GROUPS[int(k)] for k in rng.choice(6, 3, replace=False)]
            s = float(rng.uniform(2.0, 4.5))
            return f"{'+'.join(gs)} {s:.2f}", synthesize_ratios(
                {g: ratio_of_score(s, "passive") for g in gs}, base)
        g = GROUPS[int(rng.integers(6))]
        if kind == 1:
            s = float(rng.uniform(5.0, 6.5))
            return f"{g} beyond severe {s:.2f}", synthesize_ratios(
                {g: ratio_of_score(s, "passive")}, base)
        if kind == 2:
            d = float(rng.uniform(0.010, 0.020))
            s = float(rng.uniform(3.0, 4.5))
            p = synthesize_ratios({f"{g}:dynamic": ratio_of_score(s, "dynamic")}, base)
            return f"{g} {d * 1000:.0f} mm short, reflex {s:.2f}", p.with_group(
                g, slack_offset_m=-d)
        shift = np.radians(rng.uniform(10.0, 20.0, 2) * rng.choice([-1.0, 1.0], 2))
        s = float(rng.uniform(2.0, 4.5))
        moved = base.replace(q_rest_rad=tuple(float(v) for v in np.array(base.q_rest_rad)
                                              + shift))
        return (f"{g} {s:.2f}, rest posture {np.degrees(shift[0]):+.0f}°, "
                f"{np.degrees(shift[1]):+.0f}°"), synthesize_ratios(
            {g: ratio_of_score(s, "passive")}, moved)
    raise ParameterError(f"unknown family {family!r}; known: {', '.join(FAMILIES)}")


def family_arms(family: str, n: int, seed: int) -> tuple[TrialArm, ...]:
    """``n`` arms of ``family`` (module docstring), seeded."""
    out = []
    for k in range(n):
        rng = np.random.default_rng([seed, FAMILIES.index(family), k])
        name, params = _one(family, rng)
        out.append(TrialArm(family, name, params, truth_label(params)))
    return tuple(out)


@dataclass(frozen=True)
class Outcome:
    """One trial: the arm, what the classifier answered and with what probability."""

    family: str
    arm: str
    truth: str
    answer: str
    probability: float
    explains: bool
    fit_p_value: float
    #: The joint-group classifier's answer on the same trace (the baseline), and whether it
    #: names a joint group holding every impaired group.
    baseline_answer: str = ""
    baseline_probability: float = float("nan")
    baseline_right: bool = False
    #: The classifier's uncalibrated posterior over the sets of impaired groups (most
    #: probable first), from which :func:`fieldbank.evaluate.openset.calibrated` states its
    #: answer; kept so that a calibration can be measured on the same trials.
    labels: tuple[str, ...] = ()
    label_probability: tuple[float, ...] = ()
    #: How well the strokes see each group's reflex
    #: (:attr:`fieldbank.evaluate.openset.OpenClassification.reflex_evidence`, rows per group).
    reflex_evidence: tuple[tuple[float, ...], ...] = ()

    @property
    def right(self) -> bool:
        """The impaired groups named; for an arm outside the candidates, also "none of the
        candidates"."""
        return self.answer == self.truth or (self.family == "outside the candidates"
                                             and self.answer == NONE_OF_THEM)

    @classmethod
    def from_record(cls, row: dict[str, Any]) -> Outcome:
        """The outcome a saved record holds (:func:`dataclasses.asdict` through JSON); keys
        that are not the outcome's (a run's noise level) are left to the caller."""
        fields = {f.name for f in dataclasses.fields(cls)}
        return cls(**{**{k: v for k, v in row.items() if k in fields},
                      "labels": tuple(row["labels"]),
                      "label_probability": tuple(row["label_probability"]),
                      "reflex_evidence": tuple(tuple(r)
                                               for r in row.get("reflex_evidence", ()))})

    def restated(self, calibration: Calibration) -> Outcome:
        """The same trial, its answer stated with ``calibration`` (from the posterior kept in
        :attr:`labels`)."""
        c = self.classification(calibration)
        answer, p = c.answer
        return dataclasses.replace(self, answer=answer, probability=p)

    def classification(self, calibration: Calibration) -> OpenClassification:
        ev = np.asarray(self.reflex_evidence, dtype=float).reshape(
            (len(GROUPS), -1) if self.reflex_evidence else (0, 0))
        return OpenClassification(self.labels, np.asarray(self.label_probability), (),
                                  math.nan, math.nan, self.fit_p_value, math.nan,
                                  np.zeros((len(GROUPS), len(KINDS))), calibration, ev)

    def truth_probability(self, calibration: Calibration) -> float:
        """The probability ``calibration`` states for the truth: its set of groups, and for an
        arm outside the candidates also "none of the candidates"."""
        c = self.classification(calibration)
        q = dict(zip(c.labels, c.label_probability, strict=True)).get(self.truth, 0.0)
        return float(q) + (c.other_probability if self.family == "outside the candidates"
                           else 0.0)


#: The calibrations :func:`fit_calibration` tries: the posterior's power, how fast it falls
#: with the best arm's misfit, the share for an arm outside the set, the fit test's p-value
#: below which the residual adds to that share.
POWERS = tuple(round(0.1 * k, 1) for k in range(2, 21))
MISFIT_SLOPES = (0.0, 0.25, 1.0, 4.0)
OTHERS = tuple(round(0.02 * k, 2) for k in range(0, 21))
MISFIT_LEVELS = (FIT_LEVEL, 0.003, 0.01, 0.03, 0.1)
#: A stated probability is floored at this in the log score (one confident miss costs
#: ln 1e-6, not infinity).
LOG_FLOOR = 1e-6
#: What the stated probabilities are held to in every family: an expected calibration error
#: of at most :data:`ECE_TARGET`, and at most :data:`SURE_WRONG_TARGET` of the claims stated
#: with p ≥ :data:`SURE_LEVEL` wrong.
ECE_TARGET = 0.05
SURE_LEVEL = 0.95
SURE_WRONG_TARGET = 0.02


def truth_groups(truth: str) -> frozenset[str]:
    """The impaired groups of a truth label ('ef+bf' → {'ef', 'bf'}; 'unimpaired' → {})."""
    return frozenset() if truth == "unimpaired" else frozenset(truth.split("+"))


#: The priors on the number of impaired groups tried (no group, two groups;
#: :attr:`~fieldbank.evaluate.opencalibration.Calibration.prior_none`): the set's own, and
#: case mixes from an arm with no group impaired as often as one in six to one in fifty.
COUNT_PRIORS: tuple[tuple[float, float], ...] = ((SET_COUNT_PRIOR[0], SET_COUNT_PRIOR[2]),
                                                 *itertools.product(
                                                     (0.02, 0.05, 0.1, 0.16),
                                                     (0.1, 0.2, 0.3, 0.4, 0.5)))
#: How many of the best calibrations of the groups' claims alone are tried with each share for
#: an arm outside the set, misfit level and :data:`OUTSIDE_MIXES`.
KEPT = 40
#: What is stated per group counts the chance that the arm is none of the set with these
#: weights, a group then impaired with these probabilities
#: (:attr:`~fieldbank.evaluate.opencalibration.Calibration.outside_weight`).
OUTSIDE_MIXES: tuple[tuple[float, float, float], ...] = ((0.0, 0.25, 0.0), *itertools.product(
    (0.25, 0.5, 0.75, 1.0), (0.1, 0.2, 0.3, 0.5), (0.0, 0.2, 0.4, 0.6)))
UNSEEN = (0.0, 0.005, 0.01, 0.02, 0.03, 0.05, 0.08, 0.12, 0.2, 0.3)
#: The evidence scales (χ²) over which a group's unseen share falls (0: no fall), and the
#: reflex scores whose evidence is read (:class:`~fieldbank.evaluate.opencalibration.Calibration`;
#: 0: the least visible reflex raised off the scale's path).
UNSEEN_EVIDENCE = (0.0, 1.0, 3.0, 10.0, 30.0, 100.0)
UNSEEN_SCORES = (0.0, 0.5, 1.0, 2.0)


Table = tuple[FloatArray, np.ndarray, np.ndarray, float, FloatArray, np.ndarray]


def _held_probability(tables: Sequence[Table], cal: Calibration) -> FloatArray:
    """Each group's probability of being impaired from the restated and tempered posterior
    alone (no unseen share), (outcomes, groups)."""
    out = np.zeros((len(tables), len(GROUPS)))
    log_w = np.log(cal.count_weights())
    for k, (logp, held, _truth, fit_p, _ev, counts) in enumerate(tables):
        lq = cal.power_at(fit_p) * (logp + log_w[counts])
        q = np.exp(lq - lq.max())
        out[k] = np.clip(q @ held / q.sum(), 0.0, 1.0)
    return out


def _unseen_shares(tables: Sequence[Table], cal: Calibration) -> FloatArray:
    """Each group's unseen share under ``cal``, (outcomes, groups)."""
    return np.array([[cal.unseen_share(yardstick(ev, i, cal.unseen_score))
                      for i in range(len(GROUPS))] for *_rest, ev, _n in tables])


def _log_score(pg: FloatArray, truth: np.ndarray) -> FloatArray:
    """Mean log probability stated for each group's truth (impaired or not), over every group
    of every outcome (the last two axes), each group stated impaired with ``pg``; one score
    per calibration along the leading axes."""
    return np.asarray(np.log(np.maximum(np.where(truth, pg, 1.0 - pg), LOG_FLOOR)).mean(
        axis=(-2, -1)), dtype=float)


def _group_tables(outcomes: Sequence[Outcome]) -> list[Table]:
    """Per outcome: the log posterior of each label (its most probable at 0), which groups
    each label holds, which groups the truth holds, the fit test's p-value, the evidence of
    each group's reflex, how many groups each label holds."""
    out = []
    for o in outcomes:
        logp = np.log(np.maximum(np.asarray(o.label_probability, dtype=float), 1e-300))
        held = np.array([[g in lab.split("+") for g in GROUPS] for lab in o.labels], float)
        truth = np.array([g in truth_groups(o.truth) for g in GROUPS])
        out.append((logp - logp.max(), held, truth, o.fit_p_value,
                    o.classification(Calibration()).reflex_evidence, label_counts(o.labels)))
    return out


def _family_excess(pg: FloatArray, truth: np.ndarray, family: np.ndarray) -> FloatArray:
    """By how many points the claims per group - each group of each outcome (the last two
    axes) impaired or not, at the probability ``pg`` of its impairment - miss the targets in
    the worst of the families (``family``: each outcome's index): the expected calibration
    error beyond :data:`ECE_TARGET` plus the share wrong at p ≥ :data:`SURE_LEVEL` beyond
    :data:`SURE_WRONG_TARGET`, binned as :func:`reliability_bins` bins them; one figure per
    calibration along the leading axes."""
    lead = pg.shape[:-2]
    m = int(np.prod(lead))
    stated = np.maximum(pg, 1.0 - pg).reshape(m, -1)
    right = ((pg >= 0.5) == truth).reshape(m, -1)
    nf, nb = int(family.max()) + 1, len(BINS)
    fam = np.broadcast_to(np.repeat(family, pg.shape[-1]), stated.shape)
    k = np.clip(np.searchsorted([lo for lo, _hi in BINS], stated, side="right") - 1, 0, nb - 1)
    cell = (np.arange(m)[:, None] * nf + fam) * nb + k  # (calibration, family, bin)
    gap = np.abs(np.bincount(cell.ravel(), right.ravel(), m * nf * nb)
                 - np.bincount(cell.ravel(), stated.ravel(), m * nf * nb))
    n = np.bincount(np.repeat(family, pg.shape[-1]), minlength=nf)
    ece = gap.reshape(m, nf, nb).sum(axis=2) / np.maximum(n, 1)
    sure = stated >= SURE_LEVEL
    fam_cal = (np.arange(m)[:, None] * nf + fam)
    wrong = np.bincount(fam_cal[sure], ~right[sure], m * nf).reshape(m, nf) / np.maximum(
        np.bincount(fam_cal[sure], minlength=m * nf).reshape(m, nf), 1)
    miss = np.maximum(ece - ECE_TARGET, 0.0) + np.maximum(wrong - SURE_WRONG_TARGET, 0.0)
    return np.asarray(100.0 * miss[:, n > 0].max(axis=1), dtype=float).reshape(lead)


def fit_calibration(outcomes: Sequence[Outcome]) -> tuple[Calibration, float]:
    """The calibration under which the stated probabilities are as often right as they say,
    in every family of ``outcomes`` - the targets (:data:`ECE_TARGET`,
    :data:`SURE_WRONG_TARGET`) met in each, or missed by as little as the grid allows - and
    among those by a proper score (the mean log probability stated for the truth, each
    floored at :data:`LOG_FLOOR`), with that score for the groups:

    * the prior on the number of impaired groups, the power, its fall with the misfit and
      each group's share of an impairment the recording does not show
      (:data:`COUNT_PRIORS` × :data:`POWERS` × :data:`MISFIT_SLOPES` × :data:`UNSEEN`) by
      what is stated per group - each group impaired or not, over every group of every
      outcome (the targets checked on these claims; partner groups stated as a set, a few in
      a hundred, are checked by the benchmark);
    * for the :data:`KEPT` best of those, the share for an arm outside the set, the misfit
      level and how far what is stated per group counts that share (:data:`OTHERS` ×
      :data:`MISFIT_LEVELS` × :data:`OUTSIDE_MIXES`), by the same targets and then the sum of
      the groups' score and that of the statement that none of the candidates explains the
      recording (right for an arm outside the candidates, wrong for every other).

    The score returned is the groups' mean log probability under the calibration chosen."""
    tables = _group_tables(outcomes)
    truth = np.array([t[2] for t in tables], dtype=bool).reshape(-1, len(GROUPS))
    known = all(o.reflex_evidence for o in outcomes)
    shares = [Calibration(unseen=u, unseen_evidence=e, unseen_score=sc)
              for u in UNSEEN
              for e, sc in (itertools.product(UNSEEN_EVIDENCE, UNSEEN_SCORES)
                            if known and u > 0 else [(0.0, 1.0)])]
    unseen = np.array([_unseen_shares(tables, c) for c in shares])  # (shares, outcomes, groups)
    fams = sorted({o.family for o in outcomes})
    family = np.array([fams.index(o.family) for o in outcomes])
    ranked: list[tuple[tuple[float, float], int, Calibration]] = []
    for (p0, p2), a, b in itertools.product(COUNT_PRIORS, POWERS, MISFIT_SLOPES):
        held = _held_probability(tables, Calibration(a, misfit_slope=b, prior_none=p0,
                                                     prior_two=p2))
        pg = 1.0 - (1.0 - held)[None] * (1.0 - unseen)
        excess, score = _family_excess(pg, truth, family), _log_score(pg, truth)
        for c, e, sc in zip(shares, excess, score, strict=True):
            # rounded: calibrations that state the same are tied, the first kept
            ranked.append(((round(float(e), 6), round(-float(sc), 12)), len(ranked),
                           dataclasses.replace(c, power=a, misfit_slope=b, prior_none=p0,
                                               prior_two=p2)))
    ranked.sort(key=lambda r: r[:2])
    outside = np.array([o.family == OUTSIDE for o in outcomes])
    fit_p = np.array([o.fit_p_value for o in outcomes], dtype=float)
    far = np.array([Calibration().far_share(p) for p in fit_p])[:, None]
    mix = np.array(OUTSIDE_MIXES)
    best, key = Calibration(), (math.inf, math.inf)
    for _k, _n, group in ranked[:KEPT]:
        p_set = 1.0 - (1.0 - _held_probability(tables, group)) * (
            1.0 - _unseen_shares(tables, group))
        for o_share, lv in itertools.product(OTHERS, MISFIT_LEVELS):
            other = outside_share(np.nan_to_num(fit_p, nan=1.0), lv, o_share)
            none = float(np.log(np.maximum(np.where(outside, other, 1.0 - other),
                                           LOG_FLOOR)).mean())
            pg = counting_outside(p_set, mix[:, 0, None, None] * other[None, :, None], far,
                                  mix[:, 1, None, None], mix[:, 2, None, None])
            excess, score = _family_excess(pg, truth, family), _log_score(pg, truth)
            for (w, r, r_far), e, sc in zip(OUTSIDE_MIXES, excess, score, strict=True):
                k = (round(float(e), 6), round(-(float(sc) + none), 12))
                if k < key:
                    best, key = dataclasses.replace(
                        group, other=o_share, misfit_level=lv, outside_weight=w,
                        outside_group=r, outside_far=r_far), k
    return best, float(_log_score(_stated_groups(outcomes, best), truth))


def _stated_groups(outcomes: Sequence[Outcome], cal: Calibration) -> FloatArray:
    """Each group's stated probability of being impaired under ``cal``, (outcomes, groups)."""
    return np.array([[c.group_probability[g] for g in GROUPS]
                     for c in (o.classification(cal) for o in outcomes)])


def stated_claims(outcomes: Sequence[Outcome], calibration: Calibration
                  ) -> list[tuple[Outcome, Statement, bool]]:
    """Every statement (:func:`fieldbank.evaluate.statements.state`) of every outcome under
    ``calibration``, with whether it was right."""
    out = []
    for o in outcomes:
        truth = truth_groups(o.truth)
        for st in state(o.classification(calibration)):
            out.append((o, st, st.right(truth, o.family == OUTSIDE)))
    return out


def ece_noise_floor(stated: Sequence[float], bins: Sequence[tuple[float, float]] = BINS,
                    repeats: int = 2000, seed: int = 0) -> tuple[float, float]:
    """The expected calibration error a perfectly calibrated classifier shows on these stated
    probabilities by sampling alone: outcomes drawn right with the stated probability, binned
    as :func:`reliability_bins` bins them, ``repeats`` times; (mean, 95th percentile)."""
    s = np.asarray(stated, dtype=float)
    if s.size == 0:
        return math.nan, math.nan
    rng = np.random.default_rng(seed)
    drawn = rng.random((repeats, s.size)) < s[None, :]
    which = np.full(s.size, -1)
    for k, (lo, hi) in enumerate(bins):
        top = k == len(bins) - 1
        which[(s >= lo) & ((s <= hi) if top else (s < hi))] = k
    gap = np.zeros(repeats)
    for k in range(len(bins)):
        m = which == k
        if m.any():
            gap += np.abs(drawn[:, m].sum(axis=1) - s[m].sum())
    ece = gap / s.size
    return float(ece.mean()), float(np.quantile(ece, 0.95))


def run_trials(arms: Sequence[TrialArm], noise: NoiseModel, draws: int = 4, seed: int = 0,
               progress: Progress | None = None, baseline: bool = False,
               calibration: Calibration | None = None) -> list[Outcome]:
    """Every arm probed with the clinic's fast stretch of each group from where the arm
    rests (:func:`~fieldbank.evaluate.design.coverage.stretch_set`, performed with the
    operator's scatter) and classified among every state of its groups
    (:func:`~fieldbank.evaluate.openset.classify_open` on the arm's body), ``draws``
    sensor-noise draws per execution (module docstring). ``baseline``: also the joint-group
    classifier (:func:`fieldbank.evaluate.classify.classify` among the twelve severity
    candidates and the unimpaired arm) on the same traces. ``calibration``: how the answers
    are stated (:func:`~fieldbank.evaluate.openset.classify_open`'s default unless given)."""
    out: list[Outcome] = []
    scatter = stretch_noise(noise)
    for k, arm in enumerate(arms):
        rng = np.random.default_rng([seed, k, 7])
        # the clinic knows the body (its anthropometry), not the muscles nor the rest posture
        p = arm.params
        openset = OpenSet.for_arm(ArmParams.from_anthropometry(p.body_mass_kg, p.height_m,
                                                               p.side))
        true_arm = Arm.from_params(arm.params)
        obs = []
        for m in stretch_set(openset.unimpaired, noise=noise):
            # sampled at 1 kHz; the executed speed scales the times (0.8-1.25 ms a sample)
            run = draw_execution(m, scatter, rng)
            dt = float(run.times_s[1] - run.times_s[0])
            start = (float(run.positions_m[0, 0]), float(run.positions_m[0, 1]))
            force = replay_forces([true_arm], run.positions_m, run.velocities_m_per_s, dt,
                                  start)[0]
            obs.append(Observation.from_arrays(run.name, run.times_s, run.positions_m, force,
                                               run.velocities_m_per_s, reset_m=start))
        trace = OpenTrace.of(obs, openset, noise)
        joint = severity_candidates(levels=LEVELS[1:], unimpaired=True,
                                    base=openset.base) if baseline else ()
        jpreds = [predict([c.arm for c in joint], o) for o in obs] if baseline else []
        for _ in range(draws):
            noisy = [with_force_noise(o, noise, rng) for o in obs]
            c = classify_open(noisy, openset, trace=trace, calibration=calibration)
            answer, stated = c.answer
            extra: dict[str, object] = {}
            if baseline:
                b = classify(noisy, joint, noise=noise, next_probe=False, predictions=jpreds)
                held = set(JOINT_GROUPS.get(b.group, ())) if b.group != "unimpaired" else set()
                truth = set(arm.truth.split("+")) if arm.truth != "unimpaired" else set()
                extra = {"baseline_answer": b.group,
                         "baseline_probability": b.group_posterior[b.group],
                         "baseline_right": truth <= held and bool(held) == bool(truth)}
            out.append(Outcome(arm.family, arm.name, arm.truth, answer, stated, c.explains,
                               c.fit_p_value, labels=c.labels,
                               label_probability=tuple(float(v) for v in c.raw_probability),
                               reflex_evidence=tuple(tuple(float(v) for v in row)
                                                     for row in c.reflex_evidence),
                               **extra))  # type: ignore[arg-type]
        if progress is not None:
            progress(k + 1, len(arms))
    return out


@dataclass(frozen=True)
class ReliabilityBin:
    """Answers stated with a probability in [low, high): how many, their mean stated
    probability and the fraction right, with its binomial SE."""

    low: float
    high: float
    n: int
    stated: float
    observed: float

    @property
    def gap(self) -> float:
        """Observed accuracy minus stated probability (negative: over-confident)."""
        return self.observed - self.stated

    @property
    def se(self) -> float:
        return math.sqrt(max(self.stated * (1 - self.stated), 1e-4) / self.n) if self.n \
            else math.nan


def reliability_bins(stated: Sequence[float], right: Sequence[bool],
                     bins: Sequence[tuple[float, float]] = BINS) -> tuple[ReliabilityBin, ...]:
    """Stated probability against observed accuracy, per bin of the stated probability."""
    s = np.asarray(stated, dtype=float)
    r = np.asarray(right, dtype=bool)
    out = []
    for k, (lo, hi) in enumerate(bins):
        top = k == len(bins) - 1
        m = (s >= lo) & ((s <= hi) if top else (s < hi))
        n = int(m.sum())
        out.append(ReliabilityBin(lo, hi, n, float(s[m].mean()) if n else math.nan,
                                  float(r[m].mean()) if n else math.nan))
    return tuple(out)


def calibration_error(bins: Sequence[ReliabilityBin]) -> float:
    """Expected calibration error: the trial-weighted mean |observed − stated| over bins."""
    n = sum(b.n for b in bins)
    return sum(b.n * abs(b.gap) for b in bins if b.n) / n if n else math.nan


def wrong_when_sure(outcomes: Sequence[Outcome], level: float = 0.95) -> tuple[int, int]:
    """(wrong answers, answers) among those stated with a probability ≥ ``level``."""
    sure = [o for o in outcomes if o.probability >= level]
    return sum(not o.right for o in sure), len(sure)


__all__ = [
    "BINS",
    "COUNT_PRIORS",
    "ECE_TARGET",
    "FAMILIES",
    "KEPT",
    "LOG_FLOOR",
    "MISFIT_LEVELS",
    "MISFIT_SLOPES",
    "OTHERS",
    "OUTSIDE",
    "OUTSIDE_MIXES",
    "POWERS",
    "SURE_LEVEL",
    "SURE_WRONG_TARGET",
    "UNSEEN",
    "Outcome",
    "ReliabilityBin",
    "TrialArm",
    "calibration_error",
    "ece_noise_floor",
    "family_arms",
    "fit_calibration",
    "reliability_bins",
    "run_trials",
    "stated_claims",
    "truth_groups",
    "truth_label",
    "wrong_when_sure",
]
