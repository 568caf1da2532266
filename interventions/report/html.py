"""The report page: one self-contained HTML file, images embedded as PNG data URIs.

Written with the standard library (``html.escape``); no external resources, so the file can be
mailed or archived alone. A small script marks ``<body data-images-ok="yes">`` once every image
has loaded with a non-zero width (read by the browser test). Nothing in the page depends on the
time of writing unless a stamp is given.
"""

from __future__ import annotations

import base64
from collections.abc import Mapping, Sequence
from html import escape
from typing import Any

from fieldbank.evaluate.probing import STRETCHES
from fieldbank.interventions.report.compute import COLUMNS, STRETCH_READOUTS, CaseResult
from fieldbank.params import GROUPS
from fieldbank.severity import GRADED_STRETCH, MUSCLE_GROUP_NAMES

CSS = """
body { font-family: system-ui, sans-serif; margin: 1.5em auto; padding: 0 1em; max-width: 1180px;
       color: #222; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; }
h2 { font-size: 1.15em; border-top: 2px solid #ccd; padding-top: 0.6em; margin-top: 1.6em; }
table { border-collapse: collapse; font-size: 0.78em; margin: 0.6em 0; }
th, td { border: 1px solid #ccd; padding: 2px 6px; text-align: right; vertical-align: top; }
th { background: #eef; }
td.t, th.t { text-align: left; }
.note { color: #844; font-size: 0.9em; }
.warn { color: #a00; font-weight: bold; font-size: 0.95em; }
.legend { color: #555; font-size: 0.8em; max-width: 60em; }
table.clinical td { white-space: nowrap; }
.inputs td, .inputs th { text-align: left; }
.scroll { overflow-x: auto; }
figure { margin: 0.6em 0 1em 0; }
figcaption { font-size: 0.82em; color: #555; max-width: 60em; }
img { max-width: 100%; height: auto; }
ul.steps { font-size: 0.95em; list-style: none; padding-left: 0.5em; }
"""

SCRIPT = """
window.addEventListener("load", function () {
  var imgs = Array.prototype.slice.call(document.images);
  var bad = imgs.filter(function (i) { return !(i.complete && i.naturalWidth > 0); });
  document.body.setAttribute("data-images", String(imgs.length));
  document.body.setAttribute("data-images-ok", bad.length === 0 ? "yes" : "no");
});
"""

TEXT_COLUMNS = {"patient", "plan_label", "kinds", "sessions", "case_date", "severity_before",
                "severity_after", "warnings"}


def fmt(v: Any) -> str:
    """A table cell: floats to 4 significant digits, None as an em dash."""
    if v is None:
        return "—"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def _png_tag(png: bytes, alt: str) -> str:
    w = int.from_bytes(png[16:20], "big")
    h = int.from_bytes(png[20:24], "big")
    data = base64.b64encode(png).decode("ascii")
    return (f'<img src="data:image/png;base64,{data}" width="{w}" height="{h}" '
            f'alt="{escape(alt)}">')


def _table(rows: Sequence[Mapping[str, Any]], link: bool) -> list[str]:
    out = ['<div class="scroll"><table>', "<tr>"]
    out += [f'<th class="{"t" if k in TEXT_COLUMNS else ""}">{escape(h)}</th>'
            for k, h in COLUMNS]
    out.append("</tr>")
    for r in rows:
        out.append("<tr>")
        for k, _ in COLUMNS:
            cell = escape(fmt(r.get(k)))
            if link and k == "plan_id":
                cell = f'<a href="#plan-{r["plan_id"]}">{cell}</a>'
            out.append(f'<td class="{"t" if k in TEXT_COLUMNS else ""}">{cell}</td>')
        out.append("</tr>")
    out.append("</table></div>")
    return out


def _steps(steps: Sequence[str]) -> list[str]:
    return ["<ul class=\"steps\">", *(f"<li>{escape(t)}</li>" for t in steps), "</ul>"]


def _case_table(row: Mapping[str, Any]) -> list[str]:
    """One case's metrics as name/value pairs, three pairs per line."""
    pairs = [(h, fmt(row.get(k))) for k, h in COLUMNS if k not in TEXT_COLUMNS
             and k not in ("plan_id", "base_model_id", "result_model_id")]
    out = ['<table class="kv">']
    for i in range(0, len(pairs), 3):
        out.append("<tr>" + "".join(f'<th class="t">{escape(h)}</th><td>{escape(v)}</td>'
                                    for h, v in pairs[i:i + 3]) + "</tr>")
    for k in ("severity_before", "severity_after"):
        out.append(f'<tr><th class="t">{escape(dict(COLUMNS)[k])}</th>'
                   f'<td class="t" colspan="5">{escape(fmt(row.get(k)))}</td></tr>')
    out.append("</table>")
    return out


def _change(row: Mapping[str, Any], key: str) -> str:
    return f"{fmt(row.get(key + '_before'))} → {fmt(row.get(key + '_after'))}"


def _clinical_tables(row: Mapping[str, Any]) -> list[str]:
    """Joint stretches per joint and direction, and grades per muscle group, before → after."""
    out = ['<table class="clinical">', '<tr><th class="t">joint stretch</th>']
    out += [f"<th>{escape(head)}</th>" for _, _, head in STRETCH_READOUTS]
    out.append("</tr>")
    for j, d in STRETCHES:
        out.append(f'<tr><th class="t">{escape(f"{j} {d}")}</th>')
        out += [f"<td>{escape(_change(row, f'{j}_{d}_{stem}'))}</td>"
                for _, stem, _ in STRETCH_READOUTS]
        out.append("</tr>")
    out.append("</table>")
    out.append('<table class="clinical"><tr><th class="t">muscle group</th>'
               '<th class="t">graded on</th><th class="t">passive (contracture)</th>'
               '<th class="t">dynamic (spasticity)</th></tr>')
    for g in GROUPS:
        joint, direction = GRADED_STRETCH[g]
        out.append(f'<tr><th class="t">{escape(MUSCLE_GROUP_NAMES[g])} ({g})</th>'
                   f'<td class="t">{escape(f"{joint} {direction}")}</td>'
                   f'<td class="t">{escape(_change(row, f"severity_{g}_passive"))}</td>'
                   f'<td class="t">{escape(_change(row, f"severity_{g}_dynamic"))}</td></tr>')
    out.append("</table>")
    out.append('<p class="legend">Slow stretch 5°/s, fast 180°/s, one joint through its range, '
               "the other at rest. Catch (Tardieu-style): R1 where the fast stretch, R2 where "
               "the slow one first meets twice the unimpaired arm's largest slow-stretch "
               "torque (— never); R2 − R1 is the velocity-dependent part. Grades: + beyond "
               "severe, * rests on a parameter the fit did not identify.</p>")
    return out


def render(results: Sequence[CaseResult], inputs: Mapping[str, Any]) -> str:
    """The whole page for ``results`` (in order); ``inputs`` are shown as generation inputs."""
    title = str(inputs.get("title", "fieldbank report"))
    out = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
           f"<title>{escape(title)}</title>", f"<style>{CSS}</style>",
           f"<script>{SCRIPT}</script>", "</head>", "<body>",
           f"<h1>{escape(title)}</h1>",
           '<p class="note">Model predictions from the fitted arm models, not treatment '
           "advice.</p>", '<table class="inputs">']
    for k, v in inputs.items():
        if k != "title":
            out.append(f"<tr><th>{escape(str(k))}</th><td>{escape(str(v))}</td></tr>")
    out.append("</table>")
    out.append(f"<h2>Metrics ({len(results)} case{'s' if len(results) != 1 else ''})</h2>")
    out += _table([r.row for r in results], link=True)
    for r in results:
        s = r.spec
        out.append(f'<h2 id="plan-{s.plan_id}">{escape(s.title)}</h2>')
        who = s.patient
        if who:
            out.append(f"<p>Patient {escape(str(who['code']))}: {who['body_mass_kg']:g} kg, "
                       f"{who['height_m']:g} m, {escape(str(who['side']))} arm. ")
        else:
            out.append("<p>")
        sess = ", ".join(f"{lb} ({d or 'undated'})" for lb, d in s.sessions)
        out.append(f"Before: model {s.base_model_id} ({escape(s.base_origin)}: "
                   f"{escape(s.base_label)}); after: model {s.result_model_id}. "
                   f"Sessions fitted: {escape(sess or 'none recorded')}. "
                   f"Case date {escape(s.case_date)}.</p>")
        out += _steps(r.detail.get("steps") or [])
        out += [f'<p class="warn">Warning: {escape(w)}.</p>'
                for w in r.detail.get("warnings") or []]
        out += _case_table(r.row)
        for f in r.figures:
            out.append(f"<figure>{_png_tag(f.png, f.caption)}"
                       f"<figcaption>{escape(f.caption)}</figcaption></figure>")
        out += _clinical_tables(r.row)
    out += ["</body>", "</html>", ""]
    return "\n".join(out)
