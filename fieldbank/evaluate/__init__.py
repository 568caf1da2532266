"""Algorithms on a compiled arm: every function takes :class:`fieldbank.model.Arm`, never
:class:`fieldbank.params.ArmParams`.

As pinocchio's algorithms take ``model, data``, these take the arm compiled once by
``Arm.from_params`` (``arm.params`` gives the parameters back), so a use case that compares,
follows weeks or searches compiles each model once (:class:`ArmCache`). They live in the core
so that fitting, interventions and haptics can all use them.

Modules
-------
probing   the seed's probing motions, the force felt along them, the clinic's slow and fast
          single-joint stretches (resisting torque, its velocity-dependent part, Tardieu catch);
          a probe as plain data (ProbePath)
design    probing motions that tell candidate arms apart: what a hand feels, information,
          the seed's min-max and orientation paradigms, the search
classify  a recorded probe scored against candidate arms; the next probe
plot      figures of probes and classifications (matplotlib loads with the first figure)
compare   standard conditions, one arm's evaluation on them, before/after comparison
arms      ArmCache: each distinct parameter set compiled once per use case

``compare`` grades severity (:mod:`fieldbank.severity`, which itself builds on ``probing``), so
it is imported as ``fieldbank.evaluate.compare``, not re-exported here.
"""

from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.probing import (
    JointStretch,
    ProbeMotion,
    ProbeProfile,
    StretchProfile,
    joint_stretch,
    profile,
    standard_probes,
    standard_stretches,
    stretch_profile,
    unimpaired_reference,
)

__all__ = [
    "ArmCache",
    "JointStretch",
    "ProbeMotion",
    "ProbeProfile",
    "StretchProfile",
    "joint_stretch",
    "profile",
    "standard_probes",
    "standard_stretches",
    "stretch_profile",
    "unimpaired_reference",
]
