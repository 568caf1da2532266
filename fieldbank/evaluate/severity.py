"""Severity of hypertonia per muscle group and direction, passive and dynamic (BRIEF §5).

The seed ("Haptic rendering of hypertonic-like forces") renders hypertonia between two
boundaries - the unimpaired arm below, MAS 4 above - with intermediate levels spaced by the
Weber fraction w = 0.6 of stiffness discrimination in free exploration: counting down from
severe (the upper boundary), each level is the one above divided by 1 + w (severe, moderate,
mild, very mild). The seed sets the boundaries on passive stiffness only. Spasticity, though, is
by definition velocity-dependent resistance (Lance 1980), and clinicians grade per muscle group
and direction (MAS, Tardieu). So here every one of the six muscle groups gets two grades on that
ladder:

* **passive** (position-dependent: contracture, stiffness) - the passive torque the group adds
  to a slow stretch of the joint it is graded on (:data:`GRADED_STRETCH`), angle by angle, over
  the unimpaired arm's (same segments and geometry, unimpaired muscles:
  :meth:`fieldbank.params.ArmParams.with_unimpaired_muscles`)::

      P* = 1 + max_θ [P(θ) − P_ref(θ)] / max_θ P_ref(θ)

  For a change of Km alone P = r P_ref and P* = r, the seed's Km ratio. A contracture of the
  slack length (a shorter rest length, ``slack_offset_m`` < 0) with normal stiffness adds torque
  where the unimpaired arm is still slack - the resistance comes earlier in the range - and is
  graded by it, although its largest torque at the end of the range barely changes (the passive
  force of seed eq. 5 saturates: 20 mm shorter adds ≈ 0.26 N·m at 67° to an elbow whose
  unimpaired peak is 0.37 N·m, P* ≈ 1.7, but only 14% at the end of the range). MAS-4 boundary
  (:attr:`SeverityScale.passive_upper_ratio`, 10): peak resistive elbow torque over the passive
  range rises ≈ 0.9 → 9.8 N·m from MAS 0 to 4 (Pei et al. 2021), unimpaired elbow stiffness
  0.4-1.8 N·m/rad (Wiegner & Watts 1986); the seed's "≈ 10 × unimpaired".
* **dynamic** (velocity-dependent: spasticity, the stretch reflex) - the velocity-dependent torque
  (fast minus slow stretch, 180°/s against 5°/s) the group adds, angle by angle, over the
  unimpaired group's, against the unimpaired resistance to the fast stretch::

      D = 1 + max_θ [V(θ) − V_ref(θ)] / max_θ [P_ref(θ) + V_ref(θ)]

  P_ref the unimpaired group's passive torque along the stretch, V the group's
  velocity-dependent torque. D = 1 when the reflex is unimpaired, and D = 10 when the fast
  stretch meets ten times the unimpaired resistance because of the reflex alone. Where the
  reflex adds most where the passive torque peaks (the end of the range: the scale's own
  synthesized arms) this is max_θ [P_ref + V] / max_θ [P_ref + V_ref]; a reflex that catches
  mid-range is graded by what it adds there. MAS-4 boundary
  (:attr:`SeverityScale.dynamic_upper_ratio`, 10; assumption): the same "≈ 10 × unimpaired" as
  the passive scale, applied to the resistance felt at a fast stretch, where MAS is graded
  (Liang et al. 2020: 1.3 → 6.7 N·m from MAS 0 to 4 at ≥ 150°/s, ≈ 5 ×; Pei et al. 2021 ≈ 10 ×;
  McPherson 2018: the reflex needs stretches faster than 100°/s).

A group that adds nothing anywhere (a weakened, released or lengthened group) gets the ratio of
its peak to the unimpaired peak instead (< 1: less than unimpaired).

**What a hand feels below the first step.** The levels are one free-exploration stiffness JND
apart (w = 0.6), so the nearest-level rule alone would call everything up to ≈ 1.56 ×
unimpaired "unimpaired" - α raised tenfold at the unimpaired gain (0.1 N·m more at the end of a
fast elbow stretch, D ≈ 1.25) among it. A clinician stretching the limb compares forces at a
place in the range, where the force-magnitude JND is ≈ 7-10 % (Jones 1989; Pang, Tan & Durlach
1991): MAS 1 is "a catch and release or minimal resistance at the end of the range". So a
component is *unimpaired* only while what the group adds stays within
:attr:`SeverityScale.felt_fraction` (10 %) of the unimpaired peak; a felt addition below very
mild is graded very mild, and above it the nearest level. Each grade reports the torque added,
the angle where it is largest and the angle from which it is felt (the resistance's onset for
the passive grade, the catch for the dynamic one), so the grade says where in the range it was
felt.

The clinical read-outs the grades rest on (slow- and fast-stretch torque, the velocity-dependent
part, the Tardieu catch) are computed per joint and direction in
:mod:`fieldbank.evaluate.probing`.

Synthesis runs the scale backwards (:func:`synthesize`): a passive level sets the group's Km
(closed form: the passive torque is linear in Km); a dynamic level moves the group's α and β
along the seed's path - α scales like the stiffness ratio r (α = 100 N · r), β rises
geometrically from 0.1 to 1 at r = 10 (assumption) and stays at 1 beyond - to the point where
D reaches the level (a one-dimensional root). Targets (:func:`parse_severity_options`)::

    elbow=severe                 both groups of the joint, passive and dynamic
    elbow-flexors=moderate       one muscle group (also 'ef'), both components
    elbow-flexors:dynamic=severe reflex only ('dynamic', 'reflex', 'spasticity')
    ef:passive=mild              passive only ('passive', 'contracture', 'stiffness')
    elbow:dynamic=mild           both directions of the joint, reflex only

Read-outs of a fitted model name the parameters behind each grade that the maps did not
identify (``unidentified``): Km (and the slack length, when fitted) of the group for the passive
grade, α and β for the dynamic one.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from fieldbank.errors import ParameterError
from fieldbank.evaluate.probing import (
    Profiles,
    StretchProfile,
    stretch_profile,
    stretch_profiles,
    unimpaired_reference,
)
from fieldbank.evaluate.tone import (
    FELT_FRACTION,
    GRADED_STRETCH,
    POSITIONED_STRETCH,
    GroupTone,
    dynamic_ratio,
    group_tone,
    positioned_hold_rad,
    positioned_profiles,
)
from fieldbank.model import Arm
from fieldbank.params import (
    DEFAULT_ALPHA_N,
    DEFAULT_BETA,
    GROUP_INDEX,
    GROUP_LEGEND,
    GROUP_NAMES,
    JOINT_GROUPS,
    ArmParams,
)

WEBER_FRACTION = 0.6
UPPER_RATIO = 10.0
BETA_SEVERE = 1.0
LEVELS: tuple[str, ...] = ("unimpaired", "very mild", "mild", "moderate", "severe")
COMPONENTS: tuple[str, ...] = ("passive", "dynamic")

MUSCLE_GROUP_NAMES: dict[str, str] = GROUP_NAMES
#: The fitted parameters each component rests on, per group.
COMPONENT_PARAMETERS: dict[str, tuple[str, ...]] = {"passive": ("km", "slack"),
                                                    "dynamic": ("alpha", "beta")}

_ALIASES = {
    "none": "unimpaired", "unimpaired": "unimpaired", "normal": "unimpaired",
    "very mild": "very mild", "very-mild": "very mild", "very_mild": "very mild",
    "verymild": "very mild", "mild": "mild", "moderate": "moderate", "severe": "severe",
}
_GROUP_ALIASES = {
    "shoulder": "shoulder", "elbow": "elbow", "biarticular": "biarticular",
    "bi-articular": "biarticular", "bi": "biarticular", "biart": "biarticular",
}
_COMPONENT_ALIASES = {
    "passive": "passive", "contracture": "passive", "stiffness": "passive",
    "position": "passive", "dynamic": "dynamic", "reflex": "dynamic",
    "spasticity": "dynamic", "velocity": "dynamic",
}
_DIRECTION_ALIASES = {"flexors": 0, "flexor": 0, "extensors": 1, "extensor": 1}
#: Largest path parameter of the dynamic synthesis (α = 100 N · 10^s; 10^4 reaches the
#: ArmParams bound of α, 1e6 N).
_S_MAX = 4.0


@dataclass(frozen=True)
class SeverityScale:
    """The ladder of levels (documented, overridable defaults; module docstring).

    Parameters
    ----------
    weber_fraction : float
        Spacing of the levels below severe (seed: 0.6).
    passive_upper_ratio, dynamic_upper_ratio : float
        MAS-4 boundary of each component as a ratio to unimpaired.
    felt_fraction : float
        Added torque, as a fraction of the unimpaired peak, below which a component reads
        unimpaired (force-magnitude JND, 10 %); above it and below very mild it reads very mild.
    """

    weber_fraction: float = WEBER_FRACTION
    passive_upper_ratio: float = UPPER_RATIO
    dynamic_upper_ratio: float = UPPER_RATIO
    felt_fraction: float = FELT_FRACTION

    def __post_init__(self) -> None:
        if not self.weber_fraction > 0:
            raise ParameterError(f"weber_fraction must be > 0; got {self.weber_fraction!r}.")
        if not 0 < self.felt_fraction < self.weber_fraction:
            raise ParameterError(f"felt_fraction must lie in (0, weber_fraction); got "
                                 f"{self.felt_fraction!r}.")
        for name in ("passive_upper_ratio", "dynamic_upper_ratio"):
            upper = getattr(self, name)
            if not upper > (1.0 + self.weber_fraction) ** 3:
                raise ParameterError(
                    f"{name} must exceed (1 + weber_fraction)³ so that very mild lies above "
                    f"unimpaired; got {upper!r}.")

    def upper(self, component: str) -> float:
        return self.passive_upper_ratio if component == "passive" else self.dynamic_upper_ratio

    def level_ratio(self, level: str, component: str = "passive") -> float:
        """Ratio to unimpaired at ``level``: severe = the upper boundary, each lower level the
        one above / (1 + w), unimpaired = 1."""
        if level == "unimpaired":
            return 1.0
        k = ("severe", "moderate", "mild", "very mild").index(level)
        return self.upper(component) / (1.0 + self.weber_fraction) ** k

    def score(self, ratio: float, component: str = "passive") -> float:
        """Continuous score: 0 unimpaired, 1 very mild, … 4 severe (may exceed 4)."""
        vm = self.level_ratio("very mild", component)
        if ratio <= 1.0:
            return 0.0
        if ratio < vm:
            return math.log(ratio) / math.log(vm)
        return 1.0 + math.log(ratio / vm) / math.log(1.0 + self.weber_fraction)

    def level(self, ratio: float, component: str = "passive") -> str:
        """'unimpaired' while the ratio stays within the felt fraction of 1, else the nearest
        impaired level in log-ratio distance (very mild for a felt ratio below it)."""
        if ratio <= 1.0 + self.felt_fraction:
            return "unimpaired"
        return min(LEVELS[1:], key=lambda lvl: abs(math.log(ratio / self.level_ratio(
            lvl, component))))

    def beyond(self, ratio: float, component: str = "passive") -> bool:
        """Above severe by more than half a Weber step."""
        return ratio > self.upper(component) * math.sqrt(1.0 + self.weber_fraction)


SCALE = SeverityScale()
#: Ratio to unimpaired at each level of the default scale (both components).
LEVEL_RATIO: dict[str, float] = {lvl: SCALE.level_ratio(lvl) for lvl in LEVELS}


def score_from_ratio(ratio: float) -> float:
    """Continuous score of a ratio on the default scale (0 unimpaired … 4 severe)."""
    return SCALE.score(ratio)


# --- names -----------------------------------------------------------------------------------
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


def _target_help() -> str:
    return (f"joint groups {', '.join(JOINT_GROUPS)}; muscle groups ({GROUP_LEGEND}) or "
            "e.g. elbow-flexors, shoulder-extensors, biarticular-flexors; optional "
            f":COMPONENT ({', '.join(COMPONENTS)})")


def target_name(text: str) -> str:
    """Canonical target for user text: a joint group ('elbow') or a muscle group ('ef'),
    with an optional component ('ef:dynamic').

    >>> target_name("Elbow-Flexors:reflex")
    'ef:dynamic'
    """
    where, _, comp = text.strip().lower().partition(":")
    where = where.strip().replace("_", "-").replace(" ", "-")
    if where in GROUP_INDEX:
        base = where
    elif where in _GROUP_ALIASES:
        base = _GROUP_ALIASES[where]
    else:
        joint, _, side = where.rpartition("-")
        if joint in _GROUP_ALIASES and side in _DIRECTION_ALIASES:
            base = JOINT_GROUPS[_GROUP_ALIASES[joint]][_DIRECTION_ALIASES[side]]
        else:
            kind = "joint group" if "-" not in where else "muscle group"
            raise ParameterError(f"Unknown {kind} {text.partition(':')[0].strip()!r}; known: "
                                 f"{_target_help()}.")
    if not comp:
        return base
    c = comp.strip()
    if c not in _COMPONENT_ALIASES:
        raise ParameterError(f"Unknown severity component {c!r} in {text.strip()!r}; known: "
                             "passive (contracture, stiffness), dynamic (reflex, spasticity).")
    return f"{base}:{_COMPONENT_ALIASES[c]}"


def expand_target(target: str) -> list[tuple[str, str]]:
    """The (muscle group, component) pairs a target names (any text :func:`target_name` reads)."""
    canon = target_name(target)
    base, _, comp = canon.partition(":")
    groups = JOINT_GROUPS[base] if base in JOINT_GROUPS else (base,)
    comps = (comp,) if comp else COMPONENTS
    return [(g, c) for g in groups for c in comps]


def parse_severity_options(items: Iterable[str]) -> dict[str, str]:
    """Parse CLI items like ``elbow=severe`` or ``elbow-flexors:dynamic=mild`` (comma-separated
    or repeated) into {canonical target: level}, in the order given; :func:`synthesize` applies
    them in that order, so a later, narrower item refines an earlier one."""
    out: dict[str, str] = {}
    for item in items:
        for part in item.split(","):
            part = part.strip()
            if not part:
                continue
            if "=" not in part:
                raise ParameterError(
                    f"Severity {part!r} must look like TARGET[:COMPONENT]=LEVEL, e.g. "
                    f"elbow=severe or elbow-flexors:dynamic=moderate ({_target_help()}; "
                    f"levels: {', '.join(LEVELS)})."
                )
            t, lvl = part.split("=", 1)
            key = target_name(t)
            out.pop(key, None)  # a repeated target moves to its latest position
            out[key] = level_name(lvl)
    return out


# --- classification --------------------------------------------------------------------------
@dataclass(frozen=True)
class ComponentGrade:
    """One component of one group on the scale.

    level : nearest level; score : 0 unimpaired … 4 severe (continuous, may exceed 4);
    ratio : the measure over unimpaired; beyond_scale : above severe by more than half a step;
    unidentified : fitted parameters behind this grade that the maps did not identify
    """

    level: str
    score: float
    ratio: float
    beyond_scale: bool
    unidentified: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, object]:
        return {"level": self.level, "score": round(self.score, 4),
                "ratio": round(self.ratio, 4), "beyond_scale": self.beyond_scale,
                "unidentified": list(self.unidentified)}

    def text(self) -> str:
        """The level, '+' beyond the scale, '*' when it rests on an unidentified parameter."""
        return self.level + ("+" if self.beyond_scale else "") + ("*" if self.unidentified
                                                                  else "")


@dataclass(frozen=True)
class GroupSeverity:
    """Passive and dynamic grade of one muscle group, with the torques behind them."""

    group: str
    passive: ComponentGrade
    dynamic: ComponentGrade
    tone: GroupTone

    @property
    def name(self) -> str:
        return MUSCLE_GROUP_NAMES[self.group]

    @property
    def stretch(self) -> str:
        joint, direction = GRADED_STRETCH[self.group]
        return f"{joint} {direction}"

    def component(self, name: str) -> ComponentGrade:
        return self.passive if name == "passive" else self.dynamic

    def to_dict(self) -> dict[str, object]:
        t = self.tone
        return {
            "group": self.group, "name": self.name, "graded_on": self.stretch,
            "passive": {**self.passive.to_dict(), "stretch": t.passive_stretch,
                        "peak_torque_n_m": t.passive_n_m,
                        "unimpaired_peak_torque_n_m": t.passive_ref_n_m,
                        **t.passive_added.to_dict()},
            "dynamic": {**self.dynamic.to_dict(), "stretch": t.dynamic_stretch,
                        "velocity_dependent_torque_n_m": t.velocity_dependent_n_m,
                        "unimpaired_velocity_dependent_torque_n_m":
                            t.velocity_dependent_ref_n_m,
                        **t.dynamic_added.to_dict()},
        }


def _grade(ratio: float, component: str, scale: SeverityScale,
           unidentified: tuple[str, ...]) -> ComponentGrade:
    return ComponentGrade(scale.level(ratio, component), scale.score(ratio, component), ratio,
                          scale.beyond(ratio, component), unidentified)


def classify(arm: Arm, unidentified: Collection[str] = (), reference: Arm | None = None,
             scale: SeverityScale = SCALE, profiles: Profiles | None = None,
             reference_profiles: Profiles | None = None,
             reference_positioned: dict[str, StretchProfile] | None = None
             ) -> dict[str, GroupSeverity]:
    """Grade every muscle group of ``arm``: passive and dynamic level (module docstring).

    Parameters
    ----------
    arm : Arm
    unidentified : collection of str
        Names of fitted parameters the maps did not identify (``km_ef``, ``alpha_ef``, …, as
        :mod:`fieldbank.fitting.identify` reports them); each grade lists those it rests on.
    reference : Arm, optional
        The unimpaired arm (default: ``arm``'s).
    scale : SeverityScale
    profiles, reference_profiles : optional
        Stretch profiles of ``arm`` and of the reference, when already computed.
    reference_positioned : optional
        The reference's bi-articular groups' own stretches
        (:func:`fieldbank.evaluate.tone.positioned_profiles`), when already computed.
    """
    flagged = set(unidentified)
    out: dict[str, GroupSeverity] = {}
    for g, t in group_tone(arm, reference, profiles, reference_profiles,
                           scale.felt_fraction,
                           reference_positioned=reference_positioned).items():
        grades = {}
        for comp, ratio in (("passive", t.passive_ratio), ("dynamic", t.dynamic_ratio)):
            names = tuple(f"{k}_{g}" for k in COMPONENT_PARAMETERS[comp]
                          if f"{k}_{g}" in flagged)
            grades[comp] = _grade(ratio, comp, scale, names)
        out[g] = GroupSeverity(g, grades["passive"], grades["dynamic"], t)
    return out


def severity_dict(sev: Mapping[str, GroupSeverity]) -> dict[str, dict[str, object]]:
    """JSON form of :func:`classify`'s result, keyed by muscle group."""
    return {g: s.to_dict() for g, s in sev.items()}


def summary(sev: Mapping[str, GroupSeverity]) -> str:
    """One line: every impaired group and component, e.g. 'ef dynamic severe; ee passive mild'
    ('unimpaired' when none is); '*' marks a grade resting on an unidentified parameter."""
    parts = [f"{g} {c} {s.component(c).text()}" for g, s in sev.items() for c in COMPONENTS
             if s.component(c).level != "unimpaired"]
    flagged = [f"{g} {c} unimpaired*" for g, s in sev.items() for c in COMPONENTS
               if s.component(c).level == "unimpaired" and s.component(c).unidentified]
    return "; ".join(parts + flagged) or "unimpaired"


# --- synthesis -------------------------------------------------------------------------------
def _reflex_path(s: float) -> tuple[float, float]:
    """α (N) and β on the seed's path at log10 stiffness ratio s (module docstring)."""
    r = 10.0 ** s
    beta = min(BETA_SEVERE, DEFAULT_BETA * (BETA_SEVERE / DEFAULT_BETA) ** (s / math.log10(
        UPPER_RATIO)))
    return DEFAULT_ALPHA_N * r, beta


def reflex_path(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """α (N) and β on the synthesis path (module docstring) at path parameters ``s`` (any
    shape; α = 100 N · 10^s, β rising geometrically from 0.1 to 1 at s = 1)."""
    sa = np.asarray(s, dtype=float)
    beta = np.minimum(BETA_SEVERE, DEFAULT_BETA * (BETA_SEVERE / DEFAULT_BETA) ** (
        sa / math.log10(UPPER_RATIO)))
    return DEFAULT_ALPHA_N * 10.0 ** sa, beta


#: Largest path parameter of the dynamic synthesis (public name of the module's limit).
REFLEX_PATH_MAX = _S_MAX


def ratio_of_score(score: float, component: str = "passive",
                   scale: SeverityScale = SCALE) -> float:
    """The ratio to unimpaired at a continuous score (the inverse of
    :meth:`SeverityScale.score`; 0 → 1, 1 → very mild, 4 → severe)."""
    vm = scale.level_ratio("very mild", component)
    if score <= 0.0:
        return 1.0
    if score < 1.0:
        return float(vm ** score)
    return float(vm * (1.0 + scale.weber_fraction) ** (score - 1.0))


def _solve_dynamic(arm: Arm, ref_profs: Sequence[StretchProfile], group: str,
                   target: float) -> float:
    """Path parameter s at which ``group``'s dynamic ratio - the larger over its graded
    stretches ``ref_profs`` (the reference's: the clinic's, and a bi-articular group's own,
    :mod:`fieldbank.evaluate.tone`) - reaches ``target`` (≥ 1)."""
    i = GROUP_INDEX[group]
    joint, direction = GRADED_STRETCH[group]
    holds = [None] + ([positioned_hold_rad(arm, group)] if group in POSITIONED_STRETCH else [])

    def ratio(s: float) -> float:
        a, b = _reflex_path(s)
        trial = arm.with_muscles(arm.params.with_group(group, alpha_n=a, beta=b))
        best = 0.0
        for rp, hold in zip(ref_profs, holds, strict=True):
            v = stretch_profile(trial, joint, direction,
                                hold_rad=hold).velocity_dependent_n_m[:, i]
            best = max(best, dynamic_ratio(v, rp.passive_n_m[:, i],
                                           rp.velocity_dependent_n_m[:, i],
                                           rp.angles_rad)[0])
        return best

    if target <= ratio(0.0) * (1 + 1e-12):
        return 0.0
    if ratio(_S_MAX) < target:
        raise ParameterError(
            f"{MUSCLE_GROUP_NAMES[group]}: no reflex on the synthesis path reaches a dynamic "
            f"ratio of {target:g} (largest {ratio(_S_MAX):.3g}).")
    from scipy.optimize import brentq  # heavy: loaded where a level is synthesised

    return float(brentq(lambda s: math.log(ratio(s) / target), 0.0, _S_MAX, xtol=1e-10))


def synthesize(severities: Mapping[str, str], base: ArmParams | None = None,
               scale: SeverityScale = SCALE) -> ArmParams:
    """An arm with the named targets at the named levels.

    ``severities`` maps a target (``'elbow'``, ``'ef'``, ``'elbow-flexors:dynamic'``; see
    :func:`target_name`) to a level; ``{'elbow': 'severe'}`` makes both elbow groups severe in
    both components. Targets apply in order, a later one overriding an earlier one for the
    same group and component. Groups and components not named keep the base values (default:
    unimpaired, 75 kg, 1.75 m).
    """
    wanted: dict[tuple[str, str], float] = {}
    for target, lvl in severities.items():
        level = level_name(lvl)
        for g, comp in expand_target(target):
            wanted[(g, comp)] = scale.level_ratio(level, comp)
    return _synthesize(wanted, base, scale)


def synthesize_ratios(ratios: Mapping[str, float], base: ArmParams | None = None,
                      scale: SeverityScale = SCALE) -> ArmParams:
    """An arm with the named targets at a ratio to unimpaired (≥ 1; any value, between the
    levels too: a patient need not sit on the scale's steps), as :func:`synthesize`."""
    wanted: dict[tuple[str, str], float] = {}
    for target, ratio in ratios.items():
        if not (isinstance(ratio, (int, float)) and math.isfinite(ratio) and ratio >= 1.0):
            raise ParameterError(f"severity ratio of {target!r} must be a number >= 1; got "
                                 f"{ratio!r}.")
        for pair in expand_target(target):
            wanted[pair] = float(ratio)
    return _synthesize(wanted, base, scale)


def _synthesize(wanted: Mapping[tuple[str, str], float], base: ArmParams | None,
                scale: SeverityScale) -> ArmParams:
    p = base if base is not None else ArmParams.from_anthropometry()
    if not wanted:
        return p
    km = np.array(p.km_n_per_m)
    alpha = np.array(p.alpha_n)
    beta = np.array(p.beta)
    base_arm = Arm.from_params(p)  # the one compilation: the variants share its geometry
    ref_arm = unimpaired_reference(base_arm)
    ref_prof = stretch_profiles(ref_arm)
    ref_own = positioned_profiles(ref_arm)
    if any(c == "passive" for _, c in wanted):
        unit = stretch_profiles(base_arm.with_muscles(p.replace(km_n_per_m=(1.0,) * 6)))
    for (g, comp), ratio in wanted.items():
        i = GROUP_INDEX[g]
        rp = ref_prof[GRADED_STRETCH[g]]
        if comp == "passive":
            per_newton_per_m = float(unit[GRADED_STRETCH[g]].passive_n_m[:, i].max())
            km[i] = ratio * float(rp.passive_n_m[:, i].max()) / per_newton_per_m
        else:
            own = [ref_own[g]] if g in ref_own else []
            alpha[i], beta[i] = _reflex_path(_solve_dynamic(base_arm, [rp, *own], g, ratio))
    return p.replace(km_n_per_m=tuple(km.tolist()), alpha_n=tuple(alpha.tolist()),
                     beta=tuple(beta.tolist()))


__all__ = [
    "COMPONENTS",
    "LEVELS",
    "LEVEL_RATIO",
    "MUSCLE_GROUP_NAMES",
    "REFLEX_PATH_MAX",
    "SCALE",
    "ComponentGrade",
    "GroupSeverity",
    "SeverityScale",
    "classify",
    "expand_target",
    "level_name",
    "parse_severity_options",
    "ratio_of_score",
    "reflex_path",
    "severity_dict",
    "summary",
    "synthesize",
    "synthesize_ratios",
    "target_name",
]
