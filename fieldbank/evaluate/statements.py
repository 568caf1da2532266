"""What the open-set classifier states: per group and direction, partner groups as a set when
the recording cannot tell them apart, and whether any candidate explains the recording.

A clinician asks per group: "are the elbow flexors impaired?", "is there a contracture of the
elbow extensors?". The posterior over about 20,800 arms of up to two groups
(:mod:`fieldbank.evaluate.openset`) answers that directly - the stated probability of every set
of groups holding a given one - and its joint answer ("ef+bf") is not what a clinician uses.
Where two groups act in the same stretch (:data:`PARTNERS`: the elbow flexors and the
bi-articular flexors both resist elbow extension; …) one can take over what the other does
(the recording fits "ef" and "bf" alike), and neither can be stated alone; their union can:
"elbow flexors or bi-articular flexors: resistance to elbow extension, the recording cannot
tell which", stated with the probability that at least one of them is impaired.

The statements of one recording (:func:`state`):

* every group whose stated probability either way is at least :data:`DECIDED` (0.9): "impaired"
  or "not impaired" with that probability;
* the others paired with an undecided partner, the pair whose union is most decided first,
  when the union is more decided than either group alone: "at least one of them impaired" or
  "neither", with the union's probability;
* a group left undecided with no partner to pair: stated alone, the probability as it is;
* "none of the candidates explains this recording" when that is more likely than not, with
  its probability (:attr:`~fieldbank.evaluate.openset.OpenClassification.other_probability`).

Each statement is a yes/no claim with a probability, so each is checked the same way: how
often the claims stated with p in a bin are right (:mod:`fieldbank.evaluate.reliability`).
"""

from __future__ import annotations

from dataclasses import dataclass

from fieldbank.evaluate.openset import OpenClassification
from fieldbank.params import GROUP_NAMES, GROUPS

#: Groups stretched by the same motion, each pair with the resistance both give: one can fit a
#: recording the other made.
PARTNERS: dict[tuple[str, str], str] = {
    ("ef", "bf"): "resistance to elbow extension",
    ("ee", "be"): "resistance to elbow flexion",
    ("sf", "bf"): "resistance to shoulder extension",
    ("se", "be"): "resistance to shoulder flexion",
}
#: A group stated alone when its stated probability either way is at least this.
DECIDED = 0.9


@dataclass(frozen=True)
class Statement:
    """One claim: ``groups`` (one group, or partner groups) impaired - at least one of them -
    or not, with its ``probability``; or, with no groups, that none of the candidates explains
    the recording."""

    groups: tuple[str, ...]
    impaired: bool
    probability: float

    @property
    def kind(self) -> str:
        return "none" if not self.groups else "group" if len(self.groups) == 1 else "partners"

    def right(self, truth: frozenset[str] | set[str], outside: bool) -> bool:
        """Whether the claim holds for an arm whose impaired groups are ``truth``
        (``outside``: an arm none of the candidates is)."""
        if not self.groups:
            return outside
        return bool(set(self.groups) & set(truth)) == self.impaired

    @property
    def text(self) -> str:
        if not self.groups:
            return "none of the candidates explains this recording"
        names = [f"{GROUP_NAMES[g]} ({g})" for g in self.groups]
        if len(names) == 1:
            return f"{names[0]}: {'impaired' if self.impaired else 'not impaired'}"
        pair = PARTNERS.get((self.groups[0], self.groups[1]), "")
        if self.impaired:
            return (f"{' or '.join(names)}: {pair} - the recording cannot tell which")
        return f"neither {' nor '.join(names)} impaired"

    def to_dict(self) -> dict[str, object]:
        return {"groups": list(self.groups), "impaired": self.impaired,
                "probability": round(self.probability, 6), "says": self.text}


def _sure(p: float) -> float:
    return max(p, 1.0 - p)


def state(c: OpenClassification, decided: float = DECIDED) -> tuple[Statement, ...]:
    """What the classification ``c`` states (module docstring), groups in the model's order,
    "none of the candidates" first when stated."""
    out: list[Statement] = []
    if c.other_probability > 0.5:
        out.append(Statement((), True, c.other_probability))
    gp = c.group_probability
    open_ = {g for g in GROUPS if _sure(gp[g]) < decided}
    pairs = sorted(((c.any_impaired(pair), pair) for pair in PARTNERS
                    if set(pair) <= open_), key=lambda x: -_sure(x[0]))
    said: dict[str, Statement] = {}
    for union, (a, b) in pairs:
        if a in said or b in said or _sure(union) <= max(_sure(gp[a]), _sure(gp[b])):
            continue
        said[a] = said[b] = Statement((a, b), union >= 0.5, _sure(union))
    for g in GROUPS:
        s = said.get(g, Statement((g,), gp[g] >= 0.5, _sure(gp[g])))
        if s not in out:
            out.append(s)
    return tuple(out)


def open_report(c: OpenClassification) -> dict[str, object]:
    """The classification ``c`` as a document: what is stated first (``statements``), then
    :meth:`~fieldbank.evaluate.openset.OpenClassification.to_dict`."""
    return {"statements": [s.to_dict() for s in state(c)], **c.to_dict()}


__all__ = ["DECIDED", "PARTNERS", "Statement", "open_report", "state"]
