"""What a what-if rests on: the fit behind the model, what it guessed, and how sure it is.

A prediction is only as good as the model it starts from (BRIEF §14). For a model that came
out of a fit (or was derived from one), this module turns the stored fit report into what the
what-if must say:

* **refusal of a poor fit** (:func:`check_fit`): a fit whose goodness-of-fit verdict is 'poor'
  (:mod:`fieldbank.fitting.quality`) does not describe the patient's maps, so a what-if, a
  stored plan or a report on it is refused with :class:`PoorFitError` - unless the user insists
  (``accept_poor_fit``), which the output then records;
* **the guesses** (:func:`guesses`): every parameter the fit did not identify, with the fit's
  reason (held at the unimpaired value, or left near the prior). The result lists them all: each
  enters the predicted fields;
* **reflexes the maps did not see** (:func:`unseen_reflexes`): for every group whose stretch
  reflex the fit held at the unimpaired value, a sentence saying that the maps cannot tell a
  normal reflex from a severe one (or, where the maps limit the range, from one at the level
  they still allow) and which stretch or moving map would;
* **warnings** (:func:`plan_warnings`): a plan step that acts on a guessed parameter - botulinum
  toxin, rhizotomy or baclofen into a group whose reflex (α, β) was never identified, surgery or
  casting on a group whose passive stiffness (Km) was not - predicts a change that rests on the
  unimpaired default, not on the patient ("no effect" would otherwise be predicted silently);
* **intervals** (:func:`prediction_intervals`): the plan applied to each of the fit's parameter
  samples (bootstrap replicates or Gaussian draws, :mod:`fieldbank.fitting.uncertainty`) gives
  the spread of the headline metrics before, after and of the change; reported as the 2.5-97.5
  percentiles (95%) beside the point prediction. Parameters held at the unimpaired value are
  drawn from their stated prior range (:mod:`fieldbank.fitting.prior`: unimpaired to the top
  of the severity scale's severe band, as far as the maps allow), so an interval that rests
  on a guess is as wide as the guess; the same samples with the held values kept give the
  interval of what the maps identified (``without_guesses``), which the reported interval
  also holds (the held values are the range's unimpaired end), and a metric whose interval
  the guesses widen by more than :data:`GUESS_WIDENING` says it rests on a guess
  (``rests_on_guess``, ``*`` in the text). The
  samples run in one vectorised pass (:func:`sample_metrics`, :class:`fieldbank.armbatch.ArmBatch`:
  the model before's geometry, every muscle value - Km, α, β, slack offset, rest length, rest
  posture - free per sample). :class:`IntervalSet` is what a report keeps with the fit under
  :func:`interval_key`.

The model before is compiled once by the caller and passed down as an :class:`Arm`: its
parameters (``arm.params``) and its geometry go together to every step.

Which parameters a step acts on follows from the catalogue's public contract (``targets()``
and ``EFFECTS``): a change of α or β scales the group's reflex force, which rests on both α
and β of the group; a change of Km or of the slack length moves its passive force, which rests
on Km and (when the fit fitted it) the slack length.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.compare import Conditions
from fieldbank.evaluate.severity import MUSCLE_GROUP_NAMES, SCALE, ratio_of_score
from fieldbank.fitchoices import MODEL_VERSION
from fieldbank.fitting.prior import PRIOR_VERSION, GuessRange, Prior, draw, ranges_from_report
from fieldbank.fitting.uncertainty import FitSamples
from fieldbank.interventions.errors import InterventionError
from fieldbank.interventions.plan import Plan
from fieldbank.interventions.samplemetrics import SampleMetrics, sample_metrics
from fieldbank.interventions.suggest import reflex_test
from fieldbank.interventions.whatifchoices import DEFAULT_INTERVAL_SAMPLES
from fieldbank.model import Arm, FloatArray
from fieldbank.modelsource import ModelSource
from fieldbank.params import ArmParams

#: Percentiles of the reported intervals.
INTERVAL_PERCENTILES = (2.5, 97.5)
#: An interval rests on a guess when drawing the held parameters from their prior range
#: widens it (before, after or of the change) by more than this factor over the interval of
#: what the maps identified.
GUESS_WIDENING = 1.25

#: Changed parameter (catalogue ``EFFECTS`` key) -> what the change scales and the fitted
#: parameters that size it.
_FORCE_OF = {"alpha_n": ("reflex", ("alpha", "beta")), "beta": ("reflex", ("alpha", "beta")),
             "km_n_per_m": ("passive", ("km", "slack")),
             "slack_offset_m": ("passive", ("km", "slack"))}
_WHAT = {"reflex": "stretch reflex (α, β)", "passive": "passive force (Km, slack length)"}


class PoorFitError(InterventionError):
    """The model before comes from a fit whose goodness-of-fit verdict is 'poor'."""


@dataclass(frozen=True)
class Guess:
    """A parameter the fit did not identify, its value in the model and why."""

    name: str
    value: float
    held: bool
    reason: str

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "value": self.value, "held_at_unimpaired": self.held,
                "reason": self.reason}


@dataclass(frozen=True, eq=False)
class FitBasis:
    """What a prediction knows about the fit behind its model.

    ``same_model``: the model before *is* the fitted model (its samples apply directly);
    otherwise it was derived from it by earlier plans.
    """

    fit_id: int
    fitted_model_id: int
    same_model: bool
    status: str
    verdict: str
    reasons: tuple[str, ...]
    unidentified: tuple[tuple[str, str], ...]
    held: tuple[str, ...]
    samples: FitSamples | None
    #: The held parameters' prior ranges (:func:`fieldbank.fitting.prior.ranges_from_report`)
    #: and the seed their draws use (the fit's).
    ranges: tuple[GuessRange, ...] = ()
    seed: int = 0

    @classmethod
    def of(cls, source: ModelSource) -> FitBasis | None:
        """The basis of a resolved model, or None when no fit lies behind it."""
        if source.fit is None or source.fitted_model_id is None:
            return None
        return cls.from_report(source.fit.id, source.fitted_model_id,
                               source.model_id == source.fitted_model_id, source.fit.result)

    @classmethod
    def from_report(cls, fit_id: int, fitted_model_id: int, same_model: bool,
                    report: Mapping[str, Any]) -> FitBasis:
        """The basis from a stored fit report (:meth:`fieldbank.fitting.ArmFitter.report`)."""
        gof = report.get("goodness_of_fit") or {}
        unid = tuple((str(u.get("name")), str(u.get("reason", "")))
                     for u in report.get("unidentified", []) if isinstance(u, Mapping))
        return cls(int(fit_id), int(fitted_model_id), bool(same_model),
                   str(report.get("status", "unknown")), str(gof.get("verdict", "unknown")),
                   tuple(str(r) for r in gof.get("reasons", [])), unid,
                   tuple(str(h) for h in report.get("held_at_unimpaired", []) or []),
                   FitSamples.from_report(report), ranges_from_report(report),
                   int(report.get("seed", 0) or 0))


@dataclass(frozen=True)
class Interval:
    """A metric's point prediction and 95% interval, before, after and of the change."""

    metric: str
    unit: str
    before: float
    after: float
    before_low: float
    before_high: float
    after_low: float
    after_high: float
    change_low: float
    change_high: float
    #: Whether the held parameters' prior range widens the interval (module docstring), and
    #: the intervals of what the maps identified (held parameters kept at the held value):
    #: (before low, before high, after low, after high, change low, change high).
    rests_on_guess: bool = False
    identified: tuple[float, ...] | None = None

    @property
    def change(self) -> float:
        return self.after - self.before

    def to_dict(self) -> dict[str, Any]:
        out = {"unit": self.unit, "before": self.before, "after": self.after,
               "change": self.change, "before_interval": [self.before_low, self.before_high],
               "after_interval": [self.after_low, self.after_high],
               "change_interval": [self.change_low, self.change_high],
               "rests_on_guess": self.rests_on_guess}
        if self.identified is not None:
            i = self.identified
            out["without_guesses"] = {"before_interval": [i[0], i[1]],
                                      "after_interval": [i[2], i[3]],
                                      "change_interval": [i[4], i[5]]}
        return out


@dataclass(frozen=True, eq=False)
class Guesses:
    """What a what-if result says about the ground it stands on (module docstring)."""

    basis: FitBasis | None
    guesses: tuple[Guess, ...] = ()
    warnings: tuple[str, ...] = ()
    intervals: tuple[Interval, ...] = ()
    interval_note: str = ""
    n_samples: int = 0
    accepted_poor_fit: bool = False
    #: What the maps could not tell about the held reflexes (:func:`unseen_reflexes`).
    notes: tuple[str, ...] = field(default_factory=tuple)
    #: 95% bands of the fast-stretch torque curves (:func:`prediction_intervals`), for
    #: figures; not part of the JSON (the intervals of their peaks are).
    bands: dict[str, dict[str, tuple[FloatArray, FloatArray]]] = field(default_factory=dict)

    def fit_dict(self) -> dict[str, Any] | None:
        b = self.basis
        if b is None:
            return None
        return {"fit_id": b.fit_id, "fitted_model_id": b.fitted_model_id, "status": b.status,
                "goodness_of_fit": b.verdict, "reasons": list(b.reasons),
                "accepted_poor_fit": self.accepted_poor_fit}

    def to_dict(self) -> dict[str, Any]:
        """The parts of the what-if JSON: ``fit``, ``unidentified``, ``warnings``,
        ``intervals``."""
        return {"fit": self.fit_dict(),
                "unidentified": [g.to_dict() for g in self.guesses],
                "unseen_reflexes": list(self.notes),
                "warnings": list(self.warnings),
                "intervals": {"level": 0.95, "samples": self.n_samples,
                              "note": self.interval_note,
                              "metrics": {i.metric: i.to_dict() for i in self.intervals}}}


def check_fit(basis: FitBasis | None, accept_poor_fit: bool = False) -> str | None:
    """Refuse a poor fit unless accepted; returns the note to record when it was accepted.

    Raises
    ------
    PoorFitError
        The fit behind the model is poor and ``accept_poor_fit`` is False.
    """
    if basis is None or basis.status != "poor":
        return None
    why = "; ".join(basis.reasons) or "goodness of fit failed"
    if not accept_poor_fit:
        raise PoorFitError(
            f"the model comes from fit {basis.fit_id}, a poor fit ({why}); a prediction from "
            "it would not describe this patient. Refit (other maps, 'fieldbank fit --fit "
            "km,alpha,beta,q_rest', or with a contracture's slack length: '--fit "
            "km,alpha,beta,slack'), or give --accept-poor-fit to run it anyway (recorded in "
            "the output).")
    return f"poor fit accepted by the user (--accept-poor-fit): fit {basis.fit_id}: {why}"


def unseen_reflexes(basis: FitBasis | None, arm: Arm) -> tuple[str, ...]:
    """One sentence per group whose stretch reflex the fit held at the unimpaired value: what
    the maps cannot tell apart, and which measurement would (module docstring). ``arm``: the
    model before (its geometry sets the stretch and the direction named)."""
    if basis is None:
        return ()
    held = [r for r in basis.ranges if r.component == "dynamic"]
    if not held:
        return ()
    prior = Prior.for_arm(arm)
    free, limited = [], []
    for r in held:
        level = SCALE.level(ratio_of_score(prior.high(r), "dynamic"), "dynamic")
        if not r.limited_by_maps:
            free.append(r.group)
        elif level != "unimpaired":  # else the maps rule out any felt reflex
            limited.append((r.group, level))
    out = []
    if free:
        names = ", ".join(f"{MUSCLE_GROUP_NAMES[g]} ({g})" for g in free)
        out.append(f"the maps cannot tell a normal stretch reflex from a severe one in the "
                   f"{names}: no measured movement stretched {'it' if len(free) == 1 else 'them'}"
                   " fast where the reflex fires. What would show it:")
    for g, level in limited:
        out.append(f"the maps rule out a stretch reflex of the {MUSCLE_GROUP_NAMES[g]} ({g}) "
                   f"above {level}, but cannot tell a normal one from a {level} one. What would "
                   "show it:")
    for g in free + [g for g, _ in limited]:
        out.append(f"{g}: {reflex_test(arm, g)}")
    return tuple(out)


def acted_on(plan: Plan) -> list[tuple[int, str, str, tuple[str, ...]]]:
    """(step number, step description, what it changes, fitted parameters that size it)."""
    out = []
    for i, step in enumerate(plan.steps, 1):
        seen: dict[tuple[str, str], tuple[str, ...]] = {}
        for effect in step.EFFECTS:
            if effect not in _FORCE_OF:
                continue
            force, kinds = _FORCE_OF[effect]
            for g in step.targets():
                seen[(force, g)] = tuple(f"{k}_{g}" for k in kinds)
        for (force, g), names in seen.items():
            out.append((i, step.describe(), f"{_WHAT[force]} of {g}", names))
    return out


def guesses(basis: FitBasis | None, params: ArmParams) -> tuple[Guess, ...]:
    """The parameters the fit did not identify, valued in ``params`` (the model before)."""
    if basis is None:
        return ()
    values = _values(params)
    held = set(basis.held)
    return tuple(Guess(n, values.get(n, float("nan")), n in held, r)
                 for n, r in basis.unidentified)


def plan_warnings(plan: Plan, basis: FitBasis | None, params: ArmParams) -> tuple[str, ...]:
    """One warning per plan step and muscle group whose change rests on a guessed parameter."""
    if basis is None:
        return ()
    unid = dict(basis.unidentified)
    held = set(basis.held)
    values = _values(params)
    out = []
    for i, desc, what, names in acted_on(plan):
        guessed = [n for n in names if n in unid]
        if not guessed:
            continue
        vals = ", ".join(f"{n} = {values.get(n, float('nan')):.3g}" for n in guessed)
        how = ("held at the unimpaired value" if all(n in held for n in guessed) else
               "not identified")
        out.append(
            f"step {i} ({desc}) acts on the {what}, which fit {basis.fit_id} did not identify "
            f"({how}: {vals}): the predicted change rests on a guess, not on this patient's "
            f"maps. Why: {unid[guessed[0]]}.")
    return tuple(out)


def prediction_intervals(basis: FitBasis | None, before: Arm, plan: Plan,
                         cond: Conditions, arms: ArmCache,
                         n_samples: int = DEFAULT_INTERVAL_SAMPLES,
                         bands: dict[str, dict[str, tuple[FloatArray, FloatArray]]]
                         | None = None) -> tuple[tuple[Interval, ...], str, int]:
    """The plan applied to each of the fit's samples of the model ``before``: (intervals,
    note, samples used). ``arms`` keeps what depends on the fit and the model before only.

    ``bands``, when given, receives the 95% band of each fast-stretch torque curve before and
    after: ``{"before" | "after": {stretch name: (low, high)}}`` (N·m along the angle).
    """
    if basis is None:
        return (), "the model is not a fitted model: no fit uncertainty to carry", 0
    if basis.samples is None:
        return (), f"fit {basis.fit_id} stored no parameter samples (refit to get them)", 0
    if not basis.same_model:
        return (), (f"the model before is derived from fitted model {basis.fitted_model_id} by "
                    "earlier plans: intervals need the fitted model itself"), 0
    # what depends on the fit and the model before only is derived once per use case
    # (ArmCache.derived): a composer changing doses on one model reuses it
    p0 = before.params
    fit = (basis.fit_id, basis.fitted_model_id, basis.same_model, basis.seed, p0, n_samples)
    samples = basis.samples
    if not basis.ranges:
        plain = arms.derived(("fit samples", *fit), lambda: samples.params(p0, n_samples))
        # the model itself rides along as set 0: its metrics are the point predictions
        sm = sample_metrics([p0, *plain], plan, cond, before, memo=arms)
        note = (f"95% intervals over {len(plain)} parameter samples of fit {basis.fit_id}; "
                "the fit held no parameter at a guessed value")
        return intervals_of(sm, bands), note, len(plain)
    prior = arms.derived(("prior", p0), lambda: Prior.for_arm(before))
    # as many draws as asked for: the fit's replicates are cycled when fewer, the guesses
    # drawn afresh for each
    ranges, seed = basis.ranges, basis.seed
    guessed = arms.derived(("drawn guesses", *fit), lambda: draw(
        samples, ranges, prior, n_samples, seed=seed).params(p0))
    plain = arms.derived(("held guesses", *fit), lambda: draw(
        samples, (), prior, n_samples).params(p0))
    n = len(guessed)
    # one pass: the model (set 0), the samples with the guesses drawn (1…n), the samples with
    # the held values kept (n+1…2n)
    sm = sample_metrics([p0, *guessed, *plain], plan, cond, before, memo=arms)
    drawn = intervals_of(_rows(sm, range(0, n + 1)), bands)
    kept_bands: dict[str, dict[str, tuple[FloatArray, FloatArray]]] | None = (
        None if bands is None else {})
    kept = intervals_of(_rows(sm, [0, *range(n + 1, 2 * n + 1)]), kept_bands)
    if bands is not None and kept_bands:  # what the maps identified, drawn apart in figures
        bands.update({f"{when} {IDENTIFIED}": per for when, per in kept_bands.items()})
    out = tuple(_with_identified(a, b) for a, b in zip(drawn, kept, strict=True))
    held = ", ".join(n for r in basis.ranges for n in r.names)
    note = (f"95% intervals over {n} parameter samples of fit {basis.fit_id}; the held "
            f"parameters ({held}) drawn from their prior range (unimpaired to the top of the "
            "severe band, as far as the maps allow); * rests on them")
    return out, note, n


def _rows(sm: SampleMetrics, rows: Sequence[int]) -> SampleMetrics:
    """The parameter sets ``rows`` of ``sm`` (row 0 first: the point predictions)."""
    idx = np.asarray(list(rows), dtype=int)
    return SampleMetrics(sm.keys, sm.units, sm.before[idx], sm.after[idx],
                         {when: {name: stack[idx] for name, stack in per.items()}
                          for when, per in sm.curves.items()})


def _with_identified(drawn: Interval, kept: Interval) -> Interval:
    """``drawn`` widened to hold the intervals of what the maps identified (``kept``: the
    guesses at their held, unimpaired, end of the range - a member of the range the draws'
    percentiles may cut off), with those intervals and whether the guesses widen it by more
    than :data:`GUESS_WIDENING`."""
    drawn = replace(drawn, before_low=min(drawn.before_low, kept.before_low),
                    before_high=max(drawn.before_high, kept.before_high),
                    after_low=min(drawn.after_low, kept.after_low),
                    after_high=max(drawn.after_high, kept.after_high),
                    change_low=min(drawn.change_low, kept.change_low),
                    change_high=max(drawn.change_high, kept.change_high))
    pairs = (((drawn.before_low, drawn.before_high), (kept.before_low, kept.before_high)),
             ((drawn.after_low, drawn.after_high), (kept.after_low, kept.after_high)),
             ((drawn.change_low, drawn.change_high), (kept.change_low, kept.change_high)))
    scale = max(abs(drawn.before), abs(drawn.after), 1e-12)
    wider = any(hi - lo > GUESS_WIDENING * (khi - klo) + 1e-9 * scale
                for (lo, hi), (klo, khi) in pairs)
    ident = (kept.before_low, kept.before_high, kept.after_low, kept.after_high,
             kept.change_low, kept.change_high)
    return replace(drawn, rests_on_guess=wider, identified=ident)


def intervals_of(sm: SampleMetrics,
                 bands: dict[str, dict[str, tuple[FloatArray, FloatArray]]] | None = None
                 ) -> tuple[Interval, ...]:
    """The point predictions (set 0 of ``sm``: the model itself) with the 95% intervals of
    the samples (sets 1…S); ``bands`` receives the curves' percentile bands (see
    :func:`prediction_intervals`)."""
    lo, hi = INTERVAL_PERCENTILES
    if bands is not None and len(sm.before) > 1:
        for when, per_name in sm.curves.items():
            bands[when] = {}
            for name, stack in per_name.items():
                low, high = np.percentile(stack[1:], [lo, hi], axis=0)
                bands[when][name] = (low, high)
    pb, pa = sm.before[0], sm.after[0]
    vb, va = sm.before[1:], sm.after[1:]
    bl, bh = np.percentile(vb, [lo, hi], axis=0)
    al, ah = np.percentile(va, [lo, hi], axis=0)
    cl, ch = np.percentile(va - vb, [lo, hi], axis=0)
    return tuple(Interval(k, sm.units[i], float(pb[i]), float(pa[i]), float(bl[i]),
                          float(bh[i]), float(al[i]), float(ah[i]), float(cl[i]), float(ch[i]))
                 for i, k in enumerate(sm.keys))


@dataclass(frozen=True, eq=False)
class IntervalSet:
    """What :func:`prediction_intervals` gives for one plan on one fitted model: the
    intervals, their note, the samples used and the curve bands. Kept with the fit in the
    database (:meth:`to_document`), so a report that meets the same fit, model and plan again
    reads them instead of computing them."""

    intervals: tuple[Interval, ...]
    note: str
    n_samples: int
    bands: dict[str, dict[str, tuple[FloatArray, FloatArray]]]

    def to_document(self) -> tuple[dict[str, Any], bytes | None]:
        """A JSON document and the bands as float64 little-endian bytes (exact: read back,
        every figure and number is the same to the last bit)."""
        names = [[when, name] for when, per in self.bands.items() for name in per]
        parts = [np.asarray(side, dtype="<f8") for when, name in names
                 for side in self.bands[when][name]]
        doc = {"intervals": [{f.name: getattr(i, f.name) for f in fields(Interval)}
                             for i in self.intervals],
               "note": self.note, "n_samples": self.n_samples,
               "bands": names, "band_length": [len(p) for p in parts]}
        return doc, (b"".join(p.tobytes() for p in parts) if parts else None)

    @classmethod
    def from_document(cls, doc: Mapping[str, Any], arrays: bytes | None) -> IntervalSet:
        flat = np.frombuffer(arrays or b"", dtype="<f8").astype(float)
        bands: dict[str, dict[str, tuple[FloatArray, FloatArray]]] = {}
        at = 0
        lengths = iter(doc["band_length"])
        for when, name in doc["bands"]:
            sides = []
            for _ in range(2):
                n = next(lengths)
                sides.append(flat[at:at + n])
                at += n
            bands.setdefault(when, {})[name] = (sides[0], sides[1])
        return cls(tuple(Interval(**{**i, "identified": None if i.get("identified") is None
                                     else tuple(i["identified"])}) for i in doc["intervals"]),
                   str(doc["note"]),
                   int(doc["n_samples"]), bands)


#: Raised with every change of how intervals are computed; with
#: :data:`fieldbank.fitchoices.MODEL_VERSION` part of :func:`interval_key`. 2: the bands of what
#: the maps identified kept beside the bands with the guesses drawn.
INTERVALS_VERSION = 2
#: The suffix of a band of what the maps identified (``bands["after identified"]``): the
#: samples with the guessed parameters at their held value.
IDENTIFIED = "identified"


def interval_key(basis: FitBasis, before: ArmParams, plan: Plan, n_samples: int) -> str:
    """SHA-256 of everything :func:`prediction_intervals` depends on: the fit (its samples),
    the model before, the plan, the number of samples, the model and interval versions and
    the prior the held parameters are drawn from (:data:`fieldbank.fitting.prior.PRIOR_VERSION`,
    the fit's ranges and seed).
    A refit, another model or plan, or a new version gives another key."""
    doc = {"fit": basis.fit_id, "fitted_model": basis.fitted_model_id,
           "same_model": basis.same_model, "before": before.to_dict(), "plan": plan.to_dict(),
           "n_samples": n_samples, "model_version": MODEL_VERSION,
           "intervals_version": INTERVALS_VERSION, "prior_version": PRIOR_VERSION,
           "prior_ranges": [r.to_dict() for r in basis.ranges], "draw_seed": basis.seed}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode("utf-8")).hexdigest()


def interval_set(basis: FitBasis | None, before: Arm, plan: Plan, cond: Conditions,
                 arms: ArmCache, n_samples: int = DEFAULT_INTERVAL_SAMPLES) -> IntervalSet:
    """:func:`prediction_intervals` with its bands, as one :class:`IntervalSet`."""
    if n_samples <= 0:
        return IntervalSet((), "intervals not asked for", 0, {})
    bands: dict[str, dict[str, tuple[FloatArray, FloatArray]]] = {}
    intervals, note, used = prediction_intervals(basis, before, plan, cond, arms, n_samples,
                                                 bands)
    return IntervalSet(intervals, note, used, bands)


def examine(basis: FitBasis | None, before: Arm, plan: Plan, cond: Conditions,
            arms: ArmCache, *, accept_poor_fit: bool = False,
            n_samples: int = DEFAULT_INTERVAL_SAMPLES,
            known: IntervalSet | None = None) -> Guesses:
    """Everything above for one what-if on the model ``before`` whose fit basis is
    ``basis`` (:meth:`FitBasis.of` its source; raises :class:`PoorFitError` first); ``known``:
    its intervals read from the fit's stored documents (:func:`interval_key`, reports), used
    instead of computing them."""
    note = check_fit(basis, accept_poor_fit)
    iv = known if known is not None else interval_set(basis, before, plan, cond, arms,
                                                      n_samples)
    warn = list(plan_warnings(plan, basis, before.params))
    if note:
        warn.insert(0, note)
    return Guesses(basis, guesses(basis, before.params), tuple(warn), iv.intervals, iv.note,
                   iv.n_samples, note is not None, unseen_reflexes(basis, before),
                   bands=iv.bands)


def _values(params: ArmParams) -> dict[str, float]:
    out = {}
    for kind, attr in (("km", "km_n_per_m"), ("alpha", "alpha_n"), ("beta", "beta"),
                       ("slack", "slack_offset_m")):
        for g, v in zip(("sf", "se", "ef", "ee", "bf", "be"), getattr(params, attr),
                        strict=True):
            out[f"{kind}_{g}"] = float(v)
    out["q_rest_shoulder"], out["q_rest_elbow"] = (float(v) for v in params.q_rest_rad)
    return out


def summary_lines(g: Guesses) -> Sequence[str]:
    """Plain-text lines for the what-if: fit, guesses, warnings, intervals."""
    lines: list[str] = []
    b = g.basis
    if b is None:
        lines.append("Fit: none behind this model (no fit uncertainty, nothing guessed).")
    else:
        state = " (accepted by the user)" if g.accepted_poor_fit else ""
        lines.append(f"Fit {b.fit_id} behind the model: status {b.status}{state}; goodness of "
                     f"fit {b.verdict}")
    if g.guesses:
        lines.append(f"Parameters the fit did not identify ({len(g.guesses)}; the prediction "
                     "depends on them):")
        lines += [f"  {x.name} = {x.value:.4g}" + (" (held at unimpaired)" if x.held else "")
                  for x in g.guesses]
    lines += [f"    {n}" if n[2:4] == ": " else f"  {n[0].upper()}{n[1:]}" for n in g.notes]
    for w in g.warnings:
        lines.append(f"WARNING: {w}")
    if g.intervals:
        lines.append("")
        lines.append(f"Predicted metrics with 95% intervals ({g.interval_note}):")
        lines.append(f"  {'metric':<40}{'before':>22}{'after':>22}{'change':>24}")
        for i in g.intervals:
            lines.append(
                f"  {i.metric + ', ' + i.unit + ('*' if i.rests_on_guess else ''):<40}"
                f"{_iv(i.before, i.before_low, i.before_high):>22}"
                f"{_iv(i.after, i.after_low, i.after_high):>22}"
                f"{_iv(i.change, i.change_low, i.change_high, True):>24}")
    elif g.interval_note:
        lines.append(f"No intervals: {g.interval_note}.")
    return lines


def _iv(v: float, lo: float, hi: float, signed: bool = False) -> str:
    f = "+.2f" if signed else ".2f"
    return f"{v:{f}} [{lo:{f}}, {hi:{f}}]"
