"""Severity per muscle group and direction (BRIEF §5): the scale, its synthesis and its read-outs,
against a hand derivation from the model equations and the published magnitudes of BRIEF §3/§5."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from fieldbank.errors import ParameterError
from fieldbank.evaluate.probing import joint_stretch, stretch_profile
from fieldbank.evaluate.severity import (
    COMPONENTS,
    LEVEL_RATIO,
    LEVELS,
    SeverityScale,
    classify,
    expand_target,
    parse_severity_options,
    summary,
    synthesize,
    target_name,
)
from fieldbank.model import Arm
from fieldbank.params import GROUP_INDEX, GROUPS, JOINT_GROUPS, ArmParams

IMPAIRED = LEVELS[1:]
BASE = ArmParams.from_anthropometry()


def _grades(p: ArmParams, unidentified: tuple[str, ...] = ()):
    return classify(Arm.from_params(p), unidentified)


def test_levels_are_spaced_by_the_weber_fraction():
    ratios = [LEVEL_RATIO[lvl] for lvl in IMPAIRED]
    assert ratios[-1] == pytest.approx(10.0)
    for lower, upper in itertools.pairwise(ratios):
        assert upper / lower == pytest.approx(1.6)
    scale = SeverityScale(dynamic_upper_ratio=6.0)
    assert scale.level_ratio("severe", "dynamic") == 6.0
    assert scale.level_ratio("severe", "passive") == 10.0
    with pytest.raises(ParameterError, match="dynamic_upper_ratio"):
        SeverityScale(dynamic_upper_ratio=3.0)


@pytest.mark.parametrize("group", GROUPS)
@pytest.mark.parametrize("component", COMPONENTS)
def test_each_group_and_component_synthesizes_and_classifies_back(group, component):
    other = "dynamic" if component == "passive" else "passive"
    for level in IMPAIRED:
        p = synthesize({f"{group}:{component}": level})
        sev = _grades(p)
        assert sev[group].component(component).level == level
        assert sev[group].component(component).score == pytest.approx(
            IMPAIRED.index(level) + 1.0, abs=1e-6)
        assert sev[group].component(other).level == "unimpaired"
        for g in GROUPS:
            if g != group:
                assert sev[g].passive.level == sev[g].dynamic.level == "unimpaired"
        # only the group's own parameters of that component changed
        i = GROUP_INDEX[group]
        fields = ("km_n_per_m",) if component == "passive" else ("alpha_n", "beta")
        for name in ("km_n_per_m", "alpha_n", "beta"):
            changed = [k for k, (a, b) in enumerate(zip(getattr(BASE, name), getattr(p, name),
                                                        strict=True)) if a != b]
            assert changed == ([i] if name in fields else []), (name, changed)


def test_joint_group_target_keeps_its_old_meaning():
    both = synthesize({"elbow": "severe"})
    assert both == synthesize({"ef": "severe", "elbow-extensors": "severe"})
    sev = _grades(both)
    for g in ("ef", "ee"):
        assert sev[g].passive.level == sev[g].dynamic.level == "severe"
    for g in ("sf", "se", "bf", "be"):
        assert sev[g].passive.level == sev[g].dynamic.level == "unimpaired"
    # a narrower, later target refines a broader one
    p = synthesize({"elbow": "severe", "ef:dynamic": "mild"})
    sev = _grades(p)
    assert sev["ef"].dynamic.level == "mild" and sev["ef"].passive.level == "severe"
    assert sev["ee"].dynamic.level == "severe"


def test_reflex_only_keeps_km_and_passive_only_keeps_the_reflex():
    reflex = synthesize({"elbow-flexors:dynamic": "severe"})
    assert reflex.km_n_per_m == BASE.km_n_per_m
    i = GROUP_INDEX["ef"]
    assert reflex.alpha_n[i] > 10 * BASE.alpha_n[i] and reflex.beta[i] == 1.0
    passive = synthesize({"ef:passive": "severe"})
    assert passive.alpha_n == BASE.alpha_n and passive.beta == BASE.beta
    # the seed's scale for Km alone: the passive ratio is the Km ratio
    assert passive.km_n_per_m[i] == pytest.approx(10.0 * BASE.km_n_per_m[i])


def test_six_fold_elbow_flexor_km_is_graded_on_the_flexors():
    i = GROUP_INDEX["ef"]
    km = list(BASE.km_n_per_m)
    km[i] *= 6.0
    sev = _grades(BASE.replace(km_n_per_m=tuple(km)))
    ef = sev["ef"].passive
    assert ef.ratio == pytest.approx(6.0, rel=1e-9)
    assert ef.level == "moderate"  # 6.25 × unimpaired; mild is 3.9 ×
    assert ef.score == pytest.approx(3.0 + math.log(6.0 / 6.25) / math.log(1.6))
    assert sev["ee"].passive.level == "unimpaired"  # the extensors are not averaged in
    assert all(s.dynamic.level == "unimpaired" for s in sev.values())
    assert summary(sev) == "ef passive moderate"


def test_beyond_scale_and_unidentified_are_flagged():
    i = GROUP_INDEX["ef"]
    km = list(BASE.km_n_per_m)
    km[i] = 100.0 * km[i]
    sev = _grades(BASE.replace(km_n_per_m=tuple(km)), ("alpha_ef", "km_se", "beta_sf"))
    assert sev["ef"].passive.level == "severe" and sev["ef"].passive.beyond_scale
    assert sev["ef"].passive.score > 4.0
    assert sev["ef"].dynamic.unidentified == ("alpha_ef",)
    assert sev["ef"].passive.unidentified == ()
    assert sev["se"].passive.unidentified == ("km_se",)
    assert sev["sf"].dynamic.unidentified == ("beta_sf",)
    assert sev["ef"].passive.text() == "severe+"
    assert sev["ef"].dynamic.text() == "unimpaired*"
    doc = sev["ef"].to_dict()
    assert doc["dynamic"]["unidentified"] == ["alpha_ef"]  # type: ignore[index]
    assert "ef dynamic unimpaired*" in summary(sev)


def test_targets_and_their_errors():
    assert target_name("Elbow-Flexors:reflex") == "ef:dynamic"
    assert target_name("bi-articular extensors:contracture") == "be:passive"
    assert target_name("shoulder_flexors") == "sf"
    assert target_name("bi-articular") == "biarticular"
    assert expand_target("elbow:dynamic") == [("ef", "dynamic"), ("ee", "dynamic")]
    assert expand_target("sf") == [("sf", "passive"), ("sf", "dynamic")]
    assert parse_severity_options(["elbow=severe", "bi-articular=very-mild"]) == {
        "elbow": "severe", "biarticular": "very mild"}
    assert parse_severity_options(["elbow-flexors:dynamic=severe, ee:passive=mild"]) == {
        "ef:dynamic": "severe", "ee:passive": "mild"}
    with pytest.raises(ParameterError, match="Unknown joint group 'knee'"):
        parse_severity_options(["knee=severe"])
    with pytest.raises(ParameterError, match="Unknown muscle group 'knee-flexors'"):
        parse_severity_options(["knee-flexors=severe"])
    with pytest.raises(ParameterError, match="Unknown severity component 'fast'"):
        parse_severity_options(["elbow:fast=severe"])
    with pytest.raises(ParameterError, match="TARGET"):
        parse_severity_options(["elbow"])
    with pytest.raises(ParameterError, match="Unknown severity level 'awful'"):
        synthesize({"ef:dynamic": "awful"})


# --- against a hand derivation from the model equations ---------------------------------------
def _ldot_max_by_hand(p: ArmParams) -> np.ndarray:
    """λ̇_max (seed eq. 4): largest |λ̇| with the hand on a 35 cm circle at 2 Hz, by finite
    differences of the law-of-cosines inverse kinematics (not the model's analytic Jacobian)."""
    l1, l2 = p.upper_arm_length_m, p.forearm_length_m
    c1, c2 = p.circle_centre_rad
    centre = np.array([l1 * math.cos(c1) + l2 * math.cos(c1 + c2),
                       l1 * math.sin(c1) + l2 * math.sin(c1 + c2)])
    dt = 1e-6
    t = np.linspace(0.0, 0.5, 20001)[:-1]
    out = np.zeros(6)
    rho = np.array([[-a if k % 2 == 0 else a, -b if k % 2 == 0 else b] for k, (a, b) in
                    enumerate(zip(p.moment_arm_shoulder_m, p.moment_arm_elbow_m, strict=True))])

    def ik(tt: np.ndarray) -> np.ndarray:
        th = 2 * math.pi * p.circle_frequency_hz * tt
        x = centre[0] + 0.5 * p.circle_diameter_m * np.cos(th)
        y = centre[1] + 0.5 * p.circle_diameter_m * np.sin(th)
        q2 = np.arccos((x * x + y * y - l1 * l1 - l2 * l2) / (2 * l1 * l2))
        q1 = np.arctan2(y, x) - np.arctan2(l2 * np.sin(q2), l1 + l2 * np.cos(q2))
        return np.stack([q1, q2], axis=1)

    qdot = (ik(t + dt) - ik(t - dt)) / (2 * dt)
    out = np.abs(qdot @ rho.T).max(axis=0)
    return out


def _elbow_extension_by_hand(p: ArmParams, q2: float, speed_rad_s: float) -> dict[str, float]:
    """Torque (N·m) each elbow-crossing group puts against an elbow extension at ``q2`` and
    ``speed_rad_s``, shoulder at rest: seed eqs. 2-5 written out for one posture."""
    ldot_max = _ldot_max_by_hand(p)
    out = {}
    for g in ("ef", "ee", "bf", "be"):
        i = GROUP_INDEX[g]
        flexor = i % 2 == 0
        rho_e = p.moment_arm_elbow_m[i]
        rho_s = p.moment_arm_shoulder_m[i]
        # λ = λ_rest + J_λ (q - q_rest); a flexor lengthens as the elbow extends
        lever = rho_e if flexor else -rho_e  # dλ per radian of extension
        lam = p.rest_length_m[i] + lever * (p.q_rest_rad[1] - q2)
        # excursion over the range of motion: both joints' spans times the moment arms
        span_s = p.shoulder_range_rad[1] - p.shoulder_range_rad[0]
        span_e = p.elbow_range_rad[1] - p.elbow_range_rad[0]
        ell = rho_s * span_s + rho_e * span_e
        lam_max = p.rest_length_m[i] + (
            rho_s * (p.q_rest_rad[0] - p.shoulder_range_rad[0]) + rho_e * (
                p.q_rest_rad[1] - p.elbow_range_rad[0]) if flexor else
            rho_s * (p.shoulder_range_rad[1] - p.q_rest_rad[0]) + rho_e * (
                p.elbow_range_rad[1] - p.q_rest_rad[1]))
        lam_min = lam_max - ell
        d = lam - p.rest_length_m[i] - p.slack_offset_m[i]
        w = p.passive_smoothing_m
        psi = p.km_n_per_m[i] * w * math.log1p(math.exp(d / w)) * math.exp(-(d / ell) ** 2)
        ldot = lever * speed_rad_s
        u = p.beta[i] * min(max(ldot / ldot_max[i], 0.0), 1.0)
        gam = (lam - lam_min) / ell - (p.rest_length_m[i] / lam_max) * (1.0 - u)
        phi = max(0.0, p.alpha_n[i] * u * gam * math.exp(-gam * gam))
        out[g] = lever * (psi + phi)
    return out


@pytest.mark.parametrize("spec", [{}, {"elbow": "severe"}, {"ef:dynamic": "moderate"},
                                  {"bf:passive": "mild", "be:dynamic": "severe"}])
def test_stretch_torques_match_a_hand_derivation(spec):
    p = synthesize(spec)
    arm = Arm.from_params(p)
    np.testing.assert_allclose(arm.ldot_max, _ldot_max_by_hand(p), rtol=1e-4)
    prof = stretch_profile(arm, "elbow", "extension")
    for k in (0, 30, 60, 90, 120):
        q2 = float(prof.angles_rad[k])
        for speed, reflex in ((prof.slow_speed_rad_s, prof.reflex_slow_n_m),
                              (prof.fast_speed_rad_s, prof.reflex_fast_n_m)):
            hand = _elbow_extension_by_hand(p, q2, speed)
            model = prof.passive_n_m[k] + reflex[k]
            for g, v in hand.items():
                assert model[GROUP_INDEX[g]] == pytest.approx(v, rel=1e-3, abs=1e-6), (g, k)
            assert model[GROUP_INDEX["sf"]] == model[GROUP_INDEX["se"]] == 0.0


def _hand_curves(p: ArmParams) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Along an elbow extension from 150° to 0° (121 samples): the elbow flexors' passive
    torque and velocity-dependent torque (180°/s against 5°/s), of ``p`` and of the unimpaired
    arm, from the hand derivation."""
    ref = ArmParams.from_anthropometry()
    angles = np.radians(np.linspace(150.0, 0.0, 121))
    fast, slow = math.radians(180.0), math.radians(5.0)

    def ef(par: ArmParams, q2: float, speed: float) -> float:
        return _elbow_extension_by_hand(par, q2, speed)["ef"]

    def passive(par: ArmParams, q2: float) -> float:
        return ef(par.replace(alpha_n=(0.0,) * 6), q2, 0.0)

    return (np.array([passive(p, a) for a in angles]),
            np.array([passive(ref, a) for a in angles]),
            np.array([ef(p, a, fast) - ef(p, a, slow) for a in angles]),
            np.array([ef(ref, a, fast) - ef(ref, a, slow) for a in angles]))


def test_grades_match_a_hand_derivation():
    # ef dynamic: 1 + max (V - V_ref) / max (P_ref + V_ref) from hand-computed torques; on the
    # synthesis path the reflex adds most where the passive torque peaks, so this is also
    # max (P_ref + V) / max (P_ref + V_ref)
    p = synthesize({"ef:dynamic": "moderate"})
    _, p_ref, v, v_ref = _hand_curves(p)
    expected = 1.0 + (v - v_ref).max() / (p_ref + v_ref).max()
    got = _grades(p)["ef"].dynamic.ratio
    assert got == pytest.approx(expected, rel=2e-3)
    assert expected == pytest.approx((p_ref + v).max() / (p_ref + v_ref).max(), rel=1e-9)
    assert got == pytest.approx(LEVEL_RATIO["moderate"], rel=1e-6)


def test_alpha_alone_raised_tenfold_is_felt_at_the_end_of_a_fast_stretch():
    # α × 10 at the unimpaired gain: the reflex fires only near the end of the range (Γ > 0
    # needs λ close to λ_max while u ≤ β = 0.1) and adds ≈ 0.094 N·m there to a fast-stretch
    # resistance of 0.379 N·m: D ≈ 1.25, below the first Weber step (1.56) but 2.5 force JNDs
    # above unimpaired - MAS 1's "minimal resistance at the end of the range".
    i = GROUP_INDEX["ef"]
    alpha = list(BASE.alpha_n)
    alpha[i] *= 10.0
    p = BASE.replace(alpha_n=tuple(alpha))
    _, p_ref, v, v_ref = _hand_curves(p)
    expected = 1.0 + (v - v_ref).max() / (p_ref + v_ref).max()
    assert 1.2 < expected < 1.3
    sev = _grades(p)
    ef = sev["ef"].dynamic
    assert ef.ratio == pytest.approx(expected, rel=2e-3)
    assert ef.level == "very mild" and 0.0 < ef.score < 1.0
    added = sev["ef"].tone.dynamic_added
    assert added.torque_n_m == pytest.approx((v - v_ref).max(), rel=2e-3)
    assert added.at_deg == pytest.approx(0.0, abs=1e-9)  # at the end of the range
    assert added.felt_from_deg is not None and 0.0 < added.felt_from_deg < 20.0
    assert sev["ef"].passive.level == "unimpaired"
    assert summary(sev) == "ef dynamic very mild"
    # raised only 2×, the reflex adds 2.5% of the resistance: not felt
    alpha[i] = 2.0 * BASE.alpha_n[i]
    assert _grades(BASE.replace(alpha_n=tuple(alpha)))["ef"].dynamic.level == "unimpaired"


def test_a_shorter_slack_length_is_graded_by_the_resistance_it_adds_earlier():
    # 20 mm shorter (slack_offset_m = -0.02) at normal Km: the passive force starts 0.02 /
    # 0.025 rad = 46° earlier in the elbow extension; its peak at the end of the range grows
    # only 14% (ψ = Km d exp(-(d/ℓ)²) saturates), but at 66° it adds ≈ 0.26 N·m where the
    # unimpaired flexors give 0.04: P* ≈ 1.7.
    i = GROUP_INDEX["ef"]
    slack = list(BASE.slack_offset_m)
    slack[i] = -0.02
    p = BASE.replace(slack_offset_m=tuple(slack))
    pp, p_ref, _, _ = _hand_curves(p)
    assert pp.max() / p_ref.max() < 1.2  # the seed's peak ratio would call it unimpaired
    expected = 1.0 + (pp - p_ref).max() / p_ref.max()
    assert 1.6 < expected < 1.8
    sev = _grades(p)
    ef = sev["ef"].passive
    assert ef.ratio == pytest.approx(expected, rel=2e-3)
    assert ef.level == "very mild"
    added = sev["ef"].tone.passive_added
    assert 55.0 < added.at_deg < 75.0
    # felt from where the contracted group's passive torque reaches 10% of the unimpaired peak
    felt = np.radians(np.linspace(150.0, 0.0, 121))[np.argmax(pp - p_ref >= 0.1 * p_ref.max())]
    assert added.felt_from_deg == pytest.approx(math.degrees(felt))
    assert added.felt_from_deg > 100.0  # the unimpaired group is slack down to 70° (q_rest)
    assert sev["ef"].dynamic.level == "unimpaired"
    doc = sev["ef"].to_dict()["passive"]
    assert doc["added_torque_n_m"] == pytest.approx(added.torque_n_m)  # type: ignore[index]
    # the contracture grows with the shortening; a lengthening adds nothing
    slack[i] = -0.04
    assert _grades(BASE.replace(slack_offset_m=tuple(slack)))["ef"].passive.ratio > ef.ratio
    slack[i] = 0.01
    longer = _grades(BASE.replace(slack_offset_m=tuple(slack)))["ef"].passive
    assert longer.level == "unimpaired" and longer.ratio < 1.0


def test_unimpaired_only_while_the_addition_is_not_felt():
    scale = SeverityScale()
    assert scale.level(1.0) == scale.level(1.099) == "unimpaired"
    assert scale.level(1.101) == scale.level(1.5) == scale.level(2.44) == "very mild"
    assert scale.level(3.2) == "mild"
    assert SeverityScale(felt_fraction=0.3).level(1.25) == "unimpaired"
    with pytest.raises(ParameterError, match="felt_fraction"):
        SeverityScale(felt_fraction=0.7)
    # Km 5% above unimpaired is within the JND; 20% above is felt
    i = GROUP_INDEX["ee"]
    for factor, level in ((1.05, "unimpaired"), (1.2, "very mild")):
        km = list(BASE.km_n_per_m)
        km[i] *= factor
        got = _grades(BASE.replace(km_n_per_m=tuple(km)))["ee"].passive
        assert got.ratio == pytest.approx(factor, rel=1e-9) and got.level == level


# --- against published magnitudes --------------------------------------------------------------
def test_elbow_stretch_torques_meet_the_published_mas_magnitudes():
    unimpaired = joint_stretch(Arm.from_params(BASE), "elbow", "extension")
    severe = joint_stretch(Arm.from_params(synthesize({"elbow": "severe"})), "elbow",
                           "extension")
    # MAS 0: 0.9 N·m peak resistive torque (Pei et al. 2021), 1.3 N·m at ≥ 150°/s (Liang et
    # al. 2020); the unimpaired arm lies between them at both speeds.
    for t in (unimpaired.slow_torque_n_m, unimpaired.peak_torque_n_m):
        assert 0.9 <= t <= 1.3
    # MAS 4: 6.7 N·m at ≥ 150°/s (Liang 2020) to 9.8 N·m (Pei 2021); the severe elbow
    # (both directions, both components) at 180°/s lies between them.
    assert 6.7 <= severe.peak_torque_n_m <= 9.8
    # ≈ 5× (Liang) to ≈ 11× (Pei) the unimpaired resistance
    assert 5.0 <= severe.peak_torque_n_m / unimpaired.peak_torque_n_m <= 11.0
    # the levels between rise monotonically
    fast = [joint_stretch(Arm.from_params(synthesize({"elbow": lvl})), "elbow",
                          "extension").peak_torque_n_m for lvl in LEVELS]
    assert fast == sorted(fast)


def test_velocity_dependent_torque_needs_a_fast_stretch():
    # McPherson 2018: the reflex shows only in stretches faster than 100°/s.
    arm = Arm.from_params(synthesize({"elbow": "severe"}))
    by_speed = {s: joint_stretch(arm, "elbow", "extension", speed_rad_s=math.radians(s))
                .reflex_torque_n_m for s in (30.0, 100.0, 180.0)}
    assert by_speed[30.0] < 0.1 * by_speed[180.0]
    assert by_speed[30.0] < by_speed[100.0] < by_speed[180.0]


def test_tardieu_catch_separates_spasticity_from_contracture():
    plain = joint_stretch(Arm.from_params(BASE), "elbow", "extension")
    assert plain.catch_angle_deg is None and plain.slow_stop_angle_deg is None
    assert plain.dynamic_range_deg is None  # neither R1 nor R2: no R2 - R1
    assert plain.catch_threshold_n_m == pytest.approx(2.0 * plain.slow_torque_n_m)
    reflex = joint_stretch(Arm.from_params(synthesize({"ef:dynamic": "severe"})), "elbow",
                           "extension")
    assert reflex.catch_angle_deg is not None and reflex.slow_stop_angle_deg is None
    # the catch comes well before the end of the range (0°), and R2 was never reached: no
    # R2 - R1 is reported (it would rest on an angle the slow stretch never met)
    assert reflex.catch_angle_deg > 20.0 and reflex.dynamic_range_deg is None
    stiff = joint_stretch(Arm.from_params(synthesize({"ef:passive": "severe"})), "elbow",
                          "extension")
    assert stiff.slow_stop_angle_deg is not None and stiff.catch_angle_deg is not None
    assert stiff.dynamic_range_deg is not None and stiff.dynamic_range_deg < 1.0
    both = joint_stretch(Arm.from_params(synthesize({"ef": "severe"})), "elbow", "extension")
    assert both.slow_stop_angle_deg == pytest.approx(stiff.slow_stop_angle_deg, abs=0.5)
    assert both.catch_angle_deg > stiff.catch_angle_deg + 5.0  # the catch comes earlier


def test_fast_pull_directions_single_out_the_shoulder():
    # Seed Fig. 3b: pulling from rest along the mid-sagittal direction, the force from a
    # hypertonic shoulder is oriented unlike those from the elbow and bi-articular groups.
    def directions(group: str) -> np.ndarray:
        arm = Arm.from_params(synthesize({group: "severe"}))
        x0 = arm.rest_position()
        s = np.linspace(0.0, 0.15, 7)[1:]
        f = arm.endpoint_force(x0 + s[:, None] * np.array([0.0, -1.0]), [0.0, -1.0])
        return np.degrees(np.arctan2(f[:, 1], f[:, 0]))

    d = {g: directions(g) for g in JOINT_GROUPS}
    for g in JOINT_GROUPS:
        assert np.all(np.sin(np.radians(d[g])) > 0), g
    assert np.all(np.cos(np.radians(d["shoulder"])) < 0)
    assert np.all(np.cos(np.radians(d["elbow"])) > 0)
    assert np.all(np.cos(np.radians(d["biarticular"])) > 0)
    sep_se = np.abs(d["shoulder"] - d["elbow"]).mean()
    sep_sb = np.abs(d["shoulder"] - d["biarticular"]).mean()
    sep_eb = np.abs(d["elbow"] - d["biarticular"]).mean()
    assert min(sep_se, sep_sb) > sep_eb


def test_with_muscles_shares_the_geometry_and_equals_a_compilation():
    arm = Arm.from_params(BASE)
    q = synthesize({"elbow": "severe"}).replace(slack_offset_m=(0.0, 0.0, 0.01, 0.0, 0.0, 0.0))
    fast, full = arm.with_muscles(q), Arm.from_params(q)
    assert fast.params == q
    for name in ("jl", "lam_rest", "lam_slack", "lam_min", "lam_max", "excursion", "ldot_max",
                 "km", "alpha", "beta", "_pot_total", "_jl_products"):
        np.testing.assert_array_equal(getattr(fast, name), getattr(full, name), err_msg=name)
    x = np.array([[0.05, 0.45], [0.2, 0.35]])
    for a, b in zip(fast.field(x, [0.3, -0.2]), full.field(x, [0.3, -0.2]), strict=True):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(ParameterError, match="q_rest_rad"):
        arm.with_muscles(q.replace(q_rest_rad=(0.8, 1.3)))


@pytest.mark.parametrize(("change", "felt"), [({"alpha_n": 1000.0}, True),
                                              ({"beta": 0.5}, True),
                                              ({"km_n_per_m": 720.0}, True),
                                              ({"slack_offset_m": -0.005}, True),
                                              ({"alpha_n": 200.0}, False),
                                              ({"beta": 0.2}, False)])
def test_every_group_is_graded_alike_when_one_parameter_leaves_unimpaired(change, felt):
    """A parameter changed alone reads the same in every group: the bi-articular groups are
    graded on their own stretch too (the elbow stretch with the shoulder placed to lengthen
    them), where their reflex fires as a mono-articular group's does at the end of its range.
    On the clinic's elbow stretch alone a tenfold α of be added 7 % and read unimpaired."""
    comp = "passive" if set(change) & {"km_n_per_m", "slack_offset_m"} else "dynamic"
    ratios = {}
    for g in GROUPS:
        grade = _grades(BASE.with_group(g, **change))[g]
        got = grade.component(comp)
        assert (got.level != "unimpaired") == felt, (g, change, got)
        assert grade.component("passive" if comp == "dynamic" else "dynamic").level \
            == "unimpaired"
        ratios[g] = got.ratio
    # alike: the groups' ratios differ by less than half of what the change adds
    spread = max(ratios.values()) - min(ratios.values())
    assert spread < 0.5 * (max(ratios.values()) - 1.0) + 0.01, ratios


def test_a_biarticular_reflex_is_graded_on_its_own_stretch():
    p = BASE.with_group("be", alpha_n=1000.0)
    sev = _grades(p)["be"]
    assert sev.dynamic.level == "very mild"
    assert sev.tone.dynamic_stretch == "elbow flexion, shoulder flexed"
    # the clinic's stretch with the shoulder at rest alone would not feel it
    at_rest = stretch_profile(Arm.from_params(p), "elbow", "flexion")
    ref = stretch_profile(Arm.from_params(BASE), "elbow", "flexion")
    i = GROUP_INDEX["be"]
    added = (at_rest.velocity_dependent_n_m[:, i] - ref.velocity_dependent_n_m[:, i]).max()
    peak = (ref.passive_n_m[:, i] + ref.velocity_dependent_n_m[:, i]).max()
    assert 1.0 + added / peak < 1.1
    assert sev.to_dict()["dynamic"]["stretch"] == "elbow flexion, shoulder flexed"
