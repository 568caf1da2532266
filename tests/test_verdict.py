"""The verdict's rules (fieldbank.interventions.verdict): each rule of the module docstring
reached from hand-made evidence, in its order - the first rule that holds decides."""

from __future__ import annotations

import dataclasses

from fieldbank.interventions.realised import (
    CONFIRMED,
    DEFAULT_RULES,
    FAILED,
    INCONCLUSIVE,
    OVER,
    PARTIAL,
    Fraction,
)
from fieldbank.interventions.verdict import Evidence, judge

SEEN = Fraction(value=1.0, noise_se=0.05, fit_se=0.05, sensitivity_sd=20.0, n_samples=40)


def evidence(**kw: object) -> Evidence:
    base = Evidence(compared=True, fraction=SEEN, shown=True, limits=(-1.0, 3.0),
                    treated="elbow flexors", fit_id=7, advise=lambda: "measure a fast stretch")
    return dataclasses.replace(base, **kw)  # type: ignore[arg-type]


def test_a_clean_fraction_is_decided_by_its_interval() -> None:
    v = judge(evidence())
    assert v.verdict == CONFIRMED and v.decided and v.advice == ""
    assert v.reasons[-1].startswith("realised fraction 1.00 ± 0.07")
    for value, want in ((0.5, PARTIAL), (0.0, FAILED), (1.6, OVER)):
        f = dataclasses.replace(SEEN, value=value)
        assert judge(evidence(fraction=f)).verdict == want, value


def test_the_rules_apply_in_order() -> None:
    misfit = (("map 3: chi2/n 9.1 above 2",),)
    assert judge(evidence(compared=False)).verdict == INCONCLUSIVE
    held = judge(evidence(unexplained=misfit, untested=("elbow slack length",)))
    assert held.verdict == INCONCLUSIVE and "held at the unimpaired value" in held.reasons[-1]
    assert held.reasons[0] == misfit[0][0]
    away = judge(evidence(unexplained=misfit, elsewhere=(3,)))
    assert away.verdict == INCONCLUSIVE and "map(s) 3" in away.reasons[-1]
    failed = judge(evidence(unexplained=misfit, scale=0.8))
    assert failed.verdict == FAILED and "0.80 × the predicted change" in failed.reasons[-1]
    # a misfit outranks everything after it, even a confirming fraction
    assert not failed.decided
    blind = judge(evidence(fraction=dataclasses.replace(SEEN, sensitivity_sd=1.0)))
    assert blind.verdict == INCONCLUSIVE and blind.advice == "measure a fast stretch"
    assert "1.0 sd in all" in blind.reasons[-1]
    guess = judge(evidence(guessed=("alpha_n[ef]",), all_guessed=True, all_held=True))
    assert guess.verdict == INCONCLUSIVE and "held at the unimpaired value" in guess.reasons[-1]
    loose = judge(evidence(fraction=dataclasses.replace(SEEN, noise_se=0.4, fit_se=0.1)))
    assert loose.verdict == INCONCLUSIVE and "too noisy" in loose.reasons[-1]
    part = judge(evidence(guessed=("beta[ef]",)))
    assert part.verdict == CONFIRMED and "part of the prediction rests on a guess" in \
        part.reasons[0]


def test_the_advice_is_asked_only_when_a_verdict_needs_it() -> None:
    asked: list[int] = []

    def advise() -> str:
        asked.append(1)
        return "measure"

    judge(evidence(advise=advise))
    assert asked == []
    judge(evidence(advise=advise, fraction=dataclasses.replace(SEEN, value=None)),
          DEFAULT_RULES)
    assert asked == [1]
