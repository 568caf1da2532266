"""What each muscle group adds to the joint torque along its graded stretch, against the
unimpaired arm: the measures the severity grades rest on (:mod:`fieldbank.evaluate.severity`'s
docstring defines them).

Per group, along the single-joint stretch that lengthens it (:data:`GRADED_STRETCH`): the
passive torque against the slow stretch (position-dependent: contracture) and the
velocity-dependent torque, fast minus slow (spasticity), each beside the unimpaired arm's, in
N·m, and the part of the stretch where the added torque is felt (:data:`FELT_FRACTION`).

**A group's own stretch.** A bi-articular group is long only when both joints lengthen it: at
the elbow stretch with the shoulder at rest the triceps long head (be) never reaches the part
of its range where the seed's reflex fires at an unimpaired gain (Γ > 0 needs the muscle in the
top fifth of its excursion at β = 0.1), so a tenfold α alone added 7 % at a fast stretch there
and read "unimpaired". The clinic tests a two-joint muscle on stretch over both joints (the long
head of triceps with the shoulder flexed, the biceps with the shoulder extended), and so do the
grades: each bi-articular group is also stretched at the elbow with the shoulder held
:data:`POSITION_MARGIN_DEG` inside the end of its range that lengthens the group
(:data:`POSITIONED_STRETCH`), and each component is graded on whichever of the two stretches
shows it more (the larger ratio; the read-out names the stretch). A tenfold α alone then adds
23 % at the fast stretch (be) and is felt. For a change of Km alone both stretches give the
Km ratio, so the passive scale is unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fieldbank.evaluate.probing import (
    Profiles,
    StretchProfile,
    stretch_profile,
    stretch_profiles,
    unimpaired_reference,
)
from fieldbank.model import Arm
from fieldbank.params import GROUP_INDEX, GROUPS

#: Force-magnitude JND of a force felt at one place (Jones 1989: 7 % matching forces; Pang, Tan &
#: Durlach 1991: 5-15 %; the upper end of 7-10 %): an added torque within this fraction of the
#: unimpaired peak is not felt (module docstring).
FELT_FRACTION = 0.10
#: The stretch each group is graded on: the single-joint stretch that lengthens it. The
#: bi-articular groups (biceps short, triceps long) are graded at the elbow, where the clinic
#: tests them and where their moment arm is the larger (BRIEF §3).
GRADED_STRETCH: dict[str, tuple[str, str]] = {
    "sf": ("shoulder", "extension"), "se": ("shoulder", "flexion"),
    "ef": ("elbow", "extension"), "ee": ("elbow", "flexion"),
    "bf": ("elbow", "extension"), "be": ("elbow", "flexion"),
}
#: The bi-articular groups' own stretch: the elbow stretch of :data:`GRADED_STRETCH` with the
#: shoulder held where the group is longest - extended for the biceps short head (bf), flexed
#: for the triceps long head (be) - as the clinic tests a two-joint muscle (module docstring).
POSITIONED_STRETCH: dict[str, str] = {"bf": "shoulder extended", "be": "shoulder flexed"}
#: How far inside the end of its range the shoulder is held for a positioned stretch, degrees
#: (the probe design's margin from the range of motion, ``fieldbank.evaluate.design``).
POSITION_MARGIN_DEG = 10.0


def stretch_name(group: str, positioned: bool = False) -> str:
    """The stretch a grade of ``group`` was measured on, in words ("elbow flexion" or
    "elbow flexion, shoulder flexed")."""
    joint, direction = GRADED_STRETCH[group]
    return f"{joint} {direction}" + (f", {POSITIONED_STRETCH[group]}" if positioned else "")


def positioned_hold_rad(arm: Arm, group: str) -> float:
    """The shoulder angle (rad) a bi-articular group's own stretch holds: the end of the
    shoulder's range that lengthens it, :data:`POSITION_MARGIN_DEG` inside."""
    lo, hi = arm.params.shoulder_range_rad
    margin = math.radians(POSITION_MARGIN_DEG)
    # the group lengthens with the shoulder angle when its shoulder moment arm is positive
    return hi - margin if arm.jl[GROUP_INDEX[group], 0] > 0 else lo + margin


def positioned_profiles(arm: Arm) -> dict[str, StretchProfile]:
    """The own stretch of each bi-articular group (:data:`POSITIONED_STRETCH`), by group."""
    return {g: stretch_profile(arm, *GRADED_STRETCH[g], hold_rad=positioned_hold_rad(arm, g))
            for g in POSITIONED_STRETCH}


# --- measures --------------------------------------------------------------------------------
@dataclass(frozen=True)
class GroupTone:
    """The torques one group's grades rest on, along its graded stretch (N·m).

    passive_n_m, passive_ref_n_m : largest passive torque against the slow stretch, this arm
        and the unimpaired one
    velocity_dependent_n_m, velocity_dependent_ref_n_m : largest velocity-dependent torque
        (fast minus slow)
    passive_ratio, dynamic_ratio : the grades' measures (module docstring)
    passive_added, dynamic_added : what the group adds along the stretch (:class:`Added`)
    passive_stretch, dynamic_stretch : the stretch each component was graded on, in words
        (:func:`stretch_name`)
    """

    group: str
    passive_n_m: float
    passive_ref_n_m: float
    velocity_dependent_n_m: float
    velocity_dependent_ref_n_m: float
    passive_ratio: float
    dynamic_ratio: float
    passive_added: Added
    dynamic_added: Added
    passive_stretch: str = ""
    dynamic_stretch: str = ""


@dataclass(frozen=True)
class Added:
    """The torque one component of a group adds to its graded stretch over the unimpaired
    group's, and where (joint angles of BRIEF §3, degrees).

    torque_n_m : largest added torque along the stretch (≤ 0: adds nothing anywhere)
    at_deg : the angle where it is largest
    felt_from_deg : the first angle along the travel where the added torque reaches the felt
        fraction of the unimpaired peak (the resistance's onset, or the catch); None: never
    reference_peak_n_m : the unimpaired peak the ratio is taken against
    """

    torque_n_m: float
    at_deg: float
    felt_from_deg: float | None
    reference_peak_n_m: float

    def to_dict(self) -> dict[str, object]:
        return {"added_torque_n_m": self.torque_n_m, "added_at_deg": self.at_deg,
                "felt_from_deg": self.felt_from_deg}


def _added(torque: np.ndarray, torque_ref: np.ndarray, reference_peak: float,
           angles_rad: np.ndarray, felt_fraction: float) -> tuple[float, Added]:
    """The ratio of one component (module docstring) and what it rests on."""
    extra = torque - torque_ref
    k = int(np.argmax(extra))
    peak = float(extra[k])
    felt = np.flatnonzero(extra >= felt_fraction * reference_peak)
    added = Added(peak, math.degrees(float(angles_rad[k])),
                  math.degrees(float(angles_rad[felt[0]])) if felt.size else None,
                  reference_peak)
    if peak > 0.0:
        return 1.0 + peak / reference_peak, added
    return float(np.max(torque_ref + extra) / reference_peak), added


def dynamic_ratio(v: np.ndarray, p_ref: np.ndarray, v_ref: np.ndarray,
                   angles_rad: np.ndarray, felt_fraction: float = FELT_FRACTION
                   ) -> tuple[float, Added]:
    """D of the module docstring: what the reflex adds to the fast stretch."""
    return _added(p_ref + v, p_ref + v_ref, float(np.max(p_ref + v_ref)), angles_rad,
                  felt_fraction)


def _passive_ratio(p: np.ndarray, p_ref: np.ndarray, angles_rad: np.ndarray,
                   felt_fraction: float = FELT_FRACTION) -> tuple[float, Added]:
    """P* of the module docstring: what the passive force adds to the slow stretch."""
    return _added(p, p_ref, float(np.max(p_ref)), angles_rad, felt_fraction)


#: (ratio, what is added, peak torque, unimpaired peak torque, stretch name) of one component.
_Pick = tuple[float, Added, float, float, str]


def group_tone(arm: Arm, reference: Arm | None = None, profiles: Profiles | None = None,
               reference_profiles: Profiles | None = None,
               felt_fraction: float = FELT_FRACTION,
               positioned: dict[str, StretchProfile] | None = None,
               reference_positioned: dict[str, StretchProfile] | None = None
               ) -> dict[str, GroupTone]:
    """Per muscle group, the measures of its passive and dynamic grade (module docstring).

    ``reference`` is the unimpaired arm (default: ``arm``'s,
    :func:`fieldbank.evaluate.probing.unimpaired_reference`); ``profiles`` and
    ``reference_profiles`` the stretch profiles of both, ``positioned`` and
    ``reference_positioned`` their bi-articular groups' own stretches
    (:func:`positioned_profiles`), when already computed.
    """
    prof = profiles if profiles is not None else stretch_profiles(arm)
    own = positioned if positioned is not None else positioned_profiles(arm)
    ref_prof = reference_profiles
    ref_own = reference_positioned
    if ref_prof is None or ref_own is None:
        ref = reference if reference is not None else unimpaired_reference(arm)
        if ref_prof is None:
            ref_prof = prof if ref is arm else stretch_profiles(ref)
        if ref_own is None:
            ref_own = own if ref is arm else positioned_profiles(ref)
    out: dict[str, GroupTone] = {}
    for g in GROUPS:
        i = GROUP_INDEX[g]
        stretches = [(stretch_name(g), prof[GRADED_STRETCH[g]], ref_prof[GRADED_STRETCH[g]])]
        if g in own:
            stretches.append((stretch_name(g, True), own[g], ref_own[g]))
        passive: _Pick | None = None
        dynamic: _Pick | None = None
        for name, a, r in stretches:
            p, p_ref = a.passive_n_m[:, i], r.passive_n_m[:, i]
            v, v_ref = a.velocity_dependent_n_m[:, i], r.velocity_dependent_n_m[:, i]
            pr, pa = _passive_ratio(p, p_ref, a.angles_rad, felt_fraction)
            dr, da = dynamic_ratio(v, p_ref, v_ref, a.angles_rad, felt_fraction)
            # each component on the stretch that shows it more (the first on a tie)
            if passive is None or pr > passive[0]:
                passive = (pr, pa, float(p.max()), float(p_ref.max()), name)
            if dynamic is None or dr > dynamic[0]:
                dynamic = (dr, da, float(v.max()), float(v_ref.max()), name)
        assert passive is not None and dynamic is not None
        out[g] = GroupTone(g, passive[2], passive[3], dynamic[2], dynamic[3], passive[0],
                           dynamic[0], passive[1], dynamic[1], passive[4], dynamic[4])
    return out
