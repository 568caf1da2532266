"""The stated range of what the maps did not identify, and draws from it.

A fit holds a parameter the maps do not identify at its unimpaired value
(:class:`~fieldbank.fitting.ArmFitter`): the value is a guess, not a measurement. A prediction
that rests on it must be as wide as the guess (BRIEF §14), so every prediction interval draws
the held parameters from a stated prior range instead of keeping them at the held value:

* **the range**, per muscle group and component, runs along the severity scale
  (:mod:`fieldbank.evaluate.severity`, BRIEF §5) from unimpaired (score 0) to the top of its
  severe band (score :data:`SCORE_HIGH` = 4.5: the MAS-4 boundary, 10 × unimpaired, raised by
  half a Weber step - the largest ratio the scale still calls severe rather than beyond it,
  10 · √1.6 ≈ 12.6). A severe group lies inside the range, not on its edge;
* **passive** (Km of the group): Km = Km_unimpaired · r, r the passive ratio (for Km alone the
  passive ratio is the Km ratio: 600 to 7,590 N/m on the default arm);
* **dynamic** (α and β of the group, drawn together - never α at the top of its range with β
  at the top of its own): the point of the scale's synthesis path (α = 100 N · 10^s, β rising
  from 0.1 to 1) at which the group's dynamic ratio is r - on the default arm the elbow
  flexors run from α 100 N, β 0.1 to α ≈ 1,570 N, β 1. When only one of α and β is held the
  other keeps its fitted samples. **Not beyond severe at the joint**: a group's ratio is taken
  against its own unimpaired resistance, which for a bi-articular group is 2.3 × a
  mono-articular one's at the elbow (its longer moment arm and excursion: 0.95 against 0.41
  N·m for the elbow flexion's), so the top of its own severe band added 11 N·m of reflex to a
  fast elbow flexion where the top of the elbow extensors' adds 4.7 N·m - three times a severe
  elbow's reflex. A bi-articular group's reflex range therefore ends where it adds as much
  reflex torque to any standard joint stretch as the top of severe of the mono-articular group
  graded on that stretch (:attr:`Prior.dynamic_top`; the elbow flexors' for elbow extension,
  the extensors' for flexion, the shoulder groups' for the shoulder): on the default arm bf
  and be end near their own moderate level, every stretch's reflex within the scale's severe
  band;
* **contracture** (the slack offset of the group, when the fit fits it): from no contracture
  (0) to the brief's shortest slack (:data:`fieldbank.fitting.space.SLACK_RANGE_M`, -20 mm),
  linear in the place in the range - the severity scale does not reach a contracture's
  grade (20 mm shorter makes the elbow's passive torque ≈ 1.7 × unimpaired), so its range is
  the brief's, on the same [0, top] place as the others (:func:`contracture_slack`);
* **draws**: the severity score uniform on [0, top] - each level equally likely - stratified
  (one draw in each of n equal slices, in a seeded random order), so 40 samples reach both
  ends of the range. The held units of one sample share their place in their ranges (the
  same fraction of each unit's top): the guesses move together from all unimpaired to all
  past severe. Every headline metric grows with each group's Km and reflex, so an interval
  between those ends holds any mixture of them (a severe elbow-flexor reflex beside an
  unimpaired bi-articular one included), where independent draws would leave out both ends
  of a sum of guesses (the 2.5th percentile of two independent reflexes is already well
  above unimpaired);
* **what the maps allow**: a held parameter can be poorly constrained rather than free. At fit
  time the top of each unit's range is checked against the maps (:func:`fit_ranges`): the
  unit at the top, everything else at the fit, the fitted linear parameters (Km, α) re-solved;
  when Δχ² of the maps exceeds the χ² quantile :data:`RANGE_TEST_LEVEL` with the unit's
  degrees of freedom, the top is lowered by bisection to the highest score the maps allow. The
  fit report keeps the ranges (``prior``), and the fit's stored samples keep the held value (so
  what the maps identified is unchanged); prediction intervals draw at use time
  (:func:`draw`), deterministically for a seed.

:data:`PRIOR_VERSION` names this definition: anything cached from the draws (intervals kept
with a fit) must be keyed by it.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fieldbank.armbatch import ArmBatch
from fieldbank.errors import FitError
from fieldbank.evaluate.batch import stretch_torques
from fieldbank.evaluate.probing import (
    DIRECTION_SIGN,
    JOINTS,
    STRETCHES,
    stretch_profile,
    unimpaired_reference,
)
from fieldbank.evaluate.severity import (
    REFLEX_PATH_MAX,
    SCALE,
    SeverityScale,
    ratio_of_score,
    reflex_path,
)
from fieldbank.evaluate.tone import GRADED_STRETCH, POSITIONED_STRETCH, positioned_hold_rad
from fieldbank.fitting.problem import FitProblem
from fieldbank.fitting.space import SLACK_RANGE_M
from fieldbank.fitting.uncertainty import FitSamples
from fieldbank.model import Arm, FloatArray
from fieldbank.params import GROUP_INDEX, GROUPS, ArmParams

#: Version of the prior's definition (range, path, draws). Raise it when any of them changes.
#: 2: bi-articular reflexes not beyond a severe joint (:attr:`Prior.dynamic_top`); slack ranges.
PRIOR_VERSION = 2
#: Top of every range on the severity score: the severe band's upper edge (4 + 1/2 step).
SCORE_HIGH = 4.5
#: The maps allow the top of a range while Δχ² stays within this χ² quantile.
RANGE_TEST_LEVEL = 0.95
#: Bisection steps when the maps lower the top of a range (a 4.5 / 2¹² ≈ 0.001 score).
RANGE_BISECTIONS = 12
#: Path parameters tabulated per group, evenly over [0, PATH_TOP]; the table grows to the
#: path's own top when a group's reflex needs more to reach the top of the severe band.
PATH_POINTS = 65
PATH_TOP = 1.6
#: Kind of each fitted parameter -> the component of its prior range: the severity grade it
#: sizes, or the contracture (the slack offset).
COMPONENT_OF: dict[str, str] = {"km": "passive", "alpha": "dynamic", "beta": "dynamic",
                                "slack": "contracture"}


def contracture_slack(scores: FloatArray) -> FloatArray:
    """The slack offset (m) at places ``scores`` (0 … :data:`SCORE_HIGH`) of a contracture's
    range: linear from 0 to the brief's shortest slack (module docstring)."""
    return np.asarray(np.asarray(scores, dtype=float) / SCORE_HIGH * SLACK_RANGE_M[0],
                      dtype=float)


def unit_of(name: str) -> tuple[str, str]:
    """(group, component) of a fitted parameter name ('alpha_ef' -> ('ef', 'dynamic')).

    Raises
    ------
    FitError
        Not a per-group Km, α or β name (q_rest has no severity range).
    """
    kind, _, group = name.rpartition("_")
    if kind not in COMPONENT_OF or group not in GROUP_INDEX:
        raise FitError(f"{name!r} has no prior range on the severity scale (only Km, α, β and "
                       "the slack length of a muscle group do).")
    return group, COMPONENT_OF[kind]


def units(names: Collection[str]) -> dict[tuple[str, str], tuple[str, ...]]:
    """The names grouped by (group, component), in the fit's order (Km, α, β per group);
    names without a range (q_rest) are left out."""
    out: dict[tuple[str, str], list[str]] = {}
    for kind in ("km", "alpha", "beta", "slack"):
        for g in GROUPS:
            name = f"{kind}_{g}"
            if name in names:
                out.setdefault((g, COMPONENT_OF[kind]), []).append(name)
    return {k: tuple(v) for k, v in out.items()}


@dataclass(frozen=True)
class GuessRange:
    """The prior range of one held unit (a group's Km, or its α and β).

    ``score_top``: the prior's top of the range on the severity score (:meth:`Prior.top`);
    ``score_high``: the top the maps allow (``score_top`` unless the maps lowered it);
    ``delta_chi2_at_top``: what the maps say about the prior's top (None when not checked).
    """

    group: str
    component: str
    names: tuple[str, ...]
    score_high: float = SCORE_HIGH
    delta_chi2_at_top: float | None = None
    threshold: float | None = None
    score_top: float = SCORE_HIGH

    @property
    def limited_by_maps(self) -> bool:
        return self.score_high < self.score_top - 1e-12

    @property
    def ratio_high(self) -> float | None:
        """The severity ratio at the top (None for a contracture: its range is in mm)."""
        if self.component == "contracture":
            return None
        return ratio_of_score(self.score_high, self.component)

    def to_dict(self) -> dict[str, Any]:
        return {"group": self.group, "component": self.component, "names": list(self.names),
                "score_high": self.score_high, "ratio_high": self.ratio_high,
                "score_top": self.score_top, "limited_by_maps": self.limited_by_maps,
                "delta_chi2_at_top": self.delta_chi2_at_top, "threshold": self.threshold}

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> GuessRange:
        names = tuple(str(n) for n in doc.get("names", ()))
        group, component = str(doc.get("group")), str(doc.get("component"))
        if not names or any(unit_of(n) != (group, component) for n in names):
            raise FitError(f"prior range of {group} {component}: names {list(names)} do not "
                           "belong to it.")
        high = float(doc.get("score_high", SCORE_HIGH))
        if not 0.0 <= high <= SCORE_HIGH:
            raise FitError(f"prior range of {group} {component}: score_high must lie in "
                           f"[0, {SCORE_HIGH}]; got {high!r}.")
        d = doc.get("delta_chi2_at_top")
        t = doc.get("threshold")
        top = float(doc.get("score_top", SCORE_HIGH))
        if not high <= top <= SCORE_HIGH:
            raise FitError(f"prior range of {group} {component}: score_top must lie in "
                           f"[score_high, {SCORE_HIGH}]; got {top!r}.")
        return cls(group, component, names, high, None if d is None else float(d),
                   None if t is None else float(t), top)


def full_ranges(held: Collection[str]) -> tuple[GuessRange, ...]:
    """The unchecked ranges of the held parameters (a fit stored before ranges were kept)."""
    return tuple(GuessRange(g, c, names) for (g, c), names in units(held).items())


def ranges_from_report(report: Mapping[str, Any] | None) -> tuple[GuessRange, ...]:
    """The ranges a fit report keeps (``prior.ranges``), else the full ranges of its held
    parameters (``held_at_unimpaired``)."""
    doc = (report or {}).get("prior")
    if isinstance(doc, Mapping) and isinstance(doc.get("ranges"), list):
        return tuple(GuessRange.from_dict(r) for r in doc["ranges"] if isinstance(r, Mapping))
    return full_ranges([str(h) for h in (report or {}).get("held_at_unimpaired", []) or []])


#: Prior tables a process keeps (:meth:`Prior.for_arm`), the oldest dropped first; a table is
#: about 10 kB.
TABLES_KEPT = 64


@dataclass(frozen=True, eq=False)
class Prior:
    """The severity scale's parameter values for one arm geometry (module docstring).

    ``reference``: the arm with unimpaired muscles; ``path_s`` (K,) the tabulated path
    parameters; ``path_ratio`` (6, K) each group's dynamic ratio along the path;
    ``dynamic_top`` (6,) the top of each group's reflex range on its severity score
    (:data:`SCORE_HIGH`, lower for a group whose top of severe would add more reflex torque to
    a joint stretch than that stretch's severe mono-articular group: module docstring).
    """

    reference: Arm
    scale: SeverityScale
    path_s: FloatArray
    path_ratio: FloatArray
    dynamic_top: FloatArray

    @classmethod
    def for_arm(cls, arm: Arm, scale: SeverityScale = SCALE) -> Prior:
        """Tabulate each group's dynamic ratio along the synthesis path, all groups and path
        points in one vectorised pass (:class:`~fieldbank.model.ArmBatch`).

        The table depends on the arm's geometry and the scale only (it is built on the arm
        with unimpaired muscles): the last :data:`TABLES_KEPT` are kept in the process, so a
        report's cases, a fit and its intervals, or a cluster worker's successive tasks on
        one body tabulate it once - the same object, the same numbers."""
        ref = unimpaired_reference(arm)
        key = (ref.params, scale)
        kept = _TABLES.get(key)
        if kept is not None:
            return kept
        top = ratio_of_score(SCORE_HIGH, "dynamic", scale)
        for end in (PATH_TOP, REFLEX_PATH_MAX):
            table = cls._table(ref, scale, np.linspace(0.0, end, PATH_POINTS))
            if table.path_ratio[:, -1].min() >= top:
                break
        for a in (table.path_s, table.path_ratio, table.dynamic_top):
            a.setflags(write=False)
        _TABLES[key] = table
        while len(_TABLES) > TABLES_KEPT:
            _TABLES.pop(next(iter(_TABLES)), None)
        return table

    @classmethod
    def _table(cls, arm: Arm, scale: SeverityScale, s: FloatArray) -> Prior:
        ref = unimpaired_reference(arm)
        p0 = ref.params
        alpha, beta = reflex_path(s)
        ratio = np.ones((len(GROUPS), s.size))
        # every standard stretch with each group it lengthens along the path (the groups
        # graded on it and a bi-articular group crossing its joint), then each bi-articular
        # group's own stretch (fieldbank.evaluate.tone): a group's ratio is the larger of its
        # graded stretches', as its grade; the reflex torque each group adds to each standard
        # stretch sets the joint cap (module docstring)
        stretches: list[tuple[tuple[str, str], float | None, list[str]]] = []
        for stretch in STRETCHES:
            j = JOINTS.index(stretch[0])
            lever = DIRECTION_SIGN[stretch[1]] * ref.jl[:, j]
            stretches.append((stretch, None, [g for g in GROUPS if lever[GROUP_INDEX[g]] > 0]))
        stretches += [(GRADED_STRETCH[g], positioned_hold_rad(ref, g), [g])
                      for g in POSITIONED_STRETCH]
        added_on: dict[tuple[str, tuple[str, str]], FloatArray] = {}
        for stretch, hold, moved in stretches:
            # the reference (set 0), then each moved group along the path, the others at p0
            size = 1 + len(moved) * s.size
            alpha_sets = np.tile(np.asarray(p0.alpha_n, dtype=float), (size, 1))
            beta_sets = np.tile(np.asarray(p0.beta, dtype=float), (size, 1))
            for k, g in enumerate(moved):
                rows = slice(1 + k * s.size, 1 + (k + 1) * s.size)
                alpha_sets[rows, GROUP_INDEX[g]] = alpha
                beta_sets[rows, GROUP_INDEX[g]] = beta
            st = stretch_torques(ArmBatch.from_arrays(ref, size, alpha_n=alpha_sets,
                                                      beta=beta_sets), *stretch, hold_rad=hold)
            v_all = st.fast_n_m - st.slow_n_m
            prof = stretch_profile(ref, *stretch, hold_rad=hold)
            for k, g in enumerate(moved):
                i = GROUP_INDEX[g]
                rows = slice(1 + k * s.size, 1 + (k + 1) * s.size)
                added = np.maximum((v_all[rows] - v_all[0]).max(axis=1), 0.0)  # only g differs
                if hold is None:
                    added_on[(g, stretch)] = added
                if GRADED_STRETCH[g] != stretch:
                    continue
                peak = float((prof.passive_n_m[:, i] + prof.velocity_dependent_n_m[:, i]).max())
                ratio[i] = np.maximum(ratio[i], 1.0 + added / peak)
        return cls(ref, scale, s, ratio, _joint_tops(scale, s, ratio, added_on))

    def top(self, group: str, component: str) -> float:
        """The top of ``group``'s ``component`` range on the score, before the maps:
        :data:`SCORE_HIGH`, or :attr:`dynamic_top` for a reflex."""
        if component == "dynamic":
            return float(self.dynamic_top[GROUP_INDEX[group]])
        return SCORE_HIGH

    def path_at(self, group: str, ratio: FloatArray) -> tuple[FloatArray, FloatArray]:
        """α (N) and β on the path where ``group``'s dynamic ratio is ``ratio`` (any shape)."""
        r = self.path_ratio[GROUP_INDEX[group]]
        # the ratio rises with s; flat stretches (the reflex not yet firing) are nudged up so
        # the table inverts
        lr = np.maximum.accumulate(np.log(r)) + 1e-12 * np.arange(r.size)
        want = np.log(np.asarray(ratio, dtype=float))
        if np.any(want > lr[-1]):
            raise FitError(f"{group}: the synthesis path does not reach a dynamic ratio of "
                           f"{float(np.exp(want.max())):.3g}.")
        return reflex_path(np.interp(want, lr, self.path_s))

    def values(self, group: str, component: str, scores: FloatArray
               ) -> dict[str, FloatArray]:
        """The parameters of ``group``'s ``component`` at severity scores (n,): {name: (n,)}."""
        sc = np.atleast_1d(np.asarray(scores, dtype=float))
        if component == "contracture":
            return {f"slack_{group}": contracture_slack(sc)}
        ratio = np.array([ratio_of_score(float(x), component, self.scale) for x in sc])
        i = GROUP_INDEX[group]
        if component == "passive":
            return {f"km_{group}": self.reference.params.km_n_per_m[i] * ratio}
        alpha, beta = self.path_at(group, ratio)
        return {f"alpha_{group}": alpha, f"beta_{group}": beta}

    def interval(self, rng: GuessRange) -> dict[str, tuple[float, float]]:
        """Each name's values at the bottom and the top of ``rng``: {name: (low, high)}."""
        lo = self.values(rng.group, rng.component, np.array([0.0]))
        hi = self.values(rng.group, rng.component, np.array([self.high(rng)]))
        return {n: (float(lo[n][0]), float(hi[n][0])) for n in rng.names}

    def high(self, rng: GuessRange) -> float:
        """The top of ``rng`` on the score: what the maps allow, never above the prior's own
        top (:meth:`top`; a range kept by an older fit may not know it)."""
        return min(rng.score_high, self.top(rng.group, rng.component))


#: (unimpaired reference parameters, scale) -> its table, in the order they were made.
_TABLES: dict[tuple[ArmParams, SeverityScale], Prior] = {}


def _joint_tops(scale: SeverityScale, s: FloatArray, ratio: FloatArray,
                added_on: Mapping[tuple[str, tuple[str, str]], FloatArray]) -> FloatArray:
    """Top of each group's reflex range (score): :data:`SCORE_HIGH`, or lower where the
    group would add more reflex torque to a standard stretch than the top of severe of the
    stretch's mono-articular group (module docstring)."""
    top_ratio = ratio_of_score(SCORE_HIGH, "dynamic", scale)
    cap: dict[tuple[str, str], float] = {}
    for (g, stretch), added in added_on.items():
        if g in POSITIONED_STRETCH or GRADED_STRETCH[g] != stretch:
            continue
        i = GROUP_INDEX[g]
        at_top = float(np.interp(np.log(top_ratio), np.maximum.accumulate(np.log(ratio[i]))
                                 + 1e-12 * np.arange(s.size), added))
        cap[stretch] = max(cap.get(stretch, 0.0), at_top)
    out = np.full(len(GROUPS), SCORE_HIGH)
    for g in POSITIONED_STRETCH:
        i = GROUP_INDEX[g]
        ok = np.ones(s.size, dtype=bool)
        for (h, stretch), added in added_on.items():
            if h == g and stretch in cap:
                ok &= added <= cap[stretch]
        # the last path point of the leading run within every cap, and its score
        last = int(np.argmin(ok)) - 1 if not ok.all() else s.size - 1
        r = float(ratio[i, max(last, 0)])
        out[i] = min(SCORE_HIGH, scale.score(r, "dynamic"))
    return out


def stratified_scores(n: int, high: float, rng: np.random.Generator) -> FloatArray:
    """n scores uniform on [0, high], one in each of n equal slices, in random order."""
    return np.asarray((rng.permutation(n) + rng.uniform(size=n)) / n * high, dtype=float)


def draw(samples: FitSamples, ranges: Sequence[GuessRange], prior: Prior, n: int | None = None,
         seed: int = 0) -> FitSamples:
    """``n`` samples (default: as many as the fit's) with every held parameter of ``ranges``
    drawn from its range (module docstring); identified parameters keep the fit's samples,
    taken in order and cycled when ``n`` exceeds them (the draws of the guesses then still
    differ). A held name the samples lack becomes a new column."""
    count = samples.values.shape[0]
    size = count if n is None else int(n)
    if count == 0 or size < 1:
        raise FitError(f"draws need at least one fit sample and n >= 1; got {count} and "
                       f"{size}.")
    rows = samples.values[np.arange(size) % count]
    names = list(samples.names)
    cols = {name: rows[:, k].copy() for k, name in enumerate(names)}
    # one position in the range per sample, shared by every held unit
    where = stratified_scores(size, 1.0, np.random.default_rng(seed))
    for r in ranges:
        drawn = prior.values(r.group, r.component, where * prior.high(r))
        for name in r.names:
            if name not in cols:
                names.append(name)
            cols[name] = drawn[name]
    values = np.column_stack([cols[name] for name in names]) if names else rows
    return FitSamples(tuple(names), np.asarray(values, dtype=float))


def fit_ranges(problem: FitProblem, theta: FloatArray, held: Collection[str], prior: Prior
               ) -> tuple[GuessRange, ...]:
    """The range of each held unit, its top checked against the maps (module docstring).

    ``problem``: the fit's problem with the held parameters fixed at their values in
    ``theta`` (:func:`fieldbank.fitting.uncertainty.reduced_problem`).
    """
    base = problem.project(theta).r
    from scipy.stats import chi2  # heavy: loaded when a fit runs, not with the module

    chi0 = float(base @ base)
    out = []
    idx = {name: k for k, name in enumerate(problem.space.names)}

    def delta(rng: GuessRange, score: float) -> float:
        t = np.array(theta, dtype=float)
        for name, v in prior.values(rng.group, rng.component, np.array([score])).items():
            if name in rng.names:
                t[idx[name]] = float(v[0])
        r = problem.project(t).r
        return float(r @ r) - chi0

    for (g, c), names in units(held).items():
        rng = GuessRange(g, c, names)
        limit = float(chi2.ppf(RANGE_TEST_LEVEL, len(names)))
        ceiling = prior.top(g, c)
        top = delta(rng, ceiling)
        high = ceiling
        if top > limit:
            lo, hi = 0.0, ceiling
            for _ in range(RANGE_BISECTIONS):
                mid = 0.5 * (lo + hi)
                if delta(rng, mid) > limit:
                    hi = mid
                else:
                    lo = mid
            high = lo
        out.append(GuessRange(g, c, names, high, top, limit, ceiling))
    return tuple(out)


def prior_dict(ranges: Sequence[GuessRange], prior: Prior) -> dict[str, Any]:
    """The fit report's ``prior`` entry: the definition's version, the scale's ends and each
    held unit's range with its parameter values."""
    return {
        "version": PRIOR_VERSION,
        "description": ("held parameters are drawn, for prediction intervals, from the "
                        "severity scale between unimpaired (score 0) and the top of its "
                        f"severe band (score {SCORE_HIGH:g}, {ratio_of_score(SCORE_HIGH):.3g} "
                        "× unimpaired), uniform in the score, unless the maps allow less; "
                        "a held slack length from none to the brief's shortest "
                        f"({1000 * SLACK_RANGE_M[0]:g} mm)"),
        "score_high": SCORE_HIGH,
        "ranges": [{**r.to_dict(), "values": {n: list(v) for n, v in
                                              prior.interval(r).items()}} for r in ranges],
    }

