"""The most informative probing motions for a set of candidate arms, and the seed's min-max and
orientation paradigms as computations (seed, "Selection of specific probing motions" and
"A guided approach to manipulation"; the search for the most informative motion is the seed's
stated next step).

Each module holds one step, and each builds only on the ones above it::

    config      sourced defaults and assumptions; Perception, NoiseModel, ProbeLimits with their
                bounds tables
    candidates  the arms a clinician hesitates between (Candidate, severity_candidates), their
                equilibrium, the prior
    paths       the stroke and circle families (Stroke, Circle, FAMILIES), the seed's circles
    predict     the force a hand moving a candidate along a path feels; executions within the
                motion noise; which paths every candidate can follow
    perception  what a hand feels apart (JNDs in magnitude, direction and place) and what a
                recording tells (D_KL, information, Bayes error)
    score       scores of given probes, per path and per set (ProbeScore, ProbeSetScore)
    search      the search for the most informative set (design, ProbeDesign)
    paradigms   the seed's min-max and orientation paradigms, the seed's probes, a design beside
                them (DesignReport)

The public names are gathered here; import them from ``fieldbank.evaluate.design``.
"""

from fieldbank.evaluate.design.candidates import (
    Candidate,
    check_candidates,
    check_prior,
    equilibrium,
    open_candidates,
    severity_candidates,
)
from fieldbank.evaluate.design.config import NoiseModel, Perception, ProbeLimits
from fieldbank.evaluate.design.paradigms import (
    DesignReport,
    Paradigms,
    design_report,
    paradigms,
    seed_probes,
)
from fieldbank.evaluate.design.paths import FAMILIES, Circle, Stroke, circles, direction_words
from fieldbank.evaluate.design.perception import (
    entropy_bits,
    felt_jnd,
    information_bits,
    pair_error,
)
from fieldbank.evaluate.design.predict import (
    draw_execution,
    executions,
    feasible,
    path_accelerations,
    predict,
    saturate,
)
from fieldbank.evaluate.design.score import (
    PathFeatures,
    ProbeScore,
    ProbeSetScore,
    path_features,
    score_probes,
    target_labels,
)
from fieldbank.evaluate.design.search import ProbeDesign, design

__all__ = [
    "FAMILIES",
    "Candidate",
    "Circle",
    "DesignReport",
    "NoiseModel",
    "Paradigms",
    "PathFeatures",
    "Perception",
    "ProbeDesign",
    "ProbeLimits",
    "ProbeScore",
    "ProbeSetScore",
    "Stroke",
    "check_candidates",
    "check_prior",
    "circles",
    "design",
    "design_report",
    "direction_words",
    "draw_execution",
    "entropy_bits",
    "equilibrium",
    "executions",
    "feasible",
    "felt_jnd",
    "information_bits",
    "open_candidates",
    "pair_error",
    "paradigms",
    "path_accelerations",
    "path_features",
    "predict",
    "saturate",
    "score_probes",
    "seed_probes",
    "severity_candidates",
    "target_labels",
]
