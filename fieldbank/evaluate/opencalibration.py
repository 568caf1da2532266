"""How the open-set classifier states its posterior (:mod:`fieldbank.evaluate.openset`): the
prior on how many groups are impaired it is restated under, how far it is tempered, what is set
aside for an arm none of the candidates is and for an impairment the recording does not show.
Fitted on arms of their own (:func:`fieldbank.evaluate.reliability.fit_calibration`,
``benchmarks/tune_open_calibration.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from fieldbank.errors import ParameterError
from fieldbank.evaluate.classify import FIT_LEVEL
from fieldbank.evaluate.openstates import SCORES, SET_COUNT_PRIOR
from fieldbank.model import FloatArray
from fieldbank.validation import Interval, check_fields


@dataclass(frozen=True)
class Calibration:
    """How the posterior over the sets of impaired groups is stated: each set's probability
    raised to a power and renormalised (below 1: the likelihood tempered for the misfit the
    grid of states leaves - an arm between the grid's states, a partner group compensating),
    then a share ``other`` set aside for an arm the set does not hold, which no residual
    reveals (its force fitted within the noise by some arm of the set). Above 1 the
    posterior is sharpened: a grid coarser than what the recording tells spreads it.

    The power is ``power / (1 + misfit_slope · m)``, m the misfit of the most probable arm in
    decades of its fit test's p-value (m = −log10 p; about 0.4 on average for an arm the set
    holds, 3 at p = 0.001): the worse the best arm fits, the less its likelihood is trusted
    (outside the set, or between its states, the posterior is over-confident; inside, it is
    not). Fitted on arms of their own (:func:`fieldbank.evaluate.reliability.fit_calibration`)."""

    power: float = 1.0
    other: float = 0.0
    #: Below this p-value of the fit test the share for an arm outside the set is at least
    #: 1 − p/level (a residual a little beyond the noise: a rest posture other than assumed,
    #: a partner group compensating), as below the fit test's own level.
    misfit_level: float = FIT_LEVEL
    misfit_slope: float = 0.0
    #: Each group's probability of an impairment the recording does not show, whatever the
    #: posterior says (a reflex raised by α or β alone, off the scale's path, changes a 2 N
    #: recording by tenths of a newton yet is felt on the group's own stretch): "not impaired"
    #: is stated with at most 1 − unseen.
    unseen: float = 0.0
    #: How the share falls with how well the recording sees the group's reflex: a group's
    #: share is ``unseen · exp(−E / unseen_evidence)``, E the evidence a reflex of that group
    #: at the severity score ``unseen_score`` would give on these strokes
    #: (:attr:`OpenClassification.reflex_evidence`; score 0: the least visible of the group's
    #: reflexes raised off the scale's path, :data:`REFLEX_ALONE`): a group whose reflex the
    #: strokes do not reach keeps the share, one they see well loses it. 0: the same share
    #: for every group.
    unseen_evidence: float = 0.0
    unseen_score: float = 1.0
    #: The prior probability that no group, and that two groups, are impaired under which the
    #: posterior is stated (one group: the rest) - the case mix the classifier meets. The
    #: set's own prior (:data:`SET_COUNT_PRIOR`: 0.158 and 0.435) is the default. Where a
    #: clinic's arms mostly have one group impaired, an arm whose recording shows nothing is
    #: more likely one with an impairment the strokes do not see (a reflex raised by α or β
    #: alone) than an unimpaired one, and is stated so; where one group shows, the others
    #: stay "not impaired".
    prior_none: float = SET_COUNT_PRIOR[0]
    prior_two: float = SET_COUNT_PRIOR[2]
    #: How far what is stated per group counts the chance that the arm is none of the set
    #: (:attr:`~fieldbank.evaluate.openset.OpenClassification.other_probability`): 1 - a
    #: group's stated probability is ``(1 − o) · p_set + o · outside_group`` with ``o`` that
    #: chance times this weight, ``p_set`` what the set's posterior says and
    #: :attr:`outside_group` a group's chance of being impaired in an arm outside the set,
    #: which the recording cannot attribute (a partner group fits in the true one's place, a
    #: rest posture other than assumed reads as some group's stiffness). 0: stated should the
    #: arm be one of the set.
    outside_weight: float = 0.0
    outside_group: float = 0.25
    #: Where the residual is far beyond the noise, the set's answer is not wrong so much as
    #: short (three groups impaired where it holds two): the groups it names stay, and each
    #: other group is impaired at this rate. The chance of an arm outside the set is shared
    #: between :attr:`outside_group` and this reading by the misfit (:meth:`far_share`).
    outside_far: float = 0.0

    def __post_init__(self) -> None:
        check_fields(self, CALIBRATION_BOUNDS, what="open-set calibration")
        if self.prior_none + self.prior_two >= 1.0:
            raise ParameterError(
                f"open-set calibration: the priors of no group ({self.prior_none:g}) and of "
                f"two groups ({self.prior_two:g}) impaired leave nothing for one group; "
                "their sum must be below 1.")

    def far_share(self, fit_p_value: float) -> float:
        """How far the best arm's residual is off, from 0 (within the noise) to 1 (its fit
        test at or below :data:`MISFIT_FLOOR`), in decades of the p-value."""
        if not math.isfinite(fit_p_value):
            return 0.0
        return -math.log10(min(max(fit_p_value, MISFIT_FLOOR), 1.0)) / -math.log10(MISFIT_FLOOR)

    def count_weights(self) -> FloatArray:
        """Per number of impaired groups (0, 1, 2), the factor that restates the set's
        posterior under :attr:`prior_none` and :attr:`prior_two`."""
        want = (self.prior_none, 1.0 - self.prior_none - self.prior_two, self.prior_two)
        return np.array([w / s for w, s in zip(want, SET_COUNT_PRIOR, strict=True)])

    def power_at(self, fit_p_value: float) -> float:
        """The power applied to a posterior whose best arm's fit test gave ``fit_p_value``."""
        if not math.isfinite(fit_p_value):
            return self.power
        misfit = -math.log10(min(max(fit_p_value, MISFIT_FLOOR), 1.0))
        return self.power / (1.0 + self.misfit_slope * misfit)

    def unseen_share(self, evidence: float) -> float:
        """A group's share of an impairment the recording does not show, the evidence of its
        reflex at :attr:`unseen_score` being ``evidence`` (unknown: not finite)."""
        if self.unseen_evidence == 0.0 or not math.isfinite(evidence):
            return self.unseen
        return self.unseen * math.exp(-max(evidence, 0.0) / self.unseen_evidence)


def outside_share(fit_p_value: ArrayLike, misfit_level: float, other: float) -> FloatArray:
    """The stated probability that no arm of the set made a recording whose best arm's fit
    test gave ``fit_p_value`` (one or many): 1 − p/level below the misfit level (at least
    :data:`~fieldbank.evaluate.classify.FIT_LEVEL`), and never below the share ``other``."""
    return np.maximum(1.0 - np.asarray(fit_p_value, dtype=float) / max(misfit_level, FIT_LEVEL),
                      other)


def counting_outside(in_set: ArrayLike, outside: ArrayLike, far: ArrayLike,
                     rate: ArrayLike, far_rate: ArrayLike, groups: int = 1) -> FloatArray:
    """The stated probability that at least one of ``groups`` groups is impaired, counting the
    chance ``outside`` (weighed) that the arm is none of the set: ``in_set`` as the set says
    it, and outside the set each group impaired at ``rate`` - or, as far as the residual is
    beyond the noise (``far``, :meth:`Calibration.far_share`), what the set says with each
    group's ``far_rate`` beside it (:attr:`Calibration.outside_weight`). Arrays broadcast:
    one recording's groups, or every calibration of a grid over every outcome."""
    p, o, f = (np.asarray(v, dtype=float) for v in (in_set, outside, far))
    r, rf = np.asarray(rate, dtype=float), np.asarray(far_rate, dtype=float)
    away = (1.0 - f) * (1.0 - (1.0 - r) ** groups) + f * (1.0 - (1.0 - p) * (1.0 - rf) ** groups)
    return np.asarray((1.0 - o) * p + o * away, dtype=float)


#: The smallest fit-test p-value the misfit reads (12 decades: beyond it, misfit enough).
MISFIT_FLOOR = 1e-12
CALIBRATION_BOUNDS = {"power": Interval(0.0, 4.0, "", low_closed=False),
                      "other": Interval(0.0, 1.0, "", high_closed=False),
                      "misfit_level": Interval(FIT_LEVEL, 0.5, ""),
                      "misfit_slope": Interval(0.0, 10.0, ""),
                      "unseen": Interval(0.0, 0.5, "", high_closed=False),
                      "unseen_evidence": Interval(0.0, 1e4, ""),
                      "unseen_score": Interval(0.0, SCORES[-1], ""),
                      "prior_none": Interval(0.0, 1.0, "", low_closed=False,
                                             high_closed=False),
                      "prior_two": Interval(0.0, 1.0, "", low_closed=False,
                                            high_closed=False),
                      "outside_weight": Interval(0.0, 1.0, ""),
                      "outside_group": Interval(0.0, 1.0, ""),
                      "outside_far": Interval(0.0, 1.0, "")}
#: No calibration: the posterior as the likelihood and the prior give it.
RAW = Calibration()
#: The calibration the classifier states its answers with: fitted by
#: ``benchmarks/tune_open_calibration.py`` on 1,140 trials of every family at seeds 7 to 11
#: (the benchmark's are seeds 31 to 33), the targets met in every tuning family: the posterior
#: restated for a case mix with no group impaired in one arm of fifty and two groups in one
#: of ten, sharpened to the power 1.1; each group 8 % of an impairment the recording does not
#: show when its reflex at score 2 is unseen (falling over an evidence of 1); 8 % set aside
#: for an arm outside the set (more below p = 0.001), counted in full in what is stated per
#: group: a group then impaired at 0.1 where the residual is within the noise, and as the set
#: says where it is far beyond it.
CALIBRATED = Calibration(power=1.1, other=0.08, misfit_level=0.001, unseen=0.08,
                         unseen_evidence=1.0, unseen_score=2.0, prior_none=0.02, prior_two=0.1,
                         outside_weight=1.0, outside_group=0.1, outside_far=0.0)


__all__ = [
    "CALIBRATED",
    "CALIBRATION_BOUNDS",
    "MISFIT_FLOOR",
    "RAW",
    "Calibration",
    "counting_outside",
    "outside_share",
]
