"""Leave-one-map-out cross-validation of a stored fit: does the fitted model generalise?

What it tests: whether the model fitted to a patient's maps predicts a map it was **not**
fitted on. For each map the fit used, the fit is repeated without it - same algorithm, seed,
fitted kinds and prior weight, read from the stored report; Gauss–Newton uncertainty with
:data:`LOO_SAMPLES` parameter draws - and the refitted model predicts the map left out. It
checks the fit, not a plan: whether a plan's prediction held is ``fieldbank validate`` without
``--loo`` (:mod:`fieldbank.interventions.validate`), and the two verdicts use different words.

Figures per map: R², RMS error (N or N/m), χ²/n against the map's sd widened by the spread of
the refit's prediction over its parameter draws (what the other maps leave open), and the
verdict of :mod:`fieldbank.fitting.quality`. Per map:

* **predicted**: the others predict it within its noise and their own uncertainty;
* **not predicted**: they do not - and why, in words: the parameters the fit without it moves
  furthest from the full fit (in SDs of the full fit: the map carries information the others
  lack, or contradicts them), and those it no longer identifies;
* **not testable**: it is the only map measured while moving. Static maps do not identify the
  stretch reflex (BRIEF §14): without it the reflex comes from the unimpaired prior, so failing
  to predict it says nothing about the fit.

Overall: *generalises* when no map is "not predicted", else *does not generalise*
(``fieldbank validate --loo`` exits with status 1 then).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from fieldbank.errors import FitError, ParameterError
from fieldbank.fitting.fitter import ArmFitter
from fieldbank.fitting.problem import map_sd
from fieldbank.fitting.quality import MapFit, map_fit
from fieldbank.fitting.records import FitStore, PatientMap
from fieldbank.fitting.space import named_values
from fieldbank.fitting.uncertainty import FitSamples
from fieldbank.maps import model_map_like
from fieldbank.model import Arm

GENERALISES = "generalises"
NOT_GENERALISED = "does not generalise"
PREDICTED = "predicted"
NOT_PREDICTED = "not predicted"
NOT_TESTABLE = "not testable"
#: Parameter draws of each refit whose predictions widen the map's sd.
LOO_SAMPLES = 40
#: A parameter moved by at least this many SDs of the full fit is named as a reason.
SHIFT_SDS = 2.0
#: At most this many moved parameters are named per map.
MAX_SHIFTS = 3
#: What the command prints above the table.
EXPLANATION = (
    "Leave-one-map-out tests whether the fitted model generalises to a map it was not fitted "
    "on: each map is left out in turn, the others are refitted and predict it (within its "
    "noise and the refit's own uncertainty). It checks the fit, not a plan ('fieldbank "
    "validate PATIENT' checks plans). Static maps do not identify the stretch reflex: the only "
    "map measured while moving cannot be predicted from static ones (not testable).")


@dataclass(frozen=True)
class Shift:
    """A parameter the fit without a map puts elsewhere: full fit, without it, and the move in
    SDs of the full fit."""

    name: str
    full: float
    without: float
    sds: float

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "full": self.full, "without": self.without, "sds": self.sds}


@dataclass(frozen=True)
class LeftOut:
    """One map left out: its figures, what the fit without it could not identify, and why it
    is or is not predicted."""

    map_id: int | str
    moving: bool
    fit: MapFit
    status_without: str
    unidentified_without: tuple[str, ...]
    note: str
    outcome: str = PREDICTED
    shifts: tuple[Shift, ...] = ()
    noise_chi2_per_value: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        f = self.fit
        return {"map_id": self.map_id, "kind": f.kind, "moving": self.moving,
                "n_values": f.n_values, "r2": f.r2, "rms_error": f.rms_residual,
                "unit": f.unit, "chi2_per_value": f.chi2_per_value,
                "noise_only_chi2_per_value": self.noise_chi2_per_value,
                "chi2_limit": f.chi2_limit, "verdict": self.outcome,
                "goodness_of_fit": f.verdict, "reasons": list(f.reasons),
                "fit_without": {"status": self.status_without,
                                "unidentified": list(self.unidentified_without),
                                "moved": [x.to_dict() for x in self.shifts]},
                "note": self.note}


@dataclass(frozen=True)
class CrossValidation:
    """Every map of a fit, left out in turn."""

    patient: str
    model_id: int | str
    maps: tuple[LeftOut, ...]

    @property
    def verdict(self) -> str:
        return (NOT_GENERALISED if any(m.outcome == NOT_PREDICTED for m in self.maps)
                else GENERALISES)

    def to_dict(self) -> dict[str, Any]:
        return {"patient": self.patient, "model_id": self.model_id, "verdict": self.verdict,
                "what_it_tests": EXPLANATION,
                "left_out": [m.to_dict() for m in self.maps]}


def latest_fitted_model(store: FitStore, patient: str) -> int | str:
    """The id of ``patient``'s latest fitted model."""
    fitted = [m for m in store.list_models(patient) if m.origin == "fitted"]
    if not fitted:
        raise FitError(f"patient {patient!r} has no fitted model: fit one first "
                       f"('fieldbank fit {patient}').")
    return max(fitted, key=lambda m: m.id).id


def cross_validate(store: FitStore, model_id: int | str,
                   progress: Callable[[str], None] | None = None) -> CrossValidation:
    """Leave each map of the fit behind ``model_id`` out in turn (module docstring).

    Raises
    ------
    FitError
        The model was not fitted, or its fit used fewer than two maps.
    """
    detail = store.get_model(model_id)
    report = detail.fit
    patient = detail.model.patient_code
    if report is None or patient is None:
        raise FitError(f"model {model_id} was not fitted to a patient's maps: nothing to "
                       "cross-validate.")
    ids = list(report.get("map_ids") or [])
    by_id = {m.map_id: m for m in store.maps_for(patient)}
    used: list[PatientMap] = [by_id[i] for i in ids if i in by_id]
    if len(used) < 2:
        raise FitError(f"the fit of model {model_id} used {len(used)} stored map(s); leaving "
                       "one out needs at least two.")
    base = store.patient_params(patient)
    kinds = tuple(report.get("fitted") or ("km", "alpha", "beta"))
    full = named_values(detail.model.params)
    full_sd = {n: float(v.get("sd", math.nan)) for n, v in (report.get("intervals") or {}).items()
               if isinstance(v, Mapping)}
    full_unid = {str(u.get("name")) for u in report.get("unidentified", [])
                 if isinstance(u, Mapping)}
    out = []
    for k, left in enumerate(used):
        others = [m.map for j, m in enumerate(used) if j != k]
        if progress:
            progress(f"leaving out map {left.map_id} ({left.map.kind}): refitting "
                     f"{len(others)} map(s)")
        fitter = ArmFitter(algorithm=str(report.get("algorithm", "mlsl+lbfgs")),
                           seed=int(report.get("seed", 0)), fit=kinds,
                           prior_weight=float(report.get("prior_weight", 1.0)),
                           uncertainty="gauss-newton", replicates=LOO_SAMPLES)
        fitter.fit(others, base)
        target = left.map.as_arm_on_handle()
        predicted = fitter.predict([target])[0].values
        sd = map_sd(target)
        spread = _prediction_spread(fitter, target)
        mf = map_fit(k, target, predicted, np.sqrt(sd**2 + spread.reshape(sd.shape) ** 2),
                     label=f"map {left.map_id}")
        noise_only = map_fit(k, target, predicted, label=f"map {left.map_id}")
        moving = target.speed_m_per_s > 0
        others_moving = any(m.speed_m_per_s > 0 for m in others)
        unid = tuple(u.name for u in fitter.unidentified_)
        shifts = _shifts(full, full_sd, named_values(fitter.params_), set(full_unid) | set(unid))
        if mf.verdict == "good":
            outcome, note = PREDICTED, ""
        elif moving and not others_moving:
            outcome = NOT_TESTABLE
            note = ("no other map was measured while moving: static maps do not identify the "
                    "stretch reflex, so the model without this map predicts the reflex from "
                    "the unimpaired prior - not a fault of the fit")
        else:
            outcome, note = NOT_PREDICTED, _why(shifts, sorted(set(unid) - full_unid))
        out.append(LeftOut(left.map_id, moving, mf, fitter.status_, unid, note, outcome,
                           shifts, noise_only.chi2_per_value))
    return CrossValidation(patient, model_id, tuple(out))


def _prediction_spread(fitter: ArmFitter, target: Any) -> np.ndarray:
    """SD over the refit's parameter draws of its prediction of ``target``, shaped like it."""
    samples = FitSamples.from_report({"samples": fitter.uncertainty_detail_.samples_dict()})
    if samples is None or samples.values.shape[0] < 2:
        return np.zeros(target.values.shape)
    arm = Arm.from_params(fitter.params_)
    ys = []
    for p in samples.params(fitter.params_):
        try:  # samples differ in muscle values only, unless q_rest was fitted
            arm_p = arm.with_muscles(p)
        except ParameterError:
            arm_p = Arm.from_params(p)
        ys.append(model_map_like(arm_p, target).values)
    return np.asarray(np.std(np.array(ys), axis=0, ddof=1))


def _shifts(full: dict[str, float], sd: dict[str, float], without: dict[str, float],
            unidentified: set[str]) -> tuple[Shift, ...]:
    """Identified parameters the fit without the map moves by ≥ :data:`SHIFT_SDS` SDs of the
    full fit, largest first (at most :data:`MAX_SHIFTS`)."""
    moved = []
    for name, v in full.items():
        s = sd.get(name, math.nan)
        if name in unidentified or not s or not math.isfinite(s):
            continue
        z = (without[name] - v) / s
        if abs(z) >= SHIFT_SDS:
            moved.append(Shift(name, v, without[name], z))
    moved.sort(key=lambda x: -abs(x.sds))
    return tuple(moved[:MAX_SHIFTS])


def _why(shifts: tuple[Shift, ...], lost: list[str]) -> str:
    parts = []
    if shifts:
        moved = ", ".join(f"{x.name} {x.full:.3g} → {x.without:.3g} ({x.sds:+.1f} SD)"
                          for x in shifts)
        parts.append(f"without this map the fit moves {moved}: the other maps determine these "
                     "less well than this map measures them, or disagree with it")
    if lost:
        parts.append(f"without it the fit no longer identifies {', '.join(lost)}")
    if not parts:
        parts.append("the fit without it stays within its SDs, yet misses this map by more "
                     "than its noise: the maps disagree (a map measured differently, or a "
                     "model that does not describe the arm there)")
    return "; ".join(parts)
