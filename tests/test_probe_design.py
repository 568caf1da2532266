"""Designing probing motions: paths, measures, limits, the seed's paradigms, the search."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy import integrate
from scipy.stats import norm

from fieldbank.dynamics import hand_inertial_force
from fieldbank.errors import ParameterError
from fieldbank.evaluate.design import (
    Candidate,
    Circle,
    NoiseModel,
    Perception,
    ProbeLimits,
    Stroke,
    check_candidates,
    check_prior,
    circles,
    design,
    design_report,
    direction_words,
    draw_execution,
    entropy_bits,
    equilibrium,
    executions,
    feasible,
    information_bits,
    pair_error,
    paradigms,
    predict,
    saturate,
    score_probes,
    seed_probes,
    severity_candidates,
)
from fieldbank.evaluate.probing import ProbeMotion, profile, pull
from fieldbank.evaluate.severity import synthesize
from fieldbank.model import Arm
from fieldbank.params import GROUP_INDEX, GROUP_SIGN, JOINT_GROUPS, ArmParams

LEVELS4 = ("very mild", "mild", "moderate", "severe")


@pytest.fixture(scope="module")
def severe3() -> tuple[Candidate, ...]:
    return severity_candidates()


@pytest.fixture(scope="module")
def all12() -> tuple[Candidate, ...]:
    return severity_candidates(levels=LEVELS4)


# --- the severe groups: the designed set against the seed's probes ----------------------------
def test_severe_three_designed_set_has_at_most_two_probes_and_separates_all(severe3) -> None:  # type: ignore[no-untyped-def]
    rep = design_report(severe3)
    d, seed = rep.design, rep.seed
    assert 1 <= len(d.paths) <= 2
    assert d.score.separates_all("feel")
    assert d.score.separates_all("information")
    ds, ss = d.score.summary(), seed.summary()
    # discriminability next to the seed's pull + semi-ellipse, measured the same way
    print(f"\ndesigned {[p.describe() for p in d.paths]}: {ds}\nseed pull + semi-ellipse: {ss}")
    assert ds["worst_felt_jnd"] > ss["worst_felt_jnd"]  # the closest pair is felt further apart
    assert ds["worst_felt_jnd"] >= 1.0 and ss["worst_felt_jnd"] >= 1.0
    doc = rep.to_dict()
    assert doc["seed_probes"]["summary"]["probes"] == 2  # type: ignore[index]
    assert len(doc["probes"]) == len(d.paths)  # type: ignore[arg-type]


def test_group_target_needs_only_groups_apart(all12) -> None:  # type: ignore[no-untyped-def]
    d = design(all12, criterion="information", target="group", max_probes=1)
    pairs = d.score.pairs()
    same = [p for p in pairs if not p["to_tell_apart"]]
    assert len(same) == 3 * 6  # 3 groups, C(4, 2) severity pairs each
    assert all(p["pair"][0].split()[0] == p["pair"][1].split()[0] for p in same)  # type: ignore[index]
    assert d.score.information_max_bits == pytest.approx(math.log2(3))
    assert 0.5 * math.log2(3) < d.score.information_bits <= math.log2(3) + 1e-9


# --- physics against independent derivations ------------------------------------------------
def _only(group_index: tuple[int, int]) -> Candidate:
    """A severe arm in which only one group's muscles act (the others have no force)."""
    p = ArmParams.from_anthropometry()
    km = [0.0] * 6
    alpha = [0.0] * 6
    for i in group_index:
        km[i] = 6000.0
        alpha[i] = 1000.0
    return Candidate("only", Arm.from_params(
        p.replace(km_n_per_m=tuple(km), alpha_n=tuple(alpha), beta=(1.0,) * 6)))


@pytest.mark.parametrize("group, along", [((0, 1), "forearm"), ((2, 3), "shoulder-hand")])
def test_force_direction_of_a_mono_articular_group_follows_the_geometry(group, along) -> None:  # type: ignore[no-untyped-def]
    """A shoulder-only torque τ = (τ1, 0) gives F = J⁻ᵀτ with J[:,1]·F = 0: F lies along the
    forearm; an elbow-only torque (0, τ2) gives J[:,0]·F = 0: F lies along the shoulder-hand
    line. Checked on the predicted force along a stroke, from the segment geometry alone."""
    cand = _only(group)
    arm = cand.arm
    m = Stroke(tuple(arm.rest_position()), -60.0, 0.12, 0.4, 0.3).motion()
    f = predict([cand], m.positions_m, m.velocities_m_per_s, None)[0]
    q = arm.ik(m.positions_m)
    elbow = np.c_[arm.l1 * np.cos(q[:, 0]), arm.l1 * np.sin(q[:, 0])]
    axis = m.positions_m - elbow if along == "forearm" else m.positions_m
    axis = axis / np.linalg.norm(axis, axis=1)[:, None]
    big = np.linalg.norm(f, axis=1) > 0.5
    assert big.sum() > 20
    cross = np.abs(axis[big, 0] * f[big, 1] - axis[big, 1] * f[big, 0])
    assert np.all(cross <= 1e-6 * np.linalg.norm(f[big], axis=1) + 1e-9)


def _issue13_severe(group: str) -> ArmParams:
    """A severe arm on the scale issue 13 was measured on (before severity was graded per
    muscle group and direction): the group's two muscles get the Km that makes the passive
    joint stiffness at rest - the diagonal of J_λᵀ diag(Km/2) J_λ; shoulder K₁₁, elbow K₂₂,
    bi-articular K₁₁ + K₂₂ - ten times the unimpaired arm's (Km 600 N/m everywhere), α = 100 N
    × Km / 600 N/m, β = 1. For the elbow that is Km ≈ 16,600 N/m."""
    p = ArmParams.from_anthropometry()
    idx = [GROUP_INDEX[m] for m in JOINT_GROUPS[group]]
    sign = np.array(GROUP_SIGN)
    jl = np.c_[sign * np.array(p.moment_arm_shoulder_m), sign * np.array(p.moment_arm_elbow_m)]

    def measure(km: np.ndarray) -> float:
        k = jl.T @ np.diag(km / 2.0) @ jl
        return {"shoulder": k[0, 0], "elbow": k[1, 1], "biarticular": k[0, 0] + k[1, 1]}[group]

    km = np.full(6, 600.0)
    off = km.copy()
    off[idx] = 0.0
    unit = off.copy()
    unit[idx] = 1.0
    k = (10.0 * measure(km) - measure(off)) / (measure(unit) - measure(off))  # linear in Km
    km[idx] = k
    alpha = np.full(6, 100.0)
    alpha[idx] = 100.0 * k / 600.0
    beta = np.full(6, 0.1)
    beta[idx] = 1.0
    return p.replace(km_n_per_m=tuple(km), alpha_n=tuple(alpha), beta=tuple(beta))


def _pull_force_from_the_equations(arm: Arm) -> np.ndarray:
    """The force the arm puts on the handle along the seed's pull (15 cm toward the body in
    0.3 s, minimum jerk, from the rest hand position), written out from BRIEF §3 without the
    model's code: two-link kinematics, λ = λ_rest + J_λ(q − q_rest), λ̇ = J_λ q̇, the smoothed
    passive force (eq. 5), the reflex (eqs. 3-4), τ = −J_λᵀ(ψ + φ) and F = J⁻ᵀτ. Only the
    compiled constants λ_min, λ_max, λ̇_max (the seed's 2 Hz circle) come from the arm."""
    p = arm.params
    l1, l2 = p.upper_arm_length_m, p.forearm_length_m
    q1r, q2r = p.q_rest_rad
    start = np.array([l1 * math.cos(q1r) + l2 * math.cos(q1r + q2r),
                      l1 * math.sin(q1r) + l2 * math.sin(q1r + q2r)])
    tau = np.linspace(0.0, 1.0, 61)
    s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
    ds = 30 * tau**2 - 60 * tau**3 + 30 * tau**4
    x = start + 0.15 * s[:, None] * np.array([0.0, -1.0])
    v = (0.15 / 0.3) * ds[:, None] * np.array([0.0, -1.0])
    r2 = (x**2).sum(axis=1)
    q2 = np.arccos((r2 - l1 * l1 - l2 * l2) / (2 * l1 * l2))  # flexed elbow
    q1 = np.arctan2(x[:, 1], x[:, 0]) - np.arctan2(l2 * np.sin(q2), l1 + l2 * np.cos(q2))
    jac = np.empty((len(tau), 2, 2))
    jac[:, 0, 0] = -l1 * np.sin(q1) - l2 * np.sin(q1 + q2)
    jac[:, 0, 1] = -l2 * np.sin(q1 + q2)
    jac[:, 1, 0] = l1 * np.cos(q1) + l2 * np.cos(q1 + q2)
    jac[:, 1, 1] = l2 * np.cos(q1 + q2)
    qdot = np.linalg.solve(jac, v[..., None])[..., 0]
    rs, re = np.array(p.moment_arm_shoulder_m), np.array(p.moment_arm_elbow_m)
    jl = np.array([[-rs[0], 0.0], [rs[1], 0.0], [0.0, -re[2]], [0.0, re[3]],
                   [-rs[4], -re[4]], [rs[5], re[5]]])
    lam_rest = np.array(p.rest_length_m)
    lam = lam_rest + (np.c_[q1, q2] - [q1r, q2r]) @ jl.T
    ldot = qdot @ jl.T
    ell = arm.lam_max - arm.lam_min
    d = lam - lam_rest
    w = p.passive_smoothing_m
    psi = np.array(p.km_n_per_m) * w * np.logaddexp(0.0, d / w) * np.exp(-((d / ell) ** 2))
    u = np.array(p.beta) * np.clip(ldot / arm.ldot_max, 0.0, 1.0)
    gam = (lam - arm.lam_min) / ell - (lam_rest / arm.lam_max) * (1.0 - u)
    phi = np.maximum(0.0, np.array(p.alpha_n) * u * gam * np.exp(-gam * gam))
    torque = -(psi + phi) @ jl
    return np.linalg.solve(np.transpose(jac, (0, 2, 1)), torque[..., None])[..., 0]


def test_issue_measurements_of_the_fast_pull_directions(severe3) -> None:  # type: ignore[no-untyped-def]
    """Issue 13 measured the fast pull's force directions for severe shoulder / elbow /
    bi-articular as ≈ 122° / 80° / 47° (time-averaged force of the kinematic probe, inertia
    left out). Those figures rest on the severity scale of the time (joint stiffness at rest;
    a severe elbow had Km ≈ 16,600 N/m): rebuilt here, it gives them again. On the per-group
    scale (a severe elbow's Km is 6,000 N/m) the directions are those the muscle equations give
    for its arms, written out independently - still spread, each pair ≥ one direction JND
    (25.6°) apart and the shoulder not set apart from the other two. With the arm's inertia the
    early part of the fast pull looks alike for all."""
    old = [math.degrees(profile(a, pull(a)).mean_direction_rad)
           for a in (Arm.from_params(_issue13_severe(g)) for g in JOINT_GROUPS)]
    assert old == pytest.approx([122.0, 80.0, 47.0], abs=1.5)
    # severe passive = 10 × the unimpaired torque; for a change of Km alone that is 10 × 600 N/m
    assert synthesize({"elbow": "severe"}).km_n_per_m[2] == pytest.approx(6000.0, rel=1e-6)
    mean = [math.degrees(profile(c.arm, pull(c.arm)).mean_direction_rad) for c in severe3]
    by_hand = []
    for c in severe3:
        f = _pull_force_from_the_equations(c.arm)
        np.testing.assert_allclose(f, profile(c.arm, pull(c.arm)).force_n, rtol=1e-9,
                                   atol=1e-9)
        m = f.mean(axis=0)
        by_hand.append(math.degrees(math.atan2(m[1], m[0])))
    assert mean == pytest.approx(by_hand, abs=1e-6)
    gaps = [mean[0] - mean[1], mean[1] - mean[2]]
    assert min(gaps) >= 25.6 and max(gaps) <= 2.0 * min(gaps)
    s = score_probes(severe3, [pull(severe3[0].arm)])
    peak = [f.max_direction_deg for f in s.probes[0].features]
    assert abs(peak[0] - peak[2]) < 10.0  # shoulder and bi-articular peak alike, early on


def test_max_and_min_locations_on_a_circle_are_those_of_the_forces(severe3) -> None:  # type: ignore[no-untyped-def]
    motions = circles(equilibrium(severe3), (0.06,))
    res = paradigms(severe3, motions, closed=[True])
    m = motions[0]
    acc = np.gradient(m.velocities_m_per_s, m.times_s, axis=0, edge_order=2)
    for c, feat in zip(severe3, res.score.probes[0].features, strict=True):
        f = c.arm.endpoint_force(m.positions_m, m.velocities_m_per_s) \
            + hand_inertial_force(c.arm, m.positions_m, m.velocities_m_per_s, acc)
        mag = np.linalg.norm(f, axis=1)
        assert feat.max_force_n == pytest.approx(mag.max())
        assert feat.min_force_n == pytest.approx(mag.min())
        k = int(np.argmax(mag))
        assert feat.max_at_m == pytest.approx(tuple(m.positions_m[k]))
        assert feat.max_at_s == pytest.approx(m.times_s[k])
    assert len(res.minmax_set) <= len(severe3) - 1
    assert len(res.orientation_set) <= len(severe3) - 1


def test_paradigm_sets_use_at_most_n_minus_one_paths_and_say_if_they_separate(severe3) -> None:  # type: ignore[no-untyped-def]
    """Each paradigm's set has at most n − 1 paths, and says truly whether some choice of at
    most n − 1 of the given paths separates every pair (checked against every choice).

    On the per-group scale the seed's fixed paths do not separate the three severe groups by
    orientation: the fast pull's peak is the arm's inertia, the same for every arm, and the
    elbow and bi-articular peaks point within a JND of each other under the motion noise on
    the semi-ellipse and the circles. A designed stroke does separate them."""
    motions = seed_probes(severe3) + circles(equilibrium(severe3))
    res = paradigms(severe3, motions, closed=[False, False, True, True, True])
    assert len(res.orientation_set) <= 2 and len(res.minmax_set) <= 2
    d = res.to_dict()
    assert d["minmax_set"]["separates_all"] == res.minmax_complete  # type: ignore[index]
    assert d["orientation_set"]["paths"] == list(res.orientation_set)  # type: ignore[index]
    pairs = np.triu_indices(3, 1)
    for what, chosen, complete in (("orientation", res.orientation_set,
                                    res.orientation_complete),
                                   ("minmax", res.minmax_set, res.minmax_complete)):
        covers = {p.name: p.separations[what][pairs] >= 1.0 for p in res.score.probes}
        assert complete == bool(np.logical_or.reduce([covers[n] for n in chosen]).all()
                                if chosen else False)
        possible = any(np.logical_or.reduce([covers[n] for n in choice]).all()
                       for k in (1, 2) for choice in itertools.combinations(covers, k))
        assert complete == possible, what
    # felt with the arm's inertia the fast pull peaks early, where the inertial force - the
    # same for every arm - is the larger part of each arm's force: its orientation tells no
    # pair apart
    pull_score = res.score.probes[0]
    m = pull_score.motion
    k = [int(np.argmax(np.linalg.norm(f, axis=1))) for f in pull_score.force_n]
    inertia = hand_inertial_force(severe3[0].arm, m.positions_m, m.velocities_m_per_s,
                                  m.accelerations_m_per_s2)
    for c, i in zip(severe3, k, strict=True):
        muscles = c.arm.endpoint_force(m.positions_m[i:i + 1], m.velocities_m_per_s[i:i + 1])[0]
        assert np.linalg.norm(inertia[i]) > np.linalg.norm(muscles)
    assert (pull_score.separations["orientation"][pairs] < 1.0).all()
    oriented = design(severe3, criterion="orientation")
    assert len(oriented.paths) <= 2 and oriented.score.separates_all("orientation")


# --- paths ----------------------------------------------------------------------------------
def test_stroke_geometry_and_velocity() -> None:
    s = Stroke((0.1, 0.5), 30.0, 0.12, 0.4, 0.25)
    m = s.motion(401)
    u = np.array([math.cos(math.radians(30)), math.sin(math.radians(30))])
    n = np.array([-u[1], u[0]])
    assert m.positions_m[0] == pytest.approx([0.1, 0.5])
    assert m.positions_m[-1] == pytest.approx(np.array([0.1, 0.5]) + 0.12 * u)
    lateral = (m.positions_m - [0.1, 0.5]) @ n
    assert lateral.max() == pytest.approx(0.25 * 0.12, rel=1e-4)
    fd = np.gradient(m.positions_m, m.times_s, axis=0)
    assert np.abs(fd[5:-5] - m.velocities_m_per_s[5:-5]).max() < 1e-3
    assert np.abs(m.velocities_m_per_s[[0, -1]]).max() < 1e-12
    straight = Stroke((0.0, 0.5), 0.0, 0.1, 0.5).motion(2001)
    assert straight.peak_speed_m_per_s == pytest.approx(1.875 * 0.1 / 0.5, rel=1e-5)


def test_the_seed_pull_is_a_member_of_the_stroke_family(severe3) -> None:  # type: ignore[no-untyped-def]
    arm = severe3[0].arm
    p = pull(arm)
    s = Stroke(tuple(arm.rest_position()), -90.0, 0.15, 0.3, 0.0).motion(len(p.times_s))
    assert np.abs(s.positions_m - p.positions_m).max() < 1e-12
    assert np.abs(s.velocities_m_per_s - p.velocities_m_per_s).max() < 1e-12


def test_circle_goes_round_its_centre_once() -> None:
    m = Circle((0.1, 0.5), 0.05, 2.0, -1.0).motion(201)
    r = np.linalg.norm(m.positions_m - [0.1, 0.5], axis=1)
    assert r == pytest.approx(np.full(201, 0.05))
    assert m.positions_m[0] == pytest.approx([0.1, 0.45])
    assert m.positions_m[-1] == pytest.approx([0.1, 0.45])
    ang = np.unwrap(np.arctan2(*(m.positions_m - [0.1, 0.5]).T[::-1]))
    assert ang[-1] - ang[0] == pytest.approx(-2 * math.pi)  # clockwise


def test_executions_rotate_scale_and_speed_up_about_the_start() -> None:
    m = Stroke((0.1, 0.5), 0.0, 0.1, 0.5).motion()
    ex = executions(m, NoiseModel(direction_sd_deg=10, length_sd=0.2, speed_sd=0.25))
    assert len(ex) == 7
    assert all(e.positions_m[0] == pytest.approx([0.1, 0.5]) for e in ex)
    end = [e.positions_m[-1] - [0.1, 0.5] for e in ex]
    assert math.degrees(math.atan2(end[1][1], end[1][0])) == pytest.approx(10.0)
    assert math.degrees(math.atan2(end[2][1], end[2][0])) == pytest.approx(-10.0)
    assert np.linalg.norm(end[3]) == pytest.approx(0.12)
    assert ex[5].times_s[-1] == pytest.approx(0.5 / 1.25)
    assert ex[5].peak_speed_m_per_s == pytest.approx(1.25 * m.peak_speed_m_per_s)
    assert len(executions(m, NoiseModel(direction_sd_deg=0, length_sd=0, speed_sd=0))) == 1
    one = draw_execution(m, NoiseModel(), np.random.default_rng(3))
    assert one.positions_m[0] == pytest.approx([0.1, 0.5])
    assert "executed" in one.description


def test_direction_words_for_both_sides() -> None:
    assert direction_words(-90) == "toward the body"
    assert direction_words(90) == "away from the body"
    assert direction_words(0) == "outward"
    assert direction_words(0, "left") == "inward"
    assert direction_words(-135) == "toward the body and inward"


# --- measures against independent computations ------------------------------------------------
def _mutual_information_two_gaussians(mu: float) -> float:
    """I(C; Y) in bits for Y ~ N(0, 1) or N(mu, 1) with equal priors, by quadrature."""
    def mix(y: float) -> float:
        return 0.5 * (norm.pdf(y) + norm.pdf(y - mu))

    h_mix, _ = integrate.quad(lambda y: -mix(y) * math.log2(max(mix(y), 1e-300)), -15, mu + 15)
    return h_mix - 0.5 * math.log2(2 * math.pi * math.e)


@pytest.mark.parametrize("mu", [0.3, 1.0, 2.0, 4.0])
def test_information_bound_brackets_the_true_mutual_information(mu: float) -> None:
    kl = mu * mu / 2.0
    d = np.array([[0.0, kl], [kl, 0.0]])
    prior = np.array([0.5, 0.5])
    true = _mutual_information_two_gaussians(mu)
    lower = float(information_bits(d, prior))
    upper = float(information_bits(4.0 * d, prior))  # the same estimate with D_KL itself
    assert lower <= true + 1e-6 <= upper + 2e-6
    assert pair_error(np.array(kl)) == pytest.approx(norm.cdf(-mu / 2.0))


def test_group_information_is_zero_without_and_full_with_separation() -> None:
    prior = np.full(4, 0.25)
    labels = ["a", "a", "b", "b"]
    assert float(information_bits(np.zeros((4, 4)), prior, labels)) == pytest.approx(0.0)
    far = np.full((4, 4), 1e4) - np.diag(np.full(4, 1e4))
    assert float(information_bits(far, prior, labels)) == pytest.approx(1.0)
    assert float(information_bits(far, prior)) == pytest.approx(2.0)
    assert entropy_bits(prior, labels) == pytest.approx(1.0)
    assert entropy_bits(np.array([0.5, 0.25, 0.25])) == pytest.approx(1.5)


def test_felt_separation_in_jnds_of_a_magnitude_step(severe3) -> None:  # type: ignore[no-untyped-def]
    """Two arms whose forces differ by a factor r everywhere are ln r / ln(1 + JND) apart.

    The felt force is the muscles' plus the arm's inertia. Scaling Km and α by r scales the
    muscles' force exactly (ψ is linear in Km, φ in α); scaling the segment masses and moments
    of inertia by r scales the inertial force −J⁻ᵀ(H q̈ + C q̇) too, so the whole force is r
    times the other arm's at every moment, in the same direction: the separation is
    ln 1.5 / ln 1.1 = 4.254 JND exactly (the 1 N floor only lowers it where both are small).
    Scaling the muscles alone is not enough: the inertia, the same for both arms, bends the
    ratio and the direction wherever it is not negligible - on the per-group scale a severe
    elbow pulls ≈ 4 N at the end of this slow 5 cm stroke against up to ≈ 0.6 N of inertia."""
    a = severe3[1]
    p = a.arm.params
    b = Candidate("stiffer", a.arm.from_params(p.replace(
        km_n_per_m=tuple(1.5 * k for k in p.km_n_per_m),
        alpha_n=tuple(1.5 * v for v in p.alpha_n),
        upper_arm_mass_kg=1.5 * p.upper_arm_mass_kg, forearm_mass_kg=1.5 * p.forearm_mass_kg,
        upper_arm_inertia_kg_m2=1.5 * p.upper_arm_inertia_kg_m2,
        forearm_inertia_kg_m2=1.5 * p.forearm_inertia_kg_m2)))
    m = Stroke(tuple(a.arm.rest_position()), -90.0, 0.05, 1.0).motion()
    quiet = NoiseModel(direction_sd_deg=0, length_sd=0, speed_sd=0)
    s = score_probes([a, b], [m], noise=quiet, limits=ProbeLimits(force_limit_n=1e6))
    assert s.matrix("feel")[0, 1] == pytest.approx(math.log(1.5) / math.log(1.1), rel=1e-9)


def test_saturation_and_prediction_shapes(severe3) -> None:  # type: ignore[no-untyped-def]
    f = np.array([[30.0, 40.0], [3.0, 4.0]])
    assert saturate(f, 10.0) == pytest.approx(np.array([[6.0, 8.0], [3.0, 4.0]]))
    pos = np.tile(equilibrium(severe3), (2, 5, 1))
    out = predict(severe3, pos, np.zeros_like(pos), 40.0)
    assert out.shape == (3, 2, 5, 2)


# --- limits -------------------------------------------------------------------------------
def test_designed_probes_respect_every_limit(severe3) -> None:  # type: ignore[no-untyped-def]
    """Every execution within the operator's ±1 SD, not only the nominal one, keeps the speed
    limit, the workspace box and the range of motion - at every point of the drawn polyline
    and, within a micrometre, on the path between them (the search checks four points per
    segment of the polyline; a bulged stroke can overshoot its chord between those by about
    h²|p''|/8 ≈ 1 µm)."""
    eq = equilibrium(severe3)
    box = (eq[0] - 0.08, eq[0] + 0.08, eq[1] - 0.12, eq[1] + 0.05)
    lim = ProbeLimits(max_speed_m_per_s=0.6, workspace_m=box, rom_margin_deg=15.0)
    d = design(severe3, limits=lim)
    noise = NoiseModel()
    for path, drawn in zip(d.paths, d.motions, strict=True):
        for m, tol in ((drawn, 0.0), (path.motion(2001), 2e-6)):
            ex = executions(m, noise)
            assert all(e.peak_speed_m_per_s <= 0.6 * (1 + 1e-4) for e in ex)
            pts = np.vstack([e.positions_m for e in ex])
            assert np.all((pts[:, 0] >= box[0] - tol) & (pts[:, 0] <= box[1] + tol)
                          & (pts[:, 1] >= box[2] - tol) & (pts[:, 1] <= box[3] + tol))
            for c in severe3:
                q = np.degrees(c.arm.ik(pts))
                assert q[:, 0].min() >= -20.0 + 15.0 - 1e-3 and q[:, 0].max() <= 130.0 - 15.0 + 1e-3
                assert q[:, 1].min() >= 15.0 - 1e-3 and q[:, 1].max() <= 150.0 - 15.0 + 1e-3
    mask = feasible(severe3, np.array([d.motions[0].positions_m]),
                    np.array([d.motions[0].velocities_m_per_s]), lim)
    assert mask.tolist() == [True]


def test_no_feasible_path_is_a_clear_error(severe3) -> None:  # type: ignore[no-untyped-def]
    eq = equilibrium(severe3)
    tiny = ProbeLimits(workspace_m=(eq[0] - 0.005, eq[0] + 0.005, eq[1] - 0.005, eq[1] + 0.005))
    with pytest.raises(ParameterError, match="No stroke within the limits"):
        design(severe3, limits=tiny)


def test_configuration_bounds_are_checked() -> None:
    with pytest.raises(ParameterError, match="'force_jnd' perception parameter"):
        Perception(force_jnd=0.0)
    with pytest.raises(ParameterError, match="'force_sd_n' noise parameter"):
        NoiseModel(force_sd_n=-1.0)
    with pytest.raises(ParameterError, match="min_length_m < max_length_m"):
        ProbeLimits(min_length_m=0.3, max_length_m=0.2)
    with pytest.raises(ParameterError, match="workspace_m"):
        ProbeLimits(workspace_m=(0.5, 0.1, 0.0, 1.0))
    assert Perception.free_exploration().force_jnd == 0.6


def test_candidates_and_priors_are_checked(severe3) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ParameterError, match="at least 2 candidate"):
        check_candidates(severe3[:1])
    with pytest.raises(ParameterError, match="repeated: shoulder severe"):
        check_candidates([severe3[0], severe3[0]])
    with pytest.raises(ParameterError, match="The prior must be 3"):
        check_prior([1.0, -1.0, 1.0], 3)
    assert check_prior([2.0, 1.0, 1.0], 3) == pytest.approx([0.5, 0.25, 0.25])
    with pytest.raises(ParameterError, match="criterion"):
        design(severe3, criterion="loudness")
    with pytest.raises(ParameterError, match="same group"):
        design(severity_candidates(("elbow",), ("mild", "severe")), target="group")


# --- the search --------------------------------------------------------------------------------
def test_the_search_is_deterministic_and_beats_its_own_grid(severe3) -> None:  # type: ignore[no-untyped-def]
    a = design(severe3, criterion="information", max_probes=1)
    b = design(severe3, criterion="information", max_probes=1)
    assert a.paths == b.paths
    grid_only = design(severe3, criterion="information", max_probes=1, polish_evals=0)
    assert a.score.score("information") >= grid_only.score.score("information") - 1e-9


def test_a_prior_moves_the_design_toward_the_likely_candidates(all12) -> None:  # type: ignore[no-untyped-def]
    """A prior that makes two candidates likely moves the design to the stroke that tells
    those two apart: under that prior it carries more information than the stroke designed
    for a flat prior, and the likely pair's Bayes error is small."""
    prior = np.full(12, 1e-3)
    names = [c.name for c in all12]
    for n in ("elbow very mild", "biarticular very mild"):
        prior[names.index(n)] = 1.0
    d = design(all12, criterion="information", max_probes=1, prior=prior)
    flat = design(all12, criterion="information", max_probes=1)
    assert d.paths != flat.paths
    flat_under_prior = score_probes(all12, flat.motions, prior=prior)
    assert d.score.information_bits > flat_under_prior.information_bits
    i, j = names.index("elbow very mild"), names.index("biarticular very mild")
    assert pair_error(d.score.matrix("kl")[i, j]) <= 0.05


def test_a_left_arm_feels_the_mirror_image_of_a_right_arm(severe3) -> None:  # type: ignore[no-untyped-def]
    left = severity_candidates(base=ArmParams.from_anthropometry(side="left"))
    assert equilibrium(left)[0] == pytest.approx(-equilibrium(severe3)[0])
    right_design = design(severe3, max_probes=1)
    flip = np.array([-1.0, 1.0])
    mirrored = [ProbeMotion(m.name, m.times_s, m.positions_m * flip,
                            m.velocities_m_per_s * flip, m.description)
                for m in right_design.motions]
    s = score_probes(left, mirrored)
    assert s.matrix("feel") == pytest.approx(right_design.score.matrix("feel"))
    assert s.matrix("kl") == pytest.approx(right_design.score.matrix("kl"))
    fr = right_design.score.probes[0].features[0].max_direction_deg
    fl = s.probes[0].features[0].max_direction_deg
    assert ((fl + fr) % 360.0) == pytest.approx(180.0)  # θ ↦ 180° − θ


def test_minmax_design_on_circles() -> None:
    c = design(severity_candidates(), criterion="minmax", family="circle", max_probes=1)
    assert isinstance(c.paths[0], Circle)
    assert c.score.probes[0].closed
