"""The candidate arms a probe command works with (``fieldbank probe design|classify|paths``),
from its options: severity levels of muscle groups (``--groups``, ``--levels``), the
unimpaired arm, parameter files and stored models, each compiled once. A stored model that
rests on guesses says so in its candidate's notes.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from fieldbank import modelsource
from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.design import Candidate, check_candidates, severity_candidates
from fieldbank.evaluate.severity import group_name, level_name
from fieldbank.params import JOINT_GROUPS, ArmParams
from fieldbank.storage import Database

#: Every level ``--levels all`` means.
ALL_LEVELS = ("very mild", "mild", "moderate", "severe")


def named_list(text: str | None, canon: Callable[[str], str],
               every: tuple[str, ...]) -> list[str]:
    """``'a,b'`` as canonical names (``canon``), ``'all'`` as ``every``, None as none."""
    if text is None:
        return []
    if text.strip().lower() == "all":
        return list(every)
    return [canon(t) for t in text.split(",") if t.strip()]


def candidate_set(groups: str, levels: str | None, unimpaired: bool = False,
                  param_files: Sequence[Path] = (), model_ids: Sequence[int] = (),
                  mass_kg: float | None = None, height_m: float | None = None,
                  side: str | None = None, db_url: str | None = None) -> list[Candidate]:
    """The candidates the options name, at least two and all of one geometry
    (:func:`~fieldbank.evaluate.design.check_candidates`). Without ``levels``: every level of
    the groups unless parameter files or models are given (then none)."""
    cache = ArmCache()
    base = modelsource.synthetic([], body_mass_kg=mass_kg, height_m=height_m, side=side).params
    out: list[Candidate] = []
    lv = levels if levels is not None else (None if param_files or model_ids else "severe")
    if lv:
        gs = named_list(groups, group_name, tuple(JOINT_GROUPS))
        ls = named_list(lv, level_name, ALL_LEVELS)
        out += severity_candidates(gs, ls, unimpaired=unimpaired, base=base, cache=cache)
    elif unimpaired:
        out.append(Candidate.from_severity(None, "unimpaired", base, cache))
    for path in param_files:
        out.append(Candidate(path.stem, cache(ArmParams.from_file(path))))
    if model_ids:
        with Database.open(db_url, create=False) as db:
            for mid in model_ids:
                src = modelsource.stored(db, mid)
                out.append(Candidate(f"model {mid}", cache(src.params),
                                     notes=tuple(f"rests on a guess: {g}"
                                                 for g in src.guesses)))
    return list(check_candidates(out, 2))
