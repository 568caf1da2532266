"""Blinded comparison of two models: A/B/X trials with seeded randomization.

In each trial the clinician can feel A, B and X as often as they like; X is secretly A or B
(drawn per trial); they answer which one X is. With ``hide_labels`` the assignment of A and B to
the before and after models is also drawn at random once per session, so neither label reveals
the intervention. Every presentation and answer is recorded with its time.
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field
from typing import Any

from fieldbank.haptic.errors import CommandError

#: Most trials in one block (a request cannot make the renderer hold more).
MAX_ABX_TRIALS = 1000


@dataclass
class AbxSession:
    """A block of A/B/X trials.

    Parameters
    ----------
    n_trials : int
    seed : int
        Seeds the draw of X per trial (and of the A/B labels with ``hide_labels``).
    hide_labels : bool
        Randomize which model (0 = before, 1 = after) is called A.
    """

    n_trials: int = 10
    seed: int = 0
    hide_labels: bool = True
    answers: list[dict[str, Any]] = field(default_factory=list)

    def __post_init__(self) -> None:
        if (isinstance(self.n_trials, bool) or not isinstance(self.n_trials, int)
                or not 1 <= self.n_trials <= MAX_ABX_TRIALS):
            raise CommandError(f"A/B/X needs 1 to {MAX_ABX_TRIALS} trials; got "
                               f"{self.n_trials!r}")
        rng = random.Random(self.seed)
        a_model = rng.randrange(2) if self.hide_labels else 0
        self.label_model = {"A": a_model, "B": 1 - a_model}
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

    def answer(self, choice: str, t_s: float) -> dict[str, Any]:
        """Record that X sounded like ``choice`` ('A' or 'B'); advance to the next trial."""
        choice = choice.upper()
        if choice not in ("A", "B"):
            raise CommandError(f"an A/B/X answer is 'A' or 'B'; got {choice!r}")
        if self.done:
            raise CommandError(f"the A/B/X block of {self.n_trials} trials is finished")
        x = self.x_labels[self.trial]
        rec = {"trial": self.trial, "answer": choice, "x_is": x, "correct": choice == x,
               "x_model": self.label_model[x], "t_s": t_s}
        self.answers.append(rec)
        self.trial += 1
        return rec

    def result(self) -> dict[str, Any]:
        """Answers so far, with the key (revealed only here) and the score."""
        n = len(self.answers)
        k = sum(1 for a in self.answers if a["correct"])
        return {"n_trials": self.n_trials, "answered": n, "correct": k, "seed": self.seed,
                "hide_labels": self.hide_labels, "label_model": dict(self.label_model),
                "answers": list(self.answers)}
