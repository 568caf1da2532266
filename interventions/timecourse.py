"""Botulinum toxin A: dose → peak effect, and effect over the weeks after an injection.

Effect e ∈ [0, 1) is the fractional drop of the injected group's reflex force capacity
(α × (1 - e); β, the spinal reflex gain, stays: BRIEF §7). Doses are onabotulinumtoxinA
(Botox®) units. It is the product of two documented curves:

* dose → peak effect, an Emax curve (assumption, BRIEF §7)::

      E_peak(D) = E_max · D^h / (D^h + ED50^h)

* the time course, a gamma-variate shape normalised to 1 at the peak week t_p::

      s(t) = (t / t_p)^k · exp(k · (1 - t / t_p)),   t ≥ 0 weeks

  It starts at 0 on the day of injection, rises over the first days and weeks, peaks at
  t_p (default 5 weeks; ≈ 3-6 weeks: Eek & Himmelmann 2016, Gäverth et al. 2014, Chen et al.
  2022) and decays smoothly. The shape k is not a free number: it follows from where the
  effect has worn off, s(t_off) = f_off (default 10% at 14 weeks: back near baseline by
  ≈ 12-16 weeks):
  k = ln f_off / (ln(t_off / t_p) + 1 - t_off / t_p).

Repeated injections compound through the plan: each botulinum step multiplies α by its own
(1 - e), so three injections of 50% leave 12.5% (Fortuna et al. 2011, 2015: > 80-95% drop
after repeated injections).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from fieldbank.interventions.errors import InterventionError

if TYPE_CHECKING:  # numpy is imported where a curve is computed: a plan is read without it
    import numpy as np
    from numpy.typing import ArrayLike, NDArray


def shape_exponent(peak_week: float, wearoff_week: float, wearoff_fraction: float) -> float:
    """Gamma-variate exponent k with s(peak) = 1 and s(wearoff_week) = wearoff_fraction."""
    if not 0.0 < peak_week < wearoff_week:
        raise InterventionError(
            f"botulinum time course: need 0 < peak_week < wearoff_week; got peak_week="
            f"{peak_week:g}, wearoff_week={wearoff_week:g}."
        )
    if not 0.0 < wearoff_fraction < 1.0:
        raise InterventionError(
            f"botulinum time course: wearoff_fraction must lie in (0, 1); got {wearoff_fraction:g}."
        )
    r = wearoff_week / peak_week
    return math.log(wearoff_fraction) / (math.log(r) + 1.0 - r)


def time_shape(
    weeks: ArrayLike, peak_week: float, wearoff_week: float, wearoff_fraction: float
) -> NDArray[np.float64]:
    """s(t) ∈ [0, 1], 1 at the peak week; ``weeks`` any shape, ≥ 0."""
    import numpy as np

    t = np.asarray(weeks, dtype=float)
    k = shape_exponent(peak_week, wearoff_week, wearoff_fraction)
    r = np.maximum(t, 0.0) / peak_week
    with np.errstate(divide="ignore"):
        out = np.where(r > 0, np.exp(k * (np.log(np.where(r > 0, r, 1.0)) + 1.0 - r)), 0.0)
    return np.asarray(out, dtype=float)


def dose_effect(
    units: ArrayLike, emax: float, ed50_units: float, hill: float
) -> NDArray[np.float64]:
    """Peak effect of a dose (Emax curve), same shape as ``units``, in [0, emax)."""
    import numpy as np

    d = np.maximum(np.asarray(units, dtype=float), 0.0)
    dh = d**hill
    return np.asarray(emax * dh / (dh + ed50_units**hill), dtype=float)
