"""The report page: one self-contained HTML file, figures inline as SVG.

Written with the standard library (``html.escape``); no external resources, so the file can be
mailed or archived alone. Layout, for a clinic lead reading many cases:

1. title, the inputs (selection, number of cases, the date of writing unless left out);
2. **summary** (batches): cohort figures - the change per intervention kind and treated muscle
   group, and predicted against measured change where maps measured after a plan exist;
3. **contents**: one line per patient with links to each plan;
4. **metrics**: one row per case with the columns that matter for *that* case - the joint
   stretch that lengthens each treated group (fast and slow peak torque, the velocity-dependent
   part, the catch), the treated groups' grades, the field change - so the table fits a
   printed page; every read-out of every stretch and group is in ``metrics.csv`` and
   ``metrics.json``;
5. one section per patient, one subsection per plan: the plan, its warnings, the stretch
   read-outs (treated stretches first), the figures, the grades per muscle group, the field
   metrics.

A print stylesheet lays it out for A4 (``chromium --headless --print-to-pdf``): each case
starts a page, figures and tables are not split, figures scale to the page width. A small
script marks ``<body data-figures-ok="yes">`` once every figure has been laid out with a
non-zero size (read by the browser test).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from html import escape
from typing import Any

from fieldbank.evaluate.probing import STRETCHES
from fieldbank.evaluate.severity import MUSCLE_GROUP_NAMES
from fieldbank.evaluate.tone import GRADED_STRETCH
from fieldbank.interventions.realised import CONFIRMED, FAILED, INCONCLUSIVE, PARTIAL
from fieldbank.interventions.report.compute import COLUMNS, STRETCH_READOUTS, CaseResult
from fieldbank.interventions.report.figures.common import pct
from fieldbank.params import GROUPS

CSS = """
body { font-family: system-ui, "DejaVu Sans", sans-serif; margin: 1.5em auto; padding: 0 1em;
       max-width: 1180px; color: #222; line-height: 1.35; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; }
h2 { font-size: 1.25em; border-top: 3px solid #ccd; padding-top: 0.6em; margin-top: 1.8em; }
h3 { font-size: 1.08em; border-top: 1px solid #dde; padding-top: 0.5em; margin-top: 1.4em; }
table { border-collapse: collapse; font-size: 0.85em; margin: 0.6em 0; }
th, td { border: 1px solid #ccd; padding: 3px 6px; text-align: right; vertical-align: top; }
th { background: #eef; }
td.t, th.t { text-align: left; }
tr.treated td, tr.treated th { background: #fdf0e6; }
.note { color: #844; font-size: 0.92em; }
.terms dt { font-weight: bold; margin-top: 0.4em; }
.terms dd { margin: 0 0 0 1.5em; }
.warn { color: #a00; font-weight: bold; font-size: 0.95em; }
.guess { color: #666; font-style: italic; }
.verdict { display: inline-block; font-weight: bold; border-radius: 3px; padding: 0 0.35em;
           border: 1px solid; white-space: nowrap; }
.verdict.ok { color: #00684a; background: #e3f4ee; border-color: #009E73; }
.verdict.failed { color: #fff; background: #b03a00; border-color: #b03a00; }
.verdict.partial { color: #6b3d00; background: #fdecd2; border-color: #D55E00; }
.verdict.open { color: #444; background: #f0f0f4; border-color: #888; }
p.checked { font-size: 1em; line-height: 1.7; }
.checkitem { white-space: nowrap; }
.rests { font-size: 0.92em; }
.legend, .nochange { color: #555; font-size: 0.88em; max-width: 70em; }
.nochange { border-left: 3px solid #ccd; padding-left: 0.6em; }
.inputs td, .inputs th { text-align: left; }
table.metrics { width: 100%; }
table.metrics td { font-variant-numeric: tabular-nums; }
table.metrics td.t { white-space: normal; }
table.metrics .sub { color: #555; font-size: 0.92em; }
.down { color: #0a5a8a; } .up { color: #a33c00; }
ol.toc { columns: 2; font-size: 0.92em; }
ol.toc li { break-inside: avoid; margin-bottom: 0.2em; }
figure { margin: 0.8em 0 1.2em 0; }
figcaption { font-size: 0.88em; color: #444; max-width: 70em; }
svg.fig { max-width: 100%; height: auto; display: block; }
ul.steps { font-size: 0.95em; list-style: none; padding-left: 0.5em; }
@page { size: A4; margin: 12mm 10mm; }
@media print {
  body { max-width: none; margin: 0; padding: 0; font-size: 9pt; }
  section.patient, section.case { break-before: page; }
  section.patient > section.case:first-of-type { break-before: avoid; }
  figure, table, tr { break-inside: avoid; }
  h2, h3 { break-after: avoid; }
  svg.fig { width: 100% !important; height: auto !important; }
  table.metrics { font-size: 7pt; table-layout: fixed; }
  table.metrics th, table.metrics td { padding: 1px 3px; overflow-wrap: break-word; }
  table.clinical, table.kv { font-size: 7.5pt; }
  a { color: inherit; text-decoration: none; }
  ol.toc { font-size: 8pt; }
}
"""

SCRIPT = """
window.addEventListener("load", function () {
  var figs = Array.prototype.slice.call(document.querySelectorAll("svg.fig"));
  var bad = figs.filter(function (f) {
    var r = f.getBoundingClientRect();
    var drawn = f.querySelectorAll("path,rect,circle,ellipse").length;
    return !(r.width > 0 && r.height > 0 && drawn > 0);
  });
  document.body.setAttribute("data-figures", String(figs.length));
  document.body.setAttribute("data-figures-ok", bad.length === 0 ? "yes" : "no");
});
"""

TEXT_COLUMNS = {"patient", "plan_label", "kinds", "treated_groups", "sessions", "case_date",
                "severity_before", "severity_after", "warnings"}


def fmt(v: Any) -> str:
    """A table cell: floats to 4 significant digits, None as an em dash."""
    if v is None:
        return "—"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def _num(v: Any, digits: str = ".2f") -> str:
    """A number, '—' for none; never '-0'."""
    if v is None:
        return "—"
    text = f"{v:{digits}}"
    return text[1:] if text.startswith("-") and float(text) == 0 else text


def _change(row: Mapping[str, Any], key: str, digits: str = ".2f", rel: bool = True) -> str:
    """'b → a (Δ%)' of a before/after pair of the row, HTML."""
    b, a = row.get(key + "_before"), row.get(key + "_after")
    text = f"{_num(b, digits)} → {_num(a, digits)}"
    if rel and isinstance(b, float) and isinstance(a, float):
        p = pct(b, a)
        if p and p != "±0%":
            cls = "down" if a < b else "up"
            return f'{escape(text)} <span class="{cls}">({escape(p)})</span>'
    return escape(text)


def _angle_change(row: Mapping[str, Any], key: str) -> str:
    b, a = row.get(key + "_before"), row.get(key + "_after")
    return escape(f"{_num(b, '.0f')} → {_num(a, '.0f')}")


def case_stretches(row: Mapping[str, Any]) -> list[tuple[str, str]]:
    """The (joint, direction) stretches a case's columns show: the stretch each treated group
    is graded on (bi-articular groups at the elbow), in the standard order; elbow extension
    when no group is treated."""
    treated = str(row.get("treated_groups") or "").split()
    wanted = {GRADED_STRETCH[g] for g in treated if g in GRADED_STRETCH}
    return [s for s in STRETCHES if s in wanted] or [STRETCHES[0]]


def _overview(results: Sequence[CaseResult], patient_ids: Mapping[str, str]) -> list[str]:
    """The metrics table: one row per case, the columns chosen for that case."""
    head = ["patient", "plan", "treated", "stretch of the treated group",
            "fast peak (N·m)", "velocity-dep. part (N·m)", "slow peak (N·m)", "catch R1 (°)",
            "grades that change", "ΔF RMS (N): static; moving"]
    widths = (9, 9, 10, 10, 11, 11, 11, 7, 13, 9)  # % of the printed page
    out = ['<div class="scroll"><table class="metrics"><colgroup>']
    out += [f'<col style="width:{w}%">' for w in widths]
    out.append("</colgroup><thead><tr>")
    out += [f'<th class="t">{escape(h)}</th>' for h in head]
    out.append("</tr></thead><tbody>")
    for r in results:
        row = r.row
        stretches = case_stretches(row)
        keys = [f"{j}_{d}" for j, d in stretches]

        def lines(cells: list[str]) -> str:
            return "<br>".join(cells)

        treated = str(row.get("treated_groups") or "").split()
        grades = [escape(f"{g} {comp}: {row.get(f'severity_{g}_{comp}_before')} → "
                         f"{row.get(f'severity_{g}_{comp}_after')}")
                  for g in GROUPS for comp in ("dynamic", "passive")
                  if row.get(f"severity_{g}_{comp}_before")
                  != row.get(f"severity_{g}_{comp}_after")]
        code = str(row.get("patient") or "")
        who = (f'<a href="#{patient_ids[code]}">{escape(code)}</a>' if code in patient_ids
               else escape(code or "—"))
        out.append("<tr>")
        out.append(f'<td class="t">{who}</td>')
        extra = [str(row.get("plan_label") or "")]
        if row.get("fit_status") not in (None, "", "not fitted"):
            extra.append(f"fit {row['fit_status']}")
        if row.get("warnings"):
            extra.append(f"{len(str(row['warnings']).split(' | '))} warning(s)")
        checked = row.get("validation")
        out.append(f'<td class="t"><a href="#plan-{row["plan_id"]}">{row["plan_id"]}</a>'
                   + (f"<br>{verdict_badge(str(checked))}"
                      if checked not in (None, "", "not checked") else "")
                   + "".join(f'<br><span class="sub">{escape(e)}</span>' for e in extra if e)
                   + "</td>")
        out.append(f'<td class="t">{escape(str(row.get("kinds") or ""))}: '
                   f'{escape(" ".join(treated) or "—")}</td>')
        out.append(f'<td class="t">{lines([escape(f"{j} {d}") for j, d in stretches])}</td>')
        out.append(f"<td>{lines([_change(row, f'{k}_fast_n_m') for k in keys])}</td>")
        out.append("<td>" + lines([_change(row, f"{k}_velocity_dependent_n_m")
                                   for k in keys]) + "</td>")
        out.append(f"<td>{lines([_change(row, f'{k}_slow_n_m') for k in keys])}</td>")
        out.append(f"<td>{lines([_angle_change(row, f'{k}_catch_r1_deg') for k in keys])}</td>")
        out.append(f'<td class="t">{lines(grades) or "none"}</td>')
        out.append(f"<td>{escape(_num(row.get('static_diff_rms_n')))}; "
                   f"{escape(_num(row.get('moving_diff_rms_n')))}</td>")
        out.append("</tr>")
    out.append("</tbody></table></div>")
    out.append('<p class="legend">Each row shows the joint stretch that lengthens each treated '
               "muscle group (the bi-articular groups at the elbow): peak torque resisting the "
               "fast (180°/s) and the slow (5°/s) stretch, its velocity-dependent part (fast − "
               "slow: the stretch reflex, spasticity) and the catch angle R1; the grades "
               "(dynamic: spasticity, passive: contracture) of every muscle group whose level "
               "changes. Every read-out of every stretch, muscle group and field is in "
               "metrics.csv and metrics.json.</p>")
    return out


def _steps(steps: Sequence[str]) -> list[str]:
    return ["<ul class=\"steps\">", *(f"<li>{escape(t)}</li>" for t in steps), "</ul>"]


def _case_table(row: Mapping[str, Any]) -> list[str]:
    """One case's field metrics as name/value pairs, three pairs per line."""
    skip = TEXT_COLUMNS | {"plan_id", "base_model_id", "result_model_id"}
    pairs = [(h, fmt(row.get(k))) for k, h in COLUMNS if k not in skip]
    out = ['<table class="kv">']
    for i in range(0, len(pairs), 3):
        out.append("<tr>" + "".join(f'<th class="t">{escape(h)}</th><td>{escape(v)}</td>'
                                    for h, v in pairs[i:i + 3]) + "</tr>")
    out.append("</table>")
    return out


def _clinical_tables(row: Mapping[str, Any]) -> list[str]:
    """Joint stretches per joint and direction (the treated ones first and highlighted), and
    grades per muscle group, before → after."""
    treated_stretches = case_stretches(row) if row.get("treated_groups") else []
    order = treated_stretches + [s for s in STRETCHES if s not in treated_stretches]
    out = ['<table class="clinical">', '<tr><th class="t">joint stretch</th>']
    out += [f"<th>{escape(head)}</th>" for _, _, head in STRETCH_READOUTS]
    out.append("</tr>")
    for j, d in order:
        cls = ' class="treated"' if (j, d) in treated_stretches else ""
        out.append(f'<tr{cls}><th class="t">{escape(f"{j} {d}")}</th>')
        for _, stem, _ in STRETCH_READOUTS:
            key = f"{j}_{d}_{stem}"
            cell = _angle_change(row, key) if stem.endswith("_deg") else _change(row, key)
            out.append(f"<td>{cell}</td>")
        out.append("</tr>")
    out.append("</table>")
    treated = set(str(row.get("treated_groups") or "").split())
    out.append('<table class="clinical"><tr><th class="t">muscle group</th>'
               '<th class="t">graded on</th><th class="t">passive (contracture)</th>'
               '<th class="t">dynamic (spasticity)</th></tr>')
    for g in GROUPS:
        joint, direction = GRADED_STRETCH[g]
        cls = ' class="treated"' if g in treated else ""
        cells = []
        for comp in ("passive", "dynamic"):
            b, a = row.get(f"severity_{g}_{comp}_before"), row.get(f"severity_{g}_{comp}_after")
            sb = row.get(f"severity_{g}_{comp}_score_before")
            sa = row.get(f"severity_{g}_{comp}_score_after")
            cells.append(escape(f"{b} → {a} ({_num(sb, '.1f')} → {_num(sa, '.1f')})"))
        out.append(f'<tr{cls}><th class="t">{escape(MUSCLE_GROUP_NAMES[g])} ({g})</th>'
                   f'<td class="t">{escape(f"{joint} {direction}")}</td>'
                   f'<td class="t">{cells[0]}</td><td class="t">{cells[1]}</td></tr>')
    out.append("</table>")
    out.append('<p class="legend">Slow stretch 5°/s, fast 180°/s, one joint through its range, '
               "the other at rest (treated stretches highlighted). Catch (Tardieu-style): R1 "
               "where the fast stretch, R2 where the slow one first meets twice the unimpaired "
               "arm's largest slow-stretch torque (— never); R2 − R1 is the velocity-dependent "
               "part. Grades (score 0 unimpaired … 4 severe): + beyond severe, * rests on a "
               "parameter the fit did not identify.</p>")
    return out


def _iv(v: Any, interval: Any, signed: bool = False) -> str:
    """'v [low, high]' to two decimals, '—' when a part is missing."""
    f = "+.2f" if signed else ".2f"
    lo, hi = interval if isinstance(interval, (list, tuple)) and len(interval) == 2 else (None,
                                                                                      None)
    if not all(isinstance(x, (int, float)) for x in (v, lo, hi)):
        return "—"
    return f"{v:{f}} [{lo:{f}}, {hi:{f}}]".replace("-", "−")


def _trust(detail: Mapping[str, Any]) -> list[str]:
    """What the prediction rests on: the fit, the guessed parameters, the 95% intervals, and
    the check against maps measured after the plan."""
    out: list[str] = []
    fit = detail.get("fit")
    if fit:
        accepted = " (poor fit accepted by the user)" if fit.get("accepted_poor_fit") else ""
        out.append(f'<p class="rests">Fit {fit.get("fit_id")} behind the model: status '
                   f'{escape(str(fit.get("status")))}{accepted}; goodness of fit '
                   f'{escape(str(fit.get("goodness_of_fit")))}.')
    else:
        out.append('<p class="rests">No fit behind this model (a synthetic or stored model): '
                   "no fit uncertainty, nothing guessed by a fit.")
    guesses = detail.get("unidentified") or []
    if guesses:
        names = ", ".join(f"{g['name']} = {g['value']:.3g}" + (" (held)" if
                          g.get("held_at_unimpaired") else "") for g in guesses)
        out.append(f" Not identified by the fit (the prediction rests on these guesses): "
                   f"{escape(names)}.")
    out.append("</p>")
    iv = detail.get("intervals") or {}
    metrics = iv.get("metrics") or {}
    if metrics:
        out.append('<table class="clinical intervals"><tr><th class="t">95% intervals '
                   f'({escape(str(iv.get("samples")))} fit samples)</th><th>before</th>'
                   "<th>after</th><th>change</th></tr>")
        guessed = False
        for name, m in metrics.items():
            ident = m.get("without_guesses") if m.get("rests_on_guess") else None
            cells = []
            for k in ("before", "after", "change"):
                if isinstance(ident, Mapping):  # identified first; the guess's apart, marked
                    cells.append(_iv(m.get(k), ident.get(f"{k}_interval"), k == "change")
                                 + '<br><span class="guess">* '
                                 + _iv(m.get(k), m.get(f"{k}_interval"), k == "change")
                                 .split(" ", 1)[1] + "</span>")
                else:
                    cells.append(_iv(m.get(k), m.get(f"{k}_interval"), k == "change"))
            mark = " *" if m.get("rests_on_guess") else ""
            guessed = guessed or bool(mark)
            out.append(f'<tr><th class="t">{escape(name)} ({escape(str(m.get("unit")))})'
                       f"{mark}</th>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
        out.append("</table>")
        if guessed:
            out.append('<p class="legend">* The interval rests on parameters the fit did not '
                       "identify: the first line is what the maps identified (the guessed "
                       "parameters at their held value), the second, marked *, the interval "
                       "with them drawn from their whole prior range.</p>")
    elif iv.get("note"):
        out.append(f'<p class="legend">No intervals: {escape(str(iv["note"]))}.</p>')
    v = detail.get("validation")
    if v:
        if v.get("not_checked"):
            out.append(f'<p class="legend">Prediction not checked: '
                       f'{escape(str(v["not_checked"]).rstrip("."))}.</p>')
        else:
            verdict = str(v.get("verdict"))
            cls = "warn" if verdict in (FAILED, PARTIAL) else "checked"
            out.append(f'<p class="{cls}">Checked against maps measured after the plan: '
                       f"{verdict_badge(verdict)}</p><ul class=\"steps\">")
            for sess in v.get("sessions") or []:
                why = "; ".join(str(x) for x in sess.get("reasons") or [])
                out.append(f"<li>{escape(str(sess.get('session')))} "
                           f"({escape(str(sess.get('date')))}, "
                           f"{float(sess.get('weeks_after') or 0):.1f} weeks after): "
                           f"{escape(str(sess.get('verdict')))}"
                           + (f" - {escape(why)}" if why else "") + "</li>")
            out.append("</ul>")
    return out


#: Each verdict of a check as the page marks it: a failed or partial prediction as plainly as
#: a confirmed one (a coloured badge with a sign, readable without colour too).
BADGES = {CONFIRMED: ("ok", "✓"), FAILED: ("failed", "✗"), PARTIAL: ("partial", "!"),
          INCONCLUSIVE: ("open", "?")}


def verdict_badge(verdict: str) -> str:
    """A check's verdict as a badge (:data:`BADGES`)."""
    cls, sign = BADGES.get(verdict, ("open", "?"))
    return f'<span class="verdict {cls}">{sign} {escape(verdict)}</span>'


def _figure(key: str, caption: str, svg: str) -> str:
    if not svg:
        return f'<p class="nochange" data-figure="{escape(key)}">{escape(caption)}</p>'
    return (f'<figure data-figure="{escape(key)}">{svg}'
            f"<figcaption>{escape(caption)}</figcaption></figure>")


def _patients(results: Sequence[CaseResult]) -> dict[str, list[CaseResult]]:
    groups: dict[str, list[CaseResult]] = {}
    for r in results:
        groups.setdefault(r.spec.patient_code or "", []).append(r)
    return groups


#: The terms the page uses, defined at its end (the full glossary: docs/glossary.md).
TERMS: tuple[tuple[str, str], ...] = (
    ("sf, se, ef, ee, bf, be", "muscle groups: shoulder flexors, shoulder extensors, elbow "
     "flexors, elbow extensors, bi-articular flexors (biceps short head), bi-articular "
     "extensors (triceps long head)"),
    ("spasticity (dynamic)", "velocity-dependent resistance: the stretch reflex resists a fast "
     "stretch more than a slow one"),
    ("contracture (passive)", "position-dependent resistance: passive stiffness at any speed"),
    ("velocity-dependent part", "resisting torque of the fast (180°/s) stretch minus that of "
     "the slow (5°/s) one, N·m"),
    ("catch, R1, R2", "the catch torque is twice the unimpaired arm's largest slow-stretch "
     "torque; R1 is where the fast stretch meets it, R2 where the slow one does"),
    ("R2 − R1", "the part of the range the reflex takes away; shown only where both R1 and R2 "
     "are reached (— never reached)"),
    ("χ²/n", "squared residuals over the measurement sd, per value: ≈ 1 when the model "
     "describes a map within its noise"),
    ("under-determined", "a parameter the maps do not identify: held at the unimpaired value, "
     "a guess; every prediction resting on it says so"),
    ("95% interval", "the range of a prediction over the fit's parameter samples"),
    ("U", "units of onabotulinumtoxinA (Botox®); other toxins' units are not interchangeable"),
)


def _terms() -> list[str]:
    rows = "".join(f"<dt>{escape(t)}</dt><dd>{escape(d)}.</dd>" for t, d in TERMS)
    return ['<h2 id="terms">Terms</h2>', f'<dl class="terms">{rows}</dl>',
            '<p class="note">The full glossary is docs/glossary.md of fieldbank.</p>']


def render(results: Sequence[CaseResult], inputs: Mapping[str, Any],
           summary: Sequence[tuple[str, str, str]] = ()) -> str:
    """The whole page for ``results`` (in order); ``inputs`` are shown as generation inputs;
    ``summary``: cohort figures (key, caption, SVG) shown first."""
    title = str(inputs.get("title", "fieldbank report"))
    out = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
           '<meta name="viewport" content="width=device-width, initial-scale=1">',
           f"<title>{escape(title)}</title>", f"<style>{CSS}</style>",
           f"<script>{SCRIPT}</script>", "</head>", "<body>",
           f"<h1>{escape(title)}</h1>",
           '<p class="note">Model predictions from the fitted arm models, not treatment '
           'advice. Terms (R1, R2, catch, χ²/n, under-determined, …): '
           '<a href="#terms">at the end of the page</a>.</p>', '<table class="inputs">']
    names = {"selection": "selection", "cases": "cases", "generated": "written"}
    for k, v in inputs.items():
        if k != "title":
            out.append(f"<tr><th>{escape(names.get(str(k), str(k)))}</th>"
                       f"<td>{escape(str(v))}</td></tr>")
    out.append("</table>")
    groups = _patients(results)
    patient_ids = {code: f"patient-{i + 1}" for i, code in enumerate(groups)}
    checked = [r for r in results if r.row.get("validation") not in (None, "", "not checked")]
    if summary or checked:
        out.append('<h2 id="summary">Summary</h2>')
    if checked:  # every verdict at the top, a failed one as plain as a confirmed one
        out.append('<p class="checked">Predictions checked against maps measured after the '
                   "plan: " + "; ".join(
                       f'<span class="checkitem">{verdict_badge(str(r.row["validation"]))} '
                       f'<a href="#plan-{r.spec.plan_id}">{escape(r.spec.patient_code or "")} '
                       f"plan {r.spec.plan_id}</a></span>" for r in checked) + ".</p>")
    out += [_figure(k, c, s) for k, c, s in summary]
    out.append('<h2 id="contents">Contents</h2><ol class="toc">')
    for code, cases in groups.items():
        links = ", ".join(f'<a href="#plan-{r.spec.plan_id}">plan {r.spec.plan_id}: '
                          f"{escape(r.spec.plan_label or ', '.join(r.spec.kinds))}</a>"
                          for r in cases)
        out.append(f'<li><a href="#{patient_ids[code]}">{escape(code or "no patient")}</a>: '
                   f"{links}</li>")
    out.append("</ol>")
    out.append(f'<h2 id="metrics">Metrics ({len(results)} case'
               f"{'s' if len(results) != 1 else ''})</h2>")
    out += _overview(results, patient_ids)
    for code, cases in groups.items():
        out.append(f'<section class="patient" id="{patient_ids[code]}">')
        out.append(f"<h2>Patient {escape(code or '(none)')}</h2>")
        who = cases[0].spec.patient
        if who:
            out.append(f"<p>{who['body_mass_kg']:g} kg, {who['height_m']:g} m, "
                       f"{escape(str(who['side']))} arm; {len(cases)} plan"
                       f"{'s' if len(cases) != 1 else ''}.</p>")
        for r in cases:
            out += _case(r)
        out.append("</section>")
    out += [*_terms(), "</body>", "</html>", ""]
    return "\n".join(out)


def _case(r: CaseResult) -> list[str]:
    s = r.spec
    out = [f'<section class="case" id="plan-{s.plan_id}">', f"<h3>{escape(s.title)}</h3>"]
    sess = ", ".join(f"{lb} ({d or 'undated'})" for lb, d in s.sessions)
    out.append(f"<p>Before: model {s.base_model_id} ({escape(s.base_origin)}: "
               f"{escape(s.base_label)}); after: model {s.result_model_id}. "
               f"Sessions fitted: {escape(sess or 'none recorded')}. "
               f"Case date {escape(s.case_date)}.</p>")
    out += _steps(r.detail.get("steps") or [])
    out += [f'<p class="warn">Warning: {escape(w.rstrip("."))}.</p>'
            for w in r.detail.get("warnings") or []]
    out += _trust(r.detail)
    out += _clinical_tables(r.row)
    out += [_figure(f.key, f.caption, f.svg) for f in r.figures]
    out += _case_table(r.row)
    out.append("</section>")
    return out
