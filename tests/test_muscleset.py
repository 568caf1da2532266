"""One arm is the batch of one (fieldbank/muscleset.py, Arm.field_of): for a family of random
arms - unimpaired, severe reflexes, slack offsets, rest lengths and postures moved, right and
left - each arm compiled alone gives, at positions and velocities across its workspace, the
force, stiffness and damping its row of an ArmBatch gives.
"""

from __future__ import annotations

import numpy as np
import pytest

from fieldbank.armbatch import ArmBatch
from fieldbank.evaluate.severity import synthesize
from fieldbank.model import Arm
from fieldbank.params import ArmParams

RTOL, ATOL = 1e-12, 1e-10


def _family(side: str, rng: np.random.Generator, moved: str, n: int = 14) -> list[ArmParams]:
    """Unimpaired, severe in each joint, then random muscle values (Km, α, β over several
    decades); ``moved`` 'slack' or 'lengths': also slack offsets of ±2 cm, and with 'lengths'
    the rest lengths and the rest posture."""
    base = ArmParams.from_anthropometry(side=side)
    sets = [base, synthesize({"elbow": "severe"}, base),
            synthesize({"shoulder": "severe", "biarticular": "moderate"}, base)]
    for _ in range(n):
        ch: dict[str, object] = {
            "km_n_per_m": tuple(np.asarray(base.km_n_per_m) * np.exp(rng.uniform(-1, 2, 6))),
            "alpha_n": tuple(np.asarray(base.alpha_n) * np.exp(rng.uniform(0, 4, 6))),
            "beta": tuple(rng.uniform(0.0, 1.0, 6))}
        if moved in ("slack", "lengths"):
            ch["slack_offset_m"] = tuple(rng.uniform(-0.02, 0.02, 6))
        if moved == "lengths":
            ch["rest_length_m"] = tuple(np.asarray(base.rest_length_m)
                                        * rng.uniform(0.95, 1.05, 6))
            ch["q_rest_rad"] = tuple(np.asarray(base.q_rest_rad) + rng.uniform(-0.1, 0.1, 2))
        sets.append(base.replace(**ch))
    return sets


def _workspace(arm: Arm, rng: np.random.Generator, n: int = 60) -> np.ndarray:
    """``n`` reachable hand positions spread over the arm's workspace."""
    sign = -1.0 if arm.mirror else 1.0
    gx, gy = np.meshgrid(np.linspace(-0.45, 0.45, 40), np.linspace(-0.1, 0.65, 40))
    grid = np.stack([sign * gx.ravel(), gy.ravel()], axis=1)
    ok = grid[arm.reachable(grid)]
    assert len(ok) > 3 * n
    return ok[rng.choice(len(ok), n, replace=False)]


@pytest.mark.parametrize("side", ["right", "left"])
@pytest.mark.parametrize("moved", ["values", "slack", "lengths"])
def test_each_arm_alone_equals_its_row_of_the_batch(side: str, moved: str) -> None:
    rng = np.random.default_rng([31, len(moved), len(side)])
    sets = _family(side, rng, moved)
    batch = ArmBatch.from_params(sets)
    # Km, α, β alone: the lengths are computed once for every set (the broadcast path)
    assert batch.muscles.same_lengths is (moved == "values")
    x = _workspace(batch.geometry, rng)
    velocities = [None, (0.0, 0.0), tuple(rng.uniform(-1.5, 1.5, 2)),
                  rng.uniform(-1.5, 1.5, (len(x), 2))]
    felt = 0
    for v in velocities:
        fb, kb, bb = batch.field(x, v)
        eb = batch.endpoint_force(x, v)
        assert fb.shape == (len(sets), len(x), 2) and kb.shape == (len(sets), len(x), 2, 2)
        for k, p in enumerate(sets):
            arm = Arm.from_params(p)
            f, stiff, damp = arm.field(x, v)
            np.testing.assert_allclose(f, fb[k], rtol=RTOL, atol=ATOL)
            np.testing.assert_allclose(stiff, kb[k], rtol=RTOL, atol=ATOL)
            np.testing.assert_allclose(damp, bb[k], rtol=RTOL, atol=ATOL)
            np.testing.assert_allclose(arm.endpoint_force(x, v), eb[k], rtol=RTOL, atol=ATOL)
            np.testing.assert_allclose(eb[k], f, rtol=RTOL, atol=ATOL)
            felt += int(np.abs(damp).max() > 1.0)
    # the family is not trivial: forces differ between sets, and reflexes are felt
    assert np.ptp(fb, axis=0).max() > 1.0
    assert felt > len(sets)


def test_the_single_path_is_the_set_of_one() -> None:
    p = synthesize({"elbow": "severe"}).replace(slack_offset_m=(0.0, 0.01, -0.01, 0.0, 0, 0))
    arm = Arm.from_params(p)
    assert len(arm.muscles) == 1
    for name in ("q_rest", "lam_rest", "lam_slack", "lam_min", "lam_max", "excursion", "km",
                 "alpha", "beta"):
        np.testing.assert_array_equal(getattr(arm, name), getattr(arm.muscles, name)[0])
    x = np.array([[0.05, 0.45], [0.2, 0.35]])
    one = arm.field_of(arm.muscles, x, (0.3, -0.2))
    for a, b in zip(arm.field(x, (0.3, -0.2)), one, strict=True):
        np.testing.assert_array_equal(a, b[0])
    moved = arm.with_muscles(p.replace(km_n_per_m=tuple(2 * k for k in p.km_n_per_m)))
    assert moved.muscles.lam_min is arm.muscles.lam_min  # the geometry's lengths are shared
    assert not np.array_equal(moved.field(x, (0.3, -0.2))[0], arm.field(x, (0.3, -0.2))[0])
