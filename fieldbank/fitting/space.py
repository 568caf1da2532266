"""The parameter space of a fit: which parameters, their bounds and the prior, in one table.

Fitted parameters, in this order in every vector the fitter builds:

* ``km``     Km per muscle group (6), N/m - enters the forces linearly;
* ``alpha``  α per muscle group (6), N - enters the forces linearly;
* ``beta``   β per muscle group (6), dimensionless - nonlinear;
* ``q_rest`` rest posture (2), rad - nonlinear, optional;
* ``slack``  slack offset per muscle group (6), m - nonlinear, optional: the length the group
  takes up before its passive force starts, relative to its rest length (``slack_offset_m``
  of :class:`~fieldbank.params.ArmParams`). A contracture is negative: the passive force
  starts earlier in the range.

Bounds are physiological (:data:`FIT_BOUNDS`); q_rest is bounded by the arm's range of motion.
The slack offset is bounded by the brief's range (:data:`SLACK_RANGE_M`): a contracture
shortens the optimal fibre length to 0.80-0.95 of normal (PredSim's contracture scaling), 5-20
mm of the 10 cm fibre the lengthening default assumes, so no shorter than -20 mm; a tendon
lengthening adds 1-2 cm (Delp & Zajac 1992), so no longer than +20 mm.

Prior. The cost adds ``prior_weight · Σ ((θ - θ0)/σ)²`` to the data's χ². θ0 is the unimpaired
value for the patient (``ArmParams.from_anthropometry`` with the patient's mass, height and side:
Km 600 N/m, α 100 N, β 0.1) and the base's rest posture for q_rest. σ is wide
(:data:`PRIOR_SD`: 10× the unimpaired value for Km and α, 0.5 for β, 20° for q_rest, 10 mm - half
the contracture range - for the slack offset, whose unimpaired value is 0), so the prior decides
only what the maps leave open; ``prior_weight`` (default 1) scales it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from fieldbank.errors import FitError
from fieldbank.fitchoices import DEFAULT_PRIOR_WEIGHT, FIT_KINDS
from fieldbank.model import FloatArray
from fieldbank.params import GROUPS, ArmParams
from fieldbank.validation import Interval

#: ArmParams field behind each fitted kind.
PARAM_FIELD: dict[str, str] = {
    "km": "km_n_per_m",
    "alpha": "alpha_n",
    "beta": "beta",
    "q_rest": "q_rest_rad",
    "slack": "slack_offset_m",
}
#: The per-group kinds, in the order of the fitted vector.
GROUP_KINDS: tuple[str, ...] = ("km", "alpha", "beta", "slack")


def named_values(params: ArmParams) -> dict[str, float]:
    """Every muscle parameter a fit may fit, by its name in fit reports (``km_ef``,
    ``alpha_ef``, ``beta_ef``, ``slack_ef``, ...), SI units."""
    return {f"{kind}_{g}": float(v) for kind in GROUP_KINDS
            for g, v in zip(GROUPS, getattr(params, PARAM_FIELD[kind]), strict=True)}


#: The brief's range of the slack offset, m (module docstring): a contracture of at most 20 mm
#: (optimal fibre length 0.80 of a 10 cm fibre, PredSim), a lengthening of at most 2 cm (Delp
#: & Zajac 1992).
SLACK_RANGE_M = (-0.020, 0.020)


#: Physiological bounds of the fitted parameters (q_rest: the range of motion, see below).
FIT_BOUNDS: dict[str, Interval] = {
    "km": Interval(50.0, 50_000.0, "N/m"),
    "alpha": Interval(0.0, 50_000.0, "N"),
    "beta": Interval(0.0, 1.0, ""),
    "slack": Interval(SLACK_RANGE_M[0], SLACK_RANGE_M[1], "m"),
}
#: Prior standard deviations: a factor of the unimpaired value (km, alpha) or absolute.
PRIOR_SD_FACTOR: dict[str, float] = {"km": 10.0, "alpha": 10.0}
PRIOR_SD: dict[str, float] = {"beta": 0.5, "q_rest": math.radians(20.0), "slack": 0.010}


@dataclass(frozen=True)
class ParamSpace:
    """Names, bounds and prior of the fitted parameter vector.

    Attributes
    ----------
    names : tuple of str
        ``km_sf``, …, ``alpha_be``, ``beta_sf``, …, ``q_rest_shoulder``, ``q_rest_elbow``,
        ``slack_sf``, …, ``slack_be`` (q_rest and slack only when fitted).
    kinds : tuple of str
        The kind of each entry (``km``, ``alpha``, ``beta``, ``q_rest``, ``slack``).
    fitted : ndarray of bool, shape (P,)
        False for entries held at the base value (kinds not fitted).
    lower, upper : ndarray, shape (P,)
        Bounds (SI).
    prior_mean, prior_sd : ndarray, shape (P,)
    prior_weight : float
    base : ndarray, shape (P,)
        The base parameter values (used for entries not fitted, and as a start).
    """

    names: tuple[str, ...]
    kinds: tuple[str, ...]
    fitted: np.ndarray
    lower: FloatArray
    upper: FloatArray
    prior_mean: FloatArray
    prior_sd: FloatArray
    prior_weight: float
    base: FloatArray
    fit_q_rest: bool
    fit_slack: bool = False

    @classmethod
    def build(
        cls,
        base: ArmParams,
        fit: Sequence[str] = ("km", "alpha", "beta"),
        bounds: Mapping[str, tuple[float, float]] | None = None,
        prior_weight: float = DEFAULT_PRIOR_WEIGHT,
    ) -> ParamSpace:
        """The space for fitting ``fit`` kinds around ``base``, with optional bound overrides.

        ``bounds`` maps a kind (``km``, ``alpha``, ``beta``, ``q_rest``, ``slack``) or a single
        name (``km_ef``) to (low, high) in SI units.
        """
        unknown = sorted(set(fit) - set(FIT_KINDS))
        if unknown or not fit:
            raise FitError(
                f"parameters to fit must be a non-empty subset of {', '.join(FIT_KINDS)}; "
                f"got {list(fit)!r}."
            )
        if not (math.isfinite(prior_weight) and prior_weight >= 0):
            raise FitError(f"prior_weight must be a finite number >= 0; got {prior_weight!r}.")
        unimpaired = ArmParams.from_anthropometry(base.body_mass_kg, base.height_m, base.side)
        names: list[str] = []
        kinds: list[str] = []
        lo: list[float] = []
        hi: list[float] = []
        mean: list[float] = []
        sd: list[float] = []
        start: list[float] = []
        for kind in ("km", "alpha", "beta"):
            field = PARAM_FIELD[kind]
            for i, g in enumerate(GROUPS):
                names.append(f"{kind}_{g}")
                kinds.append(kind)
                iv = FIT_BOUNDS[kind]
                lo.append(float(iv.low if iv.low is not None else -np.inf))
                hi.append(float(iv.high if iv.high is not None else np.inf))
                m = float(getattr(unimpaired, field)[i])
                mean.append(m)
                sd.append(PRIOR_SD_FACTOR[kind] * m if kind in PRIOR_SD_FACTOR else PRIOR_SD[kind])
                start.append(float(getattr(base, field)[i]))
        if "q_rest" in fit:
            for j, joint in enumerate(("shoulder", "elbow")):
                rng = base.shoulder_range_rad if j == 0 else base.elbow_range_rad
                names.append(f"q_rest_{joint}")
                kinds.append("q_rest")
                lo.append(float(rng[0]))
                hi.append(float(rng[1]))
                mean.append(float(base.q_rest_rad[j]))
                sd.append(PRIOR_SD["q_rest"])
                start.append(float(base.q_rest_rad[j]))
        if "slack" in fit:
            iv = FIT_BOUNDS["slack"]
            for i, g in enumerate(GROUPS):
                names.append(f"slack_{g}")
                kinds.append("slack")
                lo.append(float(iv.low if iv.low is not None else -np.inf))
                hi.append(float(iv.high if iv.high is not None else np.inf))
                mean.append(float(unimpaired.slack_offset_m[i]))
                sd.append(PRIOR_SD["slack"])
                start.append(float(base.slack_offset_m[i]))
        lower = np.array(lo)
        upper = np.array(hi)
        for key, pair in (bounds or {}).items():
            sel = [k for k, (n, kd) in enumerate(zip(names, kinds, strict=True))
                   if key in (n, kd)]
            if not sel:
                raise FitError(
                    f"bounds override {key!r} names no fitted parameter; use a kind "
                    f"({', '.join(FIT_KINDS)}) or a name such as 'km_ef'."
                )
            a, b = (float(v) for v in pair)
            if not (math.isfinite(a) and math.isfinite(b) and a < b):
                raise FitError(f"bounds override {key!r} must be finite (low, high) with "
                               f"low < high; got {pair!r}.")
            lower[sel] = a
            upper[sel] = b
        start_a = np.clip(np.array(start), lower, upper)
        return cls(
            names=tuple(names),
            kinds=tuple(kinds),
            fitted=np.array([k in fit for k in kinds]),
            lower=lower,
            upper=upper,
            prior_mean=np.array(mean),
            prior_sd=np.array(sd),
            prior_weight=float(prior_weight),
            base=start_a,
            fit_q_rest="q_rest" in fit,
            fit_slack="slack" in fit,
        )

    @property
    def size(self) -> int:
        return len(self.names)

    def index(self, kind: str) -> np.ndarray:
        """Indices of the entries of one kind."""
        return np.array([i for i, k in enumerate(self.kinds) if k == kind], dtype=int)

    def to_params(self, theta: FloatArray, base: ArmParams) -> ArmParams:
        """An ArmParams with the fitted values of ``theta`` written into ``base``."""
        changes: dict[str, tuple[float, ...]] = {}
        for kind in ("km", "alpha", "beta", "q_rest", "slack"):
            idx = self.index(kind)
            if idx.size:
                changes[PARAM_FIELD[kind]] = tuple(float(v) for v in theta[idx])
        return base.replace(**changes)
