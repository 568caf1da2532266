"""Which groups a recorded trace says are impaired, over every state the groups can be in, and
when no state explains it.

A classifier that chooses among a dozen joint-group arms on the scale's steps is confidently
wrong on an arm that is none of them: an elbow-extensor reflex alone was called unimpaired with
p = 1.000, and arms between severities or with two groups impaired were named with p ≥ 0.95 in
one answer of six. Here the arm is described group by group (:class:`OpenSet`):

* each muscle group is **unimpaired** or in one of
  :data:`~fieldbank.evaluate.openstates.STATES_PER_GROUP` states
  (:mod:`fieldbank.evaluate.openstates`) - its passive
  stiffness, its reflex or both at a severity score of 0.5, 1, …, 4.5 (half Weber steps, from
  below very mild to the top of severe; :func:`fieldbank.evaluate.severity.synthesize_ratios`),
  its reflex raised off the scale's path - α alone 5, 10 or 20 fold, or the stretch gain β
  alone at 0.5, 0.75 or 1 (each graded very mild on the group's own
  stretch, and each changes a 2 N recording of the clinic's stretches by as little as tenths
  of a newton: without them, such an arm was called "not impaired" with p ≥ 0.95) -, or a
  contracture (its slack length 5, 10, 15 or 20 mm short: the brief's range);
* an arm is **none, one or two** groups in such states; the prior takes each group to be
  impaired with probability 0.3 (independently; three or more groups left
  out: with them an off-grid severity of one group was "explained" by a third group's state,
  with p = 1), and an impaired group equally likely in each of its states;
* the answer is the set of impaired groups ("ef", "ef+bf", "unimpaired"), its probability the
  posterior mass of every arm with that set: a posterior over the groups' states themselves.

Every one-group arm is replayed on the recorded motion through the virtual coupling
(:func:`fieldbank.evaluate.replay.replay_forces`); an arm of several groups has its force first
taken as the sum of its groups' changes (the muscles' forces add at the hand; for two severe
groups the sum is mostly within 0.25 N of the replay, up to 1.6 N), which ranks all ≈ 20,800
arms at once through the Gram matrix of the one-group changes; the :data:`EXACT_TOP` most
probable (and the best of each leading answer) are then replayed themselves and their
likelihood made exact. The likelihood, its model-error temperature and the fit test are the
classifier's (:mod:`fieldbank.evaluate.classify`).

**None of them.** When the best arm's residual is beyond what the noise explains (its p-value
below :data:`fieldbank.evaluate.classify.FIT_LEVEL`: three groups at once, a group beyond
severe, a contracture with a reflex in one group, a rest posture other than assumed), the
answer is "none of the candidates", with probability 1 − p/level: the residual says how sure.

**Stated.** The posterior is stated through a calibration fitted on arms of their own
(:mod:`fieldbank.evaluate.opencalibration`).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fieldbank.errors import ParameterError
from fieldbank.evaluate.classify import (
    FIT_LEVEL,
    correlated_weight_sum,
    model_error_ratio,
    p_of_fit,
)
from fieldbank.evaluate.design import NoiseModel, saturate
from fieldbank.evaluate.observation import Observation
from fieldbank.evaluate.opencalibration import (
    CALIBRATED,
    RAW,
    Calibration,
    counting_outside,
    outside_share,
)
from fieldbank.evaluate.openstates import (
    COMPONENTS,
    CONTRACTURES_M,
    GROUP_PRIOR,
    KIND_OF,
    KINDS,
    MAX_GROUPS,
    REFLEX_ALONE,
    SCORES,
    GroupState,
    label_counts,
)
from fieldbank.evaluate.replay import replay_forces
from fieldbank.evaluate.severity import ratio_of_score, synthesize_ratios
from fieldbank.model import Arm, FloatArray
from fieldbank.params import GROUPS, ArmParams

#: Arms whose likelihood is made exact by their own replay, the most probable first.
EXACT_TOP = 16
#: The answer when no arm of the set explains the recording.
NONE_OF_THEM = "none of the candidates"
#: The likelihood reads the recorded force every this many seconds (the replay still ticks
#: at the recording's rate): ten samples per correlation time of the noise, each weighted by
#: the time it stands for, so the evidence is the same and the sums five times cheaper.
LIKELIHOOD_STEP_S = 0.005


@dataclass(frozen=True, eq=False)
class OpenSet:
    """Every state of every group of one patient's arm (module docstring)."""

    base: ArmParams
    states: tuple[GroupState, ...]
    params: tuple[ArmParams, ...]  # one-group arm of each state
    unimpaired: Arm
    arms: tuple[Arm, ...]  # compiled, sharing the unimpaired arm's geometry
    combos: _Combos  # every arm of up to MAX_GROUPS groups in these states, with its prior

    @classmethod
    def for_arm(cls, base: ArmParams) -> OpenSet:
        """The open set on ``base``'s body (its muscles unimpaired first)."""
        p0 = base.with_unimpaired_muscles()
        ref = Arm.from_params(p0)
        states, params = [], []
        for g in GROUPS:
            dyn = {s: synthesize_ratios({f"{g}:dynamic": ratio_of_score(s, "dynamic")}, p0)
                   for s in SCORES}
            for comp in COMPONENTS:
                for s in SCORES:
                    p = p0
                    if comp in ("passive", "both"):
                        p = p.with_group(g, km_n_per_m=p0.group_value("km_n_per_m", g)
                                         * ratio_of_score(s, "passive"))
                    if comp in ("dynamic", "both"):
                        p = p.with_group(g, alpha_n=dyn[s].group_value("alpha_n", g),
                                         beta=dyn[s].group_value("beta", g))
                    states.append(GroupState(g, comp, s))
                    params.append(p)
            for comp, v in REFLEX_ALONE:
                states.append(GroupState(g, comp, factor=v))
                params.append(p0.with_group(g, alpha_n=v * p0.group_value("alpha_n", g))
                              if comp == "alpha" else p0.with_group(g, beta=v))
            for d in CONTRACTURES_M:
                states.append(GroupState(g, "contracture", slack_m=d))
                params.append(p0.with_group(g, slack_offset_m=-d))
        return cls(p0, tuple(states), tuple(params), ref,
                   tuple(ref.with_muscles(p) for p in params), _Combos.of(states))

    def combined(self, picks: Sequence[int]) -> ArmParams:
        """The arm with the states ``picks`` (indices into :attr:`states`, distinct groups)."""
        p = self.base
        for k in picks:
            g = self.states[k].group
            src = self.params[k]
            for f in ("km_n_per_m", "alpha_n", "beta", "slack_offset_m"):
                p = p.with_group(g, **{f: src.group_value(f, g)})
        return p


@dataclass(frozen=True, eq=False)
class OpenClassification:
    """What a recorded trace says about the groups (module docstring).

    ``labels`` / ``raw_probability``: every set of impaired groups with its posterior
    probability as the likelihood and prior give it (most probable first);
    ``calibration``: how it is stated (:class:`Calibration`; :attr:`label_probability`,
    :attr:`group_probability`, :attr:`answer` are the stated ones); ``best``: the most
    probable arm's states; ``fit_p_value``: the fit test of the best arm; ``temperature``:
    the model-error correction of the likelihoods.
    """

    labels: tuple[str, ...]
    raw_probability: FloatArray
    best: tuple[str, ...]
    fit_statistic: float
    fit_expected: float
    fit_p_value: float
    temperature: float
    #: Posterior mass of each group (rows, the model's order) in each of :data:`KINDS`.
    raw_kinds: FloatArray
    calibration: Calibration = RAW
    #: Per group (rows, the model's order) and reflex state (columns: :data:`SCORES`, then
    #: :data:`REFLEX_ALONE`): the
    #: evidence a reflex of that group at that score would give against the group unimpaired
    #: on these strokes at the stated noise - the χ² of the two arms' replayed forces apart,
    #: over the model-error temperature, twice the expected log likelihood ratio. Empty when
    #: not known.
    reflex_evidence: FloatArray = dataclasses.field(default_factory=lambda: np.zeros((0, 0)))

    @property
    def explains(self) -> bool:
        return bool(self.fit_p_value >= FIT_LEVEL)

    @property
    def other_probability(self) -> float:
        """The stated probability that no arm of the set made the recording: 1 − p/level when
        the residual says so (the fit test below the calibration's misfit level, at least
        :data:`~fieldbank.evaluate.classify.FIT_LEVEL`), and never below the calibration's
        share."""
        cal = self.calibration
        return float(outside_share(self.fit_p_value, cal.misfit_level, cal.other))

    @property
    def label_share(self) -> FloatArray:
        """The stated probability of each of :attr:`labels` should the arm be one of the set:
        the posterior restated under the calibration's prior on the number of impaired groups
        (:meth:`Calibration.count_weights`), tempered (:meth:`Calibration.power_at`) and
        renormalised."""
        raw = (np.asarray(self.raw_probability, dtype=float)
               * self.calibration.count_weights()[label_counts(self.labels)])
        q = np.power(raw / raw.max(), self.calibration.power_at(self.fit_p_value))
        return np.asarray(q / q.sum(), dtype=float)

    @property
    def label_probability(self) -> FloatArray:
        """The stated probability of each of :attr:`labels` (they and
        :attr:`other_probability` sum to 1)."""
        return np.asarray(self.label_share * (1.0 - self.other_probability), dtype=float)

    def any_impaired(self, groups: Sequence[str]) -> float:
        """The stated probability that at least one of ``groups`` is impaired: should the arm
        be one of the set, the share of every label holding one of them and beside it each
        group's share :attr:`Calibration.unseen` of an impairment the recording does not show;
        should it be none of them (:attr:`other_probability`, weighed by
        :attr:`Calibration.outside_weight`), each group's
        :attr:`Calibration.outside_group` - or, as far as the residual is beyond the noise
        (:meth:`Calibration.far_share`), what the set says with each group's
        :attr:`Calibration.outside_far` beside it."""
        want = set(groups)
        held = float(sum(v for lab, v in zip(self.labels, self.label_share, strict=True)
                         if want & set(lab.split("+"))))
        seen = self.group_unseen
        in_set = 1.0 - (1.0 - held) * math.prod(1.0 - seen[g] for g in want)
        cal = self.calibration
        return float(counting_outside(in_set, cal.outside_weight * self.other_probability,
                                      cal.far_share(self.fit_p_value), cal.outside_group,
                                      cal.outside_far, len(want)))

    @property
    def group_unseen(self) -> dict[str, float]:
        """Each group's share of an impairment the recording does not show
        (:meth:`Calibration.unseen_share` of its :attr:`reflex_evidence`)."""
        cal = self.calibration
        ev = self.reflex_evidence
        return {g: cal.unseen_share(yardstick(ev, i, cal.unseen_score))
                for i, g in enumerate(GROUPS)}

    @property
    def group_probability(self) -> dict[str, float]:
        """Each group's stated probability of being impaired (:meth:`any_impaired`)."""
        return {g: self.any_impaired((g,)) for g in GROUPS}

    @property
    def answer(self) -> tuple[str, float]:
        """The most probable set of impaired groups with its stated probability, or
        :data:`NONE_OF_THEM` when that is more probable than any of them."""
        q = self.label_probability
        k = int(np.argmax(q))
        if self.other_probability > q[k]:
            return NONE_OF_THEM, self.other_probability
        return self.labels[k], float(q[k])

    def with_calibration(self, calibration: Calibration) -> OpenClassification:
        return dataclasses.replace(self, calibration=calibration)

    def group_kinds(self) -> dict[str, dict[str, float]]:
        """Per group, the stated probability of each of :data:`KINDS` (they sum to the
        group's :attr:`group_probability`): the group's stated probability shared as the
        posterior shares it."""
        out = {}
        for i, (g, p) in enumerate(self.group_probability.items()):
            row = self.raw_kinds[i]
            total = float(row.sum())
            out[g] = {k: (p * float(v) / total if total > 0 else 0.0)
                      for k, v in zip(KINDS, row, strict=True)}
        return out

    def to_dict(self) -> dict[str, object]:
        answer, p = self.answer
        q = self.label_probability
        return {"answer": answer, "probability": p,
                "labels": {lab: float(f"{v:.6g}") for lab, v in
                           zip(self.labels[:10], q[:10], strict=False)},
                "none_of_the_candidates": round(self.other_probability, 6),
                "groups_impaired": {g: round(v, 6) for g, v in self.group_probability.items()},
                "groups": {g: {"impaired": round(self.group_probability[g], 6),
                               **{k: round(v, 6) for k, v in kinds.items()}}
                           for g, kinds in self.group_kinds().items()},
                "best": list(self.best), "explains_recording": self.explains,
                "fit_test": {"statistic": round(self.fit_statistic, 3),
                             "expected": round(self.fit_expected, 3),
                             "p_value": float(f"{self.fit_p_value:.4g}"), "level": FIT_LEVEL},
                "temperature": round(self.temperature, 4),
                "calibration": dataclasses.asdict(self.calibration)}


def predict(arms: Sequence[Arm], obs: Observation) -> FloatArray:
    """Each arm's force (n, T, 2) for the recorded motion of ``obs``, replayed through the
    coupling from rest (``obs.reset_m`` or its first position), with the renderer's gain and
    saturation when the observation has them."""
    dt = np.diff(obs.times_s)
    period = float(np.median(dt))
    if np.any(np.abs(dt - period) > 0.25 * period):
        raise ParameterError(f"{obs.source or obs.name}: the open-set classifier replays the "
                             "motion and needs evenly spaced samples.")
    start = obs.reset_m if obs.reset_m is not None else (float(obs.positions_m[0, 0]),
                                                         float(obs.positions_m[0, 1]))
    f = replay_forces(arms, obs.positions_m, obs.velocities_m_per_s, period, start)
    if obs.output_gain is not None:
        f = f * obs.output_gain[None, :, None]
    return f if obs.force_limit_n is None else saturate(f, obs.force_limit_n)


@dataclass(frozen=True, eq=False)
class _Combos:
    """Every arm of at most :data:`MAX_GROUPS` impaired groups, as state indices (-1: no
    state), (A, MAX_GROUPS), with its prior (A,)."""

    picks: np.ndarray
    prior: FloatArray
    mask: np.ndarray  # the impaired groups of each arm as a bit mask (bit i: GROUPS[i])

    @classmethod
    def of(cls, states: Sequence[GroupState]) -> _Combos:
        by_group = {g: [k for k, s in enumerate(states) if s.group == g] for g in GROUPS}
        blocks = [np.full((1, MAX_GROUPS), -1)]
        g0 = (1.0 - GROUP_PRIOR) ** len(GROUPS)
        priors = [np.array([g0])]
        for n in range(1, MAX_GROUPS + 1):
            rows = [np.array(list(itertools.product(*(by_group[g] for g in gs))))
                    for gs in itertools.combinations(GROUPS, n)]
            block = np.concatenate(rows)
            blocks.append(np.hstack([block, np.full((len(block), MAX_GROUPS - n), -1)]))
            # n given groups impaired, the others not, each impaired group in one state
            each = (GROUP_PRIOR ** n * (1.0 - GROUP_PRIOR) ** (len(GROUPS) - n)
                    / np.prod([len(by_group[g]) for g in GROUPS[:n]]))
            priors.append(np.full(len(block), each))
        picks = np.concatenate(blocks)
        bit = np.array([1 << GROUPS.index(s.group) for s in states] + [0])
        mask = bit[np.where(picks < 0, len(states), picks)].sum(axis=1)
        return cls(picks, np.concatenate(priors), mask)

    def states_of(self, j: int) -> tuple[int, ...]:
        return tuple(int(k) for k in self.picks[j] if k >= 0)


@dataclass(frozen=True, eq=False)
class OpenTrace:
    """What the recorded motions of a trace give every arm of an open set, whatever force was
    recorded: each one-group arm's replayed force (the unimpaired arm first), the weighted Gram
    matrix of their changes, and the fit test's mean and variance. One per executed motion,
    reused for every noise draw or recording of it."""

    openset: OpenSet
    noise: NoiseModel
    observations: tuple[Observation, ...]
    predictions: tuple[FloatArray, ...]
    gram: FloatArray
    expected: float
    variance: float
    n_eff: float

    @classmethod
    def of(cls, observations: Sequence[Observation], openset: OpenSet,
           noise: NoiseModel | None = None) -> OpenTrace:
        nz = noise or NoiseModel()
        obs = tuple(observations)
        if not obs:
            raise ParameterError("Give at least one recorded observation to classify.")
        arms = (openset.unimpaired, *openset.arms)
        preds = tuple(predict(arms, o)[:, _read(o)] for o in obs)
        n = len(openset.states)
        gram = np.zeros((n, n))
        expected = variance = n_eff = 0.0
        for o, f in zip(obs, preds, strict=True):
            w = _weights(o, nz)
            d = f[1:] - f[0][None]
            gram += np.einsum("stk,utk->su", d * (w / nz.force_sd_n ** 2)[None, :, None], d)
            n_eff += float(w.sum())
            expected += 2.0 * float(w.sum())
            variance += 4.0 * correlated_weight_sum(o.times_s[_read(o)], w,
                                                     4.0 / nz.correlation_s)
        return cls(openset, nz, obs, preds, gram, expected, variance, n_eff)


def _read(o: Observation) -> slice:
    """The samples the likelihood reads (:data:`LIKELIHOOD_STEP_S`)."""
    period = float(np.median(np.diff(o.times_s)))
    return slice(0, None, max(1, round(LIKELIHOOD_STEP_S / period)))


def _weights(o: Observation, noise: NoiseModel) -> FloatArray:
    """Δt/τ of each sample read (trapezoid over the samples read; counted ones only)."""
    k = _read(o)
    t = o.times_s[k]
    dt = np.diff(t)
    w = np.zeros(t.shape)
    w[1:] += 0.5 * dt
    w[:-1] += 0.5 * dt
    if o.counted is not None:
        w = np.where(o.counted[k], w, 0.0)
    return np.asarray(w / noise.correlation_s, dtype=float)


def classify_open(observations: Sequence[Observation], openset: OpenSet,
                  noise: NoiseModel | None = None,
                  trace: OpenTrace | None = None,
                  calibration: Calibration | None = None) -> OpenClassification:
    """The posterior over the impaired groups of the arm that made ``observations``.

    ``trace``: the replays of these motions (:class:`OpenTrace`), when already made (the same
    motions met with other recorded forces); ``calibration``: how the answer is stated
    (:data:`CALIBRATED` unless given; :data:`RAW` for the posterior itself).
    """
    calibration = CALIBRATED if calibration is None else calibration
    obs = tuple(observations)
    tr = trace if trace is not None else OpenTrace.of(obs, openset, noise)
    nz = tr.noise
    cb = openset.combos
    wr, b = 0.0, np.zeros(len(openset.states))
    for o, f in zip(obs, tr.predictions, strict=True):
        w = _weights(o, nz) / nz.force_sd_n ** 2
        r = o.force_n[_read(o)] - f[0]
        wr += float(np.sum(w[:, None] * r * r))
        b += np.einsum("stk,tk->s", (f[1:] - f[0][None]) * w[None, :, None], r)
    gram = tr.gram
    expected, variance, n_eff = tr.expected, tr.variance, tr.n_eff
    n = len(openset.states)
    # a padding state n with no change: the arms of fewer than three groups
    bp = np.append(b, 0.0)
    dp = np.append(np.diag(gram), 0.0)
    gp = np.zeros((n + 1, n + 1))
    gp[:n, :n] = gram
    s = np.where(cb.picks < 0, n, cb.picks)
    chi2 = wr - 2.0 * bp[s].sum(axis=1) + dp[s].sum(axis=1)
    for a, c in itertools.combinations(range(s.shape[1]), 2):
        chi2 += 2.0 * gp[s[:, a], s[:, c]]
    # the most probable arms of several groups replayed themselves: their likelihood exact
    logpost = np.log(cb.prior) - 0.5 * chi2
    # the EXACT_TOP most probable, and the most probable of each of the leading labels
    lead = np.argpartition(-logpost, EXACT_TOP)[:EXACT_TOP]
    by_label: dict[int, int] = {}
    for j in np.argsort(-logpost)[:20 * EXACT_TOP]:
        by_label.setdefault(int(cb.mask[j]), int(j))
    top = [j for j in dict.fromkeys([int(j) for j in lead] + list(by_label.values()))
           if len(cb.states_of(j)) >= 2]
    if top:
        chi2[top] = _chi2(obs, [openset.unimpaired.with_muscles(
            openset.combined(cb.states_of(j))) for j in top], nz)
    q = float(chi2.min())
    p_fit = p_of_fit(q, expected, variance)
    temperature = 1.0 + model_error_ratio(q, expected, variance) * n_eff
    logpost = np.log(cb.prior) - 0.5 * chi2 / temperature
    post = np.exp(logpost - logpost.max())
    post /= post.sum()
    by_mask = np.bincount(cb.mask, weights=post, minlength=1 << len(GROUPS))
    labels = {_label(m): float(v) for m, v in enumerate(by_mask) if v > 0.0}
    kinds = np.zeros((len(GROUPS), len(KINDS)))
    g_of = np.array([GROUPS.index(st.group) for st in openset.states])
    k_of = np.array([KIND_OF[st.component] for st in openset.states])
    for col in cb.picks.T:
        held = col >= 0
        np.add.at(kinds, (g_of[col[held]], k_of[col[held]]), post[held])
    order = sorted(labels, key=lambda x: -labels[x])
    best = tuple(openset.states[i].name for i in cb.states_of(int(np.argmax(post)))) or (
        "unimpaired",)
    return OpenClassification(tuple(order), np.array([labels[x] for x in order]), best, q,
                              expected, p_fit, temperature, kinds, calibration,
                              reflex_evidence(openset, gram) / temperature)


def reflex_evidence(openset: OpenSet, gram: FloatArray) -> FloatArray:
    """Per group, the χ² a reflex of the group gives against the group unimpaired on the
    strokes whose weighted Gram matrix of the one-group changes is ``gram``
    (:class:`OpenTrace`): at each score of :data:`SCORES`, then each state of
    :data:`REFLEX_ALONE`, (groups, scores + reflexes alone)."""
    out = np.zeros((len(GROUPS), len(SCORES) + len(REFLEX_ALONE)))
    diag = np.diag(gram)
    for k, st in enumerate(openset.states):
        col = (SCORES.index(st.score) if st.component == "dynamic"
               else len(SCORES) + REFLEX_ALONE.index((st.component, st.factor))
               if st.component in ("alpha", "beta") else None)
        if col is not None:
            out[GROUPS.index(st.group), col] = diag[k]
    return out


def yardstick(evidence: FloatArray, row: int, score: float) -> float:
    """The evidence a group's unseen share is read at (:attr:`Calibration.unseen_score`):
    its reflex at the score of :data:`SCORES` nearest ``score``, or for a score of 0 its
    least visible reflex raised off the scale's path (:data:`REFLEX_ALONE`); not finite when
    ``evidence`` (:func:`reflex_evidence`, rows per group) does not hold it."""
    if evidence.size == 0:
        return math.nan
    if score == 0.0:
        alone = evidence[row, len(SCORES):]
        return float(alone.min()) if alone.size else math.nan
    return float(evidence[row, int(np.argmin(np.abs(np.asarray(SCORES) - score)))])


def classify_on_body(observations: Sequence[Observation], body: ArmParams,
                     noise: NoiseModel | None = None) -> OpenClassification:
    """:func:`classify_open` among every state of the groups of ``body`` (its muscles taken
    unimpaired first: :meth:`OpenSet.for_arm`)."""
    return classify_open(observations, OpenSet.for_arm(body), noise)


def _label(mask: int) -> str:
    """The set of groups of a bit mask ('ef+bf'; 'unimpaired' for none)."""
    return "+".join(g for i, g in enumerate(GROUPS) if mask >> i & 1) or "unimpaired"


def _chi2(obs: Sequence[Observation], arms: Sequence[Arm], noise: NoiseModel) -> FloatArray:
    """Whitened χ² of each arm's replayed force against the recorded one, (n,)."""
    out = np.zeros(len(arms))
    for o in obs:
        w = _weights(o, noise) / noise.force_sd_n ** 2
        k = _read(o)
        r = o.force_n[None, k] - predict(arms, o)[:, k]
        out += np.einsum("t,ntk->n", w, r * r)
    return out


__all__ = [
    "EXACT_TOP",
    "NONE_OF_THEM",
    "OpenClassification",
    "OpenSet",
    "OpenTrace",
    "classify_on_body",
    "classify_open",
    "predict",
    "reflex_evidence",
    "yardstick",
]
