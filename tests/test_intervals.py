"""Prediction intervals in one vectorised pass (ArmBatch) against the per-sample reference, and
the intervals kept with a fit (exact round trip, keyed, reused by reports)."""

from __future__ import annotations

import dataclasses
import filecmp
from pathlib import Path

import numpy as np
import pytest

from fieldbank.armbatch import ArmBatch
from fieldbank.errors import ParameterError
from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.batch import probe_forces, rms_forces, standard_stretch_torques
from fieldbank.evaluate.compare import Conditions
from fieldbank.evaluate.probing import profile, stretch_profiles
from fieldbank.evaluate.severity import synthesize
from fieldbank.fitting.uncertainty import FitSamples
from fieldbank.interventions.catalogue import Botulinum, Lengthening, Rhizotomy, Tenotomy
from fieldbank.interventions.guesses import (
    FitBasis,
    IntervalSet,
    interval_key,
    interval_set,
    intervals_of,
)
from fieldbank.interventions.plan import Plan
from fieldbank.interventions.samplemetrics import sample_metrics
from fieldbank.model import Arm
from fieldbank.params import GROUPS, ArmParams
from tests.sample_reference import sample_metrics_per_sample

RTOL = 1e-12


def _samples(before: ArmParams, n: int, seed: int = 0) -> list[ArmParams]:
    """``n`` sets around ``before`` in which every muscle value moves: Km, α, β, slack
    offsets, rest lengths and the rest posture (what a wider prior may one day sample)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        f = np.exp(rng.normal(scale=0.08, size=18))
        out.append(before.replace(
            km_n_per_m=tuple(np.array(before.km_n_per_m) * f[:6]),
            alpha_n=tuple(np.array(before.alpha_n) * f[6:12]),
            beta=tuple(np.minimum(np.array(before.beta) * f[12:], 1.0)),
            slack_offset_m=tuple(rng.uniform(-0.004, 0.008, 6)),
            rest_length_m=tuple(np.array(before.rest_length_m) * (1 + rng.normal(0, 0.01, 6))),
            q_rest_rad=tuple(np.array(before.q_rest_rad) + rng.normal(0, 0.04, 2))))
    return out


@pytest.fixture(params=["right", "left"])
def before(request: pytest.FixtureRequest) -> ArmParams:
    return synthesize({"elbow": "severe", "shoulder": "mild"},
                      ArmParams.from_anthropometry(68.0, 1.71, request.param))


def test_batch_forces_equal_each_arm_compiled_alone(before: ArmParams) -> None:
    sets = _samples(before, 6)
    batch = ArmBatch.from_params(sets)
    cond = Conditions.standard(Arm.from_params(before))
    x, v = cond.points(1)
    f = batch.endpoint_force(x, v)
    rms = rms_forces(batch, cond.grid_m, cond.velocities)[1]
    torques = standard_stretch_torques(batch)
    for k, p in enumerate(sets):
        arm = Arm.from_params(p)
        one = arm.endpoint_force(x, v)
        np.testing.assert_allclose(f[k], one, rtol=RTOL, atol=1e-12)
        assert rms[k] == pytest.approx(float(np.sqrt(np.mean(np.sum(one * one, axis=1)))),
                                       rel=RTOL)
        for m in cond.probes:
            np.testing.assert_allclose(probe_forces(batch, m)[k], profile(arm, m).force_n,
                                       rtol=RTOL, atol=1e-12)
        for t, ((j, d), prof) in zip(torques, stretch_profiles(arm).items(), strict=True):
            assert (t.joint, t.direction) == (j, d)
            np.testing.assert_allclose(t.fast_n_m[k], prof.fast_n_m, rtol=RTOL, atol=1e-12)
            np.testing.assert_allclose(t.slow_n_m[k], prof.slow_n_m, rtol=RTOL, atol=1e-12)
    # the reflex acts: moving forces differ from static ones (the test sees the reflex path)
    assert not np.allclose(f, batch.endpoint_force(x, np.zeros_like(v)))


@pytest.mark.parametrize("plan", [
    Plan.of(Lengthening(group="bf", delta_m=0.01), Botulinum({"ef": 200.0, "ee": 100.0})),
    Plan.of(Rhizotomy()),
    Plan.of(Tenotomy(group="be")),
], ids=["lengthening+botulinum", "rhizotomy", "tenotomy"])
def test_vectorised_pass_equals_the_per_sample_reference(before: ArmParams, plan: Plan) -> None:
    sets = [before, *_samples(before, 12, seed=3)]
    cond = Conditions.standard(Arm.from_params(before))
    fast = sample_metrics(sets, plan, cond, Arm.from_params(before))
    ref = sample_metrics_per_sample(sets, plan, cond)
    assert fast.keys == ref.keys and fast.units == ref.units
    np.testing.assert_allclose(fast.before, ref.before, rtol=RTOL, atol=1e-12)
    np.testing.assert_allclose(fast.after, ref.after, rtol=RTOL, atol=1e-12)
    for when in ("before", "after"):
        for name, stack in ref.curves[when].items():
            np.testing.assert_allclose(fast.curves[when][name], stack, rtol=RTOL, atol=1e-12)
    a, b = intervals_of(fast), intervals_of(ref)
    for x, y in zip(a, b, strict=True):
        assert x.metric == y.metric
        # the eight numbers (before, after and their intervals, the change's interval)
        np.testing.assert_allclose(list(dataclasses.astuple(x)[2:10]),
                                   list(dataclasses.astuple(y)[2:10]), rtol=RTOL, atol=1e-12)
    # the plan changes something: the change intervals are not all zero
    assert any(abs(i.change_high) + abs(i.change_low) > 1e-6 for i in a)


def test_a_set_of_another_geometry_is_refused(before: ArmParams) -> None:
    other = before.replace(moment_arm_elbow_m=(0.0, 0.0, 0.03, 0.025, 0.035, 0.035))
    with pytest.raises(ParameterError, match="set 1 differs from the geometry in "
                                             "moment_arm_elbow_m"):
        ArmBatch.from_params([before, other])


def _basis(before: ArmParams, n: int = 16) -> FitBasis:
    rng = np.random.default_rng(5)
    names = [f"{k}_{g}" for k in ("km", "alpha", "beta") for g in GROUPS]
    centre = np.array([*before.km_n_per_m, *before.alpha_n, *before.beta])
    values = centre * np.exp(rng.normal(scale=0.05, size=(n, centre.size)))
    values[:, 12:] = np.minimum(values[:, 12:], 1.0)
    return FitBasis(7, 3, True, "good", "good", (), (), (), FitSamples(tuple(names), values))


def test_interval_set_round_trips_exactly_and_keys_change_with_inputs(before: ArmParams) -> None:
    plan = Plan.of(Botulinum({"ef": 150.0}))
    basis = _basis(before)
    cond = Conditions.standard(Arm.from_params(before))
    iv = interval_set(basis, Arm.from_params(before), plan, cond, ArmCache(), 16)
    assert iv.n_samples == 16 and iv.intervals and set(iv.bands) == {"before", "after"}
    back = IntervalSet.from_document(*iv.to_document())
    assert back.intervals == iv.intervals and back.note == iv.note
    for when, per in iv.bands.items():
        for name, (lo, hi) in per.items():
            assert np.array_equal(back.bands[when][name][0], lo)
            assert np.array_equal(back.bands[when][name][1], hi)
    key = interval_key(basis, before, plan, 16)
    assert key == interval_key(basis, before, plan, 16)
    assert key != interval_key(basis, before, Plan.of(Botulinum({"ef": 100.0})), 16)
    assert key != interval_key(basis, before, plan, 8)
    assert key != interval_key(dataclasses.replace(basis, fit_id=8), before, plan, 16)
    assert key != interval_key(basis, before.with_group("ef", km_n_per_m=900.0), plan, 16)


def test_a_report_keeps_intervals_with_the_fit_and_reuses_them(tmp_path: Path) -> None:
    """The second report reads every case's intervals from the fits, computes none, and
    writes the same bytes as the first."""
    from fieldbank.interventions.report import Selection, build_report
    from fieldbank.interventions.report.trust import interval_key_of, with_known_intervals
    from fieldbank.storage import Database
    from tests.report_helpers import build_batch

    info = build_batch(tmp_path, patients=("SYN-001",))
    with Database.open(info["url"]) as db:
        first = build_report(db, Selection(), tmp_path / "a", jobs=1)
        from fieldbank.interventions.report.select import select_cases

        cases = select_cases(db, Selection())
        keys = [interval_key_of(c) for c in cases]
        assert any(k is not None for k in keys)
        kept = [db.fit_document(*k) for k in keys if k is not None]
        assert all(d is not None for d in kept)
        known = with_known_intervals(db, cases)
        assert all((c.intervals is not None) == (k is not None)
                   for c, k in zip(known, keys, strict=True))
        second = build_report(db, Selection(), tmp_path / "b", jobs=1)
        # another model version drops the fit's older documents when it stores its own
        fid, key = next(k for k in keys if k is not None)
        assert db.put_fit_document(fid, "x" * 64, 999, {"note": "newer"}) is True
        assert db.fit_document(fid, key) is None
    for f in ("report.html", "metrics.csv", "metrics.json"):
        assert filecmp.cmp(first.out_dir / f, second.out_dir / f, shallow=False), f
    assert "95%" in (tmp_path / "b" / "report.html").read_text(encoding="utf-8")
