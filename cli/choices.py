"""The library's choices and defaults that the commands' option declarations show.

They are repeated here, in a module that imports nothing, so that a subcommand's ``--help``
builds its options without loading the numerics that define them (numpy, scipy, nlopt: seconds
on a busy workstation). ``tests/test_cli_startup.py`` checks every value against the library's
own, so a change there that is not made here fails the tests.
"""

from __future__ import annotations

# fieldbank.fitting (ALGORITHMS, DEFAULT_ALGORITHM), .space, .uncertainty
FIT_ALGORITHMS: tuple[str, ...] = ("mlsl+lbfgs", "crs2+bobyqa", "direct+lbfgs", "dual_annealing")
FIT_DEFAULT_ALGORITHM = "mlsl+lbfgs"
FIT_KINDS: tuple[str, ...] = ("km", "alpha", "beta", "q_rest", "slack")
# fieldbank.model.MODEL_VERSION: the model version fits are made under (fit --older-than)
MODEL_VERSION = 1
FIT_DEFAULT_PRIOR_WEIGHT = 1.0
UNCERTAINTY_METHODS: tuple[str, ...] = ("auto", "gauss-newton", "bootstrap")
UNCERTAINTY_DEFAULT_METHOD = "auto"
UNCERTAINTY_DEFAULT_REPLICATES = 40

# fieldbank.storage.orm: the kinds of batch run (fieldbank jobs --kind)
JOB_KINDS: tuple[str, ...] = ("fit", "report", "validate")

# fieldbank.evaluate.design and .classify
PROBE_CRITERIA: tuple[str, ...] = ("feel", "information", "orientation", "minmax")
PROBE_FAMILIES: tuple[str, ...] = ("stroke", "circle")
PROBE_TARGETS: tuple[str, ...] = ("candidate", "group")
CLASSIFY_PREDICTORS: tuple[str, ...] = ("replay", "rigid", "static")

# fieldbank.interventions.defaults and .guesses
DOSE_UNIT = "onabotulinumtoxinA (Botox®) units"
BOTULINUM_SESSION_WARNING_UNITS = 400.0
BOTULINUM_WEEKS_SINCE = 5.0
CASTING_DELTA_M = 0.005
WHATIF_INTERVAL_SAMPLES = 40

# fieldbank.evaluate.design: NoiseModel(), Perception() and ProbeLimits() defaults
NOISE_FORCE_SD_N = 2.0
NOISE_CORRELATION_S = 0.05
NOISE_DIRECTION_SD_DEG = 10.0
NOISE_LENGTH_SD = 0.15
NOISE_SPEED_SD = 0.2
PERCEPTION_FORCE_JND = 0.1
PERCEPTION_DIRECTION_JND_DEG = 25.6
PROBE_MAX_SPEED_M_PER_S = 1.2
PROBE_FORCE_LIMIT_N = 40.0

# fieldbank.measure.protocol: ProtocolConfig() defaults, in the units the options show
MEASURE_PARTS: tuple[str, ...] = ("postural", "stiffness", "stretch")
MEASURE_DIRECTIONS = 8
MEASURE_DISPLACEMENT_MM = 6.0
MEASURE_HOLD_S = 0.6
MEASURE_STRETCH_SPEED_M_PER_S = 1.2
# the robot's force limit while measuring (SafetyConfig's default)
MEASURE_FORCE_LIMIT_N = 40.0

# fieldbank.haptic.remote.config: the passivity controller of a remote link, the sites' rates
PASSIVITY_MODES: tuple[str, ...] = ("tdpa", "off")
REMOTE_RATE_HZ: tuple[int, int] = (500, 4000)

# fieldbank.interventions.realised: the verdict's numbers (validate's options)
VALIDATE_CHANGE_TOLERANCE = 0.2
VALIDATE_MAX_CHANGE_SE = 0.25
