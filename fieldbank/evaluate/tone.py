"""What each muscle group adds to the joint torque along its graded stretch, against the
unimpaired arm: the measures the severity grades rest on (:mod:`fieldbank.evaluate.severity`'s
docstring defines them).

Per group, along the single-joint stretch that lengthens it (:data:`GRADED_STRETCH`): the
passive torque against the slow stretch (position-dependent: contracture) and the
velocity-dependent torque, fast minus slow (spasticity), each beside the unimpaired arm's, in
N·m, and the part of the stretch where the added torque is felt (:data:`FELT_FRACTION`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fieldbank.evaluate.probing import Profiles, stretch_profiles, unimpaired_reference
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


def group_tone(arm: Arm, reference: Arm | None = None, profiles: Profiles | None = None,
               reference_profiles: Profiles | None = None,
               felt_fraction: float = FELT_FRACTION) -> dict[str, GroupTone]:
    """Per muscle group, the measures of its passive and dynamic grade (module docstring).

    ``reference`` is the unimpaired arm (default: ``arm``'s,
    :func:`fieldbank.evaluate.probing.unimpaired_reference`); ``profiles`` and
    ``reference_profiles`` the stretch profiles of both when already computed.
    """
    prof = profiles if profiles is not None else stretch_profiles(arm)
    ref_prof = reference_profiles
    if ref_prof is None:
        ref = reference if reference is not None else unimpaired_reference(arm)
        ref_prof = prof if ref is arm else stretch_profiles(ref)
    out: dict[str, GroupTone] = {}
    for g in GROUPS:
        i = GROUP_INDEX[g]
        a, r = prof[GRADED_STRETCH[g]], ref_prof[GRADED_STRETCH[g]]
        p, p_ref = a.passive_n_m[:, i], r.passive_n_m[:, i]
        v, v_ref = a.velocity_dependent_n_m[:, i], r.velocity_dependent_n_m[:, i]
        pr, pa = _passive_ratio(p, p_ref, a.angles_rad, felt_fraction)
        dr, da = dynamic_ratio(v, p_ref, v_ref, a.angles_rad, felt_fraction)
        out[g] = GroupTone(g, float(p.max()), float(p_ref.max()), float(v.max()),
                           float(v_ref.max()), pr, dr, pa, da)
    return out
