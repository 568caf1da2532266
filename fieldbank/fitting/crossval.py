"""Leave-one-map-out cross-validation of a stored fit: does the fitted model generalise?

For each map the fit used, the fit is repeated without it - same algorithm, seed, fitted kinds
and prior weight, read from the stored report; Gauss–Newton uncertainty, since only the
prediction is needed - and the refitted model predicts the map left out. Figures per map: R²,
RMS error (N or N/m), χ²/n against the map's sd and the verdict of
:mod:`fieldbank.fitting.quality`. A map the others cannot predict fails the check
("prediction failed"); when it is the only map measured while moving, the reason says so:
static maps do not identify the stretch reflex (BRIEF §14), so the model without it predicts
the reflex from the unimpaired prior.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from fieldbank.errors import FitError
from fieldbank.fitting.fitter import ArmFitter
from fieldbank.fitting.quality import MapFit, map_fit
from fieldbank.fitting.records import FitStore, PatientMap

GENERALISES = "generalises"
FAILED = "prediction failed"


@dataclass(frozen=True)
class LeftOut:
    """One map left out: its figures, and what the fit without it could not identify."""

    map_id: int | str
    moving: bool
    fit: MapFit
    status_without: str
    unidentified_without: tuple[str, ...]
    note: str

    def to_dict(self) -> dict[str, Any]:
        f = self.fit
        return {"map_id": self.map_id, "kind": f.kind, "moving": self.moving,
                "n_values": f.n_values, "r2": f.r2, "rms_error": f.rms_residual,
                "unit": f.unit, "chi2_per_value": f.chi2_per_value,
                "chi2_limit": f.chi2_limit, "verdict": f.verdict, "reasons": list(f.reasons),
                "fit_without": {"status": self.status_without,
                                "unidentified": list(self.unidentified_without)},
                "note": self.note}


@dataclass(frozen=True)
class CrossValidation:
    """Every map of a fit, left out in turn."""

    patient: str
    model_id: int | str
    maps: tuple[LeftOut, ...]

    @property
    def verdict(self) -> str:
        return FAILED if any(m.fit.verdict == "poor" for m in self.maps) else GENERALISES

    def to_dict(self) -> dict[str, Any]:
        return {"patient": self.patient, "model_id": self.model_id, "verdict": self.verdict,
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
    out = []
    for k, left in enumerate(used):
        others = [m.map for j, m in enumerate(used) if j != k]
        if progress:
            progress(f"leaving out map {left.map_id} ({left.map.kind}): refitting "
                     f"{len(others)} map(s)")
        fitter = ArmFitter(algorithm=str(report.get("algorithm", "mlsl+lbfgs")),
                           seed=int(report.get("seed", 0)), fit=kinds,
                           prior_weight=float(report.get("prior_weight", 1.0)),
                           uncertainty="gauss-newton", replicates=2)
        fitter.fit(others, base)
        target = left.map.as_arm_on_handle()
        predicted = fitter.predict([target])[0].values
        mf = map_fit(k, target, predicted, label=f"map {left.map_id}")
        moving = target.speed_m_per_s > 0
        others_moving = any(m.speed_m_per_s > 0 for m in others)
        note = ""
        if moving and not others_moving:
            note = ("no other map was measured while moving: static maps do not identify the "
                    "stretch reflex, so the model without this map predicts the reflex from "
                    "the unimpaired prior")
        out.append(LeftOut(left.map_id, moving, mf, fitter.status_,
                           tuple(u.name for u in fitter.unidentified_), note))
    return CrossValidation(patient, model_id, tuple(out))
