"""Severity scale of hypertonia per joint group (seed, "Haptic rendering of hypertonic-like
forces"; BRIEF §5).

A group (shoulder: sf+se, elbow: ef+ee, bi-articular: bf+be) is made hypertonic by raising its
passive stiffness Km and reflex scale α between two boundaries set on passive *joint* stiffness:

* lower boundary - the unimpaired arm's joint stiffness (default Km = 600 N/m: elbow
  ≈ 1.1 N·m/rad, inside Wiegner & Watts' 0.4-1.8 N·m/rad);
* upper boundary - MAS 4, :data:`UPPER_RATIO` = 10 × unimpaired (Pei et al. 2021: peak resistive
  elbow torque 0.9 → 9.8 N·m from MAS 0 to 4; Liang et al. 2020: 1.3-6.7 N·m).

Levels below severe are spaced by the Weber fraction w = 0.6 for stiffness discrimination in
free exploration (seed): each level is the one above divided by 1 + w.

Joint stiffness here is the passive joint stiffness at the rest posture, the diagonal of
J_λᵀ diag(Km/2) J_λ (with the smoothed ramp each muscle has stiffness Km/2 at rest length,
so an agonist-antagonist pair gives the one-sided seed value). The measure of a group is the
stiffness of the joint it crosses: shoulder → K_11, elbow → K_22, bi-articular → K_11 + K_22.
The group's Km follows from the measure it must produce; α scales with Km; β rises from the
unimpaired value to 1 at severe, geometrically in the stiffness ratio (assumption).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from fieldbank.errors import ParameterError
from fieldbank.params import (
    DEFAULT_ALPHA_N,
    DEFAULT_BETA,
    DEFAULT_KM_N_PER_M,
    GROUP_INDEX,
    GROUP_SIGN,
    JOINT_GROUPS,
    ArmParams,
)

WEBER_FRACTION = 0.6
UPPER_RATIO = 10.0
BETA_SEVERE = 1.0
LEVELS: tuple[str, ...] = ("unimpaired", "very mild", "mild", "moderate", "severe")
#: Stiffness ratio to unimpaired at each level: severe = upper boundary, each lower level is
#: the one above / (1 + w); unimpaired = 1.
LEVEL_RATIO: dict[str, float] = {"unimpaired": 1.0}
for _k, _name in enumerate(("severe", "moderate", "mild", "very mild")):
    LEVEL_RATIO[_name] = UPPER_RATIO / (1.0 + WEBER_FRACTION) ** _k

_ALIASES = {
    "none": "unimpaired", "unimpaired": "unimpaired", "normal": "unimpaired",
    "very mild": "very mild", "very-mild": "very mild", "very_mild": "very mild",
    "verymild": "very mild", "mild": "mild", "moderate": "moderate", "severe": "severe",
}
_GROUP_ALIASES = {
    "shoulder": "shoulder", "elbow": "elbow", "biarticular": "biarticular",
    "bi-articular": "biarticular", "bi": "biarticular", "biart": "biarticular",
}


def level_name(text: str) -> str:
    """Canonical level name for user text ('very-mild', 'Severe', …)."""
    key = text.strip().lower()
    if key not in _ALIASES:
        raise ParameterError(
            f"Unknown severity level {text!r}; known: {', '.join(LEVELS)}."
        )
    return _ALIASES[key]


def group_name(text: str) -> str:
    """Canonical joint-group name for user text ('bi-articular' → 'biarticular')."""
    key = text.strip().lower()
    if key not in _GROUP_ALIASES:
        raise ParameterError(
            f"Unknown joint group {text!r}; known: {', '.join(JOINT_GROUPS)}."
        )
    return _GROUP_ALIASES[key]


def _joint_stiffness(p: ArmParams, km: np.ndarray) -> np.ndarray:
    jl = np.array(
        [[s * a, s * b] for s, a, b in zip(GROUP_SIGN, p.moment_arm_shoulder_m,
                                           p.moment_arm_elbow_m, strict=True)]
    )
    return np.einsum("ki,k,kj->ij", jl, 0.5 * km, jl)


def _measure(group: str, kj: np.ndarray) -> float:
    if group == "shoulder":
        return float(kj[0, 0])
    if group == "elbow":
        return float(kj[1, 1])
    return float(kj[0, 0] + kj[1, 1])


def joint_stiffness_n_m_per_rad(p: ArmParams) -> np.ndarray:
    """Passive joint stiffness matrix at rest, shape (2, 2), N·m/rad."""
    return _joint_stiffness(p, np.array(p.km_n_per_m))


def _reference(p: ArmParams, group: str) -> float:
    return _measure(group, _joint_stiffness(p, np.full(6, DEFAULT_KM_N_PER_M)))


def _group_km_for(p: ArmParams, group: str, target: float, km: np.ndarray) -> float:
    """Km of both muscles of ``group`` giving measure ``target``, other muscles as in km."""
    idx = [GROUP_INDEX[m] for m in JOINT_GROUPS[group]]
    k0 = km.copy()
    k0[idx] = 0.0
    base = _measure(group, _joint_stiffness(p, k0))
    k1 = k0.copy()
    k1[idx] = 1.0
    slope = _measure(group, _joint_stiffness(p, k1)) - base
    return (target - base) / slope


def synthesize(
    severities: Mapping[str, str], base: ArmParams | None = None
) -> ArmParams:
    """An arm with the given joint groups at the given levels, e.g. ``{'elbow': 'severe'}``.

    Groups not named keep the base values (default: unimpaired, 75 kg, 1.75 m).
    """
    p = base if base is not None else ArmParams.from_anthropometry()
    km = np.array(p.km_n_per_m)
    alpha = np.array(p.alpha_n)
    beta = np.array(p.beta)
    for g_text, lvl_text in severities.items():
        g = group_name(g_text)
        lvl = level_name(lvl_text)
        ratio = LEVEL_RATIO[lvl]
        target = ratio * _reference(p, g)
        k = _group_km_for(p, g, target, np.full(6, DEFAULT_KM_N_PER_M))
        frac = math.log(ratio) / math.log(UPPER_RATIO)
        b = DEFAULT_BETA * (BETA_SEVERE / DEFAULT_BETA) ** frac
        for m in JOINT_GROUPS[g]:
            i = GROUP_INDEX[m]
            km[i] = k
            alpha[i] = DEFAULT_ALPHA_N * k / DEFAULT_KM_N_PER_M
            beta[i] = b
    return p.replace(
        km_n_per_m=tuple(km.tolist()), alpha_n=tuple(alpha.tolist()), beta=tuple(beta.tolist())
    )


@dataclass(frozen=True)
class GroupSeverity:
    """Where one joint group sits on the scale.

    level : nearest level (log-stiffness distance)
    score : continuous, 0 = unimpaired, 1 = very mild, … 4 = severe (may exceed 4)
    stiffness_ratio : the group's joint-stiffness measure over the unimpaired one
    km_n_per_m : mean Km of the group's two muscles
    beyond_scale : above the severe level by more than half a Weber step
    """

    group: str
    level: str
    score: float
    stiffness_ratio: float
    km_n_per_m: float
    beyond_scale: bool

    def to_dict(self) -> dict[str, object]:
        return {
            "group": self.group, "level": self.level, "score": round(self.score, 4),
            "stiffness_ratio": round(self.stiffness_ratio, 4),
            "km_n_per_m": round(self.km_n_per_m, 3), "beyond_scale": self.beyond_scale,
        }


def score_from_ratio(ratio: float) -> float:
    """Continuous severity score for a stiffness ratio (0 unimpaired … 4 severe)."""
    vm = LEVEL_RATIO["very mild"]
    if ratio <= 1.0:
        return 0.0
    if ratio < vm:
        return math.log(ratio) / math.log(vm)
    return 1.0 + math.log(ratio / vm) / math.log(1.0 + WEBER_FRACTION)


def classify(p: ArmParams) -> dict[str, GroupSeverity]:
    """Place every joint group of an arm on the severity scale.

    Each group is judged by its own muscles (mean Km of the pair), the other groups held at
    unimpaired values, so one group's impairment does not leak into another's level.
    """
    out: dict[str, GroupSeverity] = {}
    km_all = np.array(p.km_n_per_m)
    for g, members in JOINT_GROUPS.items():
        idx = [GROUP_INDEX[m] for m in members]
        km = np.full(6, DEFAULT_KM_N_PER_M)
        mean_km = float(km_all[idx].mean())
        km[idx] = mean_km
        ratio = _measure(g, _joint_stiffness(p, km)) / _reference(p, g)
        logs = {lvl: abs(math.log(max(ratio, 1e-12) / r)) for lvl, r in LEVEL_RATIO.items()}
        level = min(LEVELS, key=lambda lvl: logs[lvl])
        beyond = ratio > UPPER_RATIO * math.sqrt(1.0 + WEBER_FRACTION)
        out[g] = GroupSeverity(g, level, score_from_ratio(ratio), ratio, mean_km, beyond)
    return out


def parse_severity_options(items: list[str] | tuple[str, ...]) -> dict[str, str]:
    """Parse CLI items like ``elbow=severe`` into {group: level}."""
    out: dict[str, str] = {}
    for item in items:
        for part in item.split(","):
            part = part.strip()
            if not part:
                continue
            if "=" not in part:
                raise ParameterError(
                    f"Severity {part!r} must look like GROUP=LEVEL, e.g. elbow=severe "
                    f"(groups: {', '.join(JOINT_GROUPS)}; levels: {', '.join(LEVELS)})."
                )
            g, lvl = part.split("=", 1)
            out[group_name(g)] = level_name(lvl)
    return out
