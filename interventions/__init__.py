"""Intervention what-if: clinical acts as model changes, and the field changes they predict.

Above the core, beside ``fieldbank.haptic`` (neither imports the other): the algorithms take
the compiled arm (:mod:`fieldbank.evaluate`: probing motions, standard conditions, before/after
comparison) and each use case compiles every model once.

Modules
-------
errors        InterventionError and SelectionError, the package's exception subtree
defaults      every default number with its unit and source (one table)
timecourse    botulinum dose → peak effect (Emax) and effect over the weeks (gamma variate)
catalogue     the interventions: Botulinum, Lengthening, Tenotomy, Rhizotomy, Baclofen,
              SerialCasting (frozen, validated against one bounds table each,
              ``apply(params) -> ArmParams``)
plan          Plan (ordered steps, JSON with located errors) and Derivation (lineage)
spec          plans from the command line's short texts (``--botox ef=200U``, ``bf=1cm``)
course        metrics week by week after an injection, on a compiled arm
inverse       botulinum dose split closest to the unimpaired reference (nlopt), on a compiled arm
plot          ``whatif --plot``: the report's figures of one what-if on one page
whatif        the what-if use case: search, compare, time course, figure, files, stored result
guesses       what a what-if rests on: poor fits refused, guessed parameters, warnings, intervals
validate      stored plans that were given, checked against the maps measured after them
samples       the shipped sample set, with the catalogue's botulinum between the sessions
report        reports over stored plans: select, compute (worker processes), HTML, CSV, JSON

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
