"""Where an arm model comes from: the one place that turns what a user names into parameters.

A command names a model in one of four ways, and every command resolves it here:

* a parameter file (``--params arm.json``, schema ``fieldbank.arm-params``);
* a severity specification (``--severity elbow=severe``) on the scale of
  :mod:`fieldbank.evaluate.severity`, optionally on a synthetic body (mass, height, side);
* a stored model by id (``--model-id 5``);
* a patient code: that patient's latest fitted model, else the latest synthetic one.

The result, :class:`ModelSource`, carries the parameters with a description for read-outs and,
for stored models, the model id and patient, so lineage (plans, haptic sessions) can point at
them, the fit behind the model (:func:`fit_behind`: the fit of the model or of the fitted
model it was derived from), and the parameters that fit did not identify with its reasons, so
read-outs can say what is a guess and a what-if what the prediction rests on.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from fieldbank.errors import ParameterError, StorageError
from fieldbank.evaluate.severity import parse_severity_options, synthesize
from fieldbank.params import ArmParams
from fieldbank.storage import Database, FitRecord

#: Opens the database only when a stored model is asked for.
DatabaseOpener = Callable[[], Database]


@dataclass(frozen=True)
class ModelSource:
    """A resolved model: parameters, what it is in words, and its database identity if any."""

    params: ArmParams
    description: str
    model_id: int | None = None
    patient_code: str | None = None
    unidentified: tuple[str, ...] = ()
    guesses: tuple[str, ...] = ()
    #: The fit behind a stored model (None for files, severities, unfitted models).
    fit: FitRecord | None = field(default=None, compare=False)
    #: The fitted model that fit produced (``model_id`` itself, or an ancestor of it).
    fitted_model_id: int | None = field(default=None, compare=False)


def fit_behind(db: Database, model_id: int) -> tuple[FitRecord, int] | None:
    """The fit that produced ``model_id`` or the nearest fitted model in its lineage, with
    that fitted model's id; None when the model has no fitted ancestor."""
    for m in db.model_lineage(model_id):
        if m.origin != "fitted":
            continue
        if m.patient_code is None:
            return None
        fits = [f for f in db.list_fits(m.patient_code) if f.model_id == m.id]
        return (fits[-1], int(m.id)) if fits else None
    return None


def _unidentified_entries(fit: FitRecord) -> list[object]:
    return list(fit.result.get("unidentified", ()))


def fit_unidentified(fit: FitRecord) -> tuple[str, ...]:
    """Names of the parameters a fit did not identify."""
    return tuple(str(u["name"]) for u in _unidentified_entries(fit)
                 if isinstance(u, dict) and "name" in u)


def fit_guesses(fit: FitRecord) -> tuple[str, ...]:
    """A fit's reason for each parameter its maps did not identify (α and β of one group
    share a reason: said once)."""
    return tuple(dict.fromkeys(str(u.get("reason", u)) if isinstance(u, dict) else str(u)
                               for u in _unidentified_entries(fit)))


def _with_fit(db: Database, source: ModelSource) -> ModelSource:
    """``source`` with the fit behind it (an intervention keeps what it does not change, so a
    derived model rests on its nearest fitted ancestor's fit)."""
    assert source.model_id is not None
    found = fit_behind(db, source.model_id)
    if found is None:
        return source
    fit, fitted_id = found
    return ModelSource(source.params, source.description, source.model_id,
                       source.patient_code, fit_unidentified(fit), fit_guesses(fit), fit,
                       fitted_id)


def from_file(path: str | Path) -> ModelSource:
    return ModelSource(ArmParams.from_file(path), f"parameters {path}")


def synthetic(severity: Sequence[str] = (), *, body_mass_kg: float | None = None,
              height_m: float | None = None, side: str | None = None) -> ModelSource:
    """A synthetic arm: unimpaired anthropometric defaults with the given severities."""
    kw: dict[str, float | str] = {}
    if body_mass_kg is not None:
        kw["body_mass_kg"] = body_mass_kg
    if height_m is not None:
        kw["height_m"] = height_m
    if side is not None:
        kw["side"] = side
    base = ArmParams.from_anthropometry(**kw)  # type: ignore[arg-type]
    sev = parse_severity_options(list(severity))
    if not sev:
        return ModelSource(base, "synthetic arm (unimpaired)")
    words = ", ".join(f"{g} {lvl}" for g, lvl in sev.items())
    return ModelSource(synthesize(sev, base), f"synthetic arm ({words})")


def stored(db: Database, model_id: int) -> ModelSource:
    m = db.get_model(model_id)
    return _with_fit(db, ModelSource(m.params, f"stored {m.origin} model {m.id}"
                                     + (f" of patient {m.patient_code}" if m.patient_code
                                        else ""), int(m.id), m.patient_code))


def latest_of_patient(db: Database, patient_code: str) -> ModelSource:
    """The patient's latest fitted model, else the latest synthetic one."""
    db.get_patient(patient_code)  # a clear error for an unknown patient
    models = db.list_models(patient_code)
    for origin in ("fitted", "synthetic"):
        found = [m for m in models if m.origin == origin]
        if found:
            m = max(found, key=lambda r: r.id)
            return _with_fit(db, ModelSource(m.params,
                                             f"patient {patient_code}, {origin} model {m.id}",
                                             int(m.id), patient_code))
    raise StorageError(
        f"Patient {patient_code!r} has no fitted or synthetic model in the database; fit one "
        "first ('fieldbank fit'), or give the model with --params FILE.")


def resolve(*, params_file: str | Path | None = None, severity: Sequence[str] = (),
            model_id: int | None = None, patient: str | None = None,
            open_db: DatabaseOpener | None = None, what: str = "model",
            default: ModelSource | None = None) -> ModelSource:
    """The one model named by exactly one of the arguments.

    ``open_db`` is called (and the database closed again) only for ``model_id`` or
    ``patient``. With nothing named, ``default`` is returned if given, else an error. ``what``
    names the model in messages ("before model", ...).
    """
    named = [n for n, v in (("a parameter file", params_file), ("a severity", severity),
                            ("a model id", model_id), ("a patient", patient))
             if v not in (None, (), [], "")]
    if len(named) > 1:
        raise ParameterError(f"Give the {what} once: got {' and '.join(named)}.")
    if not named:
        if default is not None:
            return default
        raise ParameterError(f"Give the {what}: a patient, --params FILE, --severity "
                             "GROUP=LEVEL or a stored model id.")
    if params_file is not None:
        return from_file(params_file)
    if severity:
        return synthetic(severity)
    if open_db is None:
        raise ParameterError(f"The {what} is in the database, but no database was given.")
    with open_db() as db:
        if model_id is not None:
            return stored(db, model_id)
        assert patient is not None
        return latest_of_patient(db, patient)
