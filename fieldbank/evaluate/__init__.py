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
severity  the severity scale per muscle group and direction, passive and dynamic: levels,
          synthesis, classification (builds on probing's stretches)
design    probing motions that tell candidate arms apart (a package, one module per step):
          candidates, paths, what a hand feels, information, the seed's paradigms, the search
classify  a recorded probe scored against candidate arms; the next probe
compare   standard conditions, one arm's evaluation on them, before/after comparison
arms      ArmCache: each distinct parameter set compiled once per use case

Each module builds only on the ones above it in this list (``arms`` on none of them), so every
module here is imported by its full name the same way; this package re-exports the probing
names the rest of the product uses most.
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
