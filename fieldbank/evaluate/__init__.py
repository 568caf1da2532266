"""Algorithms on a compiled arm: every function takes :class:`fieldbank.model.Arm`, never
:class:`fieldbank.params.ArmParams`.

As pinocchio's algorithms take ``model, data``, these take the arm compiled once by
``Arm.from_params`` (``arm.params`` gives the parameters back), so a use case that compares,
follows weeks or searches compiles each model once (:class:`ArmCache`). They live in the core
so that fitting, interventions and haptics can all use them.

Modules
-------
probing   the seed's probing motions, the force felt along them, fast single-joint stretches;
          a probe as plain data (ProbePath)
design    probing motions that tell candidate arms apart: what a hand feels, information,
          the seed's min-max and orientation paradigms, the search
classify  a recorded probe scored against candidate arms; the next probe
plot      figures of probes and classifications (matplotlib loads with the first figure)
compare   standard conditions, one arm's evaluation on them, before/after comparison
arms      ArmCache: each distinct parameter set compiled once per use case
"""

from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.compare import (
    Comparison,
    Conditions,
    Evaluation,
    FieldChange,
    PotentialChange,
    compare,
    compare_evaluations,
    evaluate_arm,
    fields_per_velocity,
)
from fieldbank.evaluate.probing import (
    JointStretch,
    ProbeMotion,
    ProbeProfile,
    joint_stretch,
    profile,
    standard_probes,
    standard_stretches,
)

__all__ = [
    "ArmCache",
    "Comparison",
    "Conditions",
    "Evaluation",
    "FieldChange",
    "JointStretch",
    "PotentialChange",
    "ProbeMotion",
    "ProbeProfile",
    "compare",
    "compare_evaluations",
    "evaluate_arm",
    "fields_per_velocity",
    "joint_stretch",
    "profile",
    "standard_probes",
    "standard_stretches",
]
