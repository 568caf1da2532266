"""``whatif --plot``: the report's figures of one what-if, on one page.

The same figures as a report case (:func:`fieldbank.interventions.report.figures.case.case_figures`:
the joint stretches, the moving field in the direction that lengthens the treated groups, the
static field and stiffness when the plan changes them, the grades, the probing motions, the
botulinum time course), stacked under a title, saved by :func:`fieldbank.figures.save`
(SVG, or PNG or PDF drawn from the same scene).
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping
from pathlib import Path

from fieldbank.evaluate.compare import Comparison
from fieldbank.figures import figure_format, save
from fieldbank.figures.scene import Scene
from fieldbank.figures.style import FONT, FONT_TITLE, GREY
from fieldbank.interventions.catalogue import Botulinum
from fieldbank.interventions.course import stretch_course
from fieldbank.interventions.plan import Plan
from fieldbank.interventions.report.figures.case import case_figures
from fieldbank.interventions.report.figures.common import WIDTH
from fieldbank.model import Arm, FloatArray

#: Characters per line of a note in a figure page (12 px type over the page's width).
NOTE_CHARS = 150


def comparison_page(arm_b: Arm, arm_a: Arm, c: Comparison, plan: Plan | None,
                    title: str = "",
                    bands: Mapping[str, Mapping[str, tuple[FloatArray, FloatArray]]]
                    | None = None) -> Scene:
    """The what-if's figures under a title, one below the other; a figure the plan leaves
    unchanged is a line of text saying so."""
    course = (stretch_course(arm_b, plan) if plan is not None
              and any(isinstance(s, Botulinum) for s in plan.steps) else None)
    head = Scene(WIDTH, 44)
    head.text(10, 22, f"{title} (model predictions, not treatment advice)" if title else
              "What-if (model predictions, not treatment advice)", FONT_TITLE + 2, bold=True)
    parts = [head]
    for f in case_figures(arm_b, arm_a, c, plan, course, bands):
        if f.scene is not None:
            parts.append(f.scene)
            continue
        lines = textwrap.wrap(f.caption, NOTE_CHARS)
        note = Scene(WIDTH, 18 * len(lines) + 10)
        for i, line in enumerate(lines):
            note.text(62, 16 + 18 * i, line, FONT, colour=GREY)
        parts.append(note)
    page = Scene.stack(parts, gap=18, label=title or "what-if")
    page.data["figure"] = "whatif"
    return page


def plot_comparison(arm_b: Arm, arm_a: Arm, c: Comparison, plan: Plan | None,
                    path: str | Path, title: str = "",
                    bands: Mapping[str, Mapping[str, tuple[FloatArray, FloatArray]]]
                    | None = None) -> Path:
    """Write :func:`comparison_page` as SVG, PNG or PDF (by the suffix); returns the path."""
    figure_format(path)  # before the figures are built
    return save(comparison_page(arm_b, arm_a, c, plan, title, bands), path)
