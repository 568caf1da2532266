"""The open-set classifier: every group's states, a stretch for every group, and "none of the
candidates" when the residual says so.

Cheap on purpose: noise-free and lightly noisy traces of a handful of arms on one body (the
reliability over seeded families of their own is ``benchmarks/bench_probe_open.py``).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fieldbank.errors import ParameterError
from fieldbank.evaluate.design import NoiseModel, open_candidates
from fieldbank.evaluate.design.coverage import differing_groups, stretch_set
from fieldbank.evaluate.observation import Observation, with_force_noise
from fieldbank.evaluate.opencalibration import RAW, Calibration
from fieldbank.evaluate.openset import (
    NONE_OF_THEM,
    OpenClassification,
    OpenSet,
    OpenTrace,
    classify_open,
)
from fieldbank.evaluate.openstates import KINDS, SCORES, SET_COUNT_PRIOR
from fieldbank.evaluate.reliability import (
    Outcome,
    calibration_error,
    ece_noise_floor,
    family_arms,
    fit_calibration,
    reliability_bins,
    truth_label,
)
from fieldbank.evaluate.replay import replay_forces
from fieldbank.evaluate.severity import synthesize, synthesize_ratios
from fieldbank.evaluate.statements import open_report, state
from fieldbank.model import Arm
from fieldbank.params import GROUPS, ArmParams
from fieldbank.sim import ArmSim

BODY = ArmParams.from_anthropometry(68.0, 1.71, "left")


def test_the_batch_replay_is_the_arm_by_arm_replay() -> None:
    """Every candidate ticked together gives what one ArmSim per candidate gives."""
    arms = [Arm.from_params(p) for p in (
        BODY, synthesize({"elbow": "severe"}, BODY), BODY.with_group("ef", slack_offset_m=-0.01),
        synthesize({"be:dynamic": "moderate"}, BODY))]
    m = stretch_set(arms[0])[2]  # the elbow flexors' stretch: its fast part, 800 ms
    m = type(m)(m.name, m.times_s[-800:], m.positions_m[-800:], m.velocities_m_per_s[-800:],
                m.description)
    dt = float(m.times_s[1] - m.times_s[0])
    start = (float(m.positions_m[0, 0]), float(m.positions_m[0, 1]))
    batch = replay_forces(arms, m.positions_m, m.velocities_m_per_s, dt, start)
    for a, got in zip(arms, batch, strict=True):
        sim = ArmSim(a, dt_s=dt)
        sim.reset_at_hand(*start)
        want = np.array([sim.tick(p[0], p[1], v[0], v[1]) for p, v in
                         zip(m.positions_m.tolist(), m.velocities_m_per_s.tolist(),
                             strict=True)])
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * np.abs(want).max())
    assert np.abs(batch[1] - batch[0]).max() > 1.0  # the arms differ


def test_the_open_set_spans_groups_components_levels_pairs_and_contractures() -> None:
    cands = open_candidates(BODY)
    labels = {c.label for c in cands}
    assert {"unimpaired", *GROUPS} <= labels and "ef+bf" in labels
    assert any("contracture" in c.name for c in cands)
    assert len(cands) == 1 + 6 * 3 * 4 + 6 * 3 + 15 * 4
    assert differing_groups(cands) == GROUPS
    # a stretch for every group: each lengthens its group fast into the end of its range
    arm = cands[0].arm
    stretches = stretch_set(arm)
    assert [m.name for m in stretches] == [f"stretch {g}" for g in GROUPS]
    for g, m in zip(GROUPS, stretches, strict=True):
        q = arm.ik(m.positions_m)
        rate = (np.gradient(q, m.times_s, axis=0) @ arm.jl.T)[:, GROUPS.index(g)]
        assert rate.max() > 0.3 * arm.ldot_max[GROUPS.index(g)] / 2  # fast
        lam = arm.muscle_lengths(q)[:, GROUPS.index(g)]
        assert (lam.max() - arm.lam_min[GROUPS.index(g)]) / arm.excursion[
            GROUPS.index(g)] > 0.7  # into the long end of its range


@pytest.fixture(scope="module")
def openset() -> OpenSet:
    return OpenSet.for_arm(BODY)


def _trace(params: ArmParams, openset: OpenSet) -> list[Observation]:
    true = Arm.from_params(params)
    out = []
    for m in stretch_set(openset.unimpaired):
        dt = float(m.times_s[1] - m.times_s[0])
        start = (float(m.positions_m[0, 0]), float(m.positions_m[0, 1]))
        f = replay_forces([true], m.positions_m, m.velocities_m_per_s, dt, start)[0]
        out.append(Observation.from_arrays(m.name, m.times_s, m.positions_m, f,
                                           m.velocities_m_per_s, reset_m=start))
    return out


@pytest.mark.slow
def test_groups_between_the_steps_are_named_and_an_arm_outside_is_flagged(
        openset: OpenSet) -> None:
    """An elbow-extensor reflex alone and two groups at scores off the grid are stated with
    their groups (and are the most probable set); three severe groups at once are none of
    the candidates - at 2 N of noise."""
    rng = np.random.default_rng(3)
    noise = NoiseModel(force_sd_n=2.0)
    arms = {
        "ee": synthesize_ratios({"ee:dynamic": 9.0}, BODY),
        "ef+be": synthesize_ratios({"ef": 3.3, "be:passive": 7.0}, BODY),
    }
    for truth, params in arms.items():
        assert truth_label(params) == truth
        obs = _trace(params, openset)
        c = classify_open([with_force_noise(o, noise, rng) for o in obs], openset,
                          trace=OpenTrace.of(obs, openset, noise))
        # what is stated: each impaired group named impaired (alone or with its partner),
        # no other group
        said = [st for st in state(c) if st.groups]
        held = {g for st in said if st.impaired for g in st.groups}
        assert set(truth.split("+")) <= held, (truth, open_report(c)["statements"])
        assert all(st.right(set(truth.split("+")), outside=False) for st in said
                   if st.impaired), (truth, open_report(c)["statements"])
        assert c.labels[int(np.argmax(c.label_probability))] == truth, c.to_dict()
        assert c.explains
    outside = synthesize({"sf": "severe", "ee": "severe", "bf": "severe"}, BODY)
    c = classify_open([with_force_noise(o, noise, rng) for o in _trace(outside, openset)],
                      openset, noise)
    answer, p = c.answer
    assert answer == NONE_OF_THEM and p > 0.99 and not c.explains, c.to_dict()


def test_the_reliability_figures() -> None:
    """Bins, calibration error and the families' truths, on numbers worked by hand."""
    bins = reliability_bins([0.5, 0.55, 0.97, 0.99, 1.0], [True, False, True, True, False])
    got = {(b.low, b.high): (b.n, b.stated, b.observed) for b in bins if b.n}
    assert got[(0.0, 0.6)] == (2, pytest.approx(0.525), 0.5)
    assert got[(0.95, 0.99)] == (1, pytest.approx(0.97), 1.0)
    assert got[(0.99, 1.0)] == (2, pytest.approx(0.995), 0.5)
    # |0.5 - 0.525| × 2 + |1 - 0.97| + |0.5 - 0.995| × 2, over 5
    assert calibration_error(bins) == pytest.approx((0.05 + 0.03 + 0.99) / 5)
    arms = family_arms("reflex only", 6, seed=99)
    assert family_arms("reflex only", 6, seed=99) == arms  # seeded
    for a in arms:  # one group's reflex, felt: the truth is that group
        assert a.truth in GROUPS, a
        g = a.truth
        assert a.params.group_value("km_n_per_m", g) == pytest.approx(600.0)


def test_a_design_that_covers_stretches_every_group_the_candidates_differ_in() -> None:
    """The two strokes designed for three joint groups never stretched the directions in which
    an elbow-extensor reflex differs; with ``cover`` the set starts with a stroke along each
    group's lengthening direction."""
    import math

    from fieldbank.evaluate.design import design, severity_candidates
    from fieldbank.evaluate.probing import lengthening_direction

    cands = severity_candidates(("elbow",), ("severe",), unimpaired=True, base=BODY)
    d = design(cands, max_probes=2, polish_evals=0, cover=True)
    assert differing_groups(cands) == ("ef", "ee")
    arm = cands[0].arm
    for g in ("ef", "ee"):
        want = lengthening_direction(arm, g)
        angle = math.degrees(math.atan2(want[1], want[0]))
        assert any(abs((p.direction_deg - angle + 180.0) % 360.0 - 180.0) <= 30.0
                   for p in d.paths), (g, [p.direction_deg for p in d.paths])


def _stated(labels: tuple[str, ...], raw: tuple[float, ...], fit_p: float,
            cal: Calibration) -> OpenClassification:
    return OpenClassification(labels, np.array(raw), ("ef dynamic 2",), 0.0, 0.0, fit_p, 1.0,
                              np.zeros((6, len(KINDS))), cal)


def test_the_calibration_tempers_the_posterior_and_sets_a_share_aside() -> None:
    """Numbers worked by hand: raw 0.8, 0.15, 0.05 at power 0.5 are √ of them over their sum
    (0.894, 0.387, 0.224 over 1.505), 0.9 of it stated when 0.1 is set aside."""
    labels = ("ef", "ef+bf", "unimpaired")
    c = _stated(labels, (0.8, 0.15, 0.05), 0.5, Calibration(power=0.5, other=0.1))
    np.testing.assert_allclose(c.label_probability, 0.9 * np.sqrt([0.8, 0.15, 0.05])
                               / np.sqrt([0.8, 0.15, 0.05]).sum())
    assert c.other_probability == 0.1
    assert c.answer == ("ef", pytest.approx(0.9 * 0.8944 / 1.5053, abs=1e-4))
    # per group, should the arm be one of the set: every label holding the group
    assert c.group_probability["ef"] == pytest.approx(1 - 0.2236 / 1.5053, abs=1e-4)
    assert c.group_probability["bf"] == pytest.approx(0.3873 / 1.5053, abs=1e-4)
    assert c.group_probability["sf"] == 0.0
    # a residual beyond the noise: none of the candidates, 1 - p/level
    c = _stated(labels, (0.8, 0.15, 0.05), 1e-4, Calibration(power=0.5, other=0.1))
    assert c.answer == (NONE_OF_THEM, pytest.approx(0.9))
    assert _stated(labels, (0.8, 0.15, 0.05), 0.5, RAW).answer == ("ef", pytest.approx(0.8))
    with pytest.raises(ParameterError, match="'other'"):
        Calibration(power=0.5, other=1.0)


def test_the_fitted_calibration_states_what_happens() -> None:
    """A posterior that says 0.99 where the truth is so four times in five: the fit tempers it
    to 0.8 (0.99^a / (0.99^a + 0.01^a) = 0.8 at a = ln 4 / ln 99 ≈ 0.30) and sets nothing
    aside for arms the set holds."""
    out = [Outcome("two groups", f"arm {k}", "ef" if k % 5 else "ee", "ef", 0.99, True, 1.0,
                   labels=("ef", "ee"), label_probability=(0.99, 0.01)) for k in range(100)]
    cal, _score = fit_calibration(out)
    assert cal == Calibration(power=0.3, other=0.0)
    stated = [o.restated(cal) for o in out]
    assert all(o.answer == "ef" and o.probability == pytest.approx(0.8, abs=0.01)
               for o in stated)
    # arms outside the set that the posterior puts on a label: a share is set aside
    outside = [dataclasses.replace(o, family="outside the candidates",
                                   truth="ef+bf+ee" if k % 4 == 0 else o.truth)
               for k, o in enumerate(out)]
    assert fit_calibration(outside)[0].other > 0.1


def test_the_prior_on_how_many_groups_restates_the_posterior_on_numbers_worked_by_hand(
        ) -> None:
    """The set's own prior gives no group 0.158, one 0.406, two 0.435 (each group at 0.3,
    at most two). Restated under 0.05 / 0.60 / 0.35, raw 0.5, 0.3, 0.2 on 'unimpaired', 'ef',
    'ef+bf' become 0.5 × 0.316, 0.3 × 1.476, 0.2 × 0.804 = 0.1582, 0.4429, 0.1607 over their
    sum 0.7618: 0.2076, 0.5814, 0.2110, and ef is impaired at 0.7924."""
    assert SET_COUNT_PRIOR == pytest.approx((0.15806, 0.40645, 0.43548), abs=1e-5)
    np.testing.assert_allclose(RAW.count_weights(), 1.0)
    cal = Calibration(prior_none=0.05, prior_two=0.35)
    c = _stated(("unimpaired", "ef", "ef+bf"), (0.5, 0.3, 0.2), 1.0, cal)
    np.testing.assert_allclose(c.label_share, [0.20763, 0.58136, 0.21101], atol=1e-5)
    assert c.group_probability["ef"] == pytest.approx(0.79237, abs=1e-5)
    assert c.group_probability["bf"] == pytest.approx(0.21101, abs=1e-5)
    with pytest.raises(ParameterError, match="nothing for one group"):
        Calibration(prior_none=0.5, prior_two=0.5)
    with pytest.raises(ParameterError, match="'prior_none'"):
        Calibration(prior_none=0.0)


def test_what_is_stated_per_group_counts_an_arm_outside_the_set_on_numbers_worked_by_hand(
        ) -> None:
    """The set says ef impaired at 0.99 with a fit within the noise (p = 1); 10 % is set
    aside for an arm outside it, where a group is impaired at 0.3. Counted fully: 0.9 × 0.99 +
    0.1 × 0.3 = 0.921, and ef or bf 0.9 × 0.99 + 0.1 × (1 − 0.7²) = 0.942; counted at half
    weight (5 %): 0.95 × 0.99 + 0.05 × 0.3 = 0.9555. Not counted, 0.99 as the set says."""
    labels, raw = ("ef", "unimpaired"), (0.99, 0.01)
    full = Calibration(other=0.1, outside_weight=1.0, outside_group=0.3)
    c = _stated(labels, raw, 1.0, full)
    assert c.other_probability == pytest.approx(0.1)
    assert c.group_probability["ef"] == pytest.approx(0.921)
    assert c.any_impaired(("ef", "bf")) == pytest.approx(0.942)
    assert c.group_probability["sf"] == pytest.approx(0.03)
    half = dataclasses.replace(full, outside_weight=0.5)
    assert _stated(labels, raw, 1.0, half).group_probability["ef"] == pytest.approx(0.9555)
    assert _stated(labels, raw, 1.0, Calibration(other=0.1)).group_probability[
        "ef"] == pytest.approx(0.99)
    with pytest.raises(ParameterError, match="'outside_group'"):
        Calibration(outside_group=1.5)


def test_a_residual_far_off_keeps_the_named_groups_and_raises_the_others_by_hand() -> None:
    """Misfit read in decades of the fit test's p-value over 12: p = 1e-12 is far off (1),
    1e-6 half way, 1 not at all. The set says ef impaired at 0.99, the arm is outside it
    (1 − p/0.001 ≈ 1) and counted in full; far off, a group the set names stays
    (1 − 0.01 × 0.6 = 0.994) and each other is impaired at 0.4; half way, an unnamed group is
    0.5 × 0.1 + 0.5 × 0.4 = 0.25 outside the set, 0.999 × 0.25 = 0.24975 stated."""
    cal = Calibration(other=0.08, misfit_level=0.001, outside_weight=1.0, outside_group=0.1,
                      outside_far=0.4)
    assert cal.far_share(1e-12) == pytest.approx(1.0)
    assert cal.far_share(1e-30) == pytest.approx(1.0)
    assert cal.far_share(1e-6) == pytest.approx(0.5)
    assert cal.far_share(1.0) == 0.0 and cal.far_share(float("nan")) == 0.0
    labels, raw = ("ef", "unimpaired"), (0.99, 0.01)
    far = _stated(labels, raw, 1e-12, cal)
    assert far.group_probability["ef"] == pytest.approx(0.994, abs=1e-9)
    assert far.group_probability["sf"] == pytest.approx(0.4, abs=1e-9)
    half = _stated(labels, raw, 1e-6, cal)
    assert half.other_probability == pytest.approx(0.999)
    assert half.group_probability["sf"] == pytest.approx(0.24975)


def test_the_fit_holds_every_family_to_the_targets_not_only_the_pool() -> None:
    """Two families see the same posterior - ee not impaired at 0.99 -, but in the reflex-only
    family ee is impaired one time in five (a reflex the strokes do not see), among the
    arms between severities never. The pooled rate (20 in 500) would state "ee not impaired"
    at 0.96, and one claim in thirty of the reflex-only family at p ≥ 0.95 would be wrong;
    the fit keeps that family within 2 % by stating it below 0.95, and no lower than the
    reflex-only family's own 0.8."""
    def trial(family: str, k: int, truth: str) -> Outcome:
        return Outcome(family, f"arm {k}", truth, "unimpaired", 0.99, True, 1.0,
                       labels=("unimpaired", "ee"), label_probability=(0.99, 0.01))
    reflex = [trial("reflex only", k, "ee" if k % 5 == 0 else "unimpaired")
              for k in range(100)]
    between = [trial("between severities", k, "unimpaired") for k in range(400)]
    cal, _score = fit_calibration(reflex + between)
    p = 1.0 - reflex[0].classification(cal).group_probability["ee"]
    assert 0.8 <= p < 0.95, (p, cal)
    said = [st for st in state(reflex[0].classification(cal)) if "ee" in st.groups]
    assert said and said[0].probability < 0.95, said


def test_the_tempering_falls_with_the_misfit() -> None:
    """Where the best arm fits (p = 1), 0.99 is right 99 times in 100; where it misfits
    (p = 0.002, 2.7 decades) 0.99 is right four times in five: the fitted power falls with
    the misfit, and each is stated as often right as it is."""
    good = [Outcome("two groups", f"good {k}", "ef" if k % 100 else "ee", "ef", 0.99, True,
                    1.0, labels=("ef", "ee"), label_probability=(0.99, 0.01))
            for k in range(200)]
    poor = [dataclasses.replace(o, arm=f"poor {k}", fit_p_value=0.002,
                                truth="ef" if k % 5 else "ee") for k, o in enumerate(good)]
    cal, _score = fit_calibration(good + poor)
    assert cal.misfit_slope > 0.0 and cal.other == 0.0, cal
    assert good[0].classification(cal).group_probability["ef"] == pytest.approx(0.99,
                                                                                abs=0.006)
    assert 0.72 < poor[0].classification(cal).group_probability["ef"] < 0.88, cal


def test_the_power_and_the_shares_on_numbers_worked_by_hand() -> None:
    """power 0.6, slope 1: at p = 0.01 (2 decades) the power is 0.6 / 3 = 0.2, at p = 1 it is
    0.6, and an unknown fit reads no misfit. raw 0.45, 0.45, 0.1 at p = 0.1 (1 decade) with
    power 1, slope 1: the power 0.5, √ of them over their sum (0.6708, 0.6708, 0.3162 over
    1.6579)."""
    cal = Calibration(power=0.6, misfit_slope=1.0)
    assert cal.power_at(0.01) == pytest.approx(0.2)
    assert cal.power_at(1.0) == pytest.approx(0.6)
    assert cal.power_at(float("nan")) == pytest.approx(0.6)
    assert cal.power_at(0.0) == pytest.approx(0.6 / 13.0)  # floored at 12 decades
    c = _stated(("ef", "bf", "unimpaired"), (0.45, 0.45, 0.1), 0.1,
                Calibration(power=1.0, misfit_slope=1.0))
    np.testing.assert_allclose(c.label_share, [0.4046, 0.4046, 0.1907], atol=1e-4)
    assert c.any_impaired(("ef", "bf")) == pytest.approx(0.8093, abs=1e-4)
    assert c.any_impaired(("ef", "sf")) == pytest.approx(0.4046, abs=1e-4)
    with pytest.raises(ParameterError, match="'misfit_slope'"):
        Calibration(misfit_slope=-1.0)
    # each group's share of an impairment the recording does not show, 0.1: ef held at
    # 0.4046 → 1 − 0.5954 × 0.9 = 0.4641; ef or bf held at 0.8093 → 1 − 0.1907 × 0.81
    c = _stated(("ef", "bf", "unimpaired"), (0.45, 0.45, 0.1), 0.1,
                Calibration(power=1.0, misfit_slope=1.0, unseen=0.1))
    assert c.group_probability["ef"] == pytest.approx(0.4641, abs=1e-4)
    assert c.group_probability["sf"] == pytest.approx(0.1)
    assert c.any_impaired(("ef", "bf")) == pytest.approx(1 - 0.1907 * 0.81, abs=1e-4)
    with pytest.raises(ParameterError, match="'unseen'"):
        Calibration(unseen=0.5)


def test_the_per_group_unseen_share_on_numbers_worked_by_hand() -> None:
    """unseen 0.2 falling over an evidence of 10, read at score 1: a group whose reflex
    gives 10 keeps 0.2 e⁻¹ = 0.07358, one giving 0 keeps 0.2, one giving 50 keeps
    0.2 e⁻⁵ = 0.001348. raw unimpaired 0.9, ef 0.1 (power 1), ef's reflex unseen (0) and
    sf's seen (50): ef 1 − 0.9 × 0.8 = 0.28, sf 0.001348, ef or sf 1 − 0.9 × 0.8 × 0.998652
    = 0.28097."""
    cal = Calibration(unseen=0.2, unseen_evidence=10.0, unseen_score=1.0)
    assert cal.unseen_share(10.0) == pytest.approx(0.2 * np.exp(-1.0))
    assert cal.unseen_share(0.0) == pytest.approx(0.2)
    assert cal.unseen_share(50.0) == pytest.approx(0.2 * np.exp(-5.0))
    assert cal.unseen_share(float("nan")) == pytest.approx(0.2)  # evidence unknown
    assert Calibration(unseen=0.2).unseen_share(50.0) == pytest.approx(0.2)  # no fall
    evidence = np.full((6, 9), 50.0)
    evidence[GROUPS.index("ef"), :] = [0.0, 0.0, 3.0, 9.0, 20.0, 30.0, 40.0, 60.0, 80.0]
    c = dataclasses.replace(_stated(("unimpaired", "ef"), (0.9, 0.1), 1.0,
                                    dataclasses.replace(cal, power=1.0)),
                            reflex_evidence=evidence)
    assert c.group_unseen["ef"] == pytest.approx(0.2)
    assert c.group_unseen["sf"] == pytest.approx(0.2 * np.exp(-5.0))
    assert c.group_probability["ef"] == pytest.approx(0.28)
    assert c.group_probability["sf"] == pytest.approx(0.001348, abs=1e-6)
    assert c.any_impaired(("ef", "sf")) == pytest.approx(0.28097, abs=1e-5)
    # read at score 2 (evidence 9 for ef): 0.2 e^-0.9 = 0.08131
    c2 = c.with_calibration(dataclasses.replace(c.calibration, unseen_score=2.0))
    assert c2.group_unseen["ef"] == pytest.approx(0.2 * np.exp(-0.9))
    with pytest.raises(ParameterError, match="'unseen_evidence'"):
        Calibration(unseen_evidence=-1.0)
    with pytest.raises(ParameterError, match="'unseen_score'"):
        Calibration(unseen_score=6.0)


def test_the_fit_tempers_a_group_the_strokes_cannot_see_and_not_a_seen_one() -> None:
    """The posterior says "not impaired" (0.999) for every group; ee, whose reflex the
    strokes do not see (evidence 0.1), is impaired in one arm of five, the others (evidence
    40-80) never. The fitted share falls with the evidence: ee is stated impaired at about
    0.2, every seen group at less than 1 %."""
    evidence = tuple(tuple(0.1 if g == "ee" else 40.0 + 8.0 * i for _s in range(9))
                     for i, g in enumerate(GROUPS))
    out = [Outcome("reflex only", f"arm {k}", "ee" if k % 5 == 0 else "unimpaired",
                   "unimpaired", 0.999, True, 1.0, labels=("unimpaired", "sf"),
                   label_probability=(0.999, 0.001), reflex_evidence=evidence)
           for k in range(100)]
    cal, _score = fit_calibration(out)
    assert cal.unseen > 0.1 and cal.unseen_evidence > 0.0, cal
    c = out[0].classification(cal)
    assert c.group_probability["ee"] == pytest.approx(0.2, abs=0.05), cal
    assert all(c.group_probability[g] < 0.01 for g in GROUPS if g != "ee"), (
        cal, c.group_probability)


@pytest.mark.slow
def test_a_reflex_the_strokes_cannot_see_is_tempered_on_a_recording(
        openset: OpenSet) -> None:
    """On a recording of the unimpaired arm: the strokes see the bi-articular extensors'
    reflex (its evidence at score 2 well beyond 10) and hardly the elbow extensors' (below
    3); a share of 0.2 falling over an evidence of 10 raises ee's stated probability of an
    impairment by more than 0.1 and be's by less than 0.005."""
    obs = _trace(BODY, openset)
    noise = NoiseModel(force_sd_n=2.0)
    cal = Calibration(power=0.5, unseen=0.2, unseen_evidence=10.0, unseen_score=2.0)
    c = classify_open([with_force_noise(o, noise, np.random.default_rng(5)) for o in obs],
                      openset, trace=OpenTrace.of(obs, openset, noise), calibration=cal)
    ev = c.reflex_evidence[:, 3]  # score 2
    assert ev[GROUPS.index("be")] > 30.0 and ev[GROUPS.index("ee")] < 3.0, ev
    assert c.group_unseen["ee"] > 0.15 and c.group_unseen["be"] < 0.01, c.group_unseen
    c0 = c.with_calibration(dataclasses.replace(cal, unseen=0.0))
    raised = {g: c.group_probability[g] - c0.group_probability[g] for g in ("ee", "be")}
    assert raised["ee"] > 0.1 and 0.0 <= raised["be"] < 0.005, raised
    # the evidence grows with the reflex's score, group by group
    assert np.all(np.diff(c.reflex_evidence[:, :len(SCORES)], axis=1) >= 0.0), \
        c.reflex_evidence


@pytest.mark.slow
def test_a_reflex_the_strokes_cannot_see_is_not_stated_absent(openset: OpenSet) -> None:
    """The elbow extensors' α raised twelvefold alone (graded very mild on their own stretch)
    changes the recording by tenths of a newton: the set holds such reflexes, so "ee not
    impaired" is not stated with p ≥ 0.95. On the same strokes a severe elbow-flexor stiffness
    is stated impaired, and the groups it leaves alone not impaired at p ≥ 0.9."""
    noise = NoiseModel(force_sd_n=2.0)
    rng = np.random.default_rng(11)
    hidden = BODY.with_group("ee", alpha_n=12.0 * BODY.group_value("alpha_n", "ee"))
    assert truth_label(hidden) == "ee"
    obs = _trace(hidden, openset)
    c = classify_open([with_force_noise(o, noise, rng) for o in obs], openset,
                      trace=OpenTrace.of(obs, openset, noise))
    assert 1.0 - c.group_probability["ee"] < 0.95, open_report(c)["statements"]
    stiff = synthesize_ratios({"ef:passive": 7.0}, BODY)
    obs = _trace(stiff, openset)
    c = classify_open([with_force_noise(o, noise, rng) for o in obs], openset,
                      trace=OpenTrace.of(obs, openset, noise))
    gp = c.group_probability
    assert gp["ef"] > 0.9 or c.any_impaired(("ef", "bf")) > 0.9, open_report(c)
    assert all(1.0 - gp[g] >= 0.9 for g in ("sf", "se", "ee", "be")), gp


def test_partner_groups_the_recording_cannot_separate_are_stated_as_a_set() -> None:
    """ef and bf each at 0.45 (the recording fits either), unimpaired at 0.1: neither can be
    stated alone, their union can - "ef or bf" at 0.9 -, every other group not impaired at
    1.0. A group undecided with no undecided partner is stated alone; a union no more decided
    than its groups is not stated; a residual beyond the noise states none of the
    candidates first."""
    c = _stated(("ef", "bf", "unimpaired"), (0.45, 0.45, 0.1), 0.5, RAW)
    got = {st.groups: (st.impaired, round(st.probability, 6)) for st in state(c)}
    assert got == {("sf",): (False, 1.0), ("se",): (False, 1.0), ("ef", "bf"): (True, 0.9),
                   ("ee",): (False, 1.0), ("be",): (False, 1.0)}
    pair = next(st for st in state(c) if st.kind == "partners")
    assert pair.right({"bf"}, outside=False) and pair.right({"ef", "bf"}, outside=False)
    assert not pair.right(set(), outside=False) and not pair.right({"ee"}, outside=False)
    assert "elbow flexors (ef) or bi-articular flexors (bf)" in pair.text
    assert "cannot tell which" in pair.text and "elbow extension" in pair.text
    # ef alone undecided, bf decided: ef stated alone at 0.6
    c = _stated(("ef", "unimpaired"), (0.6, 0.4), 0.5, RAW)
    assert [(st.groups, st.impaired, st.probability) for st in state(c)
            if st.groups == ("ef",)] == [(("ef",), True, pytest.approx(0.6))]
    # both together or neither: the union (0.5) tells no more than each group - stated alone
    c = _stated(("ef+bf", "unimpaired"), (0.5, 0.5), 0.5, RAW)
    assert {st.groups for st in state(c)} == {(g,) for g in GROUPS}
    # the fit test at 1e-4 under the level 0.001: none of the candidates, p = 0.9
    c = _stated(("ef", "bf", "unimpaired"), (0.45, 0.45, 0.1), 1e-4, RAW)
    first = state(c)[0]
    assert first.kind == "none" and first.probability == pytest.approx(0.9)
    assert first.right(set(), outside=True) and not first.right({"ef"}, outside=False)
    assert open_report(c)["statements"][0]["says"] == first.text


def test_the_noise_floor_of_the_calibration_error() -> None:
    """A calibrated classifier's ECE by sampling alone, on numbers worked by hand: one answer
    at 0.5 is right or wrong, |1 − 0.5| or |0 − 0.5| - always 0.5; answers stated at 1 are
    always right - 0; two answers at 0.5 in one bin: both right or both wrong (half the
    time) 0.5, one of each 0 - mean 0.25, 95th percentile 0.5."""
    assert ece_noise_floor([0.5]) == (pytest.approx(0.5), pytest.approx(0.5))
    assert ece_noise_floor([1.0] * 10) == (0.0, 0.0)
    mean, p95 = ece_noise_floor([0.5, 0.5], repeats=20000)
    assert mean == pytest.approx(0.25, abs=0.01) and p95 == pytest.approx(0.5)
    # bins apart: 0.5 (always 0.5 off) and 1.0 (never off), over two answers: 0.25 always
    assert ece_noise_floor([0.5, 1.0]) == (pytest.approx(0.25), pytest.approx(0.25))
    # more answers, a smaller floor
    assert ece_noise_floor([0.8] * 400)[0] < ece_noise_floor([0.8] * 25)[0] / 3
