"""Candidates: the arms a clinician hesitates between.

The arms a clinician hesitates between (:class:`Candidate`): synthetic severities per joint
group (:func:`severity_candidates`), stored fitted models, parameter files, each compiled once.
Their equilibrium is the mean of their rest hand positions; every path is in the shoulder frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fieldbank.errors import ParameterError
from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.severity import group_name, level_name, synthesize
from fieldbank.model import Arm, FloatArray
from fieldbank.params import JOINT_GROUPS, ArmParams


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
