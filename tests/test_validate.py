"""Predictions checked against measurement: ``fieldbank validate`` and its library.

The shipped samples exercise it: every patient was given botulinum toxin between the sessions
(the catalogue's effect for SYN-001 and SYN-002, a tenth of it for SYN-003); the demo's
``populate`` stores the plans as given. Pure checks on exact maps run first: a right and a
wrong prediction, a partial effect, a change the maps cannot see, a fit error the maps cannot
separate from the change. The calibration of the realised fraction's SE on a seeded cohort is
``tests/test_validate_calibration.py``.
"""

from __future__ import annotations

import csv
import json
import re
from datetime import date
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest

from fieldbank.evaluate.severity import synthesize
from fieldbank.maps import FieldMap, postural_map, stiffness_map
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from tests.report_helpers import run_cli

if TYPE_CHECKING:
    from fieldbank.interventions.validate import LaterSession as LaterSessionT


# --- the computation, on exact maps --------------------------------------------------------
def _maps_of(params: ArmParams, rng: np.random.Generator) -> list[tuple[int, FieldMap]]:
    arm = Arm.from_params(params)
    ref = Arm.from_params(ArmParams.from_anthropometry())
    q = np.column_stack([rng.uniform(0.2, 1.8, 12), rng.uniform(0.5, 2.2, 12)])
    pos = ref.fk(q)
    out = []
    for k, m in enumerate([postural_map(arm, pos), stiffness_map(arm, pos),
                           stiffness_map(arm, pos, (0.0, 1.0))]):
        sd = 0.05 * np.abs(m.values) + (0.05 if m.kind == "postural" else 5.0)
        noisy = m.values + rng.normal(size=m.values.shape) * sd
        out.append((k + 1, FieldMap(kind=m.kind, positions_m=m.positions_m, values=noisy,
                                    sd=sd, velocity_m_per_s=m.velocity_m_per_s)))
    return out


def test_check_session_confirms_a_right_prediction_and_fails_a_wrong_one() -> None:
    from fieldbank.interventions import Botulinum, Plan
    from fieldbank.interventions.realised import CONFIRMED, FAILED
    from fieldbank.interventions.validate import LaterSession, check_session

    before = synthesize({"elbow": "severe"})
    plan = Plan.of(Botulinum({"ef": 150.0}, weeks_since=5.0))
    given = date(2024, 1, 10)
    rng = np.random.default_rng(3)
    # measured 8 weeks later: the truth is the plan seen at 8 weeks, not at its stored 5
    truth_after = plan.at_week(8.0).apply(before)
    later = LaterSession("post", date(2024, 3, 6), tuple(_maps_of(truth_after, rng)))
    ok = check_session(before, plan, plan.apply(before), given, later)
    assert ok.weeks_after == pytest.approx(8.0) and ok.retimed
    assert ok.verdict == CONFIRMED, ok.reasons
    assert ok.realised_fraction == pytest.approx(1.0, abs=0.2)
    for m in ok.maps:
        assert m.prediction.verdict == "good" and m.prediction.chi2_per_value < 2
    moving = ok.maps[-1]
    assert moving.predicted_change_rms > 0 and moving.realised_fraction is not None
    assert [m.predicted_change_rms for m in ok.maps[:2]] == [0.0, 0.0]  # static: no reflex

    # nothing happened: the prediction fails, the measured change is ~0% of the predicted
    unchanged = LaterSession("post", date(2024, 3, 6), tuple(_maps_of(before, rng)))
    bad = check_session(before, plan, plan.apply(before), given, unchanged)
    assert bad.verdict == FAILED
    assert bad.realised_fraction is not None and abs(bad.realised_fraction) < 0.2
    assert bad.decided and bad.interval is not None and bad.interval[1] < 0.8
    assert any("no change distinguishable from none" in r for r in bad.reasons)
    assert bad.maps[-1].prediction.verdict == "poor"


def _later(params: ArmParams, velocities: list[tuple[float, float]], seed: int,
           noise: float = 0.05) -> LaterSessionT:
    """Maps of ``params`` (postural, then stiffness at each velocity) with relative noise."""
    from fieldbank.interventions.validate import LaterSession

    rng = np.random.default_rng(seed)
    arm = Arm.from_params(params)
    ref = Arm.from_params(ArmParams.from_anthropometry())
    pos = ref.fk(np.column_stack([rng.uniform(0.3, 1.6, 12), rng.uniform(0.6, 2.1, 12)]))
    out = []
    for k, m in enumerate([postural_map(arm, pos)] + [stiffness_map(arm, pos, v)
                                                      for v in velocities]):
        sd = noise * np.abs(m.values) + (0.05 if m.kind == "postural" else 5.0)
        out.append((k + 1, FieldMap(kind=m.kind, positions_m=m.positions_m, sd=sd,
                                    values=m.values + rng.normal(size=m.values.shape) * sd,
                                    velocity_m_per_s=m.velocity_m_per_s)))
    return LaterSession("post", date(2024, 2, 21), tuple(out))


def test_half_the_effect_is_a_partial_effect_with_its_interval() -> None:
    from fieldbank.interventions import Botulinum, Plan
    from fieldbank.interventions.realised import PARTIAL
    from fieldbank.interventions.validate import check_session

    before = synthesize({"elbow": "severe"})
    plan = Plan.of(Botulinum({"ef": 150.0}, weeks_since=6.0))
    half = Plan.of(Botulinum({"ef": 150.0}, weeks_since=6.0, emax=0.35)).apply(before)
    c = check_session(before, plan, plan.apply(before), date(2024, 1, 10),
                      _later(half, [(0.0, 0.0), (0.0, 1.0), (0.0, -1.0)], 5))
    assert c.verdict == PARTIAL, c.reasons
    assert c.decided and c.realised_fraction == pytest.approx(0.5, abs=0.1)
    assert c.interval is not None and 0 < c.interval[0] and c.interval[1] < 0.8
    assert c.fit_se is None and "no fit uncertainty" in c.fit_uncertainty  # an exact model


@pytest.mark.parametrize(("f", "se", "verdict"), [
    (1.44, 0.15, "stronger than predicted"),  # was "confirmed": its interval reached 1.2
    (1.29, 0.05, "stronger than predicted"),
    (1.33, 0.24, "inconclusive"),  # beyond the tolerance, but the interval reaches 1
    (1.10, 0.05, "prediction confirmed"),
    (0.95, 0.10, "prediction confirmed"),
    (0.45, 0.05, "partial effect"),
])
def test_an_effect_beyond_the_tolerance_is_an_over_effect_not_a_confirmation(
        f: float, se: float, verdict: str) -> None:
    from fieldbank.interventions.realised import CONTRADICTED
    from fieldbank.interventions.verdict import decide

    got, why = decide(f, se)
    assert got == verdict, why
    assert (got in CONTRADICTED) == (verdict in ("stronger than predicted", "partial effect"))


def test_a_stronger_effect_than_predicted_is_said_on_the_maps() -> None:
    from fieldbank.interventions import Botulinum, Plan
    from fieldbank.interventions.realised import OVER
    from fieldbank.interventions.validate import check_session

    before = synthesize({"elbow": "severe"})
    plan = Plan.of(Botulinum({"ef": 150.0}, weeks_since=6.0))
    stronger = Plan.of(Botulinum({"ef": 150.0}, weeks_since=6.0, emax=0.95)).apply(before)
    c = check_session(before, plan, plan.apply(before), date(2024, 1, 10),
                      _later(stronger, [(0.0, 0.0), (0.0, 1.0), (0.0, -1.0)], 7))
    assert c.verdict == OVER, c.reasons
    assert c.realised_fraction is not None and c.realised_fraction > 1.2
    assert c.interval is not None and c.interval[0] > 1.0


def test_the_se_is_never_below_what_the_two_sessions_noise_allows() -> None:
    """A fit whose samples do not vary (every parameter pinned) claims no uncertainty; the
    first session's own noise still bounds what the model before knows along the change."""
    from fieldbank.interventions import Botulinum, Plan
    from fieldbank.interventions.spread import FitSpread, Footprint, first_session_se
    from fieldbank.interventions.validate import check_session

    before = synthesize({"elbow": "severe"})
    plan = Plan.of(Botulinum({"ef": 150.0}, weeks_since=6.0))
    first = _later(before, [(0.0, 0.0), (0.0, 1.0), (0.0, -1.0)], 8)
    pinned = FitSpread(1, (before,) * 8, (), frozenset(), (), "8 samples, all alike",
                       tuple(Footprint.of(m) for _, m in first.maps))
    later = _later(plan.apply(before), [(0.0, 0.0), (0.0, 1.0), (0.0, -1.0)], 9)
    c = check_session(before, plan, plan.apply(before), date(2024, 1, 10), later,
                      spread=pinned)
    floor = first_session_se(pinned, before, plan.apply(before))
    assert floor is not None and floor > 0
    assert c.realised_se is not None and c.noise_se is not None and c.fit_se is not None
    assert c.fit_se == pytest.approx(floor)  # the samples alone would say 0
    assert c.realised_se >= np.hypot(c.noise_se, floor) * (1 - 1e-12)
    assert c.verdict == "prediction confirmed", c.reasons


def test_a_change_the_maps_cannot_see_is_inconclusive_and_says_what_would_see_it() -> None:
    """Static maps cannot see a change of the stretch reflex: no number, the group named, and
    a measurement that would see it proposed."""
    from fieldbank.interventions import Botulinum, Plan
    from fieldbank.interventions.realised import INCONCLUSIVE
    from fieldbank.interventions.validate import check_session

    before = synthesize({"elbow": "severe"})
    plan = Plan.of(Botulinum({"ef": 150.0}, weeks_since=6.0))
    for truth in (plan.apply(before), before):  # as predicted, or nothing: the same answer
        c = check_session(before, plan, plan.apply(before), date(2024, 1, 10),
                          _later(truth, [(0.0, 0.0)], 6))
        assert c.verdict == INCONCLUSIVE, c.reasons
        assert c.realised_fraction is None and c.realised_se is None and not c.decided
        assert all(m.realised_fraction is None for m in c.maps)
        (why,) = c.reasons
        assert "these maps cannot see a change of the elbow flexors' (ef) stretch reflex" in why
        assert "measure a stiffness map while the hand moves at 1 m/s" in why
        assert "fast stretch of the elbow into extension" in why
        seen = float(re.search(r"predicted change is ≈ (\d+) sd", why).group(1))  # type: ignore[union-attr]
        assert seen >= 4  # the proposed map would see it


def test_a_fit_error_on_a_barely_moving_map_gives_no_nonsense_fraction() -> None:
    """The model before is off (Km 10% high, as a fit may be) and the one moving map is slow,
    so the predicted change is tiny against the noise: the old check divided the fit error by
    it and printed fractions like -245 ± 4.8. Now no number is reported."""
    from fieldbank.interventions import Botulinum, Plan
    from fieldbank.interventions.realised import CONFIRMED
    from fieldbank.interventions.validate import check_session

    truth = synthesize({"elbow": "moderate"})
    fitted = truth.replace(km_n_per_m=tuple(1.1 * k for k in truth.km_n_per_m))
    plan = Plan.of(Botulinum({"ef": 150.0}, weeks_since=6.0))
    half = Plan.of(Botulinum({"ef": 150.0}, weeks_since=6.0, emax=0.35)).apply(truth)
    c = check_session(fitted, plan, plan.apply(fitted), date(2024, 1, 10),
                      _later(half, [(0.0, 0.0), (0.0, 0.15)], 7))
    assert c.sensitivity_sd < 4
    assert c.realised_fraction is None and c.realised_se is None
    assert all(m.realised_fraction is None for m in c.maps)
    assert c.verdict != CONFIRMED


# --- the shipped samples -------------------------------------------------------------------
@pytest.fixture(scope="module")
def samples_db(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    from tests.report_helpers import build_batch

    return build_batch(tmp_path_factory.mktemp("validate"),
                       patients=("SYN-001", "SYN-002", "SYN-003"))


def test_validate_on_the_samples_reports_per_map_figures(samples_db: dict[str, Any]) -> None:
    url = samples_db["url"]
    res = run_cli("validate", "--db", url, "--json")
    assert res.exit_code == 1, res.output  # SYN-003's prediction fails
    doc = json.loads(res.stdout)
    assert doc["verdict"] == "prediction failed"
    plans = {(p["patient"], p["label"].split()[0]): p for p in doc["plans"]}
    for code in ("SYN-001", "SYN-002"):
        p = plans[(code, "botulinum")]
        assert p["verdict"] == "prediction confirmed", p
        assert p["given_on"] == "2024-01-10"
        (s,) = p["sessions"]
        assert s["session"] == "post-BoNT" and s["retimed"]
        assert s["weeks_after"] == (6.0 if code == "SYN-001" else 4.0)
        assert len(s["maps"]) == 4
        for m in s["maps"]:
            assert m["unit"] in ("N", "N/m")
            assert m["r2"] > 0.8 and m["chi2_per_value"] < m["chi2_limit"]
            assert m["rms_error"] > 0 and m["verdict"] == "good"
        moving = [m for m in s["maps"] if m["velocity_m_per_s"] != [0.0, 0.0]]
        assert moving and moving[0]["predicted_change_rms"] > 0
        assert s["realised_fraction"] == pytest.approx(1.0, abs=0.3)
        assert s["fit_se"] > 0 and s["decided"] and s["interval"][0] >= 0.5
        dup = [m for m in s["maps"] if m["duplicate_of"] is not None]
        assert len(dup) == 1 and dup[0]["kind"] == "postural"  # one map from two files
    wrong = plans[("SYN-003", "botulinum")]
    assert wrong["verdict"] == "prediction failed"
    (s,) = wrong["sessions"]
    assert s["realised_fraction"] < 0.5 and s["decided"]
    assert s["noise_se"] > 0 and s["fit_se"] > 0  # the fit's samples widen the SE
    assert any("no change distinguishable from none" in r for r in s["reasons"])
    assert doc["contradicted"] == [wrong["plan_id"]]
    assert doc["rules"]["max_change_se"] == 0.25 and doc["rules"]["confirm_floor"] == 0.5
    for code in ("SYN-001", "SYN-002", "SYN-003"):
        explored = plans[(code, "lengthening")]
        assert explored["verdict"] == "not checked"
        assert "not recorded as given" in explored["not_checked"]

    text = run_cli("validate", "--db", url)
    assert text.exit_code == 1
    assert "PREDICTION FAILED" in text.stdout and "prediction confirmed" in text.stdout
    assert "realised fraction" in text.stdout and "(repeats map" in text.stdout
    # one overall verdict, on stdout only; the rules with their numbers above it
    assert text.stdout.count("Overall:") == 1 and "prediction failed" not in text.stderr
    assert text.stdout.rstrip().splitlines()[-1].startswith("Overall: prediction failed - plan")
    rules = " ".join(text.stdout[text.stdout.index("How the verdicts are read:"):].split())
    for needle in ("≥ 4 sd", "SE ≤ 0.25", "interval ≥ 0.5 and reaching 0.8", "inside (0, 0.8)",
                   "f > 1.2 and interval above 1", "stronger than predicted",
                   "partial effect", "inconclusive"):
        assert needle in rules, needle
    assert max(len(line) for line in text.stdout.splitlines()) <= 100
    one = run_cli("validate", "SYN-001", "--db", url)
    assert one.exit_code == 0 and "Overall: prediction confirmed" in one.stdout
    assert "Overall:" not in one.stderr


def test_a_deliberately_wrong_plan_fails_the_check(samples_db: dict[str, Any]) -> None:
    """SYN-001 had its elbow and bi-articular flexors injected; a plan claiming the shoulder
    flexors were injected instead predicts none of the change its later maps show."""
    url = samples_db["url"]
    res = run_cli("whatif", "SYN-001", "--db", url, "--botox", "sf=150U", "--weeks", "6",
                  "--save", "--given-on", "2024-01-10", "--json", "--interval-samples", "0")
    assert res.exit_code == 0, res.output
    plan_id = json.loads(res.stdout)["saved"]["plan_id"]
    check = run_cli("validate", "--plan", str(plan_id), "--db", url, "--json")
    assert check.exit_code == 1
    (p,) = json.loads(check.stdout)["plans"]
    assert p["verdict"] == "prediction failed"
    (s,) = p["sessions"]
    moving = [m for m in s["maps"] if m["velocity_m_per_s"] != [0.0, 0.0]]
    assert moving[0]["verdict"] == "poor"
    assert moving[0]["measured_change_rms"] > 5 * max(moving[0]["predicted_change_rms"], 1.0)
    assert any("changed in a way the plan does not predict" in r for r in s["reasons"])


def test_a_partial_effect_is_said_and_contradicts_the_prediction(
        samples_db: dict[str, Any], tmp_path: Path) -> None:
    """A plan that claims about twice the effect SYN-001 showed (a steeper dose curve) comes
    out as a partial effect, and the exit status says the prediction was contradicted."""
    url = samples_db["url"]
    doc = {"schema": "fieldbank.intervention-plan", "version": 1, "label": "strong toxin",
           "steps": [{"kind": "botulinum", "units": {"ef": 150, "bf": 150}, "weeks_since": 6,
                      "emax": 0.99, "ed50_units": 1.0}]}
    path = tmp_path / "strong.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    res = run_cli("whatif", "SYN-001", "--db", url, "--plan", str(path), "--save",
                  "--given-on", "2024-01-10", "--json", "--interval-samples", "0")
    assert res.exit_code == 0, res.output
    plan_id = json.loads(res.stdout)["saved"]["plan_id"]
    check = run_cli("validate", "--plan", str(plan_id), "--db", url)
    assert check.exit_code == 1, check.output
    assert "PARTIAL EFFECT" in check.stdout
    assert check.stdout.rstrip().splitlines()[-1] == (
        f"Overall: partial effect - plan {plan_id} (SYN-001) partial")
    js = json.loads(run_cli("validate", "--plan", str(plan_id), "--db", url, "--json").stdout)
    (s,) = js["plans"][0]["sessions"]
    assert s["verdict"] == "partial effect" and 0.3 < s["realised_fraction"] < 0.7
    assert 0 < s["interval"][0] and s["interval"][1] < 0.8
    # the report flags it as it flags a failed prediction
    out = tmp_path / "report"
    rep = run_cli("report", "--db", url, "--out", str(out), "--jobs", "1", "--plan",
                  str(plan_id))
    assert rep.exit_code == 0, rep.output
    html = (out / "report.html").read_text(encoding="utf-8")
    assert ('<p class="warn">Checked against maps measured after the plan: <span class="verdict '
            'partial">! partial effect</span>' in html)


def test_the_report_carries_the_same_check(samples_db: dict[str, Any], tmp_path: Path) -> None:
    url = samples_db["url"]
    given = [str(samples_db["plans"][code][0]) for code in ("SYN-001", "SYN-003")]
    res = run_cli("report", "--db", url, "--out", str(tmp_path), "--jobs", "1",
                  "--plan", given[0], "--plan", given[1])
    assert res.exit_code == 0, res.output
    rows = {r["patient"]: r for r in csv.DictReader((tmp_path / "metrics.csv").open(
        encoding="utf-8"))}
    assert rows["SYN-001"]["validation"] == "prediction confirmed"
    assert rows["SYN-003"]["validation"] == "prediction failed"
    assert float(rows["SYN-003"]["realised_change_fraction"]) < 0.5
    assert rows["SYN-001"]["validation_sessions"] == "post-BoNT"
    assert float(rows["SYN-001"]["validation_r2_min"]) > 0.8
    lo = float(rows["SYN-001"]["elbow_extension_reflex_after_low_n_m"])
    hi = float(rows["SYN-001"]["elbow_extension_reflex_after_high_n_m"])
    assert lo < hi
    doc = json.loads((tmp_path / "metrics.json").read_text(encoding="utf-8"))
    cases = {c["metrics"]["patient"]: c for c in doc["cases"]}
    maps = cases["SYN-003"]["validation"]["sessions"][0]["maps"]
    assert {"r2", "rms_error", "chi2_per_value", "realised_fraction"} <= set(maps[0])
    assert cases["SYN-001"]["fit"]["status"] in ("good", "under-determined")
    assert "intervals" in cases["SYN-001"] and "warnings" in cases["SYN-001"]
    # every stretch's intervals, not only one
    for stretch in ("elbow_flexion", "shoulder_extension", "shoulder_flexion"):
        assert float(rows["SYN-001"][f"{stretch}_peak_after_low_n_m"]) <= \
            float(rows["SYN-001"][f"{stretch}_peak_after_high_n_m"])
    # the figures: the check per case and across patients; the 95% band of the fast stretch
    html = (tmp_path / "report.html").read_text(encoding="utf-8")
    sections = {code: html[html.index(f'id="plan-{pid}"'):] for code, pid in
                (("SYN-001", given[0]), ("SYN-003", given[1]))}
    for code, sec in sections.items():
        sec = sec[:sec.index("</section>")]
        fig = sec[sec.index('<figure data-figure="validation">'):]
        fig = fig[:fig.index("</figure>")]
        assert 'data-verdict="good"' in fig
        if code == "SYN-003":  # the wrong prediction: a map poor against it, said in words
            assert 'data-verdict="poor"' in fig
            assert "prediction failed" in sec
        else:
            assert 'data-band="fast after"' in sec  # intervals drawn as a band
            # grades resting on a parameter the fit held at unimpaired say so
            assert re.search(r"(unimpaired|mild|moderate|severe)\+?\* → ", sec)
    assert '<figure data-figure="cohort-validation">' in html


def test_leave_one_map_out(samples_db: dict[str, Any]) -> None:
    url = samples_db["url"]
    res = run_cli("validate", "--loo", "SYN-001", "--db", url, "--json")
    doc = json.loads(res.stdout)
    assert doc["patient"] == "SYN-001" and len(doc["left_out"]) == 3
    assert "not a plan" in doc["what_it_tests"]
    by_kind = {(m["kind"], m["moving"]): m for m in doc["left_out"]}
    # the postural map is predicted by the stiffness maps (the same passive stiffness)
    assert by_kind[("postural", False)]["r2"] > 0.8
    moving = by_kind[("stiffness", True)]
    assert "static maps do not identify the stretch reflex" in moving["note"]
    assert moving["goodness_of_fit"] == "poor" and moving["verdict"] == "not testable"
    assert any(n.startswith("beta_") for n in moving["fit_without"]["unidentified"])
    # the only moving map cannot be predicted from static ones: expected, not a failure
    assert res.exit_code == 0 and doc["verdict"] == "generalises"
    text = run_cli("validate", "--loo", "SYN-001", "--db", url)
    assert "Leave-one-map-out of model" in text.stdout
    assert "generalises to a map it was not fitted on" in text.stdout
    assert "prediction failed" not in text.stdout + text.stderr  # the plan check's words
    assert text.stdout.count("Overall (leave-one-out, a check of the fit, not of a plan)") == 1
    usage = run_cli("validate", "--loo", "--db", url)
    assert usage.exit_code == 2 and "--loo needs one PATIENT" in usage.stderr


def test_leave_one_map_out_says_why_a_map_is_not_predicted(samples_db: dict[str, Any]) -> None:
    """SYN-002 (confirmed by the plan check): its stiffness maps alone put the passive
    stiffness elsewhere than its postural map measures it, and the check says so."""
    url = samples_db["url"]
    res = run_cli("validate", "--loo", "SYN-002", "--db", url, "--json")
    doc = json.loads(res.stdout)
    postural = next(m for m in doc["left_out"] if m["kind"] == "postural")
    assert postural["verdict"] == "not predicted"
    assert res.exit_code == 1 and doc["verdict"] == "does not generalise"
    moved = postural["fit_without"]["moved"]
    assert moved and all(abs(x["sds"]) >= 2 for x in moved)
    assert moved[0]["name"].startswith("km_") and moved[0]["name"] in postural["note"]
    text = run_cli("validate", "--loo", "SYN-002", "--db", url).stdout
    assert "why: without this map the fit moves km_" in " ".join(text.split())
    assert "prediction failed" not in text
    # the map's χ² counts the refit's own uncertainty: never above the noise-only figure
    for m in doc["left_out"]:
        assert m["chi2_per_value"] <= m["noise_only_chi2_per_value"] + 1e-9
    plans = run_cli("validate", "SYN-002", "--db", url)
    assert plans.exit_code == 0 and "Overall: prediction confirmed" in plans.stdout
