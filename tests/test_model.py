"""Kinematics, muscle forces and fields of the arm model, checked by finite differences,
independent formulas and property tests."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fieldbank.errors import UnreachableError
from fieldbank.maps import ellipse, evaluate, workspace_grid
from fieldbank.model import Arm
from fieldbank.params import ArmParams

ARM = Arm.from_params(ArmParams.from_anthropometry())


def _fd(fun, x, h):
    """Central-difference Jacobian of fun: (N,2) -> (N,m) with respect to each column of x."""
    cols = []
    for i in range(2):
        e = np.zeros(2)
        e[i] = h
        cols.append((fun(x + e) - fun(x - e)) / (2 * h))
    return np.stack(cols, axis=-1)


def test_fk_matches_trigonometry_and_ik_round_trips():
    q = np.array([[math.radians(45), math.radians(90)], [0.1, 0.3], [1.9, 2.4]])
    x = ARM.fk(q)
    l1, l2 = ARM.l1, ARM.l2
    expected = np.array([[l1 * math.cos(a) + l2 * math.cos(a + b),
                          l1 * math.sin(a) + l2 * math.sin(a + b)] for a, b in q])
    np.testing.assert_allclose(x, expected, atol=1e-15)
    np.testing.assert_allclose(ARM.ik(x), q, atol=1e-12)
    qe = ARM.ik(x, branch="extended")
    assert np.all(qe[:, 1] < 0)
    np.testing.assert_allclose(ARM.fk(qe), x, atol=1e-12)


def test_jacobian_matches_finite_differences():
    q = np.random.default_rng(1).uniform([-0.3, 0.1], [2.2, 2.5], (30, 2))
    fd = _fd(ARM.fk, q, 1e-7)
    np.testing.assert_allclose(ARM.jacobian(q), fd, atol=1e-7)


def test_unreachable_position_is_a_clear_error():
    pattern = r"\(1\.0000, 0\.0000\) m .* reaches 0\.0\d+-0\.6\d+ m"
    with pytest.raises(UnreachableError, match=pattern):
        ARM.endpoint_force([[1.0, 0.0]])
    with pytest.raises(UnreachableError, match="outside this arm's range of motion"):
        ARM.ik([[0.0, -0.4]], check_range=True)


def test_default_joint_stiffness_matches_brief():
    # BRIEF §3: default Km 600 N/m gives elbow ≈ 1.1 and shoulder ≈ 1.4 N·m/rad; the one-sided
    # value is ρ²·Km summed over the stretched muscles crossing the joint.
    q0 = ARM.q_rest
    h = 1e-3
    def torque(dq):
        return ARM.joint_torque(q0 + dq)[0]
    k_elbow = -(torque([0, h]) - torque([0, -h]))[1] / (2 * h)
    k_shoulder = -(torque([h, 0]) - torque([-h, 0]))[0] / (2 * h)
    assert k_elbow == pytest.approx(600 * (0.025**2 + 0.035**2), rel=0.02)
    assert k_shoulder == pytest.approx(600 * (0.040**2 + 0.028**2), rel=0.02)
    assert 0.4 <= k_elbow <= 1.8  # Wiegner & Watts 1986 unimpaired range


def _impaired() -> Arm:
    p = ArmParams.from_anthropometry(
        km_n_per_m=(2500.0, 2500.0, 9000.0, 9000.0, 1500.0, 1500.0),
        alpha_n=(800.0, 600.0, 3000.0, 2500.0, 900.0, 700.0),
        beta=(0.9, 0.7, 1.0, 0.8, 0.6, 0.9),
    )
    return Arm.from_params(p)


@pytest.mark.parametrize("velocity", [(0.0, 0.0), (0.0, -0.8), (0.6, 0.4), (-1.5, 0.9)])
def test_stiffness_and_damping_match_finite_differences(velocity):
    arm = _impaired()
    x = workspace_grid(arm, 9)
    v = np.array(velocity)
    _f, k, b = arm.field(x, v)
    fd_k = -_fd(lambda xx: arm.endpoint_force(xx, v), x, 1e-7)
    fd_b = -np.stack([(arm.endpoint_force(x, v + e) - arm.endpoint_force(x, v - e)) / 2e-7
                      for e in (np.array([1e-7, 0]), np.array([0, 1e-7]))], axis=-1)
    scale = np.abs(k).max()
    np.testing.assert_allclose(k, fd_k, atol=2e-5 * scale)
    if np.abs(b).max() > 0:
        np.testing.assert_allclose(b, fd_b, atol=2e-5 * np.abs(b).max())
    if velocity != (0.0, 0.0):
        assert np.abs(b).max() > 1.0  # the reflex is active and the check meant something


def test_passive_field_is_the_negative_gradient_of_the_potential():
    arm = _impaired()
    x = workspace_grid(arm, 10)
    grad = _fd(lambda xx: arm.potential(xx)[:, None], x, 1e-6)[:, 0, :]
    f = arm.endpoint_force(x)
    np.testing.assert_allclose(-grad, f, atol=1e-6 * np.abs(f).max() + 1e-7)


def test_potential_matches_independent_quadrature():
    from scipy.integrate import quad

    arm = _impaired()
    x = np.array([[0.0, 0.45], [0.2, 0.3]])
    lam = arm.muscle_lengths(arm.ik(x))
    w = arm.w
    expected = []
    for row in lam:
        total = 0.0
        for i in range(6):
            ell = arm.excursion[i]
            d = row[i] - arm.lam_rest[i]
            def psi(s, ell=ell, i=i):
                return arm.km[i] * w * np.logaddexp(0, s / w) * math.exp(-((s / ell) ** 2))
            total += quad(psi, -60 * w, d, points=[0.0] if d > 0 else None, limit=200,
                          epsabs=1e-13)[0]
        expected.append(total)
    np.testing.assert_allclose(arm.potential(x), expected, rtol=1e-8)


def test_passive_stiffness_is_symmetric_and_positive_at_rest():
    arm = _impaired()
    x = workspace_grid(arm, 12)
    _, k, _ = arm.field(x)
    asym = np.abs(k - np.transpose(k, (0, 2, 1))).max()
    assert asym < 1e-9 * np.abs(k).max()
    e = ellipse(arm.field(arm.rest_position()[None])[1])
    assert e.minor_n_per_m[0] > 0


def test_reflex_is_zero_at_rest_and_grows_with_stretch_speed():
    arm = _impaired()
    x = arm.rest_position()[None] + np.array([[0.0, -0.05]])
    static = arm.endpoint_force(x)
    # eq. 3: Γ < 0 until the stretch is fast enough, so a slow pull feels only the passive field
    slow = arm.endpoint_force(x, [0.0, -0.05])
    np.testing.assert_array_equal(slow, static)
    fast = arm.endpoint_force(x, [0.0, -1.5])
    faster = arm.endpoint_force(x, [0.0, -2.0])
    assert np.linalg.norm(faster - static) > np.linalg.norm(fast - static) > 1.0


# --- property tests ---------------------------------------------------------------------------
km_st = st.floats(50.0, 20000.0)
pair_params = st.tuples(km_st, km_st, km_st, st.floats(0.0, 1.0), st.floats(0.0, 5000.0))


@st.composite
def arms(draw):
    ks, ke, kb, beta, alpha = draw(pair_params)
    mass = draw(st.floats(30.0, 120.0))
    height = draw(st.floats(1.3, 2.0))
    side = draw(st.sampled_from(["right", "left"]))
    p = ArmParams.from_anthropometry(
        mass, height, side,
        km_n_per_m=(ks, ks, ke, ke, kb, kb), alpha_n=(alpha,) * 6, beta=(beta,) * 6,
    )
    return Arm.from_params(p)


@given(arm=arms(), dq=st.tuples(st.floats(-0.8, 0.8), st.floats(-0.8, 0.8)))
def test_property_passive_torque_restores_toward_rest(arm, dq):
    q = arm.q_rest + np.array(dq)
    lo = np.array([arm.params.shoulder_range_rad[0], arm.params.elbow_range_rad[0]])
    hi = np.array([arm.params.shoulder_range_rad[1], arm.params.elbow_range_rad[1]])
    q = np.clip(q, lo, hi)
    dqv = q - arm.q_rest
    if np.linalg.norm(dqv) < 1e-3:
        return
    tau = arm.joint_torque(q)[0]
    assert float(tau @ (-dqv)) > 0.0


@given(arm=arms(), ang=st.floats(0, 2 * math.pi), r=st.floats(0.005, 0.04))
def test_property_endpoint_field_points_toward_rest_nearby(arm, ang, r):
    x0 = arm.rest_position()
    x = x0 + r * np.array([math.cos(ang), math.sin(ang)])
    f = arm.endpoint_force(x[None])[0]
    assert float(f @ (x0 - x)) > 0.0


@given(arm=arms(), ang=st.floats(0, 2 * math.pi), r=st.floats(0.0, 0.12),
       vang=st.floats(0, 2 * math.pi), speed=st.floats(0, 1.5))
def test_property_field_is_finite_and_mirror_consistent(arm, ang, r, vang, speed):
    x = arm.rest_position() + r * np.array([math.cos(ang), math.sin(ang)])
    v = speed * np.array([math.cos(vang), math.sin(vang)])
    if not arm.reachable(x[None])[0]:
        return
    f, k, b = arm.field(x[None], v)
    assert np.all(np.isfinite(f)) and np.all(np.isfinite(k)) and np.all(np.isfinite(b))
    # the mirrored arm gives the mirrored field
    other = Arm.from_params(arm.params.replace(
        side="left" if arm.params.side == "right" else "right"))
    m = np.array([-1.0, 1.0])
    f2, k2, _ = other.field((x * m)[None], v * m)
    np.testing.assert_allclose(f2[0], f[0] * m, atol=1e-9)
    np.testing.assert_allclose(k2[0], k[0] * np.outer(m, m), atol=1e-7)


def test_evaluate_returns_consistent_shapes():
    x = workspace_grid(ARM, 6)
    mm = evaluate(ARM, x, (0.1, 0.0))
    assert mm.force_n.shape == (len(x), 2)
    assert mm.stiffness_n_per_m.shape == (len(x), 2, 2)
    assert mm.potential_j is not None and mm.potential_j.shape == (len(x),)
    assert np.all(mm.potential_j >= 0)
