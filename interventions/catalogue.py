"""The intervention catalogue (BRIEF §7): each clinical act as a frozen, validated value.

Every intervention is a frozen dataclass with

* ``kind`` - its tag in plan documents ('botulinum', 'lengthening', 'tenotomy', 'rhizotomy',
  'baclofen', 'casting');
* ``apply(params) -> ArmParams`` - a new parameter set; the input is never changed;
* ``to_dict()`` / ``from_dict()`` - the JSON form, tagged with ``kind``;
* ``targets()`` - the muscle groups it acts on;
* ``EFFECTS`` - the documented direction of the change per parameter of a target group
  ('down', 'up'); every other parameter stays as it was. The contract tests check this;
* ``BOUNDS`` - the allowed range of each numeric field (:class:`fieldbank.validation.Interval`),
  the one table the messages are generated from.

Mapping onto model parameters (defaults and sources in :mod:`interventions.defaults`):

==============  =================================================================================
botulinum       α of each injected group × (1 - e), e = E_peak(dose) · s(weeks since); β stays
                (the toxin blocks the neuromuscular junction; the reflex gain is the spinal
                circuit's). Doses in onabotulinumtoxinA (Botox®) units
lengthening     slack offset of the group + Δ (passive onset moves by Δ); α × a force-length
                factor exp(-(Δ / (c · L_f))²)
tenotomy        Km and α of the group × residual fraction (default 0: force capacity 0)
rhizotomy       β of the chosen groups (default all) × factor
baclofen        β of the chosen groups (default all) × factor
casting         slack offset of the group + Δ, Km × factor
==============  =================================================================================

Bad values raise :class:`fieldbank.interventions.errors.InterventionError` naming the
intervention, every bad field and the reason; a plan adds the step number.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, ClassVar, TypeVar, cast

from fieldbank.errors import ParameterError
from fieldbank.interventions.defaults import DOSE_UNIT, TOXIN, value
from fieldbank.interventions.errors import InterventionError
from fieldbank.interventions.timecourse import dose_effect, shape_exponent, time_shape
from fieldbank.params import GROUP_INDEX, GROUP_LEGEND, GROUPS, ArmParams
from fieldbank.validation import Interval, bound_problem


def _known_groups() -> str:
    return GROUP_LEGEND


def _check_bounds(problems: list[str], obj: Intervention, skip: tuple[str, ...] = ()) -> None:
    """Every field of ``obj``'s BOUNDS table outside its range, and every field at its
    NO_CHANGE value (an optional field left at None is not checked)."""
    optional = {f.name for f in fields(obj) if f.default is None}
    for name, interval in obj.BOUNDS.items():
        v = getattr(obj, name)
        if name in skip or (v is None and name in optional):
            continue
        msg = bound_problem(name, v, interval)
        if msg is None and name in obj.NO_CHANGE and v == obj.NO_CHANGE[name]:
            n = obj.NO_CHANGE[name]
            msg = f"'{name}' must be < {n:g} ({n:g} would change nothing)"
        if msg is not None:
            problems.append(msg)


def _check_group(problems: list[str], name: str, g: Any) -> None:
    if not isinstance(g, str) or g not in GROUP_INDEX:
        problems.append(f"unknown muscle group {g!r} in '{name}' (known: {_known_groups()})")


def _raise(kind: str, problems: list[str]) -> None:
    if problems:
        raise InterventionError(f"{kind}: " + "; ".join(problems) + ".")


def _scaled(params: ArmParams, name: str, factors: Mapping[str, float]) -> tuple[float, ...]:
    row = [float(v) for v in getattr(params, name)]
    for g, f in factors.items():
        row[GROUP_INDEX[g]] *= f
    return tuple(row)


def _shifted(params: ArmParams, name: str, deltas: Mapping[str, float]) -> tuple[float, ...]:
    row = [float(v) for v in getattr(params, name)]
    for g, d in deltas.items():
        row[GROUP_INDEX[g]] += d
    return tuple(row)


def _replace(kind: str, params: ArmParams, **changes: Any) -> ArmParams:
    try:
        return params.replace(**changes)
    except ParameterError as exc:
        raise InterventionError(f"{kind}: the resulting model is invalid: {exc}") from None


@dataclass(frozen=True)
class Intervention:
    """Base of the catalogue: JSON form and the common contract."""

    kind: ClassVar[str] = ""
    EFFECTS: ClassVar[dict[str, str]] = {}
    #: field -> allowed range (messages generated from it, :func:`_check_bounds`)
    BOUNDS: ClassVar[dict[str, Interval]] = {}
    #: field -> the value inside its range at which the intervention would change nothing
    #: (refused: a plan step that does nothing is a mistake)
    NO_CHANGE: ClassVar[dict[str, float]] = {}

    def apply(self, params: ArmParams) -> ArmParams:  # pragma: no cover - abstract
        raise NotImplementedError

    def targets(self) -> tuple[str, ...]:  # pragma: no cover - abstract
        raise NotImplementedError

    def describe(self) -> str:  # pragma: no cover - abstract
        raise NotImplementedError

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"kind": self.kind}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "units":
                v = dict(v)
            elif isinstance(v, tuple):
                v = list(v)
            d[f.name] = v
        return d

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Intervention:
        """Build from the JSON form; unknown keys and a wrong ``kind`` are refused."""
        if not isinstance(data, Mapping):
            raise InterventionError(f"expected a JSON object; got {type(data).__name__}.")
        kind = data.get("kind")
        if not isinstance(kind, str) or kind not in KINDS:
            raise InterventionError(
                f"unknown intervention kind {kind!r} (known: {', '.join(KINDS)})."
            )
        sub = KINDS[kind]
        if cls is not Intervention and sub is not cls:
            raise InterventionError(f"expected kind {cls.kind!r}; got {kind!r}.")
        names = {f.name for f in fields(sub)}
        body = {k: v for k, v in data.items() if k != "kind"}
        unknown = sorted(set(body) - names)
        if unknown:
            raise InterventionError(
                f"{kind}: unknown field(s) {', '.join(map(repr, unknown))} "
                f"(known: {', '.join(sorted(names))})."
            )
        for k, v in list(body.items()):
            if isinstance(v, list):
                body[k] = tuple(v)
        try:
            return sub(**body)
        except TypeError as exc:  # a missing required field
            raise InterventionError(f"{kind}: {exc}.") from None


@dataclass(frozen=True)
class OneGroup(Intervention):
    """An intervention on one muscle group (``group``): the group and the fields of its
    bounds table checked together, every problem in one error."""

    group: str = ""

    def __post_init__(self) -> None:
        problems: list[str] = []
        _check_group(problems, "group", self.group)
        _check_bounds(problems, self)
        _raise(self.kind, problems)

    def targets(self) -> tuple[str, ...]:
        return (self.group,)


# --- botulinum toxin A -----------------------------------------------------------------------
@dataclass(frozen=True)
class Botulinum(Intervention):
    """Botulinum toxin A into one or more groups (one injection session).

    Parameters
    ----------
    units : mapping group -> dose, onabotulinumtoxinA (Botox®) units
        Units injected into each muscle group (e.g. ``{'ef': 200}``); stored as sorted pairs.
    toxin : str
        The product the units count: only onabotulinumtoxinA. AbobotulinumtoxinA (Dysport®)
        and other products' units are not interchangeable with it (≈ 2.5-3 : 1 is only an
        assumption), so they are refused rather than converted.
    weeks_since : float, weeks
        Time from the injection to the moment the model describes.
    emax, ed50_units, hill : float
        Emax dose → peak-effect curve (assumption).
    peak_week, wearoff_week, wearoff_fraction : float
        Time course (see :mod:`interventions.timecourse`).
    scale_beta : bool
        Also scale the reflex gain β. Default false (BRIEF §7: the toxin acts on the muscle's
        force, α; scaling β as well counts the effect twice). True only reproduces plans stored
        before that recalibration, whose documents carry it.
    """

    kind: ClassVar[str] = "botulinum"
    EFFECTS: ClassVar[dict[str, str]] = {"alpha_n": "down"}
    BOUNDS: ClassVar[dict[str, Interval]] = {
        "units": Interval(0.0, value("botulinum.max_units_per_group"), "U"),  # per group
        "weeks_since": Interval(0.0, value("botulinum.max_weeks"), "weeks"),
        "emax": Interval(0.0, 0.99),
        "ed50_units": Interval(0.0, None, "U", low_closed=False),
        "hill": Interval(0.1, 10.0),
        "peak_week": Interval(0.0, None, "weeks", low_closed=False),
        "wearoff_week": Interval(0.0, None, "weeks", low_closed=False),
        "wearoff_fraction": Interval(0.0, 1.0, low_closed=False),
    }

    units: tuple[tuple[str, float], ...] | Mapping[str, float] = ()
    toxin: str = TOXIN
    weeks_since: float = value("botulinum.weeks_since")
    emax: float = value("botulinum.emax")
    ed50_units: float = value("botulinum.ed50_units")
    hill: float = value("botulinum.hill")
    peak_week: float = value("botulinum.peak_week")
    wearoff_week: float = value("botulinum.wearoff_week")
    wearoff_fraction: float = value("botulinum.wearoff_fraction")
    scale_beta: bool = False

    def __post_init__(self) -> None:
        problems: list[str] = []
        raw = self.units
        pairs: list[tuple[str, float]] = []
        if isinstance(raw, Mapping):
            items = list(raw.items())
        elif isinstance(raw, (tuple, list)) and all(
            isinstance(p, (tuple, list)) and len(p) == 2 for p in raw
        ):
            items = [(p[0], p[1]) for p in raw]
        else:
            items = []
            problems.append(f"'units' must map muscle groups to doses in U; got {raw!r}")
        if not items and not problems:
            problems.append("'units' names no muscle group; inject at least one")
        seen: set[str] = set()
        for g, u in items:
            _check_group(problems, "units", g)
            if g in seen:
                problems.append(f"muscle group {g!r} appears twice in 'units'")
            seen.add(g)
            msg = bound_problem(f"units[{g}]", u, self.BOUNDS["units"])
            if msg is not None:
                problems.append(msg)
            if isinstance(g, str) and g in GROUP_INDEX and isinstance(u, (int, float)):
                pairs.append((g, float(u)))
        _check_bounds(problems, self, skip=("units",))
        if self.toxin != TOXIN:
            problems.append(
                f"'toxin' {self.toxin!r}: doses are {TOXIN} (Botox®) units only; "
                "abobotulinumtoxinA (Dysport®) and other products' units are not "
                "interchangeable with them (≈ 2.5-3 : 1 is an assumption, not a conversion "
                "this program makes): give the dose in onabotulinumtoxinA units")
        if not isinstance(self.scale_beta, bool):
            problems.append(f"'scale_beta' must be true or false; got {self.scale_beta!r}")
        if not problems:
            try:
                shape_exponent(self.peak_week, self.wearoff_week, self.wearoff_fraction)
            except InterventionError as exc:
                problems.append(str(exc).split(": ", 1)[-1].rstrip("."))
        _raise(self.kind, problems)
        pairs.sort(key=lambda p: GROUP_INDEX[p[0]])
        object.__setattr__(self, "units", tuple(pairs))
        for name in ("weeks_since", "emax", "ed50_units", "hill", "peak_week", "wearoff_week",
                     "wearoff_fraction"):
            object.__setattr__(self, name, float(getattr(self, name)))

    @property
    def doses(self) -> dict[str, float]:
        """Units per group, U (after construction ``units`` is always sorted pairs)."""
        return dict(cast("tuple[tuple[str, float], ...]", self.units))

    def targets(self) -> tuple[str, ...]:
        return tuple(self.doses)

    def effect(self, weeks: float | None = None) -> dict[str, float]:
        """Fractional force drop e per injected group at ``weeks`` (default weeks_since)."""
        t = self.weeks_since if weeks is None else weeks
        s = float(time_shape(t, self.peak_week, self.wearoff_week, self.wearoff_fraction))
        return {
            g: float(dose_effect(u, self.emax, self.ed50_units, self.hill)) * s
            for g, u in self.doses.items()
        }

    def at_week(self, weeks: float) -> Botulinum:
        """The same injection seen ``weeks`` after it was given."""
        return _copy(self, weeks_since=float(weeks))

    def apply(self, params: ArmParams) -> ArmParams:
        keep = {g: 1.0 - e for g, e in self.effect().items()}
        changes: dict[str, Any] = {"alpha_n": _scaled(params, "alpha_n", keep)}
        if self.scale_beta:
            changes["beta"] = _scaled(params, "beta", keep)
        return _replace(self.kind, params, **changes)

    def total_units(self) -> float:
        """Units of the whole injection session, onabotulinumtoxinA (Botox®) units."""
        return float(sum(self.doses.values()))

    def describe(self) -> str:
        doses = ", ".join(f"{g} {u:g} U" for g, u in self.doses.items())
        return (f"botulinum toxin A ({doses}; {DOSE_UNIT}), {self.weeks_since:g} weeks after "
                "injection")


# --- lengthening -----------------------------------------------------------------------------
@dataclass(frozen=True)
class Lengthening(OneGroup):
    """Tendon or muscle lengthening surgery of one group by ``delta_m``.

    The passive onset moves by Δ (slack offset + Δ). The reflex force capacity α drops by the
    force-length factor exp(-(Δ / (c · L_f))²) unless ``alpha_factor`` is given.
    """

    kind: ClassVar[str] = "lengthening"
    EFFECTS: ClassVar[dict[str, str]] = {"slack_offset_m": "up", "alpha_n": "down"}
    BOUNDS: ClassVar[dict[str, Interval]] = {
        "delta_m": Interval(0.0, value("lengthening.max_delta_m"), "m", low_closed=False),
        "alpha_factor": Interval(0.0, 1.0),
        "fibre_length_m": Interval(0.0, 0.5, "m", low_closed=False),
        "width_factor": Interval(0.0, 10.0, low_closed=False),
    }

    delta_m: float = 0.0
    alpha_factor: float | None = None
    fibre_length_m: float = value("lengthening.fibre_length_m")
    width_factor: float = value("lengthening.width_factor")


    def force_factor(self) -> float:
        """Multiplier on α: the given ``alpha_factor`` or the force-length default."""
        if self.alpha_factor is not None:
            return float(self.alpha_factor)
        return math.exp(-((self.delta_m / (self.width_factor * self.fibre_length_m)) ** 2))

    def apply(self, params: ArmParams) -> ArmParams:
        return _replace(
            self.kind, params,
            slack_offset_m=_shifted(params, "slack_offset_m", {self.group: self.delta_m}),
            alpha_n=_scaled(params, "alpha_n", {self.group: self.force_factor()}),
        )

    def describe(self) -> str:
        return (f"lengthening of {self.group} by {self.delta_m * 100:g} cm "
                f"(α × {self.force_factor():.3g})")


# --- tenotomy --------------------------------------------------------------------------------
@dataclass(frozen=True)
class Tenotomy(OneGroup):
    """Tenotomy or release of one group: Km and α × residual fraction (default 0)."""

    kind: ClassVar[str] = "tenotomy"
    EFFECTS: ClassVar[dict[str, str]] = {"km_n_per_m": "down", "alpha_n": "down"}
    BOUNDS: ClassVar[dict[str, Interval]] = {
        "residual_fraction": Interval(0.0, 1.0),
    }
    NO_CHANGE: ClassVar[dict[str, float]] = {"residual_fraction": 1.0}

    residual_fraction: float = value("tenotomy.residual_fraction")


    def apply(self, params: ArmParams) -> ArmParams:
        f = {self.group: float(self.residual_fraction)}
        return _replace(self.kind, params, km_n_per_m=_scaled(params, "km_n_per_m", f),
                        alpha_n=_scaled(params, "alpha_n", f))

    def describe(self) -> str:
        return f"tenotomy / release of {self.group} (Km, α × {self.residual_fraction:g})"


# --- reflex reduction --------------------------------------------------------------------------
@dataclass(frozen=True)
class _ReflexReduction(Intervention):
    """β of the chosen groups (default: all six) × ``factor``."""

    EFFECTS: ClassVar[dict[str, str]] = {"beta": "down"}
    BOUNDS: ClassVar[dict[str, Interval]] = {
        "factor": Interval(0.0, 1.0),
    }
    NO_CHANGE: ClassVar[dict[str, float]] = {"factor": 1.0}

    groups: tuple[str, ...] = GROUPS
    factor: float = 0.5

    def __post_init__(self) -> None:
        problems: list[str] = []
        groups = self.groups
        if isinstance(groups, str):
            groups = (groups,)
        if not isinstance(groups, (tuple, list)) or not groups:
            problems.append(f"'groups' must list at least one muscle group; got {groups!r}")
            groups = ()
        for g in groups:
            _check_group(problems, "groups", g)
        if len(set(groups)) != len(groups):
            problems.append("'groups' names a muscle group twice")
        _check_bounds(problems, self)
        _raise(self.kind, problems)
        object.__setattr__(self, "groups",
                           tuple(sorted(groups, key=lambda g: GROUP_INDEX[g])))
        object.__setattr__(self, "factor", float(self.factor))

    def targets(self) -> tuple[str, ...]:
        return tuple(self.groups)

    def apply(self, params: ArmParams) -> ArmParams:
        return _replace(self.kind, params,
                        beta=_scaled(params, "beta", dict.fromkeys(self.groups, self.factor)))

    def describe(self) -> str:
        which = "all groups" if tuple(self.groups) == GROUPS else ", ".join(self.groups)
        return f"{self.kind} (β × {self.factor:g} in {which})"


@dataclass(frozen=True)
class Rhizotomy(_ReflexReduction):
    """Selective dorsal rhizotomy: stretch-reflex gain β × factor (assumption 0.5)."""

    kind: ClassVar[str] = "rhizotomy"
    factor: float = value("rhizotomy.beta_factor")


@dataclass(frozen=True)
class Baclofen(_ReflexReduction):
    """Intrathecal baclofen: stretch-reflex gain β × factor (assumption 0.6)."""

    kind: ClassVar[str] = "baclofen"
    factor: float = value("baclofen.beta_factor")


# --- serial casting --------------------------------------------------------------------------
@dataclass(frozen=True)
class SerialCasting(OneGroup):
    """Serial casting / sustained stretch of one group: slack + Δ, Km × factor."""

    kind: ClassVar[str] = "casting"
    EFFECTS: ClassVar[dict[str, str]] = {"slack_offset_m": "up", "km_n_per_m": "down"}
    BOUNDS: ClassVar[dict[str, Interval]] = {
        "delta_m": Interval(0.0, 0.02, "m", low_closed=False),
        "km_factor": Interval(0.0, 1.0, low_closed=False),
    }

    delta_m: float = value("casting.delta_m")
    km_factor: float = value("casting.km_factor")


    def apply(self, params: ArmParams) -> ArmParams:
        return _replace(
            self.kind, params,
            slack_offset_m=_shifted(params, "slack_offset_m", {self.group: self.delta_m}),
            km_n_per_m=_scaled(params, "km_n_per_m", {self.group: self.km_factor}),
        )

    def describe(self) -> str:
        return (f"serial casting of {self.group} (+{self.delta_m * 1000:g} mm slack, "
                f"Km × {self.km_factor:g})")


_I = TypeVar("_I", bound=Intervention)

KINDS: dict[str, type[Intervention]] = {
    c.kind: c for c in (Botulinum, Lengthening, Tenotomy, Rhizotomy, Baclofen, SerialCasting)
}


def _copy(obj: _I, **changes: Any) -> _I:
    """``obj`` with ``changes``, validated again through the JSON form."""
    d = obj.to_dict()
    d.update(changes)
    return cast("_I", Intervention.from_dict(d))


__all__ = [
    "KINDS",
    "Baclofen",
    "Botulinum",
    "Intervention",
    "Lengthening",
    "Rhizotomy",
    "SerialCasting",
    "Tenotomy",
]
