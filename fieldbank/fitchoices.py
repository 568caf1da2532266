"""The fit's choices and defaults: its search algorithms, the parameter kinds it can fit, the
prior's weight, how its uncertainty is estimated, and the model version fits are made under.

A leaf: it imports nothing, so that the fitter, its uncertainty and records, and the command
line's options (``fieldbank fit --help``) read these values from one place without loading the
numerics that use them.
"""

from __future__ import annotations

#: name -> (nlopt global algorithm, nlopt local algorithm), by their names in nlopt (looked up
#: when a search runs: nlopt and scipy.optimize load only when something is fitted); the local
#: one also polishes. ``dual_annealing`` is scipy's.
ALGORITHMS: dict[str, tuple[str, str]] = {
    "mlsl+lbfgs": ("G_MLSL_LDS", "LD_LBFGS"),
    "crs2+bobyqa": ("GN_CRS2_LM", "LN_BOBYQA"),
    "direct+lbfgs": ("GN_DIRECT_L", "LD_LBFGS"),
    "dual_annealing": ("", ""),
}
DEFAULT_ALGORITHM = "mlsl+lbfgs"

#: The parameter kinds a fit can estimate, per muscle group.
FIT_KINDS: tuple[str, ...] = ("km", "alpha", "beta", "q_rest", "slack")
#: Weight of the prior term of the cost.
DEFAULT_PRIOR_WEIGHT = 1.0

#: How the fit's uncertainty is estimated: ``auto`` takes Gauss-Newton where it is valid and
#: the parametric bootstrap where it is not (:mod:`fieldbank.fitting.uncertainty`).
UNCERTAINTY_METHODS: tuple[str, ...] = ("auto", "gauss-newton", "bootstrap")
DEFAULT_UNCERTAINTY = "auto"
#: Bootstrap replicates (and Gaussian draws): 40 put the 2.5/97.5 percentiles between the
#: first and second most extreme replicate; the SD is known to ≈ ±11%.
DEFAULT_REPLICATES = 40

#: Version of the arm model and of how a fit estimates it: raised with every change of the
#: equations, of the fitter or of its defaults that changes what a fit of the same maps gives.
#: Every fit records it; ``fieldbank fit --all --older-than N`` refits what older versions made.
MODEL_VERSION = 1
