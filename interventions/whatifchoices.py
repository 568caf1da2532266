"""The what-if's and its validation's defaults the command line shows: how many parameter
samples a what-if runs, and the numbers a validation's verdict reads.

A leaf: it imports nothing, so that :mod:`fieldbank.interventions.guesses`,
:mod:`fieldbank.interventions.realised` and the command line's options (``fieldbank whatif
--help``, ``fieldbank validate --help``) read these values from one place without loading the
numerics that use them. The intervention catalogue's own defaults, with their sources, are in
:mod:`fieldbank.interventions.defaults`.
"""

from __future__ import annotations

#: Parameter samples a what-if runs through its plan (at most; the fit keeps 40 by default).
DEFAULT_INTERVAL_SAMPLES = 40

#: The realised fraction decides a verdict only when its SE is at most this.
MAX_CHANGE_SE = 0.25
#: "As predicted" means within this fraction of the predicted change (80-120%).
CHANGE_TOLERANCE = 0.2
