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

:class:`TrainingSession` is the protocol's state; on the loop it is run by the
:class:`~haptic.activities.training.Training` activity, which the ``train_*`` commands of
:mod:`haptic.commands` address: ``next`` renders the next trial's arm (compiled outside the loop,
swapped in behind the push fade), ``answer`` records an assessment answer with its response
time. Times are the loop's session time (s), so each trial's window [started_s, ended_s] is its
reference into the session's trace.
"""

from __future__ import annotations

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
#: Longest protocol name.
MAX_NAME_CHARS = 64

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
    name : str
        What the protocol is called on the station and in results ("" : :attr:`title` says
        "seed", "short" or "custom" from the counts).
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
    name: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or len(self.name) > MAX_NAME_CHARS:
            raise ParameterError(f"The 'name' training parameter must be text of at most "
                                 f"{MAX_NAME_CHARS} characters; got {self.name!r} instead.")
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
    def title(self) -> str:
        """The protocol's name: :attr:`name`, else "seed" or "short" when its counts and
        durations are those of :meth:`seed_protocol` or :meth:`short`, else "custom"."""
        if self.name:
            return self.name
        f = TrainingProtocol.__dataclass_fields__
        same = all(getattr(self, k) == f[k].default for k in (
            "familiarisation_s", "assessment_s", "groups", "severities"))
        counts = (self.familiarisation_rounds, self.assessment_repetitions)
        if same and counts == (f["familiarisation_rounds"].default,
                               f["assessment_repetitions"].default):
            return "seed"
        if same and counts == (1, 1):
            return "short"
        return "custom"

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

    Owned by its activity in the loop's thread (commands change it at tick boundaries); other
    threads only read :meth:`state`.
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

    def begin(self, index: int, t_s: float, paths: Sequence[ProbePath] = (),
              window: Mapping[str, Any] | None = None) -> Trial:
        """Start trial ``index`` (the next one) at session time ``t_s``; ``window``: the
        verdict on the window of the familiarisation trial it closes."""
        if self.abandoned:
            raise CommandError("the training session was stopped; start a new one")
        if index != self.index + 1 or self.next_trial is None:
            raise CommandError(f"training: trial {index + 1} is not the next one (now at trial "
                               f"{self.index + 1} of {len(self.trials)})")
        if self.awaiting_answer:
            raise CommandError(f"training: answer trial {self.index + 1} first (shoulder, "
                               f"elbow or both)")
        self._close_familiarisation(t_s, window)
        self.index = index
        self.started_s = t_s
        self.paths = tuple(paths)
        return self.trials[index]

    def _close_familiarisation(self, t_s: float,
                               window: Mapping[str, Any] | None = None) -> None:
        cur = self.current
        if cur is not None and cur.phase == "familiarisation" and self.started_s is not None:
            self.records.append(self._record(cur, self.started_s, t_s, None, window))
            self.started_s = None

    def _record(self, trial: Trial, started_s: float, ended_s: float,
                answer: str | None = None,
                window: Mapping[str, Any] | None = None) -> dict[str, Any]:
        w = window or {}
        return {
            "flagged": bool(w.get("flagged")), "flags": list(w.get("flags", [])),
            "peak_force_n": w.get("peak_force_n"),
            "trial": trial.index, "phase": trial.phase, "condition": trial.condition,
            "group": trial.group, "severity": trial.severity,
            "instruction": self.protocol.instruction,
            "legend_shown": trial.phase == "familiarisation",
            "started_s": started_s, "ended_s": ended_s, "duration_s": trial.duration_s,
            "answer": answer, "answered_s": ended_s if answer is not None else None,
            "response_time_s": ended_s - started_s if answer is not None else None,
            "correct": (answer == trial.expected_answer) if answer is not None else None,
        }

    def answer(self, choice: str, t_s: float,
               window: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """Record the answer to the current assessment trial ('shoulder', 'elbow', 'both');
        ``window``: the verdict on its window (:mod:`haptic.trialwindow`): a flagged trial is
        kept and left out of the accuracy."""
        choice = str(choice).strip().lower()
        if choice not in ANSWERS:
            raise CommandError(f"a training answer is shoulder, elbow or both; got {choice!r}")
        cur = self.current
        if cur is None or not self.awaiting_answer or self.started_s is None:
            raise CommandError("training: no assessment trial is waiting for an answer")
        rec = self._record(cur, self.started_s, t_s, choice, window)
        self.records.append(rec)
        self.started_s = None
        return rec

    def finish(self, t_s: float, abandon: bool = False,
               window: Mapping[str, Any] | None = None) -> None:
        """Close the last familiarisation trial; ``abandon`` stops the session early."""
        self._close_familiarisation(t_s, window)
        if abandon and not self.done:
            self.abandoned = True
            self.started_s = None

    def state(self, t_s: float) -> dict[str, Any]:
        """What a display may show now (nothing that names the arm during an assessment)."""
        cur = self.current
        out: dict[str, Any] = {
            "protocol": self.protocol.title,
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
        return {"protocol": self.protocol.to_dict(), "protocol_name": self.protocol.title,
                "abandoned": self.abandoned,
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
        Trial records (:meth:`TrainingSession.answer`); only answered assessment trials whose
        window was not flagged (a fault, or no force: :mod:`haptic.trialwindow`) count.

    Returns
    -------
    dict
        ``confusion``: rows (true groups), columns (answers), counts; ``accuracy``: overall
        {n, correct, accuracy}; ``by_severity``: the same per level; ``by_instruction``: the same
        per instruction; ``chance``: 1 / number of answers; ``flagged``: answered assessment
        trials left out, with ``flagged_trials`` (their numbers, from 1).
    """
    answered = [r for r in records if r.get("phase") == "assessment" and r.get("answer")]
    rows = [r for r in answered if not r.get("flagged")]
    left_out = [r for r in answered if r.get("flagged")]
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
        "flagged": len(left_out),
        "flagged_trials": [int(r["trial"]) + 1 for r in left_out],
        "median_response_time_s": _median([float(r["response_time_s"]) for r in rows
                                           if r.get("response_time_s") is not None]),
    }


def _median(x: list[float]) -> float | None:
    if not x:
        return None
    s = sorted(x)
    n = len(s)
    return s[n // 2] if n % 2 else 0.5 * (s[n // 2 - 1] + s[n // 2])
