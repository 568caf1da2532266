"""Plain text of ``fieldbank whatif``: a three-line summary, then tables within 100 columns.

Read from the top: the model and the plan; the summary (what changes most in words and units,
the grades that change, the warnings that matter; :mod:`fieldbank.interventions.summary`); the
joint stretches (resisting torque slow and fast, its velocity-dependent part, the Tardieu-style
catch); the grades per muscle group; what the prediction rests on. ``--detail`` adds the field
change, the probing motions, the 95% intervals and the weeks after an injection; ``--json``
has everything. Terms are explained in docs/glossary.md.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence
from typing import TYPE_CHECKING

from fieldbank.interventions.defaults import DOSE_UNIT
from fieldbank.params import GROUP_NAMES

if TYPE_CHECKING:  # typing only: 'whatif --help' loads no numerics
    from fieldbank.evaluate.compare import Comparison
    from fieldbank.evaluate.probing import JointStretch
    from fieldbank.evaluate.severity import ComponentGrade
    from fieldbank.interventions.guesses import Guesses
    from fieldbank.interventions.whatif import WhatIf

#: Widest line the text output uses (tables are laid out within it; prose is wrapped to it).
WIDTH = 100
GLOSSARY = "docs/glossary.md"


def _pct(before: float, after: float) -> str:
    if abs(before) < 1e-12:
        return "" if abs(after) < 1e-12 else "(new)"
    return f"{100.0 * (after - before) / before:+.0f}%"


def _deg(rad: float) -> str:
    return f"{math.degrees(rad):4.0f}°"


def _angle(deg: float | None) -> str:
    return "—" if deg is None else f"{deg:.0f}"


def _pair(b: float | None, a: float | None) -> str:
    return f"{_angle(b)} → {_angle(a)}"


def _wrap(text: str, indent: str = "  ", first: str | None = None) -> list[str]:
    return textwrap.wrap(text, WIDTH, initial_indent=indent if first is None else first,
                         subsequent_indent=indent + "  ", break_on_hyphens=False) or [""]


def _columns(heads: Sequence[Sequence[str]], rows: Sequence[Sequence[str]]) -> list[str]:
    """Header lines and rows, the first column left-aligned, the others right-aligned; each
    column as wide as its widest cell, two spaces apart: never one cell run into the next."""
    widths = [max(len(x) for x in (*h, *(r[i] for r in rows))) for i, h in enumerate(heads)]

    def line(row: Sequence[str]) -> str:
        return (f"{row[0]:<{widths[0]}}" + "".join(f"  {v:>{w}}" for v, w in
                                                   zip(row[1:], widths[1:], strict=True)))
    return ([line([h[k] for h in heads]).rstrip() for k in range(len(heads[0]))]
            + [line(r) for r in rows])


def _stretch_lines(c: Comparison) -> list[str]:
    """Per joint and direction: slow and fast resisting torque and its velocity-dependent part;
    then where each stretch meets the catch (a table of its own: both within 100 columns)."""
    first: JointStretch = c.before.stretches[0]
    rows = list(c.stretch_rows())
    pct_w = max([len(_pct(b.peak_torque_n_m, a.peak_torque_n_m)) for _, b, a in rows]
                + [len(_pct(b.reflex_torque_n_m, a.reflex_torque_n_m)) for _, b, a in rows])
    out = _columns(
        [("Joint stretch", "(before → after)"), (f"slow {first.slow_speed_deg_s:.0f}°/s", "N·m"),
         (f"fast {first.speed_deg_s:.0f}°/s", "N·m"), ("velocity-dependent", "N·m")],
        [(name, f"{b.slow_torque_n_m:.2f} → {a.slow_torque_n_m:.2f}",
          f"{b.peak_torque_n_m:.2f} → {a.peak_torque_n_m:.2f} "
          f"{_pct(b.peak_torque_n_m, a.peak_torque_n_m):>{pct_w}}",
          f"{b.reflex_torque_n_m:.2f} → {a.reflex_torque_n_m:.2f} "
          f"{_pct(b.reflex_torque_n_m, a.reflex_torque_n_m):>{pct_w}}")
         for name, b, a in rows])
    out.append("")
    out += _columns(
        [("Catch angle", "(before → after)"), ("R1 °", "fast"), ("R2 °", "slow"),
         ("R2−R1 °", "")],
        [(name, _pair(b.catch_angle_deg, a.catch_angle_deg),
          _pair(b.slow_stop_angle_deg, a.slow_stop_angle_deg),
          _pair(b.dynamic_range_deg, a.dynamic_range_deg)) for name, b, a in rows])
    thresholds = ", ".join(f"{name} {b.catch_threshold_n_m:.2f} N·m"
                           for name, b, _ in c.stretch_rows())
    out += _wrap("R1 and R2: where the fast and the slow stretch first meet the catch torque "
                 f"(twice the unimpaired arm's largest slow-stretch torque: {thresholds}); "
                 "— never within the range; R2−R1 (the velocity-dependent part of the range) "
                 "only where both are reached. Angles: elbow 0° straight, shoulder from +x, "
                 "flexion positive.")
    return out


def _grade_cell(b: ComponentGrade, a: ComponentGrade, scores: bool) -> str:
    """'mild → very mild', with scores '(2.1 → 1.0)'; a grade and score the plan leaves as
    they were once, '= unimpaired (0.0)', so the table keeps within its width."""
    if not scores:
        return f"{b.text()} → {a.text()}"
    if b.text() == a.text() and f"{b.score:.1f}" == f"{a.score:.1f}":
        return f"= {b.text()} ({b.score:.1f})"
    return f"{b.text()} → {a.text()} ({b.score:.1f} → {a.score:.1f})"


def _severity_lines(c: Comparison, detail: bool) -> list[str]:
    """Per muscle group: passive and dynamic grade before → after (scores with --detail)."""
    rows = [(f"{g} {GROUP_NAMES.get(g, sb.name)}", _grade_cell(sb.passive, sa.passive, detail),
             _grade_cell(sb.dynamic, sa.dynamic, detail)) for g, sb, sa in c.severity_rows()]
    head = ("Severity per muscle group", "contracture (passive)", "spasticity (dynamic)")
    # columns as wide as their widest cell, two spaces apart: never one cell run into the next
    name_w = max(len(r[0]) for r in (head, *rows)) + 2
    wide = max(len(r[1]) for r in (head, *rows)) + 2
    out = [f"{head[0]:<{name_w}}{head[1]:<{wide}}{head[2]}"]
    out += [f"{name:<{name_w}}{passive:<{wide}}{dynamic}" for name, passive, dynamic in rows]
    flagged = sorted({n for _, sb, _ in c.severity_rows() for k in ("passive", "dynamic")
                      for n in sb.component(k).unidentified})
    graded = "; ".join(f"{g} on {sb.stretch}" for g, sb, _ in c.severity_rows()) if detail \
        else ""
    out += _wrap("before → after" + ("; = unchanged" if detail else "")
                 + "; + beyond severe; * rests on a parameter the fit did not "
                 "identify" + (f" ({', '.join(flagged)})" if flagged else "")
                 + ("; score 0 unimpaired … 4 severe; graded on: " + graded if detail else ""))
    return out


def _rests_on(g: Guesses | None, warnings: Sequence[str]) -> list[str]:
    out = ["What the prediction rests on"]
    b = None if g is None else g.basis
    if b is None:
        out.append("  no fit: the model was not fitted to measured maps (no fit uncertainty, "
                   "nothing guessed)")
    else:
        state = " (accepted by the user)" if g is not None and g.accepted_poor_fit else ""
        out.append(f"  fit {b.fit_id}: status {b.status}{state}; goodness of fit {b.verdict}")
    if g is not None and g.guesses:
        held = [x.name for x in g.guesses if x.held]
        other = [f"{x.name} = {x.value:.4g}" for x in g.guesses if not x.held]
        text = f"not identified by the maps ({len(g.guesses)}; the prediction depends on them): "
        text += ", ".join(held) + (" (held at the unimpaired value)" if held else "")
        text += ("; " if held and other else "") + ", ".join(other)
        out += _wrap(text)
    for n in (g.notes if g is not None else ()):  # a sentence, or 'ef: how to see it'
        each = n[2:4] == ": "
        out += _wrap(n if each else n[0].upper() + n[1:], indent="    " if each else "  ")
    for w in warnings:
        out += _wrap(f"WARNING: {w}", first="  ", indent="  ")
    return out


def _field_lines(c: Comparison) -> list[str]:
    n = c.before.conditions.grid_m.shape[0]
    out = [f"Field change on {n} grid points (moving: "
           f"{c.before.conditions.velocities[-1].shape[0]} directions)",
           f"{'speed':>6} {'RMS |F| N':>17} {'RMS |ΔF|':>9} {'max |ΔF|':>9} {'at (x, y) m':>17}"
           f" {'area ×':>7} {'Δθ':>6} {'shape ratio':>15}",
           f"{'m/s':>6} {'before → after':>17} {'N':>9} {'N':>9} {'':>17} {'median':>7}"
           f" {'mean':>6} {'before → after':>15}"]
    for f in c.fields:
        at = (f"({f.diff_max_at_m[0]:+.3f}, {f.diff_max_at_m[1]:+.3f})" if f.diff_max_n > 0
              else "-")
        rms = f"{f.force_rms_before_n:.2f} → {f.force_rms_after_n:.2f}"
        shape = f"{f.shape_ratio_before_median:.1f} → {f.shape_ratio_after_median:.1f}"
        out.append(f"{f.speed_m_per_s:6.2f} {rms:>17} {f.diff_rms_n:9.2f} {f.diff_max_n:9.2f}"
                   f" {at:>17} {f.area_ratio_median:7.3f} {f.orientation_change_deg_mean:5.1f}°"
                   f" {shape:>15}")
    p = c.potential
    where = (f" at ({p.max_at_m[0]:+.3f}, {p.max_at_m[1]:+.3f}) m" if p.max_abs_j > 0 else "")
    out += _wrap(f"potential energy ΔU: mean {p.mean_j:+.3f} J, RMS {p.rms_j:.3f} J, "
                 f"largest {p.max_abs_j:.3f} J{where}")
    return out


def _probe_lines(c: Comparison) -> list[str]:
    out = [f"{'Probing motion':<15}{'peak force N':>22}{'direction at peak':>20}"
           f"{'mean direction':>18}"]
    for name, b, a in c.probe_rows():
        peak = f"{b.peak_force_n:.2f} → {a.peak_force_n:.2f}"
        out.append(f"{name:<15}{peak:>16}{_pct(b.peak_force_n, a.peak_force_n):>6}"
                   f"{_deg(b.peak_direction_rad) + ' → ' + _deg(a.peak_direction_rad):>20}"
                   f"{_deg(b.mean_direction_rad) + ' → ' + _deg(a.mean_direction_rad):>18}")
    return out


def _iv(v: float, lo: float, hi: float, signed: bool = False) -> str:
    f = "+.2f" if signed else ".2f"
    return f"{v:{f}} [{lo:{f}}, {hi:{f}}]"


def _interval_lines(g: Guesses) -> list[str]:
    if not g.intervals:
        return [f"No 95% intervals: {g.interval_note}."] if g.interval_note else []
    out = _wrap(f"Predicted read-outs with 95% intervals ({g.interval_note})", indent="",
                first="")
    out.append(f"{'read-out':<37}{'before':>21}{'after':>21}{'change':>21}")
    for i in g.intervals:
        name = f"{i.metric}, {i.unit}" + (" *" if i.rests_on_guess else "")
        if i.rests_on_guess and i.identified is not None:
            # what the maps identified on the row; the guess's interval apart, below, marked
            bl, bh, al, ah, cl, ch = i.identified
            out.append(f"{name[:37]:<37}{_iv(i.before, bl, bh):>21}{_iv(i.after, al, ah):>21}"
                       f"{_iv(i.change, cl, ch, True):>21}")
            out.append(f"{'  * with the guesses drawn':<37}"
                       f"{_iv(i.before, i.before_low, i.before_high):>21}"
                       f"{_iv(i.after, i.after_low, i.after_high):>21}"
                       f"{_iv(i.change, i.change_low, i.change_high, True):>21}")
            continue
        out.append(f"{name[:37]:<37}"
                   f"{_iv(i.before, i.before_low, i.before_high):>21}"
                   f"{_iv(i.after, i.after_low, i.after_high):>21}"
                   f"{_iv(i.change, i.change_low, i.change_high, True):>21}")
    if any(i.rests_on_guess for i in g.intervals):
        out += _wrap("* rests on a guess: the row gives the interval of what the maps "
                     "identified (the guessed parameters at their held value), the line under "
                     "it the interval with them drawn from their prior range.", indent="",
                     first="")
    return out


def _course_lines(res: WhatIf) -> list[str]:
    course = res.course
    if course is None:
        return []
    names = list(course.stretch_peak_n_m)[:2]
    groups = list(course.effect)[:4]
    out = ["Week by week after the injection (effect: drop of α; fast-stretch peak torque N·m)",
           f"{'week':>5}" + "".join(f"{'effect ' + g:>11}" for g in groups)
           + "".join(f"{n:>20}" for n in names) + f"{'pull peak N':>13}"]
    pull = course.probe_peak_n.get("pull")
    for i, wk in enumerate(course.weeks):
        row = "".join(f"{course.effect[g][i]:11.3f}" for g in groups)
        row += "".join(f"{course.stretch_peak_n_m[n][i]:20.2f}" for n in names)
        row += f"{pull[i]:13.2f}" if pull is not None else ""
        out.append(f"{wk:5g}{row}")
    return out


def render_text(res: WhatIf, detail: bool = False) -> str:
    """The text of a what-if: summary first, every line within :data:`WIDTH` columns."""
    c = res.comparison
    out: list[str] = []
    out += _wrap(f"Model: {res.source.description}", indent="", first="")
    if res.source.fitted_on is not None:
        for line in res.source.fitted_on.lines():
            out += _wrap(line)
    out.append("Plan:")
    for line in res.plan.describe():
        out += _wrap(line)
    out.append("Summary")
    for line in res.summary().lines:
        out += _wrap(line)
    out.append("Model predictions, not treatment advice.")
    inv = res.inverse
    if inv is not None:
        out.append("")
        out += _wrap(f"Inverse what-if (botulinum split under a total of "
                     f"{inv.total_units_limit:g} U, week {inv.weeks_since:g}; {DOSE_UNIT}): "
                     + ", ".join(f"{g} {u:g} U" for g, u in inv.units.items())
                     + f"; distance to unimpaired: untreated {inv.distance_untreated_n:.2f} N, "
                     f"even split {inv.distance_even_split_n:.2f} N, best {inv.distance_n:.2f} "
                     f"N ({inv.evaluations} evaluations). {inv.notice}", indent="", first="")
    out += ["", *_stretch_lines(c), "", *_severity_lines(c, detail), "",
            *_rests_on(res.guesses, res.all_warnings())]
    if detail:
        out += ["", *_field_lines(c), "", *_probe_lines(c)]
        if res.guesses is not None:
            out += ["", *_interval_lines(res.guesses)]
        course = _course_lines(res)
        out += ["", *course] if course else []
        out += ["", f"Terms: {GLOSSARY}. Everything, with profiles: --json."]
    else:
        out += ["", *_wrap("More: --detail (field change, probing motions, 95% intervals, "
                           f"weeks after an injection), --json (everything). Terms: {GLOSSARY}.",
                           indent="", first="")]
    # a line a table could not keep within the width is wrapped, never cut: nothing hidden
    return "\n".join(w for line in out for w in (
        [line] if len(line) <= WIDTH else _wrap(line.strip(), indent=" " * (
            len(line) - len(line.lstrip()) + 2), first=line[:len(line) - len(line.lstrip())])))
