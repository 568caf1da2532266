"""Candidates: the arms a clinician hesitates between.

The arms a clinician hesitates between (:class:`Candidate`): synthetic severities per joint
group (:func:`severity_candidates`), stored fitted models, parameter files, each compiled once.
Their equilibrium is the mean of their rest hand positions; every path is in the shoulder frame.

**The open set** (:func:`open_candidates`): a classifier that chooses among joint groups at the
scale's steps is confidently wrong on an arm that is none of them (an elbow-extensor reflex
alone was called unimpaired with p = 1.000). The open set spans what a patient can be: the
unimpaired arm; every muscle group alone at every level, passive only, reflex only and both;
every group with a contracture alone (its slack length 5, 10 or 20 mm short, the brief's
range); and every two groups at once at every level. Its label is the set of impaired groups
("ef", "ef+bf", "unimpaired"): what a classification names.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fieldbank.errors import ParameterError
from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.severity import LEVELS, group_name, level_name, synthesize
from fieldbank.model import Arm, FloatArray
from fieldbank.params import GROUP_INDEX, GROUPS, JOINT_GROUPS, ArmParams

#: The contractures of the open set: slack lengths this much short, m (the brief's range:
#: optimal fibre length 0.95-0.80 of a 10 cm fibre).
OPEN_CONTRACTURES_M: tuple[float, ...] = (0.005, 0.010, 0.020)
#: The components of a single group in the open set: passive only, reflex only, both.
OPEN_COMPONENTS: tuple[str, ...] = ("passive", "dynamic", "both")


@dataclass(frozen=True, eq=False)
class Candidate:
    """One arm a clinician hesitates about.

    Attributes
    ----------
    name : str
        Unique among the candidates ("elbow severe", "model 12").
    arm : Arm
        The compiled model.
    group, level : str or None
        The impaired joint group and its severity level when known ("unimpaired": no group).
    notes : tuple of str
        What the candidate's numbers rest on that its data did not identify.
    """

    name: str
    arm: Arm
    group: str | None = None
    level: str | None = None
    notes: tuple[str, ...] = ()

    @classmethod
    def from_severity(cls, group: str | None, level: str, base: ArmParams | None = None,
                      cache: ArmCache | None = None) -> Candidate:
        """A synthetic arm with ``group`` at ``level``
        (:func:`fieldbank.evaluate.severity.synthesize`)."""
        lvl = level_name(level)
        if lvl == "unimpaired" or group is None:
            params = synthesize({}, base)
            return cls("unimpaired", (cache or Arm.from_params)(params), None, "unimpaired")
        g = group_name(group)
        params = synthesize({g: lvl}, base)
        return cls(f"{g} {lvl}", (cache or Arm.from_params)(params), g, lvl)

    @property
    def label(self) -> str:
        """The group a classification names ("unimpaired" when no group is impaired)."""
        return self.group if self.group is not None else (self.level or self.name)


def severity_candidates(groups: Sequence[str] = tuple(JOINT_GROUPS),
                        levels: Sequence[str] = ("severe",), *, unimpaired: bool = False,
                        base: ArmParams | None = None,
                        cache: ArmCache | None = None) -> tuple[Candidate, ...]:
    """Every group at every level (groups × levels), optionally with the unimpaired arm."""
    cache = cache or ArmCache()
    out = [Candidate.from_severity(g, lvl, base, cache) for lvl in levels for g in groups]
    if unimpaired:
        out.append(Candidate.from_severity(None, "unimpaired", base, cache))
    return tuple(out)


def open_candidates(base: ArmParams | None = None, levels: Sequence[str] = LEVELS[1:], *,
                    contractures_m: Sequence[float] = OPEN_CONTRACTURES_M,
                    pairs: bool = True, cache: ArmCache | None = None
                    ) -> tuple[Candidate, ...]:
    """The open set of candidates (module docstring) on the arm ``base`` (default: the
    unimpaired adult): 1 + 6 × 3 × levels + 6 × contractures + 15 × levels arms (151 with the
    defaults). Each group's values at each level are synthesised once
    (:func:`fieldbank.evaluate.severity.synthesize`) and combined."""
    p0 = base if base is not None else ArmParams.from_anthropometry()
    cache = cache or ArmCache()
    lv = [level_name(x) for x in levels]
    values: dict[tuple[str, str, str], tuple[float, float, float]] = {}
    for g in GROUPS:
        i = GROUP_INDEX[g]
        for level in lv:
            for comp in ("passive", "dynamic"):
                s = synthesize({f"{g}:{comp}": level}, p0)
                values[(g, comp, level)] = (s.km_n_per_m[i], s.alpha_n[i], s.beta[i])

    def arm(changes: dict[str, tuple[str, str]]) -> ArmParams:
        p = p0
        for g, (comp, level) in changes.items():
            kw: dict[str, float] = {}
            if comp in ("passive", "both"):
                kw["km_n_per_m"] = values[(g, "passive", level)][0]
            if comp in ("dynamic", "both"):
                _, kw["alpha_n"], kw["beta"] = values[(g, "dynamic", level)]
            p = p.with_group(g, **kw)
        return p

    out = [Candidate("unimpaired", cache(p0), None, "unimpaired")]
    for g in GROUPS:
        for comp in OPEN_COMPONENTS:
            for level in lv:
                what = level if comp == "both" else f"{comp} {level}"
                out.append(Candidate(f"{g} {what}", cache(arm({g: (comp, level)})), g, what))
        for d in contractures_m:
            what = f"contracture {d * 1000:g} mm"
            slack = p0.group_value("slack_offset_m", g) - float(d)
            out.append(Candidate(f"{g} {what}", cache(p0.with_group(g, slack_offset_m=slack)),
                                 g, what))
    if pairs:
        for a, b in itertools.combinations(GROUPS, 2):
            for level in lv:
                out.append(Candidate(f"{a}+{b} {level}",
                                     cache(arm({a: ("both", level), b: ("both", level)})),
                                     f"{a}+{b}", level))
    return tuple(out)


def check_candidates(candidates: Sequence[Candidate], at_least: int = 2) -> tuple[Candidate, ...]:
    """The candidates as a tuple; refuses fewer than ``at_least`` or repeated names."""
    cands = tuple(candidates)
    if len(cands) < at_least:
        raise ParameterError(f"Give at least {at_least} candidate arms; got {len(cands)}.")
    names = [c.name for c in cands]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ParameterError(f"Candidate names must differ; repeated: {', '.join(dup)}.")
    return cands


def equilibrium(candidates: Sequence[Candidate]) -> FloatArray:
    """The candidates' mean rest hand position, shape (2,), m, shoulder frame."""
    return np.mean([c.arm.rest_position() for c in candidates], axis=0)


def check_prior(prior: Sequence[float] | FloatArray | None, n: int) -> FloatArray:
    """Prior probabilities of n candidates (uniform when None), normalised."""
    if prior is None:
        return np.full(n, 1.0 / n)
    p = np.asarray(prior, dtype=float)
    if p.shape != (n,) or not np.all(np.isfinite(p)) or np.any(p < 0) or p.sum() <= 0:
        raise ParameterError(f"The prior must be {n} non-negative numbers with a positive sum; "
                             f"got {np.asarray(prior).tolist()!r}.")
    return p / p.sum()
