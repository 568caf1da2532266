"""Prediction intervals over what the maps did not identify: held parameters drawn from their
stated prior range (fieldbank.fitting.prior), through the vectorised pass, so an interval that
rests on a guess is wide, contains the truth and says so."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.compare import Conditions
from fieldbank.evaluate.probing import standard_stretches
from fieldbank.evaluate.severity import classify, synthesize
from fieldbank.fitting import ArmFitter
from fieldbank.fitting.prior import (
    PRIOR_VERSION,
    SCORE_HIGH,
    GuessRange,
    Prior,
    draw,
    full_ranges,
    ranges_from_report,
    stratified_scores,
)
from fieldbank.fitting.synthetic import synthetic_patient
from fieldbank.fitting.uncertainty import FitSamples
from fieldbank.interventions.catalogue import Botulinum
from fieldbank.interventions.guesses import (
    FitBasis,
    examine,
    interval_key,
    summary_lines,
)
from fieldbank.interventions.plan import Plan
from fieldbank.interventions.samplemetrics import sample_metrics
from fieldbank.model import Arm
from fieldbank.params import GROUPS, ArmParams
from tests.sample_reference import headline_metrics, sample_metrics_per_sample

BASE = ArmParams.from_anthropometry()
PLAN = Plan.of(Botulinum({"ef": 150.0}))


def test_the_range_runs_from_unimpaired_to_past_severe_on_the_scale() -> None:
    arm = Arm.from_params(BASE)
    prior = Prior.for_arm(arm)
    for g in GROUPS:
        i = GROUPS.index(g)
        # score 0 is the unimpaired arm, score 4 the scale's severe arm (synthesize), 4.5 the
        # top of the severe band: past the MAS-4 boundary, so a severe truth lies inside
        low = prior.values(g, "dynamic", np.array([0.0]))
        assert low[f"alpha_{g}"][0] == pytest.approx(100.0)
        assert low[f"beta_{g}"][0] == pytest.approx(0.1)
        severe = synthesize({f"{g}:dynamic": "severe"})
        at4 = prior.values(g, "dynamic", np.array([4.0]))
        assert at4[f"alpha_{g}"][0] == pytest.approx(severe.alpha_n[i], rel=2e-3)
        assert at4[f"beta_{g}"][0] == pytest.approx(severe.beta[i], rel=2e-3)
        top = prior.values(g, "dynamic", np.array([SCORE_HIGH]))
        trial = BASE.with_group(g, alpha_n=float(top[f"alpha_{g}"][0]),
                                beta=float(top[f"beta_{g}"][0]))
        assert classify(Arm.from_params(trial))[g].dynamic.score == pytest.approx(4.5,
                                                                                abs=5e-3)
        km = prior.values(g, "passive", np.array([0.0, 4.0, SCORE_HIGH]))[f"km_{g}"]
        assert km == pytest.approx([600.0, 6000.0, 6000.0 * 1.6 ** 0.5])
    # stratified: one draw in each of n equal slices, so both ends are reached
    s = np.sort(stratified_scores(40, SCORE_HIGH, np.random.default_rng(1)))
    assert np.all((s >= np.arange(40) * SCORE_HIGH / 40) & (s < np.arange(1, 41) * SCORE_HIGH / 40))


def test_draws_replace_only_the_held_parameters_and_run_through_the_vectorised_pass() -> None:
    before = synthesize({"elbow:passive": "severe"})
    names = [f"{k}_{g}" for k in ("km", "alpha", "beta") for g in GROUPS]
    rng = np.random.default_rng(3)
    centre = np.array([*before.km_n_per_m, *before.alpha_n, *before.beta])
    values = centre * np.exp(rng.normal(scale=0.05, size=(8, centre.size)))
    values[:, 12:] = np.minimum(values[:, 12:], 1.0)
    held = ["km_se", "alpha_ef", "beta_ef", "alpha_bf", "beta_bf"]
    for n in held:
        values[:, names.index(n)] = centre[names.index(n)]
    samples = FitSamples(tuple(names), values)
    ranges = full_ranges(held)
    assert [(r.group, r.component, r.names) for r in ranges] == [
        ("se", "passive", ("km_se",)), ("ef", "dynamic", ("alpha_ef", "beta_ef")),
        ("bf", "dynamic", ("alpha_bf", "beta_bf"))]
    arm = Arm.from_params(before)
    prior = Prior.for_arm(arm)
    drawn = draw(samples, ranges, prior, 20, seed=4)
    assert drawn.values.shape == (20, 18)
    for k, n in enumerate(names):
        col = drawn.values[:, k]
        if n in held:  # one draw in each twentieth of the range: from its bottom slice to
            # its top slice - past the scale's severe arm, for a bi-articular reflex up to
            # where it adds as much to a joint stretch as a severe mono-articular one
            g, comp = n[-2:], "passive" if n.startswith("km") else "dynamic"
            top = prior.top(g, comp)
            edges = prior.values(g, comp, np.array([top / 20, 0.95 * top]))[n]
            assert col.min() <= edges[0] + 1e-9, n
            assert col.max() >= edges[1] * (1 - 1e-9), n
            if g != "bf":
                severe = synthesize({f"{g}:{comp}": "severe"})
                field = {"km": "km_n_per_m", "alpha": "alpha_n", "beta": "beta"}[n[:-3]]
                assert col.max() >= getattr(severe, field)[GROUPS.index(g)] * (1 - 1e-3), n
        else:  # the fit's samples, cycled
            np.testing.assert_array_equal(col, values[np.arange(20) % 8, k])
    assert draw(samples, ranges, Prior.for_arm(arm), 20, seed=4).values.tolist() == \
        drawn.values.tolist()  # deterministic for a seed
    # the vectorised pass over the draws equals each drawn arm compiled alone
    sets = [before, *drawn.params(before)[:10]]
    cond = Conditions.standard(arm)
    fast = sample_metrics(sets, PLAN, cond, arm)
    ref = sample_metrics_per_sample(sets, PLAN, cond)
    np.testing.assert_allclose(fast.before, ref.before, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(fast.after, ref.after, rtol=1e-12, atol=1e-12)
    # a fit's key includes the prior: another range or version gives another key
    basis = FitBasis(7, 3, True, "good", "good", (), (), tuple(held), samples, ranges, 0)
    key = interval_key(basis, before, PLAN, 20)
    lowered = (dataclasses.replace(ranges[0], score_high=2.0), *ranges[1:])
    assert key != interval_key(dataclasses.replace(basis, ranges=lowered), before, PLAN, 20)
    assert PRIOR_VERSION >= 1


@pytest.fixture(scope="module")
def postural_only() -> tuple[ArmParams, ArmFitter]:
    """A severe elbow (passive and reflex) measured by a postural map only: the maps identify
    Km, never the reflex."""
    truth = synthesize({"elbow": "severe"})
    pat = synthetic_patient(truth, seed=8, moving=False, patient="POST-1")
    return truth, ArmFitter(seed=0).fit([pat.maps[0]], BASE)


def test_a_postural_only_fit_gives_intervals_that_hold_the_unmeasured_reflex(
        postural_only: tuple[ArmParams, ArmFitter]) -> None:
    truth, fit = postural_only
    assert {"alpha_ef", "beta_ef", "alpha_bf", "beta_bf"} <= set(fit.held_)
    report = fit.report()
    ranges = {(r.group, r.component): r for r in ranges_from_report(report)}
    # nothing in a postural map sees the reflex: the whole range stays open
    assert ranges[("ef", "dynamic")].score_high == SCORE_HIGH
    assert report["intervals"]["alpha_ef"]["basis"] == "prior"
    assert report["intervals"]["alpha_ef"]["high"] > 1000.0
    basis = FitBasis.from_report(1, 1, True, report)
    cond = Conditions.standard(Arm.from_params(fit.params_))
    g = examine(basis, Arm.from_params(fit.params_), PLAN, cond, ArmCache(), n_samples=40)
    iv = {i.metric: i for i in g.intervals}
    true_before = headline_metrics(Arm.from_params(truth), cond)
    true_after = headline_metrics(Arm.from_params(PLAN.apply(truth)), cond)
    rows = []
    for metric in ("elbow extension reflex torque", "elbow extension peak torque",
                   "pull peak force", "RMS |F| at 0.3 m/s"):
        i = iv[metric]
        tb, ta = true_before[metric][0], true_after[metric][0]
        rows.append((metric, tb, i.before, i.before_low, i.before_high, i.identified))
        assert i.rests_on_guess, metric
        assert i.before_low <= tb <= i.before_high, (metric, tb, i)
        assert i.after_low <= ta <= i.after_high, (metric, ta, i)
        assert i.change_low <= ta - tb <= i.change_high, (metric, ta - tb, i)
    # the postural map cannot tell that arm from one with the same Km and an unimpaired
    # reflex (the reflex is zero at rest): the same intervals hold that truth too
    calm = synthesize({"elbow:passive": "severe"})
    np.testing.assert_allclose(Arm.from_params(calm).endpoint_force(cond.grid_m),
                               Arm.from_params(truth).endpoint_force(cond.grid_m), atol=1e-9)
    calm_before = headline_metrics(Arm.from_params(calm), cond)
    calm_after = headline_metrics(Arm.from_params(PLAN.apply(calm)), cond)
    for metric, (value, _) in calm_before.items():
        i = iv[metric]
        assert i.before_low <= value <= i.before_high, (metric, value, i)
        assert i.after_low <= calm_after[metric][0] <= i.after_high, (metric, i)
    # before the prior draws the interval was the held value's point: the truth outside it
    reflex = iv["elbow extension reflex torque"]
    assert reflex.identified is not None
    khi = reflex.identified[1]
    assert khi < 0.1 < 3.0 < true_before["elbow extension reflex torque"][0]
    assert reflex.before_high > 10 * khi
    # the text says which intervals rest on a guess
    text = "\n".join(summary_lines(g))
    assert "elbow extension reflex torque, N·m*" in text and "drawn from their prior range" \
        in text
    print("\npostural-only fit, severe elbow, 150 U into ef (before the injection):")
    for metric, tb, point, lo, hi, ident in rows:
        print(f"  {metric:<32} truth {tb:6.2f}  point {point:6.2f}  95% [{lo:6.2f}, {hi:6.2f}]"
              f"  maps only [{ident[0]:6.2f}, {ident[1]:6.2f}]")


def test_an_identified_reflex_keeps_its_samples(
        postural_only: tuple[ArmParams, ArmFitter]) -> None:
    """Km of the elbow groups is identified by the postural map: its samples stay the fit's,
    and a plan acting only on it is not widened by the guesses of the reflex."""
    _, fit = postural_only
    report = fit.report()
    names = report["samples"]["names"]
    values = np.asarray(report["samples"]["values"])
    assert "km_ef" not in fit.held_
    basis = FitBasis.from_report(1, 1, True, report)
    drawn = draw(basis.samples, basis.ranges, Prior.for_arm(Arm.from_params(fit.params_)),
                 values.shape[0], seed=0)
    k = names.index("km_ef")
    np.testing.assert_array_equal(drawn.values[:, drawn.names.index("km_ef")], values[:, k])
    assert isinstance(ranges_from_report(report)[0], GuessRange)


def test_a_held_reflex_is_drawn_jointly_and_never_beyond_a_severe_joint() -> None:
    """Every held reflex is drawn with α and β together on the scale's path, from unimpaired
    to the top of severe: never beyond it on the group's own grade, and never adding more
    reflex torque to a joint stretch than the top of severe of the stretch's mono-articular
    group (a bi-articular group's own top of severe added 11 N·m to a fast elbow flexion,
    three times a severe elbow's reflex)."""
    arm = Arm.from_params(BASE)
    prior = Prior.for_arm(arm)
    ranges = tuple(GuessRange(g, "dynamic", (f"alpha_{g}", f"beta_{g}"), score_top=prior.top(
        g, "dynamic")) for g in GROUPS)
    drawn = draw(FitSamples((), np.zeros((1, 0))), ranges, prior, 40, seed=3)
    cap = {}
    for g in ("sf", "se", "ef", "ee"):  # the mono-articular groups at the top of severe
        top = prior.values(g, "dynamic", np.array([SCORE_HIGH]))
        trial = BASE.with_group(g, alpha_n=float(top[f"alpha_{g}"][0]),
                                beta=float(top[f"beta_{g}"][0]))
        for s in standard_stretches(Arm.from_params(trial)):
            cap[s.name] = max(cap.get(s.name, 0.0), s.reflex_torque_n_m)
    reached = dict.fromkeys(GROUPS, 0.0)
    for row in drawn.values:
        for g in GROUPS:
            a = float(row[drawn.names.index(f"alpha_{g}")])
            b = float(row[drawn.names.index(f"beta_{g}")])
            # α and β on the path: β follows from α (0.1 at 100 N, 1 from 1,000 N)
            assert b == pytest.approx(min(1.0, 0.1 * (a / 100.0)), rel=1e-6)
            one = Arm.from_params(BASE.with_group(g, alpha_n=a, beta=b))
            grade = classify(one)[g].dynamic
            assert not grade.beyond_scale
            reached[g] = max(reached[g], grade.score)
            for s in standard_stretches(one):
                assert s.reflex_torque_n_m <= cap[s.name] * 1.001, (g, s.name, a, b)
    assert min(reached[g] for g in ("sf", "se", "ef", "ee")) > 4.0  # severe reached
    assert min(reached.values()) > 2.0  # every group's range reaches past mild


def test_a_body_s_prior_table_is_made_once_and_is_the_table_made_afresh() -> None:
    import fieldbank.fitting.prior as prior_mod

    impaired = synthesize({"ef:dynamic": "severe", "sf:passive": "moderate"}, BASE)
    kept = Prior.for_arm(Arm.from_params(impaired))
    # the table depends on the geometry only: an arm of other muscle values, the same table
    assert Prior.for_arm(Arm.from_params(BASE)) is kept
    assert not kept.path_ratio.flags.writeable and not kept.dynamic_top.flags.writeable
    prior_mod._TABLES.clear()
    fresh = Prior.for_arm(Arm.from_params(BASE))
    assert fresh is not kept
    for name in ("path_s", "path_ratio", "dynamic_top"):
        assert np.array_equal(getattr(fresh, name), getattr(kept, name)), name
    assert fresh.reference.params == kept.reference.params
    # another body: its own table
    other = Prior.for_arm(Arm.from_params(ArmParams.from_anthropometry(95.0, 1.92)))
    assert other is not fresh
    assert not np.array_equal(other.path_ratio, fresh.path_ratio)


def test_the_kept_prior_tables_are_bounded_the_oldest_dropped(
        monkeypatch: pytest.MonkeyPatch) -> None:
    import fieldbank.fitting.prior as prior_mod

    monkeypatch.setattr(prior_mod, "TABLES_KEPT", 2)
    monkeypatch.setattr(prior_mod, "_TABLES", {})
    bodies = [Arm.from_params(ArmParams.from_anthropometry(m, 1.75)) for m in (60., 70., 80.)]
    first = [Prior.for_arm(a) for a in bodies]
    assert len(prior_mod._TABLES) == 2
    assert Prior.for_arm(bodies[2]) is first[2]  # kept
    again = Prior.for_arm(bodies[0])  # dropped as the oldest: made afresh, the same numbers
    assert again is not first[0]
    assert np.array_equal(again.path_ratio, first[0].path_ratio)
