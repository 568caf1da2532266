"""One figure system: every figure option writes .svg, .png and .pdf; every kind of figure says
what it shows in its SVG's data attributes, and they read back to the values drawn."""

from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import click
import numpy as np
import pytest
from click.testing import CliRunner

from fieldbank.cli.main import COMMANDS, cli
from fieldbank.cli.options import figure_path
from fieldbank.errors import ValidationError
from fieldbank.evaluate.classify import classify
from fieldbank.evaluate.design import (
    score_probes,
    seed_probes,
    severity_candidates,
)
from fieldbank.evaluate.severity import synthesize
from fieldbank.figures import FORMATS, figure_format, render, save, svg
from fieldbank.figures.fields import map_figure, spatial_height, spatial_limits
from fieldbank.figures.fit import fit_figure
from fieldbank.figures.panel import Panel
from fieldbank.figures.probes import classification_figure, probe_figure
from fieldbank.figures.scene import Scene
from fieldbank.fitting import ArmFitter
from fieldbank.fitting.synthetic import impaired_params, synthetic_patient
from fieldbank.maps import postural_map
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from tests.haptic_util import mild_shoulder_trace
from tests.report_helpers import svg_paths

MAGIC = {"svg": b"<?xml", "png": b"\x89PNG\r\n\x1a\n", "pdf": b"%PDF-"}


def _commands(group: click.Group, prefix: str = "") -> Iterator[tuple[str, click.Command]]:
    for name in group.list_commands(click.Context(group)):
        cmd = group.get_command(click.Context(group), name)
        assert cmd is not None
        path = f"{prefix} {name}".strip()
        if isinstance(cmd, click.Group):
            yield from _commands(cmd, path)
        else:
            yield path, cmd


def test_every_plot_option_checks_its_format_before_any_work() -> None:
    plots = {path: opt for path, cmd in _commands(cli) for opt in cmd.params
             if isinstance(opt, click.Option) and "--plot" in opt.opts}
    assert set(plots) == {"fit", "whatif", "probe design", "probe classify", "probe paths"}
    for path, opt in plots.items():
        assert opt.callback is figure_path, path
        assert ".svg, .png or .pdf" in (opt.help or ""), path
    assert set(COMMANDS) >= {"fit", "whatif", "probe", "field"}


@pytest.fixture(scope="module")
def trace(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return mild_shoulder_trace(tmp_path_factory.mktemp("traces") / "probe.h5")


CASES = {
    "field": lambda out, trace: ["field", "postural", "--grid", "6", "--out", out],
    "whatif": lambda out, trace: ["whatif", "--severity", "elbow=severe", "--botox", "ef=100",
                                  "--plot", out],
    "probe paths": lambda out, trace: ["probe", "paths", "--radii-cm", "5", "--plot", out],
    "probe classify": lambda out, trace: ["probe", "classify", str(trace), "--levels",
                                          "mild,severe", "--no-next", "--plot", out],
}


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("case", list(CASES))
def test_every_figure_option_writes_svg_png_and_pdf(case: str, fmt: str, trace: Path,
                                                    tmp_path: Path) -> None:
    out = tmp_path / f"figure.{fmt}"
    r = CliRunner().invoke(cli, CASES[case](str(out), trace))
    assert r.exit_code == 0, r.output
    assert out.read_bytes().startswith(MAGIC[fmt])


@pytest.mark.parametrize("fmt", FORMATS)
def test_fit_and_probe_design_plots_in_every_format(fmt: str, tmp_path: Path) -> None:
    """``probe design --plot`` through the command line; ``fit --plot`` draws the fit figure
    and saves it the same way (the command's own test runs it end to end)."""
    out = tmp_path / f"probes.{fmt}"
    r = CliRunner().invoke(cli, ["probe", "design", "--max-probes", "1", "--plot", str(out)])
    assert r.exit_code == 0, r.output
    assert out.read_bytes().startswith(MAGIC[fmt])
    assert save(_fit_scene(), tmp_path / f"fit.{fmt}").read_bytes().startswith(MAGIC[fmt])


@pytest.mark.parametrize("args", [["probe", "paths"], ["probe", "design"],
                                  ["whatif", "--severity", "elbow=severe", "--botox", "ef=1"]])
def test_a_wrong_format_is_refused_before_any_work(args: list[str], tmp_path: Path) -> None:
    out = tmp_path / "figure.jpg"
    r = CliRunner().invoke(cli, [*args, "--plot", str(out)])
    assert r.exit_code == 1, r.output
    assert "figures are written as .svg, .png or .pdf; got '.jpg'" in r.stderr
    assert not out.exists()
    with pytest.raises(ValidationError, match="no extension"):
        figure_format(tmp_path / "figure")
    assert figure_format("x.PDF") == "pdf"


def test_importing_the_figures_loads_no_matplotlib() -> None:
    code = ("import sys, fieldbank.figures, fieldbank.figures.probes, fieldbank.figures.fit; "
            "import fieldbank.interventions.report.figures; "
            "print('matplotlib' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"


# --- round trips: what a figure shows, read back from its SVG ---------------------------------

def _root(scene: Any) -> ET.Element:
    text = render(scene, "svg").decode("utf-8")
    return ET.fromstring(text.split("?>", 1)[1])


def _fit_scene() -> Any:
    base = ArmParams.from_anthropometry()
    pat = synthetic_patient(impaired_params("shoulder", "mild", base), seed=5)
    f = ArmFitter(max_evals=40).fit(pat.maps[:2], base)
    return fit_figure(f.maps_, f.predict(f.maps_), f.r2_, "fit")


def test_fit_figure_round_trip() -> None:
    base = ArmParams.from_anthropometry()
    pat = synthetic_patient(impaired_params("shoulder", "mild", base), seed=5)
    f = ArmFitter(max_evals=40).fit(pat.maps[:2], base)
    scene = fit_figure(f.maps_, f.predict(f.maps_), f.r2_, "fit")
    root = _root(scene)
    assert root.get("data-figure") == "fit" and root.get("data-maps") == "2"
    assert root.get("data-kinds") == " ".join(m.kind for m in f.maps_)
    assert [float(v) for v in root.get("data-r2", "").split()] == pytest.approx(f.r2_, abs=1e-4)
    text = svg.write(scene)
    postural = next(k for k, m in enumerate(f.maps_) if m.kind == "postural")
    n = f.maps_[postural].n
    for field in ("measured", "fitted"):
        shafts = [p for ps in svg_paths(text, field=field, map=str(postural)) for p in ps
                  if len(p) == 2]
        assert 0 < len(shafts) <= n  # one arrow per position (none shorter than a line)


def test_probe_figure_round_trip() -> None:
    cands = severity_candidates()
    motions = seed_probes(cands)
    score = score_probes(cands, motions)
    scene = probe_figure(score, cands, "seed")
    root = _root(scene)
    assert root.get("data-figure") == "probes"
    assert root.get("data-probes", "").split("|") == [m.name for m in motions]
    assert root.get("data-candidates", "").split("|") == [c.name for c in cands]
    assert float(root.get("data-information-bits", "nan")) == pytest.approx(
        score.summary()["information_bits"], abs=1e-3)
    text = svg.write(scene)
    # the drawn path of the pull has the motion's shape: its extent in px over the metres
    (path,) = svg_paths(text, probe="pull", kind="path")
    pts = np.vstack(path)
    m = motions[0].positions_m
    span_px = np.ptp(pts, axis=0)
    span_m = np.ptp(m, axis=0)
    ratio = span_px[np.argmax(span_m)] / span_m.max()
    assert span_px.min() / ratio == pytest.approx(span_m.min(), abs=2e-3)  # equal axes
    for c in cands:  # every candidate's force profile is drawn, on every probe
        for name in root.get("data-probes", "").split("|"):
            assert svg_paths(text, probe=name, candidate=c.name, curve="magnitude")


def test_classification_figure_round_trip(trace: Path) -> None:
    from fieldbank.haptic.probe import observation_from_trace
    from fieldbank.haptic.recording import read_trace_h5

    cands = severity_candidates(levels=("mild", "severe"))
    obs = observation_from_trace(read_trace_h5(trace), "probe", str(trace), None)
    cl = classify([obs], cands, next_probe=False)
    root = _root(classification_figure(cl))
    assert root.get("data-figure") == "classification" and root.get("data-best") == cl.best.name
    post = dict(kv.split("=") for kv in root.get("data-posterior", "").split("|"))
    assert {k: float(v) for k, v in post.items()} == pytest.approx(
        {c.name: float(p) for c, p in zip(cl.candidates, cl.posterior, strict=True)}, rel=1e-3)
    bars = {el.get("data-candidate"): el for el in root.iter()
            if el.get("data-candidate") and el.get("data-posterior")}
    widths = {k: float(next(iter(el)).get("width", "0")) for k, el in bars.items()}
    best = cl.best.name
    for k, w in widths.items():  # bar lengths in proportion to the posterior
        assert w == pytest.approx(widths[best] * float(post[k]) / float(post[best]), abs=0.3)


def test_field_map_round_trip() -> None:
    arm = Arm.from_params(synthesize({"elbow": "severe"}))
    grid = np.array([[x, y] for x in np.linspace(-0.2, 0.2, 5) for y in np.linspace(0.3, 0.5, 3)])
    m = postural_map(arm, grid)
    scene = map_figure(arm, m)
    root = _root(scene)
    assert root.get("data-figure") == "map" and root.get("data-kind") == "postural"
    assert root.get("data-positions") == str(len(grid))
    # the panel the figure drew on, rebuilt from the same rules: every arrow starts at its
    # position and points the way the force does (y up in metres, down on the page)
    extra = np.vstack([[0.0, 0.0], arm.rest_position()])
    h = spatial_height(grid, 460.0, extra)
    panel = Panel.at(Scene(1, 1), (70.0, 40.0, 460.0, h), *spatial_limits(grid, extra),
                     equal=True)
    px = panel.xy(grid)
    arrows = [p for ps in svg_paths(svg.write(scene), field="model") for p in ps if len(p) == 2]
    assert 0 < len(arrows) <= len(grid)
    for a in arrows:
        k = int(np.argmin(np.hypot(*(px - a[0]).T)))
        assert np.hypot(*(px[k] - a[0])) < 0.15
        d, f = a[1] - a[0], m.values[k]
        assert (d[0] * f[0] - d[1] * f[1]) / (np.hypot(*d) * np.hypot(*f)) > 0.99
