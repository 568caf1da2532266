"""Goodness of fit: does a model describe each measured map within the map's noise?

Figures per map (n measured values; sd the map's own measurement sd, else the fitter's
documented default, :func:`fieldbank.fitting.problem.map_sd`):

* χ²/n - the mean squared whitened residual Σ((y - ŷ)/sd)²/n: 1 when the model is off by
  exactly the measurement noise;
* R² - 1 - SS_res/SS_tot, each component about its own mean over the map;
* RMS residual in the map's unit (N for postural maps, N/m for stiffness maps).

Verdict per map (thresholds are documented defaults, :class:`Thresholds`):

* **poor** when χ²/n exceeds max(:data:`MIN_CHI2_LIMIT`, χ²ₙ quantile at :data:`CHI2_LEVEL` / n):
  the residuals are larger than the noise explains (p < 0.001) and at least √2 × sd in RMS, so a
  slightly optimistic sd does not condemn a fit;
* **poor** when R² < :data:`MIN_R2` (the model explains the map worse than its mean) - unless
  the map barely varies beyond its noise (its whitened spread SS_tot/sd²/n below
  :data:`NOISE_DOMINATED`), where R² says nothing and only χ²/n counts;
* **good** otherwise.

Overall: χ² of all values per degree of freedom (n - p_eff, the fit's effective number of
parameters), the whitened R² pooled over maps (residuals and spreads in units of sd, so
postural and stiffness maps add up), and the verdict 'poor' when any map is poor or the overall
χ²/dof exceeds its limit. The fit's status (:func:`status`) puts 'poor' before
'under-determined' (a parameter the maps do not identify) before 'good'.

The same figures judge a prediction against maps measured later
(:mod:`fieldbank.interventions.validate`) and a map left out of a fit.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fieldbank.fitting.problem import map_sd
from fieldbank.maps import FieldMap
from fieldbank.model import FloatArray

#: p-value below which the χ² of a map rejects the model (χ² test at level 0.999).
CHI2_LEVEL = 0.999
#: χ²/n at or below this is never poor (residual RMS within √2 × the stated sd).
MIN_CHI2_LIMIT = 2.0
#: R² below this is poor (worse than the map's mean), unless the map is noise-dominated.
MIN_R2 = 0.0
#: A map whose whitened spread SS_tot/sd²/n is below this varies too little for R² to count.
NOISE_DOMINATED = 2.0

STATUSES: tuple[str, ...] = ("good", "under-determined", "poor")
VALUE_UNIT = {"postural": "N", "stiffness": "N/m"}



def chi2_quantile(level: float, dof: float) -> float:
    """The χ² distribution's ``level`` quantile with ``dof`` degrees of freedom: 2·P⁻¹(dof/2,
    level), P⁻¹ the inverse of the regularized lower incomplete gamma function - what
    ``scipy.stats.chi2.ppf`` computes, to the last bit, without loading ``scipy.stats``
    (a second of a worker's first report task under load; ``scipy.special`` a third of it)."""
    from scipy.special import gammaincinv  # loaded where a map is judged

    return float(2.0 * gammaincinv(dof / 2.0, level))

@dataclass(frozen=True)
class Thresholds:
    """The verdict's thresholds (defaults: the module constants)."""

    chi2_level: float = CHI2_LEVEL
    min_chi2_limit: float = MIN_CHI2_LIMIT
    min_r2: float = MIN_R2
    noise_dominated: float = NOISE_DOMINATED

    def chi2_limit(self, n: int) -> float:
        """Largest χ²/n a map of n values may show and still be 'good'."""
        return max(self.min_chi2_limit, chi2_quantile(self.chi2_level, max(n, 1)) / n)

    def to_dict(self) -> dict[str, float]:
        return {"chi2_level": self.chi2_level, "min_chi2_limit": self.min_chi2_limit,
                "min_r2": self.min_r2, "noise_dominated": self.noise_dominated}


DEFAULT_THRESHOLDS = Thresholds()


@dataclass(frozen=True)
class MapFit:
    """How well predicted values match one measured map."""

    index: int
    kind: str
    n_values: int
    chi2: float
    chi2_per_value: float
    chi2_limit: float
    r2: float
    rms_residual: float
    unit: str
    spread_per_value: float
    verdict: str
    reasons: tuple[str, ...] = field(default_factory=tuple)

    def to_dict(self) -> dict[str, Any]:
        return {"index": self.index, "kind": self.kind, "n_values": self.n_values,
                "chi2": self.chi2, "chi2_per_value": self.chi2_per_value,
                "chi2_limit": self.chi2_limit, "r2": self.r2,
                "rms_residual": self.rms_residual, "unit": self.unit,
                "spread_per_value": self.spread_per_value, "verdict": self.verdict,
                "reasons": list(self.reasons)}


@dataclass(frozen=True)
class GoodnessOfFit:
    """Per-map figures and the overall verdict."""

    maps: tuple[MapFit, ...]
    chi2: float
    n_values: int
    dof: float
    chi2_per_dof: float
    chi2_limit: float
    r2: float
    verdict: str
    reasons: tuple[str, ...]
    thresholds: Thresholds = DEFAULT_THRESHOLDS

    def to_dict(self) -> dict[str, Any]:
        return {"verdict": self.verdict, "reasons": list(self.reasons), "chi2": self.chi2,
                "n_values": self.n_values, "dof": self.dof, "chi2_per_dof": self.chi2_per_dof,
                "chi2_limit": self.chi2_limit, "r2": self.r2,
                "maps": [m.to_dict() for m in self.maps],
                "thresholds": self.thresholds.to_dict()}

    def describe(self) -> str:
        """One line: the verdict, the overall figures and why."""
        head = (f"{self.verdict}: χ²/dof {self.chi2_per_dof:.2f} (limit {self.chi2_limit:.2f}), "
                f"pooled R² {self.r2:.3f} over {len(self.maps)} map(s)")
        return head + ("; " + "; ".join(self.reasons) if self.reasons else "")


def r2_score(y: FloatArray, yhat: FloatArray) -> float:
    """Coefficient of determination over all entries, each component about its own mean."""
    n = y.shape[0]
    y2 = y.reshape(n, -1)
    yh = yhat.reshape(n, -1)
    ss_res = float(((y2 - yh) ** 2).sum())
    ss_tot = float(((y2 - y2.mean(axis=0)) ** 2).sum())
    return 1.0 - ss_res / ss_tot if ss_tot > 0 else (1.0 if ss_res == 0 else -np.inf)


def map_fit(index: int, m: FieldMap, predicted: FloatArray, sd: FloatArray | None = None,
            thresholds: Thresholds = DEFAULT_THRESHOLDS, label: str | None = None) -> MapFit:
    """The figures and verdict of ``predicted`` (shaped like ``m.values``) against map ``m``.

    ``sd`` defaults to :func:`~fieldbank.fitting.problem.map_sd`; ``label`` names the map in
    the reasons (default "map <index>").
    """
    n = m.n
    y = m.values.reshape(n, -1)
    yh = np.asarray(predicted, dtype=float).reshape(n, -1)
    s = (map_sd(m) if sd is None else np.asarray(sd, dtype=float)).reshape(n, -1)
    r = (y - yh) / s
    k = y.size
    chi2 = float(np.sum(r * r))
    spread = float(np.sum(((y - y.mean(axis=0)) / s) ** 2)) / k
    r2 = r2_score(y, yh)
    limit = thresholds.chi2_limit(k)
    reasons = []
    name = label or f"map {index}"
    unit = VALUE_UNIT.get(m.kind, "")
    rms = float(np.sqrt(np.mean((y - yh) ** 2)))
    if chi2 / k > limit:
        reasons.append(f"{name} ({m.kind}): residuals {np.sqrt(chi2 / k):.2g} × the measurement "
                       f"sd in RMS (χ²/n {chi2 / k:.2f} > {limit:.2f}; RMS {rms:.3g} {unit})")
    if r2 < thresholds.min_r2 and spread >= thresholds.noise_dominated:
        reasons.append(f"{name} ({m.kind}): R² {r2:.2f} < {thresholds.min_r2:g}: the model "
                       "explains the map worse than the map's mean")
    return MapFit(index, m.kind, k, chi2, chi2 / k, limit, float(r2), rms, unit, spread,
                  "poor" if reasons else "good", tuple(reasons))


def assess(maps: Sequence[FieldMap], predicted: Sequence[FloatArray], p_eff: float = 0.0,
           thresholds: Thresholds = DEFAULT_THRESHOLDS,
           sds: Sequence[FloatArray] | None = None) -> GoodnessOfFit:
    """Goodness of fit of ``predicted`` values (one array per map) against ``maps``.

    ``p_eff``: the effective number of fitted parameters (0 for a prediction not fitted to
    these maps).
    """
    fits = []
    ss_res = ss_tot = 0.0
    for k, (m, yh) in enumerate(zip(maps, predicted, strict=True)):
        sd = None if sds is None else sds[k]
        mf = map_fit(k, m, yh, sd, thresholds)
        fits.append(mf)
        s = map_sd(m) if sd is None else np.asarray(sd, dtype=float).reshape(m.n, -1)
        y = m.values.reshape(m.n, -1)
        ss_res += float(np.sum(((y - np.asarray(yh).reshape(m.n, -1)) / s) ** 2))
        ss_tot += float(np.sum(((y - y.mean(axis=0)) / s) ** 2))
    n_values = sum(f.n_values for f in fits)
    chi2 = sum(f.chi2 for f in fits)
    dof = max(1.0, n_values - p_eff)
    limit = max(thresholds.min_chi2_limit,
                chi2_quantile(thresholds.chi2_level, dof) / dof)
    reasons = [r for f in fits for r in f.reasons]
    if chi2 / dof > limit and not reasons:
        reasons.append(f"all maps together: χ²/dof {chi2 / dof:.2f} > {limit:.2f}")
    r2 = 1.0 - ss_res / ss_tot if ss_tot > 0 else 1.0
    return GoodnessOfFit(tuple(fits), chi2, n_values, dof, chi2 / dof, limit, r2,
                         "poor" if reasons else "good", tuple(reasons), thresholds)


def status(gof: GoodnessOfFit, n_unidentified: int) -> str:
    """'poor' (goodness of fit fails), else 'under-determined' (some parameter the maps do not
    identify), else 'good'."""
    if gof.verdict == "poor":
        return "poor"
    return "under-determined" if n_unidentified else "good"
