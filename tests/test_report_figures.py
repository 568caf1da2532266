"""Figures that show what a plan changes: the drawing layer, the read-outs behind the figures,
and a botulinum report's change for a flexor and for an extensor injection."""

from __future__ import annotations

import csv
import io
import itertools
import json
import math
import re
import xml.etree.ElementTree as ET
from typing import Any

import numpy as np
import pytest

from fieldbank import figures
from fieldbank.evaluate.compare import Conditions, compare
from fieldbank.evaluate.probing import STRETCHES, lengthening_direction
from fieldbank.evaluate.severity import COMPONENTS, synthesize
from fieldbank.figures import fields, style, svg
from fieldbank.figures.panel import Panel
from fieldbank.figures.scene import Scene
from fieldbank.interventions import Botulinum, Lengthening, Plan
from fieldbank.interventions.course import stretch_course, time_course
from fieldbank.interventions.report.compute import ALL_COLUMNS, STRETCH_READOUTS
from fieldbank.interventions.report.figures.case import case_figures
from fieldbank.model import Arm
from fieldbank.params import GROUPS, ArmParams
from fieldbank.storage import Database
from tests.report_helpers import decode_path, run_cli, store_cohort, svg_paths


# --- the drawing layer --------------------------------------------------------------------
@pytest.mark.parametrize(("lo", "hi", "n"), [(0.0, 8.6, 4), (-0.62, 0.71, 3), (0, 100, 4),
                                             (-0.3, 4.6, 5), (1e-4, 3.3e-4, 5), (-25, -3, 5)])
def test_ticks_are_round_inside_and_few(lo: float, hi: float, n: int) -> None:
    t = style.nice_ticks(lo, hi, n)
    assert 2 <= len(t) <= n + 1
    assert all(lo - 1e-12 <= v <= hi + 1e-12 for v in t)
    steps = np.diff(t)
    assert np.allclose(steps, steps[0])
    mant = steps[0] / 10 ** math.floor(math.log10(steps[0]))
    assert round(mant, 6) in (1.0, 2.0, 2.5, 5.0)
    labels = [style.tick_label(v, t) for v in t]
    assert len(set(labels)) == len(labels)  # enough decimals to tell them apart
    assert not any(lab.startswith("-") for lab in labels)  # a real minus sign


def test_paths_are_compact_and_stay_within_half_a_pixel() -> None:
    x = np.linspace(0, 400, 121)
    y = 150 - 120 * np.sin(x / 130.0) ** 2
    pts = np.column_stack([x, y])
    s = Scene(420, 200)
    s.line(pts, "#000000")
    text = svg.write(s)
    (d,) = re.findall(r' d="([^"]*)"', text)
    (poly,) = decode_path(d)
    assert len(poly) < 60  # thinned: the curve is smooth
    # every original point lies within 0.5 px of the drawn polyline
    dist = np.full(len(pts), np.inf)
    for a, b in itertools.pairwise(poly):
        ab = b - a
        t = np.clip(((pts - a) @ ab) / max(ab @ ab, 1e-12), 0, 1)
        dist = np.minimum(dist, np.hypot(*(pts - (a + t[:, None] * ab)).T))
    assert dist.max() <= 0.5


def test_svg_is_well_formed_escaped_and_deterministic() -> None:
    def draw() -> Scene:
        s = Scene(300, 200, 'a "label" <x>')
        p = Panel.at(s, (50, 20, 200, 140), (0.0, 1.0), (0.0, 2.0))
        p.frame("t < & >", "x (m)", "y (N)")
        p.line([0, 1], [0, 3], style.AFTER, data={"curve": "fast after"})
        s.data["figure"] = "test"
        return s

    text = svg.write(draw(), standalone=True)
    root = ET.fromstring(text.split("?>", 1)[1])
    assert root.get("data-figure") == "test"
    assert "t &lt; &amp; &gt;" in text
    assert text == svg.write(draw(), standalone=True)
    # clipped to the panel: the line to y = 3 is drawn, the clip is defined and used
    assert 'clip-path="url(#fc0)"' in text and '<clipPath id="fc0">' in text
    png1, png2 = figures.render(draw(), "png", 1.0), figures.render(draw(), "png", 1.0)
    assert png1 == png2 and png1[:8] == b"\x89PNG\r\n\x1a\n"
    assert int.from_bytes(png1[16:20], "big") == 300  # the scene's size, scale 1
    assert figures.render(draw(), "pdf")[:5] == b"%PDF-"
    with pytest.raises(ValueError, match=r"\.svg, \.png or \.pdf"):
        figures.render(draw(), "gif")


def test_diverging_map_is_centred_on_zero() -> None:
    c = style.diverging([-2.0, 0.0, 2.0, 1e-3], 2.0)
    assert c[1] == "#f7f7f7" and c[3] == "#f7f7f7"  # white at zero
    r, _, b = (int(c[0][i:i + 2], 16) for i in (1, 3, 5))
    assert b > r  # negative blue
    r, _, b = (int(c[2][i:i + 2], 16) for i in (1, 3, 5))
    assert r > b  # positive red


def test_arrows_are_cut_and_the_key_names_the_cut() -> None:
    s = Scene(400, 300)
    grid = np.array([[x, y] for x in np.linspace(0, 0.4, 5) for y in np.linspace(0, 0.3, 4)])
    f = np.tile([1.0, 0.0], (len(grid), 1))
    f[0] = [50.0, 0.0]  # one needle
    panel = fields.spatial_panel(s, (40, 20, 300, 220), grid, "t")
    spacing = 0.1
    scale = fields.arrow_scale_px(panel, f, spacing)
    cut = fields.arrows(panel, grid, f, scale, style.MODEL,
                           fields.ARROW_CLIP * spacing * panel.px_per_x)
    assert cut == 1
    # the other arrows are long enough to read: the 90th percentile spans 80% of a step
    assert 0.79 < 1.0 / scale / (spacing * panel.px_per_x) < 0.81
    fields.arrow_key(s, 40, 280, 1.0, scale, style.MODEL, cut, 2.0)
    assert "= 1 N; 1 cut at 2 N (thick)" in svg.write(s)


def test_a_row_without_change_says_so() -> None:
    arm = Arm.from_params(synthesize({"elbow": "severe"}))
    from fieldbank.evaluate.compare import standard_grid

    g = standard_grid(arm, 9)
    f = arm.endpoint_force(g)
    s = Scene(1080, fields.row_height(g, arm.rest_position()))
    info = fields.field_row(s, 0, g, f, f, "static", rest_m=arm.rest_position())
    assert info.diff_max_n == 0.0
    assert "no change" in svg.write(s)
    assert 'data-field="change"' not in svg.write(s)


# --- the read-outs behind the figures -------------------------------------------------------
@pytest.mark.parametrize("scale_beta", [False, True])
def test_stretch_course_equals_the_full_time_course(scale_beta: bool) -> None:
    """Reflex torque is linear in α: one set of profiles gives every week exactly."""
    arm = Arm.from_params(synthesize({"elbow": "severe", "shoulder": "mild"}))
    plan = Plan.of(Botulinum({"ef": 150.0}, weeks_since=15, scale_beta=scale_beta),
                   Lengthening(group="bf", delta_m=0.01),
                   Botulinum({"ef": 100.0, "ee": 200.0, "sf": 50.0}, weeks_since=3))
    weeks = np.arange(0.0, 25.0, 3.0)
    full = time_course(arm, plan, weeks)
    light = stretch_course(arm, plan, weeks)
    assert light.plan_week == 3.0
    for name in full.stretch_peak_n_m:
        np.testing.assert_allclose(light.fast_peak_n_m[name], full.stretch_peak_n_m[name],
                                   rtol=1e-12, atol=1e-12)
    for g in full.effect:
        np.testing.assert_allclose(light.effect[g], full.effect[g], rtol=0, atol=0)
    # the injected groups' stretch loses torque at the peak and gets it back later
    ext = light.fast_peak_n_m["elbow extension"]
    assert ext[2] < ext[0] - 0.5 and ext[-1] > ext[2]


@pytest.mark.parametrize("side", ["right", "left"])
def test_lengthening_direction_lengthens_the_group_fastest(side: str) -> None:
    arm = Arm.from_params(ArmParams.from_anthropometry(70.0, 1.7, side))
    x0 = arm.rest_position()
    rng = np.random.default_rng(3)
    for k, g in enumerate(GROUPS):
        v = lengthening_direction(arm, g)
        assert abs(np.hypot(*v) - 1) < 1e-12

        def rate(u: np.ndarray, k: int = k) -> float:
            q = arm.ik(np.array([x0, x0 + 1e-6 * u]))
            return float((arm.muscle_lengths(q)[1, k] - arm.muscle_lengths(q)[0, k]) / 1e-6)

        best = rate(v)
        assert best > 0
        for th in rng.uniform(0, 2 * np.pi, 12):
            assert rate(np.array([np.cos(th), np.sin(th)])) <= best + 1e-6


# --- a botulinum report shows the change, for a flexor and for an extensor injection -------
@pytest.fixture(scope="module")
def cohort(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    root = tmp_path_factory.mktemp("cohort")
    url = f"sqlite:///{root / 'cohort.sqlite3'}"
    with Database.open(url) as db:
        ids = store_cohort(db, 3)  # botulinum ef, botulinum ee, lengthening bf
    out = root / "report"
    res = run_cli("report", "--db", url, "--out", str(out), "--jobs", "1", "--no-date")
    assert res.exit_code == 0, res.output
    rows = {int(r["plan_id"]): r for r in csv.DictReader(
        io.StringIO((out / "metrics.csv").read_text(encoding="utf-8")))}
    return {"ids": ids, "rows": rows, "html": (out / "report.html").read_text("utf-8"),
            "json": json.loads((out / "metrics.json").read_text("utf-8"))}


def _section(html: str, plan_id: int) -> str:
    start = html.index(f'<section class="case" id="plan-{plan_id}">')
    return html[start:html.index("</section>", start)]


def _peak_px(svg: str, stretch: str, curve: str) -> float:
    (path,) = svg_paths(svg, stretch=stretch, curve=curve)
    return float(-min(p[:, 1].min() for p in path))


@pytest.mark.parametrize(("which", "group", "changed", "unchanged"), [
    (0, "ef", "elbow extension", "elbow flexion"),
    (1, "ee", "elbow flexion", "elbow extension"),
])
def test_botulinum_report_shows_the_change_of_the_treated_group(
        cohort: dict[str, Any], which: int, group: str, changed: str, unchanged: str) -> None:
    plan_id = cohort["ids"][which]
    row = cohort["rows"][plan_id]
    assert row["treated_groups"] == group
    key, other = changed.replace(" ", "_"), unchanged.replace(" ", "_")
    # the CSV: the fast stretch that lengthens the injected group loses torque, its
    # velocity-dependent part most; the slow stretch and the other direction barely move
    fb, fa = float(row[f"{key}_fast_n_m_before"]), float(row[f"{key}_fast_n_m_after"])
    vb = float(row[f"{key}_velocity_dependent_n_m_before"])
    va = float(row[f"{key}_velocity_dependent_n_m_after"])
    assert fa < 0.9 * fb and va < 0.7 * vb
    sb, sa = float(row[f"{key}_slow_n_m_before"]), float(row[f"{key}_slow_n_m_after"])
    assert abs(sa - sb) < 0.02 * sb
    assert row[f"{other}_fast_n_m_after"] == row[f"{other}_fast_n_m_before"]
    assert float(row[f"severity_{group}_dynamic_score_after"]) < \
        float(row[f"severity_{group}_dynamic_score_before"])
    assert float(row["static_diff_rms_n"]) == 0.0
    # the figure: its own curve data show the drop in the treated stretch only
    sec = _section(cohort["html"], plan_id)
    stretches = sec[sec.index('data-figure="stretches"'):]
    stretches = stretches[:stretches.index("</svg>")]
    assert _peak_px(stretches, changed, "fast after") < \
        _peak_px(stretches, changed, "fast before") - 5.0
    assert _peak_px(stretches, unchanged, "fast after") == \
        _peak_px(stretches, unchanged, "fast before")
    assert f"treated: {group}" in stretches
    moving = sec[sec.index('data-figure="moving-field"'):]
    assert float(re.search(r'data-change-max-n="([^"]+)"', moving).group(1)) > 0.1  # type: ignore[union-attr]
    assert "lengthens the treated " + group in moving
    assert "no change (largest |ΔF| 0 N" in sec  # the static field, said in words
    # the time course draws the injected group's effect
    assert f'data-group="{group}"' in sec[sec.index('data-figure="timecourse"'):]
    # the metrics table of the page shows this case's treated stretch
    table = cohort["html"][cohort["html"].index('<table class="metrics">'):]
    line = table[table.index(f'href="#plan-{plan_id}"'):]
    line = line[:line.index("</tr>")]
    assert changed in line


def test_every_reflex_read_out_is_in_the_csv_and_the_json(cohort: dict[str, Any]) -> None:
    keys = {k for k, _ in ALL_COLUMNS}
    for j, d in STRETCHES:
        for _, stem, _ in STRETCH_READOUTS:
            for when in ("before", "after"):
                assert f"{j}_{d}_{stem}_{when}" in keys
    for g in GROUPS:
        for c in COMPONENTS:
            for when in ("before", "after"):
                assert f"severity_{g}_{c}_{when}" in keys
                assert f"severity_{g}_{c}_score_{when}" in keys
    for row in cohort["rows"].values():
        for j, d in STRETCHES:
            float(row[f"{j}_{d}_fast_n_m_before"])  # a number in every case
            float(row[f"{j}_{d}_velocity_dependent_n_m_after"])
    for case in cohort["json"]["cases"]:
        stretches = case["comparison"]["stretches"]
        assert set(stretches) == {f"{j} {d}" for j, d in STRETCHES}
        for name in stretches:
            for when in ("before", "after"):
                for field in ("slow_torque_n_m", "peak_torque_n_m", "reflex_torque_n_m",
                              "catch_angle_deg", "slow_stop_angle_deg", "dynamic_range_deg"):
                    assert field in stretches[name][when]
        if "botulinum" in case["kinds"]:
            tc = case["timecourse"]
            assert set(tc["fast_peak_n_m"]) == {f"{j} {d}" for j, d in STRETCHES}
            assert len(tc["weeks"]) == 25


def test_the_page_summary_contents_and_sections(cohort: dict[str, Any]) -> None:
    html = cohort["html"]
    order = [html.index(s) for s in ('<h2 id="summary">', '<h2 id="contents">',
                                     '<h2 id="metrics">', '<section class="patient"')]
    assert order == sorted(order)
    summary = html[order[0]:order[1]]
    assert 'data-figure="cohort-change"' in summary
    for code in ("SYN-C000", "SYN-C001", "SYN-C002"):
        assert f">{code}</a>" in html[order[1]:order[2]]
    assert html.count('<section class="case"') == 3
    assert "@media print" in html and "break-before: page" in html


def test_no_figure_uses_tiny_type(cohort: dict[str, Any]) -> None:
    sizes = [float(v) for v in re.findall(r'font-size="([0-9.]+)"', cohort["html"])]
    assert sizes and min(sizes) >= style.FONT_SMALL


def test_figures_stay_within_the_size_budget(cohort: dict[str, Any]) -> None:
    for plan_id in cohort["ids"]:
        assert len(_section(cohort["html"], plan_id).encode("utf-8")) < 100_000


def test_probes_unchanged_by_the_plan_are_said_not_drawn() -> None:
    """Botulinum into the elbow flexors leaves the seed's pull and semi-ellipse (which shorten
    them) as they were: two identical curves would read as "the plan does nothing", so the
    report says so in words; a lengthening changes the passive force along them: drawn."""
    before = Arm.from_params(synthesize({"elbow": "severe"}))
    for plan, drawn in ((Plan.of(Botulinum({"ef": 150.0}, weeks_since=6.0)), False),
                        (Plan.of(Lengthening(group="ef", delta_m=0.01)), True)):
        after = Arm.from_params(plan.apply(before.params))
        c = compare(before, after, Conditions.standard(before))
        diff = max(float(np.max(np.abs(a.force_n - b.force_n))) for _, b, a in c.probe_rows())
        assert (diff > fields.NO_CHANGE) is drawn
        figs = {f.key: f for f in case_figures(before, after, c, plan)}
        assert (figs["probes"].scene is not None) is drawn
        if not drawn:
            assert "no change" in figs["probes"].caption
