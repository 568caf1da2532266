"""The report and the station as a clinician reads them: the realised-fraction panel names each
row and tells a map that saw the predicted change from one that agrees only within its noise;
a failed check's badge is as plain as a confirmed one's; the station's six muscle groups stay
apart for a reader with a colour-vision deficiency."""

from __future__ import annotations

import itertools
import re

import numpy as np
import pytest

from fieldbank.figures.scene import Circles, Lines, Text
from fieldbank.figures.style import text_width
from fieldbank.interventions.report.figures.cohort import (
    AGREES,
    DISAGREES,
    WITHIN_NOISE,
    CheckPoint,
    validation_figure,
)
from fieldbank.interventions.report.html import verdict_badge
from tests.readme_runner import ROOT


def _points() -> list[CheckPoint]:
    return [
        CheckPoint("SYN-001", "SYN-001: post-BoNT map 12 (postural, ef)", "N", 2.0, 1.9, 0.95,
                   0.1, "good", True, "SYN-001 plan 1 · post-BoNT map 12"),
        CheckPoint("SYN-002", "SYN-002: post map 20 (postural, bf)", "N", 0.05, 0.4, 0.1, 2.0,
                   "good", False, "SYN-002 plan 3 · post map 20"),
        CheckPoint("SYN-003", "SYN-003: post map 31 (stiffness, ef)", "N", 3.0, 0.2, 0.05,
                   0.05, "poor", True, "SYN-003 plan 5 · post map 31"),
    ]


def test_each_check_stands_where_its_evidence_puts_it() -> None:
    agrees, within, failed = _points()
    assert (agrees.standing, within.standing, failed.standing) == (AGREES, WITHIN_NOISE,
                                                                    DISAGREES)


def test_the_realised_fraction_panel_names_each_row_and_keeps_noise_apart() -> None:
    pts = _points()
    scene = validation_figure(pts, "checks", 0.5)
    texts = [it for it in scene.items if isinstance(it, Text)]
    shown = {t.text for t in texts}
    for p in pts:  # every row of the panel carries its patient, plan and map
        assert p.short in shown
    # no label runs off the figure's left or right edge
    for t in (t for t in texts if not t.rotate):  # an axis title stands upright
        w = text_width(t.text, t.size)
        left = {"start": t.x, "middle": t.x - w / 2, "end": t.x - w}[t.anchor]
        assert left >= -0.5 and left + w <= scene.width + 0.5, t.text
    # the markers: each standing its own shape and colour, in the scatter and the legend
    drawn: dict[str, set[tuple[str, str | None]]] = {}
    for it in scene.items:
        standing = it.attrs.get("standing") if isinstance(it, (Circles, Lines)) else None
        if standing is None:
            continue
        kind = "circle" if isinstance(it, Circles) and it.fill != "#ffffff" else (
            "ring" if isinstance(it, Circles) else "polygon")
        colour = (it.fill if kind == "circle" else it.stroke) if isinstance(it, Circles) \
            else it.fill
        drawn.setdefault(standing, set()).add((kind, colour))
    assert set(drawn) == {AGREES, WITHIN_NOISE, DISAGREES}
    looks = [next(iter(v)) for v in drawn.values()]
    assert len(set(looks)) == 3  # three standings, three looks
    assert drawn[WITHIN_NOISE] != drawn[AGREES]
    legend = " ".join(shown)
    assert "agrees within noise" in legend and "disagrees with the prediction" in legend


@pytest.mark.parametrize("verdict", ["prediction failed", "confirmed", "partly confirmed",
                                     "inconclusive"])
def test_a_verdict_is_a_badge_in_words(verdict: str) -> None:
    badge = verdict_badge(verdict)
    assert verdict in badge and badge.startswith('<span class="verdict ')


def test_a_failed_prediction_is_as_plain_as_a_confirmed_one() -> None:
    failed, confirmed = verdict_badge("prediction failed"), verdict_badge("confirmed")
    cls = [re.search(r'class="verdict (\w+)"', b) for b in (failed, confirmed)]
    assert cls[0] and cls[1] and cls[0].group(1) != cls[1].group(1)
    css = (ROOT / "interventions" / "report" / "html.py").read_text(encoding="utf-8")
    rule = re.search(r"\.verdict\." + cls[0].group(1) + r" \{([^}]*)\}", css)
    assert rule and "background: #" in rule.group(1) and "color: #fff" in rule.group(1)


# --- the station's muscle colours ---------------------------------------------------------------
#: How a dichromat sees linear RGB (Machado, Oliveira & Fernandes 2009, IEEE TVCG 15(6),
#: 1291-1298: the simulation matrices at severity 1.0).
DICHROMATS = {
    "protanopia": [[0.152286, 1.052583, -0.204868], [0.114503, 0.786281, 0.099216],
                   [-0.003882, -0.048116, 1.051998]],
    "deuteranopia": [[0.367322, 0.860646, -0.227968], [0.280085, 0.672501, 0.047413],
                     [-0.011820, 0.042940, 0.968881]],
    "tritanopia": [[1.255528, -0.076749, -0.178779], [-0.078411, 0.930809, 0.147602],
                   [0.004733, 0.691367, 0.303900]],
}


def _linear(hex_colour: str) -> np.ndarray:
    c = np.array([int(hex_colour[i:i + 2], 16) for i in (1, 3, 5)]) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _lab(linear_rgb: np.ndarray) -> np.ndarray:
    """CIE L*a*b* (D65) of a linear sRGB colour."""
    m = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722],
                  [0.0193, 0.1192, 0.9505]])
    xyz = m @ np.clip(linear_rgb, 0.0, 1.0) / np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > (6 / 29) ** 3, np.cbrt(xyz), xyz / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.array([116 * f[1] - 16, 500 * (f[0] - f[1]), 200 * (f[1] - f[2])])


def _station_colours() -> list[str]:
    js = (ROOT / "haptic" / "station" / "station.js").read_text(encoding="utf-8")
    found = re.search(r"const MUSCLE_COLOURS = \[([^\]]*)\]", js)
    assert found, "station.js names one colour per muscle group in MUSCLE_COLOURS"
    return re.findall(r'"(#[0-9A-Fa-f]{6})"', found.group(1))


def _closest_pair(colours: list[str], vision: list[list[float]] | None) -> float:
    seen = [_lab(_linear(c) if vision is None else np.array(vision) @ _linear(c))
            for c in colours]
    return min(float(np.linalg.norm(a - b)) for a, b in itertools.combinations(seen, 2))


def test_the_six_muscle_groups_are_told_apart_with_every_common_deficiency() -> None:
    colours = _station_colours()
    assert len(colours) == 6 and len({c.lower() for c in colours}) == 6
    # CIE76 distance: about 2.3 is just noticeable; 10 is told apart at a glance
    assert _closest_pair(colours, None) > 20
    for name, vision in DICHROMATS.items():
        assert _closest_pair(colours, vision) > 10, name


def test_the_colour_check_catches_a_palette_of_near_pinks() -> None:
    pinks = ["#f4c2c2", "#f7c6c7", "#f2bfc4", "#f6c9c0", "#f3c5cb", "#f8c3c3"]
    assert _closest_pair(pinks, None) < 10
    assert _closest_pair(["#E69F00", "#009E73"], DICHROMATS["deuteranopia"]) > 10
    # red against green is the classic pair a deuteranope loses
    assert _closest_pair(["#d62728", "#2ca02c"], DICHROMATS["deuteranopia"]) < \
        _closest_pair(["#d62728", "#2ca02c"], None) / 2


# --- intervals that rest on a guess -------------------------------------------------------------
def test_an_interval_resting_on_a_guess_is_marked_and_shown_after_the_identified_one() -> None:
    from fieldbank.interventions.report.html import _trust

    detail = {"fit": None, "intervals": {"samples": 200, "metrics": {
        "elbow flexion, fast": {"unit": "N·m", "before": 1.39, "after": 1.2, "change": -0.19,
                                "before_interval": [1.35, 15.60], "after_interval": [1.1, 14.0],
                                "change_interval": [-1.6, 0.0], "rests_on_guess": True,
                                "without_guesses": {"before_interval": [1.35, 1.43],
                                                    "after_interval": [1.15, 1.25],
                                                    "change_interval": [-0.22, -0.16]}},
        "elbow extension, slow": {"unit": "N·m", "before": 0.5, "after": 0.4, "change": -0.1,
                                  "before_interval": [0.45, 0.55], "after_interval": [0.35, 0.45],
                                  "change_interval": [-0.12, -0.08], "rests_on_guess": False}}}}
    page = "".join(_trust(detail))
    rows = re.findall(r"<tr><th class=\"t\">(.*?)</th>(.*?)</tr>", page)
    named = {name: cells for name, cells in rows}
    guessed = named["elbow flexion, fast (N·m) *"]
    first = re.search(r"<td>(.*?)</td>", guessed)
    assert first and first.group(1).startswith("1.39 [1.35, 1.43]")  # identified first
    assert '<span class="guess">* [1.35, 15.60]</span>' in first.group(1)
    assert "elbow extension, slow (N·m)" in named and "*" not in named[
        "elbow extension, slow (N·m)"]
    assert "* The interval rests on parameters the fit did not identify" in page


# --- who answered the training ------------------------------------------------------------------
def test_training_results_say_when_a_simulated_trainee_answered() -> None:
    from fieldbank.haptic.trainingresults import trainee_note

    assert trainee_note([3], []).startswith("Simulated trainee, not a person: session(s) 3")
    both = trainee_note([3], [4, 5])
    assert "3 were answered by the simulated trainee" in both and "4, 5 by a person" in both
    assert "simulated" not in trainee_note([], [4])


# --- one name per muscle group ------------------------------------------------------------------
def test_the_group_that_crosses_both_joints_has_one_name_on_every_page() -> None:
    station = ROOT / "haptic" / "station"
    page = (station / "page.html").read_text(encoding="utf-8")
    buttons = dict(re.findall(r'class="train-answer answer" data-answer="(\w+)"[^>]*>([^<]+)<',
                              page))
    assert buttons == {"shoulder": "Shoulder", "elbow": "Elbow", "both": "Bi-articular"}
    remote = (ROOT / "haptic" / "remote" / "desk.js").read_text(encoding="utf-8")
    for table in ("GROUP_WORD", "GROUP_SHORT"):
        found = re.search(table + r" = \{([^}]*)\}", remote)
        assert found and '"Bi-articular"' in found.group(1) and "Both" not in found.group(1)
    from fieldbank.haptic.trainingresults import _ANSWER_WORDS

    assert _ANSWER_WORDS["both"] == "bi-articular"
