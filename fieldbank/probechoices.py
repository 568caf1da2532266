"""Probe design's and classification's choices and sourced defaults: the criteria, families
and targets of a design, the predictors of a classification, what a hand tells apart, the noise
of a recording and of the operator, and how fast and hard a probe may push.

A leaf: it imports nothing, so that :mod:`fieldbank.evaluate.design`'s configurations
(:class:`~fieldbank.evaluate.design.Perception`, :class:`~fieldbank.evaluate.design.NoiseModel`,
:class:`~fieldbank.evaluate.design.ProbeLimits`), :mod:`fieldbank.evaluate.classify` and the
command line's options (``fieldbank probe ... --help``) read these values from one place
without loading the numerics that use them.
"""

from __future__ import annotations

#: What a design maximises: what a hand feels apart, the information of a recording, or the
#: seed's orientation and min-max paradigms.
CRITERIA: tuple[str, ...] = ("feel", "information", "orientation", "minmax")
DEFAULT_CRITERION = "feel"
#: Tell the candidates apart one by one, or only which muscle group is impaired.
TARGETS: tuple[str, ...] = ("candidate", "group")
DEFAULT_TARGET = "candidate"
#: The path families a design searches (:data:`fieldbank.evaluate.design.paths.FAMILIES`).
PATH_FAMILIES: tuple[str, ...] = ("stroke", "circle")
#: How a recorded probe's forces are predicted for each candidate.
PREDICTORS: tuple[str, ...] = ("replay", "rigid", "static")
DEFAULT_PREDICTOR = "replay"

#: Weber fraction of force magnitude: 7 % for matched forces (Jones 1989), 5-15 % for actively
#: felt forces (Pang, Tan & Durlach 1991); the upper end of 7-10 %.
FORCE_JND = 0.10
#: Force-direction discrimination threshold with haptics alone, degrees (Barbagli et al. 2006;
#: 18.4° with congruent vision, 31.9° with incongruent vision).
DIRECTION_JND_DEG = 25.6

#: Force noise per axis, N: force sensing plus what the model leaves out (assumption).
FORCE_SD_N = 2.0
#: Time over which the force noise decorrelates, s: one independent sample per τ (assumption).
CORRELATION_S = 0.05
#: Scatter of the executed direction (deg), relative length and relative speed of a probe the
#: operator performs (assumptions).
DIRECTION_SD_DEG = 10.0
LENGTH_SD = 0.15
SPEED_SD = 0.20

#: Peak hand speed of a probe, m/s: a fast clinical stretch (the seed's pull peaks at 0.94 m/s),
#: well below the renderer's 2.5 m/s speed limit.
MAX_SPEED_M_PER_S = 1.2
#: The renderer's default force saturation, N (haptic safety).
FORCE_LIMIT_N = 40.0
