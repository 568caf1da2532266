"""Where an arm model comes from: the one place that turns what a user names into parameters.

A command names a model in one of four ways, and every command resolves it here:

* a parameter file (``--params arm.json``, schema ``fieldbank.arm-params``);
* a severity specification (``--severity elbow=severe``) on the scale of
  :mod:`fieldbank.evaluate.severity`, optionally on a synthetic body (mass, height, side);
* a stored model by id (``--model-id 5``);
* a patient code: that patient's fitted model of the latest measured session (``session``:
  of that session), else the latest synthetic one.

The result, :class:`ModelSource`, carries the parameters with a description for read-outs and,
for stored models, the model id and patient, so lineage (plans, haptic sessions) can point at
them, the fit behind the model (:func:`fit_behind`: the fit of the model or of the fitted
model it was derived from), and the parameters that fit did not identify with its reasons, so
read-outs can say what is a guess and a what-if what the prediction rests on. A fitted model
also says what it stands on (:class:`FittedOn`): the session and date of the maps it was
fitted to, the plans given to the patient before they were measured (the arm is already under
them), and the patient's other fitted sessions - so a read-out never silently moves from the
arm before a plan to the arm after it when a later session is fitted
(:func:`default_changes`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import date
from pathlib import Path

from fieldbank.errors import ParameterError, StorageError
from fieldbank.evaluate.severity import parse_severity_options, synthesize
from fieldbank.params import ArmParams
from fieldbank.storage import Database, FitRecord, StoredModel

#: Opens the database only when a stored model is asked for.
DatabaseOpener = Callable[[], Database]


@dataclass(frozen=True)
class GivenPlan:
    """A plan recorded as given to the patient (id, its label, the day)."""

    plan_id: int
    label: str
    given_on: date


@dataclass(frozen=True)
class FittedOn:
    """What a fitted model stands on.

    Attributes
    ----------
    fit_id : int
        The fit that made it.
    sessions : tuple of str
        The sessions of the maps it was fitted to.
    measured_on : date or None
        The latest date of those sessions (None: undated).
    under_plans : tuple of GivenPlan
        Plans given to the patient before that date: the arm the maps measured is already
        under them.
    others : tuple of (str, int)
        The patient's other fitted sessions and their fitted models (``--session`` chooses).
    """

    fit_id: int
    sessions: tuple[str, ...]
    measured_on: date | None
    under_plans: tuple[GivenPlan, ...] = ()
    others: tuple[tuple[str, int], ...] = ()

    def short(self) -> str:
        """'session post-BoNT, 2024-02-21'."""
        when = f", {self.measured_on.isoformat()}" if self.measured_on else ", undated"
        return f"session {', '.join(self.sessions) or '?'}{when}"

    def lines(self) -> list[str]:
        """What a read-out says first, in words (unwrapped)."""
        out = [f"fitted (fit {self.fit_id}) to the maps of {self.short()}"]
        for p in self.under_plans:
            out.append(f"already under plan {p.plan_id} (given {p.given_on.isoformat()}: "
                       f"{p.label}): these maps were measured after it, so the prediction "
                       "starts from the arm after that plan")
        if self.others:
            out.append("other fitted sessions: " + ", ".join(
                f"{label} (model {mid})" for label, mid in self.others)
                + "; --session LABEL chooses")
        return out

    def to_dict(self) -> dict[str, object]:
        return {"fit_id": self.fit_id, "sessions": list(self.sessions),
                "measured_on": None if self.measured_on is None else
                self.measured_on.isoformat(),
                "under_plans": [{"plan_id": p.plan_id, "label": p.label,
                                 "given_on": p.given_on.isoformat()} for p in self.under_plans],
                "other_sessions": [{"session": label, "model_id": mid}
                                   for label, mid in self.others]}


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
    #: What that fitted model stands on (sessions, dates, plans given before them).
    fitted_on: FittedOn | None = field(default=None, compare=False)

    def to_dict(self) -> dict[str, object]:
        """The model in a JSON document: what it is, its ids and what it stands on."""
        return {"source": self.description, "model_id": self.model_id,
                "patient": self.patient_code, "fitted_model_id": self.fitted_model_id,
                "fitted_on": None if self.fitted_on is None else self.fitted_on.to_dict()}


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


@dataclass(frozen=True)
class _Fitted:
    """A patient's fitted model with its latest fit and the sessions of that fit's maps."""

    model: StoredModel
    fit: FitRecord | None
    sessions: tuple[str, ...]
    measured_on: date | None


def _fitted_models(db: Database, patient_code: str) -> list[_Fitted]:
    """Every fitted model of the patient, oldest first, with its latest fit's sessions (none
    for a model stored as fitted without a fit record)."""
    maps = {m.id: (m.session_label, m.session_date) for m in db.list_maps(patient_code)}
    fits: dict[int, FitRecord] = {f.model_id: f for f in db.list_fits(patient_code)}
    out = []
    for m in db.list_models(patient_code, origin="fitted"):
        fit = fits.get(int(m.id))
        if fit is None:
            out.append(_Fitted(m, None, (), None))
            continue
        seen = [maps[i] for i in fit.map_ids if i in maps]
        sessions = tuple(dict.fromkeys(label for label, _ in seen)) or (
            (fit.session_label,) if fit.session_label else ())
        dates = [d for _, d in seen if d is not None]
        out.append(_Fitted(m, fit, sessions, max(dates) if dates else None))
    return out


def _fitted_on(db: Database, patient_code: str, fitted_id: int,
               candidates: list[_Fitted] | None = None) -> FittedOn | None:
    """What the fitted model ``fitted_id`` stands on (None when it has no fit)."""
    cands = _fitted_models(db, patient_code) if candidates is None else candidates
    me = next((c for c in cands if c.model.id == fitted_id), None)
    if me is None or me.fit is None:
        return None
    under = tuple(GivenPlan(int(p.id), p.label, p.given_on)
                  for p in db.list_plans(patient_code)
                  if p.given_on is not None and me.measured_on is not None
                  and p.given_on < me.measured_on)
    latest: dict[str, int] = {}
    for c in cands:
        if c.model.id != fitted_id and c.sessions and c.sessions != me.sessions:
            latest[", ".join(c.sessions)] = int(c.model.id)
    return FittedOn(int(me.fit.id), me.sessions, me.measured_on, under,
                    tuple(latest.items()))


def _with_fit(db: Database, source: ModelSource,
              candidates: list[_Fitted] | None = None) -> ModelSource:
    """``source`` with the fit behind it (an intervention keeps what it does not change, so a
    derived model rests on its nearest fitted ancestor's fit) and what that fit stands on."""
    assert source.model_id is not None
    found = fit_behind(db, source.model_id)
    if found is None:
        return source
    fit, fitted_id = found
    on = (_fitted_on(db, source.patient_code, fitted_id, candidates)
          if source.patient_code else None)
    return ModelSource(source.params, source.description, source.model_id,
                       source.patient_code, fit_unidentified(fit), fit_guesses(fit), fit,
                       fitted_id, on)


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


def latest_of_patient(db: Database, patient_code: str,
                      session: str | None = None) -> ModelSource:
    """The patient's fitted model of the latest measured session (by the maps' date, then
    the newest model), or of ``session``; else, without ``session``, the latest synthetic
    model. What the model stands on is in :attr:`ModelSource.fitted_on`."""
    db.get_patient(patient_code)  # a clear error for an unknown patient
    fitted = _fitted_models(db, patient_code)
    if session is not None:
        mine = [c for c in fitted if session in c.sessions]
        if not mine:
            held = ", ".join(f"{', '.join(c.sessions)} (model {c.model.id})" for c in fitted)
            raise StorageError(
                f"Patient {patient_code!r} has no model fitted to session {session!r}"
                + (f"; fitted: {held}" if held else "; no fitted model yet")
                + f". Fit one with 'fieldbank fit {patient_code} --session {session}'.")
        chosen = max(mine, key=lambda c: (c.sessions == (session,), c.model.id))
    elif fitted:
        chosen = max(fitted, key=lambda c: (c.measured_on or date.min, c.model.id))
    else:
        synthetic_models = db.list_models(patient_code, origin="synthetic")
        if not synthetic_models:
            raise StorageError(
                f"Patient {patient_code!r} has no fitted or synthetic model in the database; "
                "fit one first ('fieldbank fit'), or give the model with --params FILE.")
        m = max(synthetic_models, key=lambda r: r.id)
        return _with_fit(db, ModelSource(m.params, f"patient {patient_code}, synthetic model "
                                         f"{m.id}", int(m.id), patient_code))
    m = chosen.model
    return _with_fit(db, ModelSource(m.params, f"patient {patient_code}, fitted model {m.id}",
                                     int(m.id), patient_code), fitted)


def patient_defaults(db: Database, patient_codes: Sequence[str]) -> dict[str, int | None]:
    """The model each patient's code stands for in a command (:func:`latest_of_patient`):
    code -> model id (None: none yet)."""
    out: dict[str, int | None] = {}
    for code in patient_codes:
        try:
            out[code] = latest_of_patient(db, code).model_id
        except StorageError:
            out[code] = None
    return out


def default_changes(db: Database, before: dict[str, int | None]) -> list[str]:
    """A line for every patient whose code now stands for another model than ``before``
    (:func:`patient_defaults` taken before a fit): which, what it stands on, how to choose."""
    lines = []
    for code, old in before.items():
        try:
            new = latest_of_patient(db, code)
        except StorageError:  # still no model (every fit of the patient failed)
            continue
        if new.model_id == old or new.fitted_on is None:
            continue
        prev = _fitted_on(db, code, old) if old is not None else None
        under = new.fitted_on.under_plans
        line = (f"{code}: 'fieldbank whatif {code}' (every command naming the patient) now "
                f"starts from model {new.model_id} ({new.fitted_on.short()}"
                + (f"; already under plan {', '.join(str(p.plan_id) for p in under)}"
                   if under else "") + ")")
        if old is not None:
            line += f", not model {old}" + (f" ({prev.short()})" if prev else "")
            if prev is not None and prev.sessions and prev.sessions != new.fitted_on.sessions:
                line += f": --session {prev.sessions[0]} chooses it"
        lines.append(line + ".")
    return lines


def resolve(*, params_file: str | Path | None = None, severity: Sequence[str] = (),
            model_id: int | None = None, patient: str | None = None,
            open_db: DatabaseOpener | None = None, what: str = "model",
            default: ModelSource | None = None, session: str | None = None) -> ModelSource:
    """The one model named by exactly one of the arguments.

    ``open_db`` is called (and the database closed again) only for ``model_id`` or
    ``patient``. With nothing named, ``default`` is returned if given, else an error. ``what``
    names the model in messages ("before model", ...). ``session`` chooses a patient's
    model fitted to that session (:func:`latest_of_patient`).
    """
    if session is not None and patient is None:
        raise ParameterError("A session chooses among a patient's fitted models: give the "
                             "patient.")
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
        return latest_of_patient(db, patient, session)
