"""Training results as a clinician reads them: a page of accuracy per group and severity level
(:func:`results_html`, :func:`results_page`) and the same in lines of text
(:func:`accuracy_text`), from the summary :func:`haptic.training.summarise` makes.
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from typing import Any

from fieldbank.haptic.training import ANSWER_OF_GROUP


def _pct(v: float | None) -> str:
    return "–" if v is None else f"{100.0 * v:.0f}%"


#: One name per group wherever results are shown: the true group (rows) and the answer
#: (columns; the seed's third button, 'both', names the muscles that cross both joints).
_GROUP_WORDS = {"shoulder": "shoulder", "elbow": "elbow", "biarticular": "bi-articular"}
_ANSWER_WORDS = {"shoulder": "shoulder", "elbow": "elbow", "both": "bi-articular"}

_CSS = """
.fb-training{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;color:#1d2330;
  max-width:46rem}
.fb-training h2{font-size:1.25rem;margin:.2rem 0 .6rem}
.fb-training h3{font-size:1rem;margin:1rem 0 .4rem}
.fb-training table{border-collapse:collapse;margin:.2rem 0 .6rem}
.fb-training th,.fb-training td{border:1px solid #c9ced8;padding:.3rem .6rem;text-align:center;
  font-variant-numeric:tabular-nums}
.fb-training th{background:#eef1f6;font-weight:600}
.fb-training td.fb-diag{font-weight:700}
.fb-training .fb-bar{display:inline-block;height:.7rem;background:#2f6fb3;vertical-align:middle;
  margin-right:.4rem}
.fb-training .fb-note{color:#596173;font-size:.85rem;margin:.3rem 0}
"""


def trainee_note(simulated: Sequence[int], people: Sequence[int]) -> str:
    """Who answered: the sessions a simulated trainee ran (``haptic train simulate``) and those
    a person did, said first on every page of results."""
    def ids(xs: Sequence[int]) -> str:
        return ", ".join(map(str, xs))
    if simulated and not people:
        return (f"Simulated trainee, not a person: session(s) {ids(simulated)} were answered by "
                "the simulated trainee of 'fieldbank haptic train simulate' (the simulated "
                "robot's operator, judging from templates of the force it felt).")
    if simulated:
        return (f"Session(s) {ids(simulated)} were answered by the simulated trainee, session(s) "
                f"{ids(people)} by a person: the counts below pool both.")
    return f"Answered by a person at the station: session(s) {ids(people)}."


def results_html(summary: Mapping[str, Any], title: str = "Training results",
                 note: str = "", who: str = "") -> str:
    """A self-contained HTML ``<section>`` (its own style) with the confusion matrix and the
    accuracy per severity of :func:`summarise`; ``who``: who answered (:func:`trainee_note`),
    said under the title."""
    e = html.escape
    conf = summary["confusion"]
    cols = conf["columns"]
    out = [f'<section class="fb-training"><style>{_CSS}</style>', f"<h2>{e(title)}</h2>"]
    if who:
        out.append(f"<p><b>{e(who)}</b></p>")
    a = summary["accuracy"]
    out.append(f'<p>{a["correct"]} of {a["n"]} assessment answers correct '
               f'(<b>{_pct(a["accuracy"])}</b>; chance {_pct(summary["chance"])}).</p>')
    if summary.get("flagged"):
        out.append(f'<p class="fb-note">{_flagged_text(summary)}</p>')
    out.append("<h3>Confusion matrix: true impaired group (rows) against the answer "
               "(columns)</h3><table><tr><th>true group</th>"
               + "".join(f"<th>{e(_ANSWER_WORDS.get(c, c))}</th>" for c in cols)
               + "<th>n</th></tr>")
    for g, row in zip(conf["rows"], conf["counts"], strict=True):
        n = sum(row)
        cells = []
        for c, k in zip(cols, row, strict=True):
            share = k / n if n else 0.0
            diag = ANSWER_OF_GROUP.get(g) == c
            shade = f"rgba(47,111,179,{0.08 + 0.6 * share:.2f})" if k else "transparent"
            cells.append(f'<td class="{"fb-diag" if diag else ""}" style="background:{shade}">'
                         f'{k}<br><small>{_pct(share) if n else "–"}</small></td>')
        out.append(f"<tr><th>{e(_GROUP_WORDS.get(g, g))}</th>{''.join(cells)}<td>{n}</td></tr>")
    out.append("</table>")
    out.append("<h3>Accuracy per severity</h3><table><tr><th>severity</th><th>correct</th>"
               "<th>accuracy</th></tr>")
    for s, v in summary["by_severity"].items():
        w = 0 if v["accuracy"] is None else round(120 * v["accuracy"])
        out.append(f"<tr><th>{e(s)}</th><td>{v['correct']} / {v['n']}</td>"
                   f'<td style="text-align:left"><span class="fb-bar" style="width:{w}px">'
                   f"</span>{_pct(v['accuracy'])}</td></tr>")
    out.append("</table>")
    if len(summary.get("by_instruction", {})) > 1:
        out.append("<h3>Instructed against non-instructed</h3><table><tr><th>instruction</th>"
                   "<th>correct</th><th>accuracy</th></tr>")
        for i, v in summary["by_instruction"].items():
            out.append(f"<tr><th>{e(i)}</th><td>{v['correct']} / {v['n']}</td>"
                       f"<td>{_pct(v['accuracy'])}</td></tr>")
        out.append("</table>")
    rt = summary.get("median_response_time_s")
    if rt is not None:
        out.append(f'<p class="fb-note">Median response time {rt:.1f} s (from the start of '
                   "the trial; the answer has no time limit).</p>")
    out.append('<p class="fb-note">Groups: shoulder, elbow, bi-articular (the muscles that '
               "cross both joints: the answer 'both', key 3, at the station). Severities on the "
               "seed's scale (Weber fraction 0.6 between levels).</p>")
    if note:
        out.append(f'<p class="fb-note">{e(note)}</p>')
    out.append("</section>")
    return "\n".join(out)


def results_page(sections: Sequence[str], title: str = "Training results") -> str:
    """A small HTML document around :func:`results_html` sections."""
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title></head><body style=\"margin:1.5rem\">\n"
            + "\n".join(sections) + "\n</body></html>\n")


def _flagged_text(summary: Mapping[str, Any]) -> str:
    n = summary["flagged"]
    which = ", ".join(str(t) for t in summary.get("flagged_trials", []))
    return (f"{n} answered trial{'s' if n != 1 else ''} ({which}) flagged - a fault or no force "
            "during the trial - and left out of every accuracy")


def accuracy_text(summary: Mapping[str, Any]) -> list[str]:
    """The confusion matrix and accuracy per severity as plain-text lines (for the terminal)."""
    conf = summary["confusion"]
    a = summary["accuracy"]
    lines = [f"assessment: {a['correct']} of {a['n']} correct ({_pct(a['accuracy'])}; chance "
             f"{_pct(summary['chance'])})",
             *([_flagged_text(summary)] if summary.get("flagged") else []),
             "confusion (rows: true group, columns: answer):",
             "  " + " " * 13 + "".join(f"{_ANSWER_WORDS.get(c, c):>14s}"
                                        for c in conf["columns"])]
    for g, row in zip(conf["rows"], conf["counts"], strict=True):
        lines.append(f"  {_GROUP_WORDS.get(g, g):13s}" + "".join(f"{k:14d}" for k in row))
    lines.append("accuracy per severity:")
    for s, v in summary["by_severity"].items():
        lines.append(f"  {s:13s} {v['correct']:3d} / {v['n']:<3d} {_pct(v['accuracy']):>5s}")
    for i, v in summary.get("by_instruction", {}).items():
        lines.append(f"  {i}: {v['correct']} / {v['n']} ({_pct(v['accuracy'])})")
    return lines
