"""Property tests: any valid botulinum injection or lengthening keeps the contract."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from fieldbank.evaluate.severity import synthesize
from fieldbank.interventions.catalogue import Botulinum, Lengthening
from fieldbank.interventions.plan import Plan
from fieldbank.model import Arm
from fieldbank.params import GROUP_INDEX, GROUPS

BASE = synthesize({"elbow": "severe", "shoulder": "mild"})
doses = st.dictionaries(st.sampled_from(GROUPS), st.floats(0.0, 600.0), min_size=1, max_size=6)


@given(doses, st.floats(0.0, 52.0))
def test_botulinum_never_raises_reflex_capacity(units: dict[str, float], weeks: float) -> None:
    after = Botulinum(units, weeks_since=weeks).apply(BASE)
    for g in GROUPS:
        i = GROUP_INDEX[g]
        if g in units:
            assert after.alpha_n[i] <= BASE.alpha_n[i]
            assert after.beta[i] <= BASE.beta[i]
            keep = after.alpha_n[i] / BASE.alpha_n[i]
            assert 1.0 - Botulinum(units).emax <= keep <= 1.0
        else:
            assert after.alpha_n[i] == BASE.alpha_n[i] and after.beta[i] == BASE.beta[i]
    assert after.km_n_per_m == BASE.km_n_per_m


@given(doses, st.floats(0.0, 24.0))
def test_plan_json_round_trip_gives_the_same_model(units: dict[str, float], weeks: float) -> None:
    plan = Plan.of(Lengthening(group="ef", delta_m=0.01), Botulinum(units, weeks_since=weeks))
    again = Plan.from_json(plan.to_json())
    assert again == plan
    assert again.apply(BASE) == plan.apply(BASE)


@given(st.sampled_from(GROUPS), st.floats(0.001, 0.04))
def test_lengthening_never_raises_passive_force(group: str, delta_m: float) -> None:
    before = Arm.from_params(BASE)
    after = Arm.from_params(Lengthening(group=group, delta_m=delta_m).apply(BASE))
    q = np.stack(np.meshgrid(np.linspace(-0.3, 2.2, 9), np.linspace(0.05, 2.6, 9)),
                 axis=-1).reshape(-1, 2)
    lam = before.muscle_lengths(q)
    i = GROUP_INDEX[group]
    assert np.all(after.passive_forces(lam)[0][:, i] <= before.passive_forces(lam)[0][:, i]
                  + 1e-12)
