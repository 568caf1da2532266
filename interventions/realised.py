"""How much of a predicted change came: the realised fraction, how sure it is, and the verdict.

A plan predicts a change of a patient's maps: Δp = y(after) − y(before), the model after the
plan minus the model before it, at the positions and velocities of the maps measured later.
Those maps show Δm = y_measured − y(before). The **realised fraction** is the weighted
regression of the measured on the predicted change through the origin,

    f = Σ w·Δm·Δp / Σ w·Δp²,     w = 1/sd² (the maps' own sd),

1 when the change came as predicted, 0 when nothing changed, 0.5 for half of it. For botulinum
toxin the force change is proportional to the drop of α, so a toxin that did a fraction of
what was predicted gives exactly that f.

Whether the maps can see it
---------------------------
The predicted change moves the maps by S = √(Σ w·Δp²) standard deviations (its whitened
norm: the maps' sensitivity to the treated parameter times the predicted change of it). The
noise alone leaves f known to ±1/S, so a change is **observable** only when S ≥
:data:`MIN_SENSITIVITY` (4 sd: f known to ±0.25 from the noise). Static maps do not see a
change of the stretch reflex (it acts only while the arm moves), whatever their noise: for
them S = 0, and the check says which map or stretch would see it
(:func:`fieldbank.interventions.suggest.suggestion`) rather than print a number.

How sure: the maps' noise and the fit's uncertainty together
------------------------------------------------------------
Δm is measured against the *fitted* model before, whose error is not noise of the later maps:
it moves f as much as their noise does (the shipped cohort: about as much). The SE therefore
has two parts, added in quadrature:

* **noise**: 1/S, the regression's SE from the later maps' sd;
* **fit**: the spread of f over the fit's parameter samples (bootstrap replicates or Gaussian
  draws, :mod:`fieldbank.fitting.uncertainty`): for each sample θ_s the model before and the
  plan applied to it give their own Δm_s and Δp_s, hence f_s; the spread is the half-width of
  the 15.9-84.1 percentiles of f_s (one SD for a normal spread, robust to a few samples whose
  predicted change the maps barely see).

When the maps that see the change still differ from the model before + f × the change by more
than the noise and the fit's spread explain (χ²/dof > 1), the SE is multiplied by √(χ²/dof)
(:func:`misfit_scale`, a Birge ratio), as a fit's residual scale widens its intervals.

**Never below what the noise allows.** The model before was fitted to the first session's
maps: along the direction of the predicted change it cannot be known better than those maps'
noise allows, 1/S₀ with S₀ the predicted change's whitened size on them (the first session's
own sd). A fit's samples can claim less - parameters held at a guess or pinned by the prior do
not vary in them - so the fit part of the SE is at least 1/S₀
(:func:`fieldbank.interventions.spread.first_session_se`), and the SE is never below
√(1/S² + 1/S₀²), the two sessions' noise alone.

``tests/test_validate_calibration.py`` checks the result on a seeded cohort with realised
effects between 0 and 1.2 (the truth within 2 SE in ≥ 90% of decided cases);
``benchmarks/bench_validate.py`` measures the verdicts' false-alarm rate.

A realised fraction is only reported (a number) when the change is observable, the prediction
does not rest on a parameter the fit did not identify (a guess the samples do not vary), its SE
is at most :data:`MAX_REPORTED_SE` (0.5), and f lies in the physical range of the plan
(:func:`physical_range`: the parameters the plan changes stay within their bounds, and an
opposite change is at most as large as the predicted one).

The verdict (:class:`Rules`, every number a documented default)
---------------------------------------------------------------
With SE ≤ :data:`MAX_CHANGE_SE` and the interval f ± 2 SE = [lo, hi]:

* **prediction confirmed**: lo ≥ :data:`CONFIRM_FLOOR` (0.5), hi ≥ 1 − tolerance (0.8) and
  f ≤ 1 + tolerance (1.2): at least half the predicted change came, the maps are consistent
  with all of it, and the best estimate is not beyond the tolerance;
* **stronger than predicted** (an over-effect): f > 1 + tolerance and lo > 1: clearly more
  than predicted, best estimated beyond the tolerance (1.44 ± 0.15 was "confirmed" before: its
  interval reached the tolerance, its estimate was far past it);
* **partial effect**: 0 < lo and hi < 1 − tolerance: clearly some change, clearly less than
  predicted;
* **prediction failed**: hi < 1 − tolerance and lo ≤ 0 (no change distinguishable from none;
  an opposite change when hi < 0);
  also, whatever f, when a map differs from the model before plus f × the predicted change by
  more than its noise and the fit's uncertainty explain (its χ²/n above the limit of
  :mod:`fieldbank.fitting.quality`): the maps changed in a way the plan does not predict;
* **inconclusive** otherwise: the change is not observable (S < 4 sd), rests on a guess, its
  SE exceeds 0.25, or the interval reaches both below 0.5 and up to 0.8 (partial or as
  predicted: the maps cannot tell), or the estimate is beyond the tolerance but the interval
  reaches 1 (as predicted or stronger: the maps cannot tell). A misfit as above is not laid on
  the plan either where the fit used no map measured like the misfitting one
  (:class:`~fieldbank.interventions.spread.Footprint`: the model may not describe the arm
  there) or where a change of a group the fit held at the unimpaired value explains it
  (:func:`guesses_explain`).

With a calibrated SE a change that came as predicted is called failed or partial only when f
falls more than 2 SE + 0.2 below 1 or above 1.2: well under 5% of such cases.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fieldbank.armbatch import ArmBatch
from fieldbank.errors import ParameterError
from fieldbank.evaluate.severity import MUSCLE_GROUP_NAMES, synthesize
from fieldbank.fitting.problem import map_sd
from fieldbank.fitting.quality import MapFit, Thresholds, map_fit
from fieldbank.interventions.spread import arm_like
from fieldbank.interventions.whatifchoices import CHANGE_TOLERANCE, MAX_CHANGE_SE
from fieldbank.maps import FieldMap, model_map_like, model_map_values
from fieldbank.model import Arm, FloatArray
from fieldbank.params import BOUNDS, GROUPS, ArmParams
from fieldbank.validation import Interval, check_fields

#: Verdicts of a session, a plan and a whole check.
CONFIRMED = "prediction confirmed"
PARTIAL = "partial effect"
OVER = "stronger than predicted"
FAILED = "prediction failed"
INCONCLUSIVE = "inconclusive"
NOT_CHECKED = "not checked"
#: Verdicts that contradict a prediction (``fieldbank validate`` exits with status 1).
CONTRADICTED = (FAILED, OVER, PARTIAL)

#: Width of the interval the verdict reads, in SE (≈ 95%).
Z = 2.0
#: Smallest whitened size of the predicted change (sd) at which the maps can see it.
MIN_SENSITIVITY = 4.0
#: A confirmation needs at least this fraction of the predicted change, at 2 SE.
CONFIRM_FLOOR = 0.5
#: A realised fraction whose SE exceeds this is not printed: its 2-SE interval spans two whole
#: predicted changes and says nothing.
MAX_REPORTED_SE = 0.5
#: Fractions reported at most: an opposite change as large as the predicted one (-1), and
#: 3 × the predicted one (a plan's bounds usually stop it earlier: :func:`physical_range`).
FRACTION_LIMITS = (-1.0, 3.0)
#: The measurement a check proposes when its maps cannot see the change: a stiffness map while
#: Percentiles of the fit samples' realised fractions whose half-distance is the fit's SE.
_SPREAD_PERCENTILES = (15.865525393145708, 84.1344746068543)
#: Stands for the fraction of a sample that predicts no change at all (unknown).
_UNKNOWN = 1e12

#: Parameter field -> name stem in fit reports, and what a change of it moves.
_FIELDS = {"alpha_n": "alpha", "beta": "beta", "km_n_per_m": "km", "slack_offset_m": "slack"}
_REFLEX_FIELDS = ("alpha_n", "beta")


#: The range of each threshold of :class:`Rules`.
RULES_BOUNDS: dict[str, Interval] = {
    "tolerance": Interval(0.0, 1.0, low_closed=False, high_closed=False),
    "max_se": Interval(0.0, None, low_closed=False),
    "confirm_floor": Interval(0.0, 1.0, high_closed=False),
    "min_sensitivity": Interval(0.0, None, "sd", low_closed=False),
    "z": Interval(0.0, None, low_closed=False),
}


@dataclass(frozen=True)
class Rules:
    """The verdict's thresholds (module docstring); defaults: the module constants."""

    tolerance: float = CHANGE_TOLERANCE
    max_se: float = MAX_CHANGE_SE
    confirm_floor: float = CONFIRM_FLOOR
    min_sensitivity: float = MIN_SENSITIVITY
    z: float = Z

    def __post_init__(self) -> None:
        check_fields(self, RULES_BOUNDS, what="verdict threshold")

    def to_dict(self) -> dict[str, float]:
        return {"change_tolerance": self.tolerance, "max_change_se": self.max_se,
                "confirm_floor": self.confirm_floor,
                "min_sensitivity_sd": self.min_sensitivity, "z": self.z}

    def lines(self) -> list[str]:
        """The thresholds in words, with their numbers (printed under every check)."""
        z, t, lo, hi = self.z, self.tolerance, self.confirm_floor, 1.0 - self.tolerance
        return [
            "f = measured ÷ predicted change (1 as predicted, 0 none); SE from the later maps' "
            "noise and the fit's samples, never below what the two sessions' noise allows; "
            f"interval f ± {z:g} SE. Decided only when the predicted change moves the maps by "
            f"≥ {self.min_sensitivity:g} sd and SE ≤ {self.max_se:g}.",
            f"  {CONFIRMED}: interval ≥ {lo:g} and reaching {hi:g}, f ≤ {1 + t:g} (at least "
            "half the change, consistent with all of it, not beyond the tolerance)",
            f"  {OVER}: f > {1 + t:g} and interval above 1: clearly more than predicted",
            f"  {PARTIAL}: interval inside (0, {hi:g}): clearly some change, clearly less "
            "than predicted",
            f"  {FAILED}: interval below {hi:g} and reaching 0 (no change); or a map changed "
            "in a way the plan does not predict (χ²/n above its limit at the realised "
            "fraction, fit uncertainty allowed for)",
            f"  {INCONCLUSIVE}: the maps cannot see the change, it rests on a guess, SE > "
            f"{self.max_se:g}, the interval spans below {lo:g} and up to {hi:g}, or f > "
            f"{1 + t:g} with the interval reaching 1; or the maps differ from the model where "
            "the fit saw no map like them, or in a way a parameter the fit guessed explains",
        ]


DEFAULT_RULES = Rules()


# --- one map: its values before, after, measured, at the fit and at each sample ----------------
@dataclass(frozen=True, eq=False)
class MapChange:
    """One later map against the model before and the predicted after-model.

    Arrays have the map's value shape flattened per position, (N, k); the sample arrays carry
    a leading axis of samples, (B, N, k).
    """

    map_id: int
    measured: FieldMap
    sd: FloatArray
    before: FloatArray
    after: FloatArray
    before_s: FloatArray
    after_s: FloatArray
    duplicate_of: int | None = None

    @property
    def weights(self) -> FloatArray:
        return np.asarray(1.0 / self.sd**2)

    @property
    def y(self) -> FloatArray:
        return np.asarray(self.measured.values.reshape(self.sd.shape))

    def sums(self) -> tuple[float, float, FloatArray, FloatArray]:
        """Σ w·Δm·Δp and Σ w·Δp² at the fit, and per sample (each (B,))."""
        w = self.weights
        dp = self.after - self.before
        dm = self.y - self.before
        dps = self.after_s - self.before_s
        dms = self.y[None] - self.before_s
        return (float(np.sum(w * dm * dp)), float(np.sum(w * dp * dp)),
                np.sum(w * dms * dps, axis=(1, 2)), np.sum(w * dps * dps, axis=(1, 2)))

    def spread_of(self, fraction: float) -> FloatArray:
        """SD over the fit samples of the model before + ``fraction`` × the predicted change,
        per value (N, k); zeros without samples."""
        if self.before_s.shape[0] < 2:
            return np.zeros_like(self.before)
        ys = self.before_s + fraction * (self.after_s - self.before_s)
        return np.asarray(np.std(ys, axis=0, ddof=1))

    def check(self, fraction: float, thresholds: Thresholds, label: str) -> MapFit:
        """The map against the model before + ``fraction`` × the predicted change, the sd
        widened by the fit's spread of that prediction."""
        pred = self.before + fraction * (self.after - self.before)
        sd = np.sqrt(self.sd**2 + self.spread_of(fraction) ** 2)
        return map_fit(0, self.measured, pred.reshape(self.measured.values.shape),
                       sd.reshape(self.measured.values.shape), thresholds, label=label)


def map_changes(before: ArmParams, after: ArmParams, maps: Sequence[tuple[int, FieldMap]],
                samples: Sequence[tuple[ArmParams, ArmParams]] = ()
                ) -> tuple[list[MapChange], list[str]]:
    """Every map's values before, after and measured (arm-on-handle), at the fit and at each
    (before, after) sample pair; a map whose positions the model cannot evaluate is left out
    with the reason. A map repeating another (same kind, velocity, positions and values: one
    measurement stored from two files) is marked ``duplicate_of`` and counted once."""
    arm_b = Arm.from_params(before)
    sets = [before, after, *(p for pair in samples for p in pair)]
    try:  # one geometry (samples and plans change muscle values): one vectorised pass
        batch = ArmBatch.from_params(sets, arm_b)

        def values(m: FieldMap) -> FloatArray:
            return model_map_values(batch, m)
    except ParameterError:  # each set as its own arm
        arms = [arm_b, *(arm_like(arm_b, p) for p in sets[1:])]

        def values(m: FieldMap) -> FloatArray:
            return np.array([model_map_like(a, m).values for a in arms])
    out: list[MapChange] = []
    problems: list[str] = []
    for map_id, raw in maps:
        m = raw.as_arm_on_handle()
        try:
            ys = values(m)  # the model before, after, then each sample's before and after
        except (ParameterError, ValueError) as exc:
            problems.append(f"map {map_id}: not compared: {exc}")
            continue
        n = m.n
        sd = map_sd(m).reshape(n, -1)
        k = sd.shape[1]
        yb, ya = ys[0], ys[1]
        bs = ys[2::2].reshape(-1, n, k)
        as_ = ys[3::2].reshape(-1, n, k)
        dup = next((c.map_id for c in out if c.duplicate_of is None and _same(c.measured, m)),
                   None)
        out.append(MapChange(int(map_id), m, sd, yb.reshape(n, k), ya.reshape(n, k), bs, as_,
                             dup))
    return out, problems


def _same(a: FieldMap, b: FieldMap) -> bool:
    return (a.kind == b.kind and a.values.shape == b.values.shape
            and a.velocity_m_per_s == b.velocity_m_per_s
            and np.allclose(a.positions_m, b.positions_m, rtol=0, atol=1e-6)
            and np.allclose(a.values, b.values, rtol=1e-6, atol=1e-9))


# --- the estimate -----------------------------------------------------------------------------
@dataclass(frozen=True)
class Fraction:
    """The realised fraction of a set of maps, before deciding whether to report it.

    ``value`` None: the maps predict no change at all (Σ w·Δp² = 0).
    """

    value: float | None
    noise_se: float | None
    fit_se: float | None
    sensitivity_sd: float
    n_samples: int
    #: √(χ²/dof) of the maps that see the change against the model before + f × the change
    #: (sd widened by the fit's spread), when above 1: misfit neither explains widens the SE.
    misfit: float = 1.0
    #: 1/S₀: what the first session's noise allows along the predicted change (a floor of the
    #: fit part, module docstring); None: not known.
    first_se: float | None = None

    @property
    def fit_part(self) -> float | None:
        """The fit part of the SE: the samples' spread, at least :attr:`first_se`."""
        if self.fit_se is None and self.first_se is None:
            return None
        return max(self.fit_se or 0.0, self.first_se or 0.0)

    @property
    def se(self) -> float | None:
        if self.noise_se is None:
            return None
        return math.hypot(self.noise_se, self.fit_part or 0.0) * self.misfit


def fraction_of(changes: Sequence[MapChange]) -> Fraction:
    """Pooled over ``changes`` (duplicates left out): f, its noise and fit SEs, and how far the
    predicted change moves the maps (sd)."""
    used = [c for c in changes if c.duplicate_of is None]
    a = b = 0.0
    a_s: FloatArray | None = None
    b_s: FloatArray | None = None
    for c in used:
        ai, bi, asi, bsi = c.sums()
        a += ai
        b += bi
        a_s = asi if a_s is None else a_s + asi
        b_s = bsi if b_s is None else b_s + bsi
    sens = math.sqrt(b) if b > 0 else 0.0
    if b <= 0:
        return Fraction(None, None, None, 0.0, 0)
    f = a / b
    fit_se = None
    n = 0 if b_s is None else int(b_s.shape[0])
    if a_s is not None and b_s is not None and n >= 2:
        ok = b_s > 0
        # a sample whose predicted change these maps cannot see at all says f is unknown
        fs = np.where(ok, a_s / np.where(ok, b_s, 1.0), _UNKNOWN)
        lo, hi = np.percentile(fs, _SPREAD_PERCENTILES)
        fit_se = float((hi - lo) / 2.0) if hi < _UNKNOWN / 2 else math.inf
    return Fraction(f, 1.0 / sens, fit_se, sens, n, misfit_scale(used, f))


def misfit_scale(changes: Sequence[MapChange], fraction: float) -> float:
    """√(χ²/(n - 1)), at least 1, of the maps the predicted change moves by ≥ 1 sd against the
    model before + ``fraction`` × the change, the sd widened by the fit's spread (a Birge
    ratio: what neither the noise nor the fit's uncertainty explains widens the SE)."""
    chi2, n = 0.0, 0
    for c in changes:
        if float(np.sum(c.weights * (c.after - c.before) ** 2)) < 1.0:
            continue
        sd2 = c.sd**2 + c.spread_of(fraction) ** 2
        r = c.y - c.before - fraction * (c.after - c.before)
        chi2 += float(np.sum(r * r / sd2))
        n += r.size
    return math.sqrt(max(1.0, chi2 / (n - 1))) if n > 1 else 1.0


def physical_range(before: ArmParams, after: ArmParams) -> tuple[float, float]:
    """The fractions f for which before + f × (after - before) keeps every parameter the plan
    changes within its bounds, limited to :data:`FRACTION_LIMITS`."""
    lo, hi = FRACTION_LIMITS
    for field in _FIELDS:
        for p0, p1 in zip(getattr(before, field), getattr(after, field), strict=True):
            d = p1 - p0
            if d == 0:
                continue
            bound = BOUNDS[field]
            for edge in (bound.low, bound.high):
                if edge is None or not math.isfinite(edge):
                    continue
                f = (edge - p0) / d
                if f > 0:
                    hi = min(hi, f)
                elif f < 0:
                    lo = max(lo, f)
    return lo, hi


# --- what the plan acts on, and what would see it ---------------------------------------------
@dataclass(frozen=True)
class Treated:
    """A muscle group whose parameters the plan changes, and which force that moves."""

    group: str
    force: str  # 'reflex' or 'passive'
    names: tuple[str, ...]  # fit-report names of the changed parameters

    @property
    def words(self) -> str:
        what = "stretch reflex" if self.force == "reflex" else "passive stiffness"
        return f"{MUSCLE_GROUP_NAMES[self.group]}' ({self.group}) {what}"


def treated(before: ArmParams, after: ArmParams) -> tuple[Treated, ...]:
    """The groups and forces the change from ``before`` to ``after`` acts on, in model order.
    A change of α or β moves the reflex force, which rests on both; of Km or the slack
    length, the passive force, which rests on Km and the slack length."""
    out = []
    for k, g in enumerate(GROUPS):
        changed = [f for f in _FIELDS if getattr(before, f)[k] != getattr(after, f)[k]]
        if not changed:
            continue
        if any(f in _REFLEX_FIELDS for f in changed):
            out.append(Treated(g, "reflex", (f"alpha_{g}", f"beta_{g}")))
        if any(f not in _REFLEX_FIELDS for f in changed):
            out.append(Treated(g, "passive", (f"km_{g}", f"slack_{g}")))
    return tuple(out)


#: The level a held (guessed) group is raised to when asking whether it explains a misfit.
GUESS_PROBE_LEVEL = "moderate"


def guesses_explain(changes: Sequence[MapChange], before: ArmParams, held: Sequence[str],
                    fraction: float, thresholds: Thresholds) -> tuple[str, ...]:
    """The groups the fit held at the unimpaired value (guesses) whose change explains why
    ``changes`` differ from the model before + ``fraction`` × the predicted change; empty when
    they do not.

    Each held group and component (its reflex, its passive stiffness) gives one direction of
    change: the maps with that group raised to :data:`GUESS_PROBE_LEVEL` minus the maps of the
    model before. The whitened misfit is regressed on those directions (signed: the fit may
    have given the group's force to another group), and when no map is poor any more, the
    misfit may be a wrong guess rather than the plan: the groups that took part are returned.
    """
    pairs: dict[tuple[str, str], None] = {}
    for name in held:
        kind, _, g = name.rpartition("_")
        if g in GROUPS and kind in ("alpha", "beta", "km"):
            pairs[(g, "passive" if kind == "km" else "dynamic")] = None
    used = [c for c in changes if c.duplicate_of is None]
    if not pairs or not used:
        return ()
    arm_b = Arm.from_params(before)
    sds = [np.sqrt(c.sd**2 + c.spread_of(fraction) ** 2) for c in used]
    resid = np.concatenate([((c.y - c.before - fraction * (c.after - c.before)) / s).ravel()
                            for c, s in zip(used, sds, strict=True)])
    cols, names = [], []
    for g, comp in pairs:
        raised = arm_like(arm_b, synthesize({f"{g}:{comp}": GUESS_PROBE_LEVEL}, before))
        col = np.concatenate([((model_map_like(raised, c.measured).values.reshape(c.sd.shape)
                                - c.before) / s).ravel() for c, s in zip(used, sds, strict=True)])
        if np.any(col != 0):
            cols.append(col)
            what = "stretch reflex" if comp == "dynamic" else "passive stiffness"
            names.append(f"{MUSCLE_GROUP_NAMES[g]}' ({g}) {what}")
    if not cols:
        return ()
    design = np.column_stack(cols)
    coef, *_ = np.linalg.lstsq(design, resid, rcond=None)
    left = resid - design @ coef
    start = 0
    for c in used:
        k = c.sd.size
        chi2 = float(np.sum(left[start:start + k] ** 2)) / k
        start += k
        if chi2 > thresholds.chi2_limit(k):
            return ()
    return tuple(n for n, x in zip(names, coef, strict=True) if abs(x) > 1e-9)


def positions_of(changes: Sequence[MapChange]) -> FloatArray:
    """The positions a suggestion is evaluated at: the later stiffness maps', else any map's."""
    stiff = [c.measured.positions_m for c in changes if c.measured.kind == "stiffness"]
    pool = stiff or [c.measured.positions_m for c in changes]
    if not pool:
        return np.zeros((0, 2))
    return np.asarray(np.unique(np.concatenate(pool), axis=0))


# --- the verdict ------------------------------------------------------------------------------
