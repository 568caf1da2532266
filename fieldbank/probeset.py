"""What a probe command works with (``fieldbank probe design|classify|paths|trials``), from
its options: the candidate arms - severity levels of muscle groups (``--groups``,
``--levels``), the unimpaired arm, parameter files and stored models, each compiled once (a
stored model that rests on guesses says so in its candidate's notes) -, the noise and the
perception a design assumes, and the limits a probe keeps to.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from fieldbank import modelsource
from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.design import (
    Candidate,
    NoiseModel,
    Perception,
    ProbeLimits,
    check_candidates,
    severity_candidates,
)
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


def noise_and_perception(force_sd_n: float, correlation_s: float, direction_sd_deg: float,
                         length_sd: float, speed_sd: float, force_jnd: float,
                         direction_jnd_deg: float,
                         free_exploration: bool = False) -> tuple[NoiseModel, Perception]:
    """The noise of a recorded probe and the clinician's perception (the free-exploration
    thresholds when ``free_exploration``, else ``force_jnd`` and ``direction_jnd_deg``)."""
    noise = NoiseModel(force_sd_n=force_sd_n, correlation_s=correlation_s,
                       direction_sd_deg=direction_sd_deg, length_sd=length_sd,
                       speed_sd=speed_sd)
    perception = Perception.free_exploration() if free_exploration else \
        Perception(force_jnd=force_jnd, direction_jnd_deg=direction_jnd_deg)
    return noise, perception


def probe_limits(max_speed_m_per_s: float, force_limit_n: float,
                 workspace_m: tuple[float, float, float, float] | None = None,
                 shoulder_offset_m: tuple[float, float] = (0.0, 0.0)) -> ProbeLimits:
    """The limits a probe keeps to; ``workspace_m`` (x min, x max, y min, y max) is in the
    robot's frame, whose shoulder is at ``shoulder_offset_m``: the limits hold it in the
    shoulder's."""
    box = None
    if workspace_m is not None:
        (x0, x1, y0, y1), (ox, oy) = workspace_m, shoulder_offset_m
        box = (x0 - ox, x1 - ox, y0 - oy, y1 - oy)
    return ProbeLimits(max_speed_m_per_s=max_speed_m_per_s, force_limit_n=force_limit_n,
                       workspace_m=box)
