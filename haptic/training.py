"""The seed's training protocol (BRIEF §12): familiarisation, then a blinded assessment.

Melendez-Calderon et al., "Experimental protocol":

- **familiarisation** - four arms, unimpaired and maximally impaired shoulder, elbow and
  bi-articular groups, in blocks of 30 s, eight trials each (32 trials); a legend names the
  condition being felt. The seed says the conditions came "sequentially"; here each round
  presents the four in that order and the rounds repeat (interpretation);
- **assessment** - 3 impaired groups × 4 severities (very mild … severe, Weber fraction 0.6,
  :mod:`fieldbank.evaluate.severity`) × 9 repetitions = 108 trials of 15 s in random (seeded) order;
  the answer is *shoulder*, *elbow* or *both* (bi-articular), with no time limit;
- **instruction** - *non-instructed* trainees explore freely; *instructed* ones follow the
  probing motions drawn on the screen (the fast pull and the semi-ellipse,
  :mod:`fieldbank.evaluate.probing`, and any further probe - a designed one, e.g. from the file
  ``fieldbank probe design --out`` writes - as a :class:`fieldbank.probepath.ProbePath`);
- **results** - the confusion matrix of true against answered group and the accuracy per
  severity (:func:`summarise`), on the station's screen, in ``fieldbank haptic train results``
  and as a self-contained HTML section (:func:`results_html`).

Every count and duration is a field of :class:`TrainingProtocol` (bounds in
:data:`TRAINING_BOUNDS`); :meth:`TrainingProtocol.seed_protocol` is the paper's.

:class:`TrainingSession` is the protocol's state, owned by the renderer like an A/B/X block and
driven by the ``train_*`` commands of :mod:`haptic.commands`: ``next`` renders the next trial's
arm (compiled outside the loop, swapped in behind the push fade), ``answer`` records an
assessment answer with its response time. Times are the loop's session time (s), so each
trial's window [started_s, ended_s] is its reference into the session's trace.
"""

from __future__ import annotations

import html
import random
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

from fieldbank.errors import ParameterError
from fieldbank.evaluate import probing
from fieldbank.evaluate.severity import LEVELS, group_name, level_name, synthesize
from fieldbank.haptic.errors import CommandError
from fieldbank.model import Arm
from fieldbank.params import JOINT_GROUPS, ArmParams
from fieldbank.probepath import MAX_DRAWN_PROBES, ProbePath
from fieldbank.validation import Interval, check_fields

#: What a trainee answers for each impaired group (the seed's three buttons).
ANSWER_OF_GROUP: dict[str, str] = {"shoulder": "shoulder", "elbow": "elbow",
                                   "biarticular": "both"}
ANSWERS: tuple[str, ...] = ("shoulder", "elbow", "both")
INSTRUCTIONS: tuple[str, ...] = ("non-instructed", "instructed")
PHASES: tuple[str, ...] = ("familiarisation", "assessment")
#: Probing motions by name: each gives the path for a compiled arm (seed Fig. 3b, 3c).
PROBES: dict[str, Callable[[Arm], probing.ProbeMotion]] = {
    "pull": probing.pull, "semi-ellipse": probing.semi_ellipse,
}
MAX_EXTRA_PROBES = MAX_DRAWN_PROBES

#: Allowed range of each numeric field of :class:`TrainingProtocol` (messages are generated).
TRAINING_BOUNDS: dict[str, Interval] = {
    "familiarisation_rounds": Interval.whole(0, 50),
    "familiarisation_s": Interval(1.0, 600.0, "s"),
    "assessment_repetitions": Interval.whole(0, 50),
    "assessment_s": Interval(1.0, 600.0, "s"),
    "seed": Interval.whole(0, 2**63 - 1),
}


def probe_paths(arm: Arm, names: Sequence[str],
                extra: Sequence[ProbePath] = ()) -> tuple[ProbePath, ...]:
    """The named probing motions for ``arm`` (from its rest hand position), then ``extra``;
    all in the shoulder frame (the renderer places them on the robot)."""
    return (tuple(PROBES[n](arm).path() for n in names)
            + tuple(p.in_shoulder_frame() for p in extra))


@dataclass(frozen=True)
class Trial:
    """One trial of the plan.

    Attributes
    ----------
    index : int
        Position in the whole protocol, from 0.
    phase : str
        'familiarisation' or 'assessment'.
    group : str or None
        Impaired joint group ('shoulder', 'elbow', 'biarticular'); None: the unimpaired arm.
    severity : str or None
        Level on the severity scale; None for the unimpaired arm.
    duration_s : float, s
        How long the arm is felt (the seed's 30 s and 15 s).
    """

    index: int
    phase: str
    group: str | None
    severity: str | None
    duration_s: float

    @property
    def condition(self) -> str:
        """'unimpaired', or group and level ('elbow severe')."""
        return "unimpaired" if self.group is None else f"{self.group} {self.severity}"

    @property
    def legend(self) -> str:
        """What the familiarisation legend says."""
        if self.group is None:
            return "Unimpaired arm"
        names = {"shoulder": "Shoulder muscles", "elbow": "Elbow muscles",
                 "biarticular": "Bi-articular muscles (both joints)"}
        return f"{names[self.group]}: {self.severity}"

    @property
    def expected_answer(self) -> str | None:
        return None if self.group is None else ANSWER_OF_GROUP[self.group]

    def params(self, base: ArmParams) -> ArmParams:
        """The arm rendered in this trial, on ``base``'s body."""
        return base if self.group is None else synthesize({self.group: str(self.severity)}, base)


@dataclass(frozen=True)
class TrainingProtocol:
    """Counts, durations and instruction of a training session; ranges in
    :data:`TRAINING_BOUNDS`. The defaults are the seed's protocol.

    Attributes
    ----------
    instruction : str
        'non-instructed' (free exploration) or 'instructed' (follow the drawn probes).
    familiarisation_rounds : int
        Rounds of the four familiarisation arms (seed: 8, so 32 trials).
    familiarisation_s : float, s
        Length of a familiarisation trial (seed: 30 s).
    assessment_repetitions : int
        Repetitions of each group × severity (seed: 9, so 108 trials).
    assessment_s : float, s
        Length of an assessment trial (seed: 15 s; the answer has no time limit).
    groups, severities : tuple of str
        What the assessment presents (seed: the three groups, the four levels).
    probes : tuple of str
        Probing motions drawn in instructed mode (:data:`PROBES`).
    extra_probes : tuple of ProbePath
        Further probes to draw and follow (designed probes, e.g. read with
        :func:`fieldbank.probepath.read_probes`); each is drawn and followed relative to the
        shoulder (its points minus its shoulder offset), wherever the renderer puts it.
    seed : int
        Seeds the order of the assessment trials.
    body_mass_kg, height_m : float
        The body of the rendered arms (anthropometric defaults, BRIEF §3).
    side : str
        'right' or 'left'.
    """

    instruction: str = "non-instructed"
    familiarisation_rounds: int = 8
    familiarisation_s: float = 30.0
    assessment_repetitions: int = 9
    assessment_s: float = 15.0
    groups: tuple[str, ...] = ("shoulder", "elbow", "biarticular")
    severities: tuple[str, ...] = ("very mild", "mild", "moderate", "severe")
    probes: tuple[str, ...] = ("pull", "semi-ellipse")
    extra_probes: tuple[ProbePath, ...] = ()
    seed: int = 0
    body_mass_kg: float = 75.0
    height_m: float = 1.75
    side: str = "right"

    def __post_init__(self) -> None:
        if self.instruction not in INSTRUCTIONS:
            raise ParameterError(f"The 'instruction' training parameter must be one of "
                                 f"{', '.join(INSTRUCTIONS)}; got {self.instruction!r} instead.")
        check_fields(self, TRAINING_BOUNDS, what="training parameter")
        groups = tuple(group_name(g) for g in self.groups)
        levels = tuple(level_name(s) for s in self.severities)
        if not groups or len(set(groups)) != len(groups):
            raise ParameterError(f"training groups: one or more of {', '.join(JOINT_GROUPS)}, "
                                 f"each once; got {self.groups!r}")
        if not levels or len(set(levels)) != len(levels) or "unimpaired" in levels:
            raise ParameterError(f"training severities: one or more of {', '.join(LEVELS[1:])}, "
                                 f"each once; got {self.severities!r}")
        object.__setattr__(self, "groups", groups)
        object.__setattr__(self, "severities", levels)
        unknown = [p for p in self.probes if p not in PROBES]
        if unknown:
            raise ParameterError(f"unknown probing motion(s) {', '.join(map(repr, unknown))}; "
                                 f"known: {', '.join(PROBES)}")
        if len(self.extra_probes) > MAX_EXTRA_PROBES:
            raise ParameterError(f"at most {MAX_EXTRA_PROBES} extra probes; got "
                                 f"{len(self.extra_probes)}")
        if not all(isinstance(p, ProbePath) for p in self.extra_probes):
            raise ParameterError("training extra_probes: probe paths (ProbePath)")
        if self.instruction == "instructed" and not self.probes and not self.extra_probes:
            raise ParameterError("instructed training draws probes to follow; give the seed's "
                                 f"({', '.join(PROBES)}) or further ones (extra_probes)")
        if self.side not in ("right", "left"):
            raise ParameterError(f"The 'side' training parameter must be 'right' or 'left'; "
                                 f"got {self.side!r} instead.")
        if self.n_trials == 0:
            raise ParameterError("a training protocol needs at least one trial")
        self.base()  # the body is checked here, not at the first trial

    @classmethod
    def seed_protocol(cls, instruction: str = "non-instructed", seed: int = 0) -> TrainingProtocol:
        """The paper's protocol: 32 familiarisation trials, 108 assessment trials."""
        return cls(instruction=instruction, seed=seed)

    @classmethod
    def short(cls, instruction: str = "non-instructed", seed: int = 0) -> TrainingProtocol:
        """A short session with the seed's structure: 1 familiarisation round (4 trials),
        1 repetition of each group × severity (12 trials)."""
        return cls(instruction=instruction, familiarisation_rounds=1, assessment_repetitions=1,
                   seed=seed)

    @property
    def n_trials(self) -> int:
        return (4 * self.familiarisation_rounds
                + len(self.groups) * len(self.severities) * self.assessment_repetitions)

    def base(self) -> ArmParams:
        """The unimpaired arm of the protocol's body."""
        return ArmParams.from_anthropometry(self.body_mass_kg, self.height_m, self.side)

    def plan(self) -> tuple[Trial, ...]:
        """Every trial in order: the familiarisation rounds, then the shuffled assessment."""
        fam: list[tuple[str | None, str | None]] = [(None, None)] + [
            (g, "severe") for g in ("shoulder", "elbow", "biarticular")]
        out: list[Trial] = []
        for _ in range(self.familiarisation_rounds):
            for g, s in fam:
                out.append(Trial(len(out), "familiarisation", g, s, self.familiarisation_s))
        cells = [(g, s) for g in self.groups for s in self.severities]
        trials = cells * self.assessment_repetitions
        random.Random(self.seed).shuffle(trials)
        for g, s in trials:
            out.append(Trial(len(out), "assessment", g, s, self.assessment_s))
        return tuple(out)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["groups"], d["severities"], d["probes"] = (list(self.groups), list(self.severities),
                                                     list(self.probes))
        d["extra_probes"] = [p.to_dict() for p in self.extra_probes]
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TrainingProtocol:
        """From a JSON document (the control channel's ``train start``); unknown keys refused."""
        if not isinstance(d, Mapping):
            raise ParameterError("a training protocol is a JSON object")
        known = {f for f in cls.__dataclass_fields__}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ParameterError(f"unknown training parameter(s) {', '.join(unknown)}; known: "
                                 f"{', '.join(sorted(known))}")
        kw: dict[str, Any] = dict(d)
        for k in ("groups", "severities", "probes"):
            if k in kw:
                if not isinstance(kw[k], (list, tuple)) or len(kw[k]) > 16:
                    raise ParameterError(f"training {k}: a list of names")
                kw[k] = tuple(str(v) for v in kw[k])
        if "extra_probes" in kw:
            if not isinstance(kw["extra_probes"], (list, tuple)):
                raise ParameterError("training extra_probes: a list of probe paths")
            kw["extra_probes"] = tuple(
                ProbePath.from_dict(p, f"training extra_probes[{k}]")
                for k, p in enumerate(kw["extra_probes"][:MAX_EXTRA_PROBES + 1]))
        return cls(**kw)


@dataclass
class TrainingSession:
    """A training protocol being run: the plan, the current trial, every trial's record.

    Owned by the renderer's loop thread (commands change it at tick boundaries); other threads
    only read :meth:`state`.
    """

    protocol: TrainingProtocol
    trials: tuple[Trial, ...] = ()
    index: int = -1
    started_s: float | None = None
    paths: tuple[ProbePath, ...] = ()
    records: list[dict[str, Any]] = field(default_factory=list)
    abandoned: bool = False

    def __post_init__(self) -> None:
        if not self.trials:
            self.trials = self.protocol.plan()

    @property
    def current(self) -> Trial | None:
        return self.trials[self.index] if 0 <= self.index < len(self.trials) else None

    @property
    def awaiting_answer(self) -> bool:
        cur = self.current
        return (cur is not None and cur.phase == "assessment"
                and not any(r["trial"] == cur.index for r in self.records[-1:]))

    @property
    def next_trial(self) -> Trial | None:
        i = self.index + 1
        return self.trials[i] if i < len(self.trials) else None

    @property
    def done(self) -> bool:
        """Every trial presented and answered (or the session abandoned)."""
        return self.abandoned or (self.next_trial is None and self.index >= 0
                                  and not self.awaiting_answer and self.started_s is None)

    @property
    def blinded(self) -> bool:
        """True while an assessment trial is presented: nothing may say which arm it is."""
        cur = self.current
        return cur is not None and cur.phase == "assessment" and not self.done

    def begin(self, index: int, t_s: float, paths: Sequence[ProbePath] = ()) -> Trial:
        """Start trial ``index`` (the next one) at session time ``t_s``."""
        if self.abandoned:
            raise CommandError("the training session was stopped; start a new one")
        if index != self.index + 1 or self.next_trial is None:
            raise CommandError(f"training: trial {index + 1} is not the next one (now at trial "
                               f"{self.index + 1} of {len(self.trials)})")
        if self.awaiting_answer:
            raise CommandError(f"training: answer trial {self.index + 1} first (shoulder, "
                               f"elbow or both)")
        self._close_familiarisation(t_s)
        self.index = index
        self.started_s = t_s
        self.paths = tuple(paths)
        return self.trials[index]

    def _close_familiarisation(self, t_s: float) -> None:
        cur = self.current
        if cur is not None and cur.phase == "familiarisation" and self.started_s is not None:
            self.records.append(self._record(cur, self.started_s, t_s))
            self.started_s = None

    def _record(self, trial: Trial, started_s: float, ended_s: float,
                answer: str | None = None) -> dict[str, Any]:
        return {
            "trial": trial.index, "phase": trial.phase, "condition": trial.condition,
            "group": trial.group, "severity": trial.severity,
            "instruction": self.protocol.instruction,
            "legend_shown": trial.phase == "familiarisation",
            "started_s": started_s, "ended_s": ended_s, "duration_s": trial.duration_s,
            "answer": answer, "answered_s": ended_s if answer is not None else None,
            "response_time_s": ended_s - started_s if answer is not None else None,
            "correct": (answer == trial.expected_answer) if answer is not None else None,
        }

    def answer(self, choice: str, t_s: float) -> dict[str, Any]:
        """Record the answer to the current assessment trial ('shoulder', 'elbow', 'both')."""
        choice = str(choice).strip().lower()
        if choice not in ANSWERS:
            raise CommandError(f"a training answer is shoulder, elbow or both; got {choice!r}")
        cur = self.current
        if cur is None or not self.awaiting_answer or self.started_s is None:
            raise CommandError("training: no assessment trial is waiting for an answer")
        rec = self._record(cur, self.started_s, t_s, choice)
        self.records.append(rec)
        self.started_s = None
        return rec

    def finish(self, t_s: float, abandon: bool = False) -> None:
        """Close the last familiarisation trial; ``abandon`` stops the session early."""
        self._close_familiarisation(t_s)
        if abandon and not self.done:
            self.abandoned = True
            self.started_s = None

    def state(self, t_s: float) -> dict[str, Any]:
        """What a display may show now (nothing that names the arm during an assessment)."""
        cur = self.current
        out: dict[str, Any] = {
            "instruction": self.protocol.instruction, "n_trials": len(self.trials),
            "trial": None if cur is None else cur.index + 1,
            "phase": None if cur is None else cur.phase, "done": self.done,
            "abandoned": self.abandoned, "awaiting_answer": self.awaiting_answer,
            "answers": list(ANSWERS),
            "n_familiarisation": sum(t.phase == "familiarisation" for t in self.trials),
        }
        if cur is not None and not self.done:
            out["duration_s"] = cur.duration_s
            out["elapsed_s"] = (t_s - self.started_s) if self.started_s is not None else None
            out["legend"] = cur.legend if cur.phase == "familiarisation" else None
            out["paths"] = ([p.display() for p in self.paths]
                            if self.protocol.instruction == "instructed" else [])
        nxt = self.next_trial
        out["next_phase"] = None if nxt is None else nxt.phase
        if self.done:
            out["result"] = self.result()
        return out

    def result(self) -> dict[str, Any]:
        """The protocol, every trial's record and the summary (:func:`summarise`)."""
        return {"protocol": self.protocol.to_dict(), "abandoned": self.abandoned,
                "trials": list(self.records), "summary": summarise(self.records)}


# --- results ----------------------------------------------------------------------------------
def summarise(records: Sequence[Mapping[str, Any]],
              groups: Sequence[str] = ("shoulder", "elbow", "biarticular"),
              severities: Sequence[str] = ("very mild", "mild", "moderate", "severe")
              ) -> dict[str, Any]:
    """Confusion matrix of true against answered group, and accuracy per severity.

    Parameters
    ----------
    records : sequence of mapping
        Trial records (:meth:`TrainingSession.answer`); only answered assessment trials count.

    Returns
    -------
    dict
        ``confusion``: rows (true groups), columns (answers), counts; ``accuracy``: overall
        {n, correct, accuracy}; ``by_severity``: the same per level; ``by_instruction``: the same
        per instruction; ``chance``: 1 / number of answers.
    """
    rows = [r for r in records if r.get("phase") == "assessment" and r.get("answer")]
    counts = [[sum(1 for r in rows if r["group"] == g and r["answer"] == a) for a in ANSWERS]
              for g in groups]

    def acc(sel: list[Mapping[str, Any]]) -> dict[str, Any]:
        k = sum(1 for r in sel if r["correct"])
        return {"n": len(sel), "correct": k, "accuracy": (k / len(sel)) if sel else None}

    return {
        "confusion": {"rows": list(groups), "columns": list(ANSWERS), "counts": counts},
        "accuracy": acc(rows),
        "by_severity": {s: acc([r for r in rows if r["severity"] == s]) for s in severities},
        "by_group": {g: acc([r for r in rows if r["group"] == g]) for g in groups},
        "by_instruction": {i: acc([r for r in rows if r.get("instruction") == i])
                           for i in INSTRUCTIONS if any(r.get("instruction") == i for r in rows)},
        "chance": 1.0 / len(ANSWERS),
        "median_response_time_s": _median([float(r["response_time_s"]) for r in rows
                                           if r.get("response_time_s") is not None]),
    }


def _median(x: list[float]) -> float | None:
    if not x:
        return None
    s = sorted(x)
    n = len(s)
    return s[n // 2] if n % 2 else 0.5 * (s[n // 2 - 1] + s[n // 2])


def _pct(v: float | None) -> str:
    return "–" if v is None else f"{100.0 * v:.0f}%"


_GROUP_WORDS = {"shoulder": "shoulder", "elbow": "elbow", "biarticular": "bi-articular"}

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


def results_html(summary: Mapping[str, Any], title: str = "Training results",
                 note: str = "") -> str:
    """A self-contained HTML ``<section>`` (its own style) with the confusion matrix and the
    accuracy per severity of :func:`summarise`."""
    e = html.escape
    conf = summary["confusion"]
    cols = conf["columns"]
    out = [f'<section class="fb-training"><style>{_CSS}</style>', f"<h2>{e(title)}</h2>"]
    a = summary["accuracy"]
    out.append(f'<p>{a["correct"]} of {a["n"]} assessment answers correct '
               f'(<b>{_pct(a["accuracy"])}</b>; chance {_pct(summary["chance"])}).</p>')
    out.append("<h3>Confusion matrix: true impaired group (rows) against the answer "
               "(columns)</h3><table><tr><th>true group</th>"
               + "".join(f"<th>{e(c)}</th>" for c in cols) + "<th>n</th></tr>")
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
    out.append('<p class="fb-note">Answers: shoulder, elbow, or both (bi-articular muscles). '
               "Severities on the seed's scale (Weber fraction 0.6 between levels).</p>")
    if note:
        out.append(f'<p class="fb-note">{e(note)}</p>')
    out.append("</section>")
    return "\n".join(out)


def results_page(sections: Sequence[str], title: str = "Training results") -> str:
    """A small HTML document around :func:`results_html` sections."""
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title></head><body style=\"margin:1.5rem\">\n"
            + "\n".join(sections) + "\n</body></html>\n")


def accuracy_text(summary: Mapping[str, Any]) -> list[str]:
    """The confusion matrix and accuracy per severity as plain-text lines (for the terminal)."""
    conf = summary["confusion"]
    a = summary["accuracy"]
    lines = [f"assessment: {a['correct']} of {a['n']} correct ({_pct(a['accuracy'])}; chance "
             f"{_pct(summary['chance'])})",
             "confusion (rows: true group, columns: answer):",
             "  " + " " * 13 + "".join(f"{c:>10s}" for c in conf["columns"])]
    for g, row in zip(conf["rows"], conf["counts"], strict=True):
        lines.append(f"  {_GROUP_WORDS.get(g, g):13s}" + "".join(f"{k:10d}" for k in row))
    lines.append("accuracy per severity:")
    for s, v in summary["by_severity"].items():
        lines.append(f"  {s:13s} {v['correct']:3d} / {v['n']:<3d} {_pct(v['accuracy']):>5s}")
    for i, v in summary.get("by_instruction", {}).items():
        lines.append(f"  {i}: {v['correct']} / {v['n']} ({_pct(v['accuracy'])})")
    return lines
