"""Arm parameters: one immutable, validated, versioned record per arm.

An :class:`ArmParams` holds every constant of the six-muscle, two-joint arm of the seed paper
(Melendez-Calderon et al., eqs. 1-5) in SI units. It is built from body mass and height with
Winter's anthropometric fractions (:meth:`ArmParams.from_anthropometry`) or read from JSON
(:meth:`ArmParams.from_json`); every value can be overridden, and every value is checked against
one bounds table, :data:`BOUNDS`, whose entries generate the error messages.

Derived constants (muscle-length Jacobian, length extremes, maximal lengthening rates) are not
stored here: :class:`fieldbank.model.Arm` computes them once from a parameter set.

Muscle groups, in this order everywhere (arrays of six follow it):

====  ===========================================  =====================
sf    shoulder flexors (deltoid anterior, ...)     mono-articular
se    shoulder extensors (deltoid posterior)       mono-articular
ef    elbow flexors (biceps long, brachialis, ...) mono-articular
ee    elbow extensors (triceps lateral, anconeus)  mono-articular
bf    bi-articular flexors (biceps short)          both joints
be    bi-articular extensors (triceps long)        both joints
====  ===========================================  =====================
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import MISSING, asdict, dataclass, fields
from typing import Any

from fieldbank.errors import ParameterError
from fieldbank.files import JsonDocument
from fieldbank.validation import Interval, check_number, check_tuple

GROUPS: tuple[str, ...] = ("sf", "se", "ef", "ee", "bf", "be")
GROUP_INDEX: dict[str, int] = {g: i for i, g in enumerate(GROUPS)}
#: What each group code means, in the clinic's words.
GROUP_NAMES: dict[str, str] = {
    "sf": "shoulder flexors", "se": "shoulder extensors", "ef": "elbow flexors",
    "ee": "elbow extensors", "bf": "bi-articular flexors", "be": "bi-articular extensors",
}
#: ``sf = shoulder flexors, se = ...``: the legend every help text and message that lists
#: group codes carries.
GROUP_LEGEND = ", ".join(f"{g} = {n}" for g, n in GROUP_NAMES.items())
#: -1 for flexors (shorten under flexion, i.e. positive joint angle), +1 for extensors.
GROUP_SIGN: tuple[int, ...] = (-1, 1, -1, 1, -1, 1)
#: Hypertonia is described per joint group (BRIEF §5).
JOINT_GROUPS: dict[str, tuple[str, ...]] = {
    "shoulder": ("sf", "se"),
    "elbow": ("ef", "ee"),
    "biarticular": ("bf", "be"),
}

PARAMS_SCHEMA = "fieldbank.arm-params"
PARAMS_VERSION = 1

# --- Sourced defaults -----------------------------------------------------------------------
#: Winter (2004), Table 4.1: segment length / height, mass / body mass, COM and radius of
#: gyration as fractions of segment length (forearm values for the forearm+hand segment).
WINTER = {
    "upper_arm_length": 0.186,
    "forearm_length": 0.146,
    "hand_length": 0.108,
    "upper_arm_mass": 0.028,
    "forearm_hand_mass": 0.022,
    "upper_arm_com": 0.436,
    "upper_arm_gyration": 0.322,
    "forearm_hand_com": 0.682,
    "forearm_hand_gyration": 0.468,
}
DEFAULT_BODY_MASS_KG = 75.0
DEFAULT_HEIGHT_M = 1.75
#: Katayama & Kawato (1993): constant moment arms, m. Shoulder for sf/se, elbow for ef/ee,
#: bi-articular 0.028 m at the shoulder and 0.035 m at the elbow.
DEFAULT_MOMENT_ARM_SHOULDER_M = (0.040, 0.040, 0.0, 0.0, 0.028, 0.028)
DEFAULT_MOMENT_ARM_ELBOW_M = (0.0, 0.0, 0.025, 0.025, 0.035, 0.035)
#: Kambara et al. (2009) six-muscle arm; assumption.
DEFAULT_REST_LENGTH_M = (0.26, 0.26, 0.275, 0.275, 0.237, 0.237)
#: Katayama & Kawato's standard posture; assumption (fitted per patient).
DEFAULT_Q_REST_DEG = (45.0, 70.0)
#: Range of motion; assumption.
DEFAULT_SHOULDER_RANGE_DEG = (-20.0, 130.0)
DEFAULT_ELBOW_RANGE_DEG = (0.0, 150.0)
#: Unimpaired values, assumption sized by Wiegner & Watts (1986) elbow passive stiffness.
DEFAULT_KM_N_PER_M = 600.0
DEFAULT_ALPHA_N = 100.0
DEFAULT_BETA = 0.1
#: Width of the smoothed ramp at rest length (see fieldbank.model); assumption.
DEFAULT_PASSIVE_SMOOTHING_M = 0.002
#: Seed: λ̇_max from the endpoint running a 35 cm diameter circle at 2 Hz; the centre posture
#: (45°, 90°) is an assumption (BRIEF §3). For other body sizes the diameter scales with height
#: (35 cm at 1.75 m) so the circle stays inside a smaller arm's workspace (assumption).
DEFAULT_CIRCLE_DIAMETER_M = 0.35
DEFAULT_CIRCLE_FREQUENCY_HZ = 2.0
DEFAULT_CIRCLE_CENTRE_DEG = (45.0, 90.0)


_PI = math.pi
#: Every bound in one table. Keys are field names of ArmParams; a tuple field is checked
#: element-wise against the same interval.
BOUNDS: dict[str, Interval] = {
    "body_mass_kg": Interval(10.0, 300.0, "kg"),
    "height_m": Interval(0.5, 2.5, "m"),
    "upper_arm_length_m": Interval(0.05, 0.8, "m"),
    "forearm_length_m": Interval(0.05, 0.9, "m"),
    "upper_arm_mass_kg": Interval(0.05, 20.0, "kg"),
    "forearm_mass_kg": Interval(0.05, 20.0, "kg"),
    "upper_arm_com_m": Interval(0.0, 0.8, "m", low_closed=False),
    "forearm_com_m": Interval(0.0, 0.9, "m", low_closed=False),
    "upper_arm_inertia_kg_m2": Interval(0.0, 5.0, "kg·m²", low_closed=False),
    "forearm_inertia_kg_m2": Interval(0.0, 5.0, "kg·m²", low_closed=False),
    "q_rest_rad": Interval(-_PI, _PI, "rad"),
    "shoulder_range_rad": Interval(-_PI, _PI, "rad"),
    "elbow_range_rad": Interval(0.0, _PI, "rad"),
    "moment_arm_shoulder_m": Interval(0.0, 0.1, "m"),
    "moment_arm_elbow_m": Interval(0.0, 0.1, "m"),
    "rest_length_m": Interval(0.01, 1.0, "m", low_closed=False),
    "km_n_per_m": Interval(0.0, 1.0e6, "N/m"),
    "alpha_n": Interval(0.0, 1.0e6, "N"),
    "beta": Interval(0.0, 1.0, ""),
    "passive_smoothing_m": Interval(1.0e-5, 0.02, "m"),
    "circle_diameter_m": Interval(0.01, 1.0, "m", low_closed=False),
    "circle_frequency_hz": Interval(0.0, 20.0, "Hz", low_closed=False),
    "circle_centre_rad": Interval(-_PI, _PI, "rad"),
    "slack_offset_m": Interval(-0.05, 0.10, "m"),
}

_SIX = ("moment_arm_shoulder_m", "moment_arm_elbow_m", "rest_length_m", "km_n_per_m", "alpha_n",
        "beta", "slack_offset_m")
_PAIRS = ("q_rest_rad", "shoulder_range_rad", "elbow_range_rad", "circle_centre_rad")


def field_label(name: str, index: int | None) -> str:
    """How messages name entry ``index`` of field ``name``: ``beta[2] (ef)`` for a per-group
    field, ``q_rest_rad[1]`` for a pair, the name alone for a number (``index`` None)."""
    if index is None:
        return name
    if name in _SIX:
        return f"{name}[{index}] ({GROUPS[index]})"
    return f"{name}[{index}]"


def _check_value(name: str, value: Any, index: int | None = None) -> float:
    if type(value) is float and BOUNDS[name].contains(value):
        return value  # the common case, checked without building a message
    return check_number(field_label(name, index), value, BOUNDS[name])


def _check_tuple(name: str, value: Any, length: int) -> tuple[float, ...]:
    interval = BOUNDS[name]
    # the common case (a copy of validated parameters with a few values changed, e.g. each
    # of a fit's parameter samples) is checked without building labels or messages
    if type(value) is tuple and len(value) == length and all(
            type(v) is float and interval.contains(v) for v in value):
        return value
    return check_tuple(name, value, length, interval,
                       labels=[field_label(name, i) for i in range(length)])


_is_float = frozenset((float,)).__contains__
#: :data:`BOUNDS` as fast tests (:func:`_in_bounds`): per field, the length of a tuple field
#: (0: a number) and the low and high test, each a float comparison method (C-level, so that a
#: whole tuple is tested with ``map``). Every bound is finite: a NaN or an infinity fails.
_BOUND_CHECKS: dict[str, tuple[int, Callable[[float], bool], Callable[[float], bool]]] = {
    name: (6 if name in _SIX else 2 if name in _PAIRS else 0,
           float(iv.low).__le__ if iv.low_closed else float(iv.low).__lt__,
           float(iv.high).__ge__ if iv.high_closed else float(iv.high).__gt__)
    for name, iv in BOUNDS.items() if iv.low is not None and iv.high is not None}


def _in_bounds(name: str, v: Any) -> bool:
    """``v`` is a float (a tuple of floats of the field's length) inside the interval of field
    ``name``: what :func:`_check_value` and :func:`_check_tuple` accept unchanged."""
    n, low, high = _BOUND_CHECKS[name]
    if n:
        return (type(v) is tuple and len(v) == n and all(map(_is_float, map(type, v)))
                and all(map(low, v)) and all(map(high, v)))
    return type(v) is float and low(v) and high(v)


@dataclass(frozen=True)
class ArmParams(JsonDocument):
    """Constants of one arm, SI units, right-arm convention (a left arm is mirrored in x).

    Parameters
    ----------
    side : {'right', 'left'}
    body_mass_kg, height_m : float
        Body mass and height the segment values were derived from (kept for provenance).
    upper_arm_length_m, forearm_length_m : float
        L1 (shoulder-elbow) and L2 (elbow-handle; the handle is held mid-hand), m.
    upper_arm_mass_kg, forearm_mass_kg : float
        Segment masses, kg (forearm includes the hand).
    upper_arm_com_m, forearm_com_m : float
        Distance of each segment's centre of mass from its proximal joint, m.
    upper_arm_inertia_kg_m2, forearm_inertia_kg_m2 : float
        Moment of inertia about the segment's centre of mass, kg·m².
    q_rest_rad : (float, float)
        Rest posture (shoulder, elbow), rad; all muscles at rest length there.
    shoulder_range_rad, elbow_range_rad : (float, float)
        Range of motion (low, high), rad.
    moment_arm_shoulder_m, moment_arm_elbow_m : tuple of 6 float
        Moment-arm magnitudes ρ at each joint per group, m (sign from flexor/extensor).
    rest_length_m : tuple of 6 float
        λ_rest per group, m.
    km_n_per_m : tuple of 6 float
        Passive stiffness at rest length Km, N/m (eq. 5).
    alpha_n : tuple of 6 float
        Reflex force scale α, N (eq. 3).
    beta : tuple of 6 float
        Stretch-reflex gain β, dimensionless in [0, 1] (eq. 4).
    passive_smoothing_m : float
        Width w of the smoothed ramp replacing max(0, λ - λ_rest) in eq. 5, m.
    circle_diameter_m, circle_frequency_hz, circle_centre_rad
        The fast circle from which λ̇_max is measured (seed: 35 cm, 2 Hz).
    slack_offset_m : tuple of 6 float
        Extra length each group takes up before its passive force starts, m (default 0): the
        passive force of eq. 5 acts on λ - λ_rest - offset. A tendon lengthening or serial
        casting adds to it; a contracture is negative. The reflex terms keep λ_rest.
    """

    document_name = "parameters"
    document_error = ParameterError

    side: str
    body_mass_kg: float
    height_m: float
    upper_arm_length_m: float
    forearm_length_m: float
    upper_arm_mass_kg: float
    forearm_mass_kg: float
    upper_arm_com_m: float
    forearm_com_m: float
    upper_arm_inertia_kg_m2: float
    forearm_inertia_kg_m2: float
    q_rest_rad: tuple[float, float]
    shoulder_range_rad: tuple[float, float]
    elbow_range_rad: tuple[float, float]
    moment_arm_shoulder_m: tuple[float, ...]
    moment_arm_elbow_m: tuple[float, ...]
    rest_length_m: tuple[float, ...]
    km_n_per_m: tuple[float, ...]
    alpha_n: tuple[float, ...]
    beta: tuple[float, ...]
    passive_smoothing_m: float
    circle_diameter_m: float
    circle_frequency_hz: float
    circle_centre_rad: tuple[float, float]
    slack_offset_m: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        # Validation only; conversions live in the named constructors.
        self._check(None)

    def _check(self, names: Iterable[str] | None) -> None:
        """Check the fields ``names`` (None: every field) against :data:`BOUNDS`, converting
        or refusing what is not a float inside its interval, then everything that relates
        fields to one another (always)."""
        if self.side not in ("right", "left"):
            raise ParameterError(
                f"The 'side' parameter must be 'right' or 'left'; got {self.side!r} instead."
            )
        values = self.__dict__
        for name in _BOUND_CHECKS if names is None else names:
            if name == "side" or _in_bounds(name, values[name]):
                continue  # the common case, checked without a call per value
            if name in _SIX:
                checked: Any = _check_tuple(name, values[name], 6)
            elif name in _PAIRS:
                checked = _check_tuple(name, values[name], 2)
            else:
                checked = _check_value(name, values[name])
            object.__setattr__(self, name, checked)
        for rng in ("shoulder_range_rad", "elbow_range_rad"):
            lo, hi = getattr(self, rng)
            if not lo < hi:
                raise ParameterError(
                    f"The '{rng}' parameter must have low < high; got ({lo:g}, {hi:g})."
                )
        for j, rng in enumerate(("shoulder_range_rad", "elbow_range_rad")):
            lo, hi = getattr(self, rng)
            for name in ("q_rest_rad", "circle_centre_rad"):
                v = getattr(self, name)[j]
                if not lo <= v <= hi:
                    raise ParameterError(
                        f"The '{name}[{j}]' parameter must lie in the range of motion "
                        f"[{lo:g}, {hi:g}] rad; got {v:g} instead."
                    )
        if self.upper_arm_com_m >= self.upper_arm_length_m:
            raise ParameterError(
                f"The 'upper_arm_com_m' parameter must be less than upper_arm_length_m "
                f"({self.upper_arm_length_m:g} m); got {self.upper_arm_com_m:g} instead."
            )
        for i, g in enumerate(GROUPS):
            if self.moment_arm_shoulder_m[i] == 0.0 and self.moment_arm_elbow_m[i] == 0.0:
                raise ParameterError(
                    f"The muscle group '{g}' must cross at least one joint: "
                    f"moment_arm_shoulder_m[{i}] and moment_arm_elbow_m[{i}] are both 0."
                )

    # --- named constructors ------------------------------------------------------------------
    @classmethod
    def from_anthropometry(
        cls,
        body_mass_kg: float = DEFAULT_BODY_MASS_KG,
        height_m: float = DEFAULT_HEIGHT_M,
        side: str = "right",
        **overrides: Any,
    ) -> ArmParams:
        """Unimpaired defaults for a person of this mass and height (Winter 2004, Table 4.1).

        ``overrides`` replaces any field by name; an unknown name is an error.
        """
        m = _check_value("body_mass_kg", body_mass_kg)
        h = _check_value("height_m", height_m)
        w = WINTER
        l1 = w["upper_arm_length"] * h
        forearm = w["forearm_length"] * h
        l2 = forearm + 0.5 * w["hand_length"] * h
        m1 = w["upper_arm_mass"] * m
        m2 = w["forearm_hand_mass"] * m
        values: dict[str, Any] = {
            "side": side,
            "body_mass_kg": m,
            "height_m": h,
            "upper_arm_length_m": l1,
            "forearm_length_m": l2,
            "upper_arm_mass_kg": m1,
            "forearm_mass_kg": m2,
            "upper_arm_com_m": w["upper_arm_com"] * l1,
            "forearm_com_m": w["forearm_hand_com"] * forearm,
            "upper_arm_inertia_kg_m2": m1 * (w["upper_arm_gyration"] * l1) ** 2,
            "forearm_inertia_kg_m2": m2 * (w["forearm_hand_gyration"] * forearm) ** 2,
            "q_rest_rad": tuple(math.radians(a) for a in DEFAULT_Q_REST_DEG),
            "shoulder_range_rad": tuple(math.radians(a) for a in DEFAULT_SHOULDER_RANGE_DEG),
            "elbow_range_rad": tuple(math.radians(a) for a in DEFAULT_ELBOW_RANGE_DEG),
            "moment_arm_shoulder_m": DEFAULT_MOMENT_ARM_SHOULDER_M,
            "moment_arm_elbow_m": DEFAULT_MOMENT_ARM_ELBOW_M,
            "rest_length_m": DEFAULT_REST_LENGTH_M,
            "km_n_per_m": (DEFAULT_KM_N_PER_M,) * 6,
            "alpha_n": (DEFAULT_ALPHA_N,) * 6,
            "beta": (DEFAULT_BETA,) * 6,
            "passive_smoothing_m": DEFAULT_PASSIVE_SMOOTHING_M,
            "circle_diameter_m": DEFAULT_CIRCLE_DIAMETER_M * h / DEFAULT_HEIGHT_M,
            "circle_frequency_hz": DEFAULT_CIRCLE_FREQUENCY_HZ,
            "circle_centre_rad": tuple(math.radians(a) for a in DEFAULT_CIRCLE_CENTRE_DEG),
        }
        unknown = sorted(set(overrides) - set(values))
        if unknown:
            raise ParameterError(
                f"Unknown arm parameter(s) {', '.join(unknown)}; known: {', '.join(values)}."
            )
        values.update(overrides)
        return cls(**values)

    @classmethod
    def from_dict(cls, data: Any, where: str = "parameters") -> ArmParams:
        """Read the JSON document form (see :meth:`to_dict`); every field must be present."""
        if not isinstance(data, Mapping):
            raise ParameterError(f"{where}: expected a JSON object, got {type(data).__name__}.")
        schema = data.get("schema")
        version = data.get("version")
        if schema != PARAMS_SCHEMA:
            raise ParameterError(
                f"{where}: 'schema' must be {PARAMS_SCHEMA!r}; got {schema!r} instead."
            )
        if version != PARAMS_VERSION:
            raise ParameterError(
                f"{where}: 'version' {version!r} is not supported (this program reads version "
                f"{PARAMS_VERSION})."
            )
        names = [f.name for f in fields(cls)]
        body = {k: v for k, v in data.items() if k not in ("schema", "version")}
        # Fields added after version 1 documents were written carry defaults and may be absent.
        optional = {f.name for f in fields(cls) if f.default is not MISSING}
        missing = [n for n in names if n not in body and n not in optional]
        unknown = sorted(set(body) - set(names))
        if missing or unknown:
            parts = []
            if missing:
                parts.append(f"missing field(s) {', '.join(missing)}")
            if unknown:
                parts.append(f"unknown field(s) {', '.join(unknown)}")
            raise ParameterError(f"{where}: {'; '.join(parts)}.")
        try:
            return cls(**body)
        except ParameterError as exc:
            raise ParameterError(f"{where}: {exc}") from None


    # --- conversions ---------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"schema": PARAMS_SCHEMA, "version": PARAMS_VERSION}
        for k, v in asdict(self).items():
            d[k] = list(v) if isinstance(v, tuple) else v
        return d

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2, sort_keys=False)

    # --- derived copies -----------------------------------------------------------------------
    def replace(self, **changes: Any) -> ArmParams:
        """A validated copy with some fields changed."""
        names = {f.name for f in fields(self)}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise ParameterError(f"Unknown arm parameter(s) {', '.join(unknown)}.")
        return self._copy(changes)

    def _copy(self, changes: Mapping[str, Any]) -> ArmParams:
        """A copy with ``changes`` (known field names), checked as :meth:`__post_init__`
        checks a new record - only the changed fields against their bounds (the others were
        checked when this one was made), then every relation between fields."""
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__)
        new.__dict__.update(changes)
        new._check(changes)
        return new

    def with_group(self, group: str, **values: float) -> ArmParams:
        """Copy with per-group values set, e.g. ``with_group('ef', km_n_per_m=6000)``."""
        i = group_index(group)
        changes: dict[str, Any] = {}
        for name, value in values.items():
            if name not in _SIX:
                raise ParameterError(
                    f"'{name}' is not a per-group parameter; per-group: {', '.join(_SIX)}."
                )
            row = list(getattr(self, name))
            row[i] = value
            changes[name] = tuple(row)
        return self._copy(changes)

    def group_value(self, name: str, group: str) -> float:
        return float(getattr(self, name)[group_index(group)])

    def with_unimpaired_muscles(self) -> ArmParams:
        """The same arm (segments, moment arms, rest posture, range) with unimpaired muscles:
        Km, α and β at their defaults and no slack offset.

        The reference every severity grade and the inverse what-if measure against: only the
        muscles differ from this arm.
        """
        return self._copy({
            "km_n_per_m": (DEFAULT_KM_N_PER_M,) * 6, "alpha_n": (DEFAULT_ALPHA_N,) * 6,
            "beta": (DEFAULT_BETA,) * 6, "slack_offset_m": (0.0,) * 6,
        })


PER_GROUP_FIELDS: tuple[str, ...] = _SIX


def group_index(group: str) -> int:
    """Index of a muscle group name; a clear error for an unknown one."""
    try:
        return GROUP_INDEX[group]
    except KeyError:
        raise ParameterError(
            f"Unknown muscle group {group!r}; known groups: {GROUP_LEGEND}."
        ) from None
