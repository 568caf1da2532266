"""Intervention what-if: clinical acts as model changes, and the field changes they predict.

Modules
-------
defaults      every default number with its unit and source (one table)
timecourse    botulinum dose → peak effect (Emax) and effect over the weeks (gamma variate)
catalogue     the interventions: Botulinum, Lengthening, Tenotomy, Rhizotomy, Baclofen,
              SerialCasting (frozen, validated, ``apply(params) -> ArmParams``)
plan          Plan (ordered steps, JSON with located errors) and Derivation (lineage)
probing       the seed's probing motions and fast single-joint stretches
metrics       before/after comparison on standard conditions
course        metrics week by week after an injection
inverse       botulinum dose split closest to the unimpaired reference (nlopt)
plot          before / after / difference figures

Everything here is a model prediction, not treatment advice.
"""

from fieldbank.interventions.catalogue import (
    KINDS,
    Baclofen,
    Botulinum,
    Intervention,
    Lengthening,
    Rhizotomy,
    SerialCasting,
    Tenotomy,
)
from fieldbank.interventions.plan import Derivation, Plan, params_sha256

__all__ = [
    "KINDS",
    "Baclofen",
    "Botulinum",
    "Derivation",
    "Intervention",
    "Lengthening",
    "Plan",
    "Rhizotomy",
    "SerialCasting",
    "Tenotomy",
    "params_sha256",
]
