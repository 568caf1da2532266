"""Fitting a patient's arm model to measured postural and stiffness maps (BRIEF §6).

* :class:`ArmFitter` - the estimator: options in the constructor, ``fit(maps, base)``, results
  with a trailing underscore, ``report()``;
* :mod:`.space` - fitted parameters, bounds and prior in one table;
* :mod:`.problem` - the precomputed, variable-projected cost;
* :mod:`.search` - nlopt global + local, and scipy's dual annealing baseline;
* :mod:`.identify` - what the maps do not identify;
* :mod:`.uncertainty` - SDs, 95% intervals and parameter samples that cannot collapse;
* :mod:`.quality` - goodness of fit per map and overall, and the fit's status;
* :mod:`.crossval` - each map left out of a stored fit and predicted by the others;
* :mod:`.synthetic` - synthetic patients for tests and benchmarks;
* :mod:`.plot` - measured against fitted fields.
"""

from fieldbank.fitting.fitter import ArmFitter, validate_maps

__all__ = ["ArmFitter", "validate_maps"]
