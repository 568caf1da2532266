"""Blinded comparison of two models: A/B/X trials with seeded randomization.

In each trial the clinician can feel A, B and X as often as they like; X is secretly A or B
(drawn per trial, balanced); they answer which one X is. A and B mean one thing everywhere in
the product: A is the model before, B the model after; only X is hidden, and the result says
per trial whether X was before or after. Every presentation and answer is recorded with its
time and with the verdict on its window (:mod:`haptic.activities.window`): an answer whose
window held a fault or no force is kept, flagged, and left out of the score.

:class:`AbxSession` is the block itself (the draw, the answers, the score); :class:`AbxBlock`
runs it on the loop as an activity (:mod:`haptic.activities.base`): ``start``, ``present``
('A', 'B' or 'X': crossfades to it), ``answer`` ('A' or 'B'), ``result``. It is blinded from
start to end and chooses what is felt (a switch is refused); a push is allowed between trials.
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field
from typing import Any, ClassVar

from fieldbank.haptic.activities.base import Activity, ActivityHost
from fieldbank.haptic.activities.window import TrialWindow
from fieldbank.haptic.errors import CommandError

#: Most trials in one block (a request cannot make the renderer hold more).
MAX_ABX_TRIALS = 1000
#: What model index 0 and 1 are, in the words a result uses ("X was before").
X_WAS = ("before", "after")


@dataclass
class AbxSession:
    """A block of A/B/X trials.

    Parameters
    ----------
    n_trials : int
    seed : int
        Seeds the draw of X per trial.
    """

    n_trials: int = 10
    seed: int = 0
    answers: list[dict[str, Any]] = field(default_factory=list)

    def __post_init__(self) -> None:
        if (isinstance(self.n_trials, bool) or not isinstance(self.n_trials, int)
                or not 1 <= self.n_trials <= MAX_ABX_TRIALS):
            raise CommandError(f"A/B/X needs 1 to {MAX_ABX_TRIALS} trials; got "
                               f"{self.n_trials!r}")
        rng = random.Random(self.seed)
        #: model index of each label: A is before (0), B after (1), always
        self.label_model = {"A": 0, "B": 1}
        # balanced: half the trials X = A, half X = B, in random order
        xs = ["A"] * (self.n_trials // 2) + ["B"] * (self.n_trials - self.n_trials // 2)
        rng.shuffle(xs)
        self.x_labels = xs
        self.trial = 0

    @property
    def done(self) -> bool:
        return self.trial >= self.n_trials

    def model_for(self, label: str) -> int:
        """Model index (0 before, 1 after) to present for 'A', 'B' or 'X'."""
        label = label.upper()
        if label in ("A", "B"):
            return self.label_model[label]
        if label == "X":
            if self.done:
                raise CommandError("the A/B/X block is finished; no X to present")
            return self.label_model[self.x_labels[self.trial]]
        raise CommandError(f"A/B/X presents 'A', 'B' or 'X'; got {label!r}")

    def answer(self, choice: str, t_s: float,
               window: dict[str, Any] | None = None) -> dict[str, Any]:
        """Record that X felt like ``choice`` ('A' or 'B'); advance to the next trial.

        ``window``: the verdict on the trial's window (:meth:`TrialWindow.judge
        <haptic.trialwindow.TrialWindow.judge>`); a flagged trial does not count.
        """
        choice = choice.upper()
        if choice not in ("A", "B"):
            raise CommandError(f"an A/B/X answer is 'A' or 'B'; got {choice!r}")
        if self.done:
            raise CommandError(f"the A/B/X block of {self.n_trials} trials is finished")
        x = self.x_labels[self.trial]
        w = window or {}
        rec = {"trial": self.trial, "answer": choice, "x_is": x, "correct": choice == x,
               "x_model": self.label_model[x], "x_was": X_WAS[self.label_model[x]],
               "t_s": t_s, "flagged": bool(w.get("flagged")), "flags": list(w.get("flags", [])),
               "peak_force_n": w.get("peak_force_n")}
        self.answers.append(rec)
        self.trial += 1
        return rec

    def result(self) -> dict[str, Any]:
        """Answers so far, with the key (revealed only here) and the score: ``correct`` of
        ``counted`` (answered and not flagged); ``flagged`` answers are listed, not scored."""
        n = len(self.answers)
        counted = [a for a in self.answers if not a.get("flagged")]
        k = sum(1 for a in counted if a["correct"])
        return {"n_trials": self.n_trials, "answered": n, "counted": len(counted),
                "flagged": n - len(counted), "correct": k, "seed": self.seed,
                "label_model": dict(self.label_model), "answers": list(self.answers)}


class AbxBlock(Activity):
    """An A/B/X block run on the loop (every step needs the robot armed: nothing counts while
    nothing is felt).

    Parameters
    ----------
    n_trials : int
        1 to :data:`MAX_ABX_TRIALS`.
    seed : int
        Seeds the draw of X per trial.
    """

    kind: ClassVar[str] = "abx"
    title: ClassVar[str] = "an A/B/X block"
    restartable: ClassVar[bool] = True

    def __init__(self, n_trials: int = 10, seed: int = 0) -> None:
        self.session = AbxSession(n_trials, seed)
        self.window = TrialWindow()
        self.stopped = False

    @property
    def done(self) -> bool:
        return self.stopped or self.session.done

    @property
    def blinded(self) -> bool:
        return True

    @property
    def trial(self) -> int:
        """The current trial, from 0."""
        return self.session.trial

    def start(self, host: ActivityHost) -> dict[str, Any]:
        host.safety.require_armed("A/B/X start")
        ses = self.session
        self.open_window(host)
        host.log_event("abx_start", n_trials=ses.n_trials, seed=ses.seed)
        return {"trial": 0, "n_trials": ses.n_trials}

    def present(self, host: ActivityHost, label: str) -> dict[str, Any]:
        """Crossfade to 'A', 'B' or this trial's 'X'."""
        host.safety.require_armed("A/B/X")
        label = label.upper()
        host.pair.crossfade(float(self.session.model_for(label)))
        host.log_event("abx_present", label=label, trial=self.session.trial)
        return {"presenting": label, "trial": self.session.trial}

    def answer(self, host: ActivityHost, answer: str) -> dict[str, Any]:
        host.safety.require_armed("A/B/X answer")  # no answer counts while nothing is felt
        ses = self.session
        rec = ses.answer(answer, host.t_s, self.judge_window(host))
        self.open_window(host)
        host.log_event("abx_answer", trial=rec["trial"], answer=rec["answer"],
                       flagged=rec["flagged"])
        out: dict[str, Any] = {"trial": rec["trial"] + 1, "done": ses.done,
                       "flagged": rec["flagged"], "flags": rec["flags"]}
        if ses.done:
            out["result"] = ses.result()
        return out

    def stop(self, host: ActivityHost) -> dict[str, Any]:
        self.stopped = True
        host.log_event("abx_stop", trial=self.session.trial)
        return {"trial": self.session.trial, "done": True, "result": self.result()}

    def result(self) -> dict[str, Any]:
        return self.session.result()

    def state(self, t_s: float) -> dict[str, Any]:
        ses = self.session
        return {"trial": ses.trial, "n_trials": ses.n_trials, "done": ses.done}
