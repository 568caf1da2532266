"""Postural and stiffness maps: the domain type and the model's maps.

A :class:`FieldMap` is one map, measured or computed, with everything needed to read it
unambiguously (BRIEF §4, §11): kind, positions (m, shoulder frame), values with their units,
sign convention, the endpoint velocity of the measurement, optional standard deviations and
provenance. It is the unit that ingest stores, the fitter fits and the CLI writes.

Model maps:

* :func:`postural_map` - F(x) at zero velocity, with the passive potential U (F = -∇U);
* :func:`stiffness_map` - K = -∂F/∂x at a stated endpoint velocity, with damping B = -∂F/∂v;
* :func:`ellipse` - the symmetric part of K as an ellipse, and the antisymmetric (curl) part;
* :func:`workspace_grid` - a regular grid of reachable positions.
"""

from __future__ import annotations

import io
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from fieldbank.errors import MapError
from fieldbank.model import Arm, FloatArray
from fieldbank.sanitize import csv_comment

if TYPE_CHECKING:
    from fieldbank.armbatch import ArmBatch

KINDS = ("postural", "stiffness")
FRAMES = ("shoulder",)
SIGNS = ("arm-on-handle", "handle-on-arm")

POSTURAL_COLUMNS = ("x_m", "y_m", "fx_n", "fy_n")
POSTURAL_SD_COLUMNS = ("sd_fx_n", "sd_fy_n")
STIFFNESS_COLUMNS = ("x_m", "y_m", "kxx_n_per_m", "kxy_n_per_m", "kyx_n_per_m", "kyy_n_per_m")
STIFFNESS_SD_COLUMNS = ("sd_kxx_n_per_m", "sd_kxy_n_per_m", "sd_kyx_n_per_m", "sd_kyy_n_per_m")
VALUE_UNITS = {"postural": "N", "stiffness": "N/m"}


@dataclass(frozen=True, eq=False)
class FieldMap:
    """One postural or stiffness map.

    Parameters
    ----------
    kind : {'postural', 'stiffness'}
    positions_m : ndarray, shape (N, 2), m
        Hand positions in ``frame``.
    values : ndarray, shape (N, 2) N (postural) or (N, 2, 2) N/m (stiffness)
        Forces, or stiffness K = -∂F/∂x with K[i, j] = -∂F_i/∂x_j.
    sd : ndarray or None
        One standard deviation per value, same shape and unit as ``values``.
    frame : str
        'shoulder' (BRIEF §3).
    sign : {'arm-on-handle', 'handle-on-arm'}
        Whose force the values are.
    velocity_m_per_s : (float, float)
        Endpoint velocity at which the map holds (0 = static).
    source : str
        Free text: lab, robot, software and version, or the model that produced it.
    metadata : mapping of str to str
        Other provenance keys, kept verbatim.
    """

    kind: str
    positions_m: FloatArray
    values: FloatArray
    sd: FloatArray | None = None
    frame: str = "shoulder"
    sign: str = "arm-on-handle"
    velocity_m_per_s: tuple[float, float] = (0.0, 0.0)
    source: str = ""
    metadata: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise MapError(f"kind must be one of {', '.join(KINDS)}; got {self.kind!r}.")
        if self.frame not in FRAMES:
            raise MapError(f"frame must be one of {', '.join(FRAMES)}; got {self.frame!r}.")
        if self.sign not in SIGNS:
            raise MapError(f"sign must be one of {', '.join(SIGNS)}; got {self.sign!r}.")
        pos = np.array(self.positions_m, dtype=float)
        if pos.ndim != 2 or pos.shape[1] != 2 or pos.shape[0] == 0:
            raise MapError(f"positions_m must have shape (N>0, 2); got {pos.shape}.")
        want = (pos.shape[0], 2) if self.kind == "postural" else (pos.shape[0], 2, 2)
        vals = np.array(self.values, dtype=float)
        if vals.shape != want:
            raise MapError(f"{self.kind} values must have shape {want}; got {vals.shape}.")
        sd = None if self.sd is None else np.array(self.sd, dtype=float)
        if sd is not None and sd.shape != want:
            raise MapError(f"sd must have shape {want}; got {sd.shape}.")
        for name, arr in (("positions_m", pos), ("values", vals), ("sd", sd)):
            if arr is not None and not np.all(np.isfinite(arr)):
                raise MapError(f"{name} contains NaN or infinite entries.")
        if sd is not None and np.any(sd < 0):
            raise MapError("sd must be non-negative.")
        vel = tuple(float(v) for v in self.velocity_m_per_s)
        if len(vel) != 2 or not all(math.isfinite(v) for v in vel):
            raise MapError(f"velocity_m_per_s must be two finite numbers; got {vel}.")
        for arr in (pos, vals, sd):
            if arr is not None:
                arr.setflags(write=False)
        object.__setattr__(self, "positions_m", pos)
        object.__setattr__(self, "values", vals)
        object.__setattr__(self, "sd", sd)
        object.__setattr__(self, "velocity_m_per_s", vel)
        object.__setattr__(self, "metadata", dict(self.metadata))

    @property
    def n(self) -> int:
        return int(self.positions_m.shape[0])

    @property
    def speed_m_per_s(self) -> float:
        return float(math.hypot(*self.velocity_m_per_s))

    def as_arm_on_handle(self) -> FieldMap:
        """The same map with the arm-on-handle sign convention."""
        if self.sign == "arm-on-handle":
            return self
        sd = self.sd
        return FieldMap(
            kind=self.kind,
            positions_m=self.positions_m,
            values=-self.values,
            sd=sd,
            frame=self.frame,
            sign="arm-on-handle",
            velocity_m_per_s=self.velocity_m_per_s,
            source=self.source,
            metadata=self.metadata,
        )

    def columns(self) -> tuple[str, ...]:
        if self.kind == "postural":
            cols = POSTURAL_COLUMNS + (POSTURAL_SD_COLUMNS if self.sd is not None else ())
        else:
            cols = STIFFNESS_COLUMNS + (STIFFNESS_SD_COLUMNS if self.sd is not None else ())
        return cols

    def table(self) -> FloatArray:
        """Rows as written to CSV: positions, values (and sd), shape (N, len(columns()))."""
        n = self.n
        parts = [self.positions_m, self.values.reshape(n, -1)]
        if self.sd is not None:
            parts.append(self.sd.reshape(n, -1))
        return np.hstack(parts)

    def to_csv(self) -> str:
        """The BRIEF §11 CSV text: ``# key: value`` metadata, a header, one row per position.

        Metadata text is written one line per key and neutralised for spreadsheets
        (:func:`fieldbank.sanitize.csv_comment`): a value from a lab file cannot start a new
        line or run as a formula when the file is opened in a spreadsheet.
        """
        out = io.StringIO()
        out.write(f"# kind: {self.kind}\n")
        out.write(f"# frame: {self.frame}\n")
        out.write(f"# sign: {self.sign}\n")
        out.write(f"# velocity_m_per_s: {self.speed_m_per_s:.17g}\n")
        if self.speed_m_per_s > 0:
            vx, vy = self.velocity_m_per_s
            out.write(f"# velocity_vector_m_per_s: {vx:.17g}, {vy:.17g}\n")
        out.write(f"# source: {csv_comment(self.source)}\n")
        for k, v in self.metadata.items():
            if k in ("kind", "frame", "sign", "velocity_m_per_s", "velocity_vector_m_per_s",
                     "source"):
                continue
            out.write(f"# {csv_comment(k).replace(':', '_')}: {csv_comment(v)}\n")
        out.write(",".join(self.columns()) + "\n")
        for row in self.table():
            out.write(",".join(f"{v:.10g}" for v in row) + "\n")
        return out.getvalue()

    def to_json_dict(self) -> dict[str, object]:
        d: dict[str, object] = {
            "kind": self.kind,
            "frame": self.frame,
            "sign": self.sign,
            "velocity_m_per_s": list(self.velocity_m_per_s),
            "source": self.source,
            "metadata": dict(self.metadata),
            "units": {"positions": "m", "values": VALUE_UNITS[self.kind]},
            "positions_m": self.positions_m.tolist(),
            "values": self.values.tolist(),
        }
        if self.sd is not None:
            d["sd"] = self.sd.tolist()
        return d


@dataclass(frozen=True)
class Ellipse:
    """Symmetric part of stiffness matrices as ellipses, and their curl, each shape (N,).

    major_n_per_m, minor_n_per_m : eigenvalues of (K + Kᵀ)/2, major ≥ minor
    orientation_rad : angle of the major axis from +x, in (-π/2, π/2]
    shape_ratio : major / minor (inf where minor ≤ 0)
    area : π·major·minor, (N/m)²
    curl_n_per_m : antisymmetric part (K_xy - K_yx)/2
    """

    major_n_per_m: FloatArray
    minor_n_per_m: FloatArray
    orientation_rad: FloatArray
    shape_ratio: FloatArray
    area: FloatArray
    curl_n_per_m: FloatArray


def ellipse(k: ArrayLike) -> Ellipse:
    """Ellipse parameters of stiffness matrices K, shape (N, 2, 2) or (2, 2)."""
    ka = np.asarray(k, dtype=float)
    if ka.ndim == 2:
        ka = ka[None]
    a = ka[:, 0, 0]
    d = ka[:, 1, 1]
    b = 0.5 * (ka[:, 0, 1] + ka[:, 1, 0])
    mean = 0.5 * (a + d)
    rad = np.hypot(0.5 * (a - d), b)
    major = mean + rad
    minor = mean - rad
    theta = 0.5 * np.arctan2(2 * b, a - d)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(minor > 0, major / np.where(minor > 0, minor, 1.0), np.inf)
    return Ellipse(
        major_n_per_m=major,
        minor_n_per_m=minor,
        orientation_rad=theta,
        shape_ratio=ratio,
        area=np.pi * major * minor,
        curl_n_per_m=0.5 * (ka[:, 0, 1] - ka[:, 1, 0]),
    )


@dataclass(frozen=True, eq=False)
class ModelMaps:
    """A computed postural+stiffness evaluation over positions (see :func:`evaluate`)."""

    positions_m: FloatArray
    force_n: FloatArray
    stiffness_n_per_m: FloatArray
    damping_n_s_per_m: FloatArray
    potential_j: FloatArray | None
    velocity_m_per_s: tuple[float, float]


def _source(arm: Arm, label: str | None) -> str:
    return label or "fieldbank model (synthetic)"


def postural_map(arm: Arm, positions_m: ArrayLike, source: str | None = None) -> FieldMap:
    """The model's postural map: static force on the handle at each position."""
    pos = np.asarray(positions_m, dtype=float)
    force = arm.endpoint_force(pos)
    return FieldMap(kind="postural", positions_m=pos, values=force, source=_source(arm, source))


def stiffness_map(
    arm: Arm,
    positions_m: ArrayLike,
    velocity_m_per_s: ArrayLike = (0.0, 0.0),
    source: str | None = None,
) -> FieldMap:
    """The model's stiffness map K = -∂F/∂x at a fixed endpoint velocity."""
    pos = np.asarray(positions_m, dtype=float)
    vel = np.asarray(velocity_m_per_s, dtype=float).reshape(2)
    _, k, _ = arm.field(pos, vel)
    return FieldMap(
        kind="stiffness",
        positions_m=pos,
        values=k,
        velocity_m_per_s=(float(vel[0]), float(vel[1])),
        source=_source(arm, source),
    )


def model_map_like(arm: Arm, m: FieldMap, source: str | None = None) -> FieldMap:
    """The model's map of the same kind, at the positions (and velocity) of ``m``, in the
    arm-on-handle convention (compare with ``m.as_arm_on_handle()``)."""
    if m.kind == "postural":
        return postural_map(arm, m.positions_m, source)
    return stiffness_map(arm, m.positions_m, m.velocity_m_per_s, source)


def model_map_values(batch: ArmBatch, m: FieldMap) -> FloatArray:
    """The values of :func:`model_map_like` for every parameter set of ``batch`` in one
    vectorised pass: (S, N, 2) N or (S, N, 2, 2) N/m, each set's to the last bit what its own
    compiled arm gives.

    Raises
    ------
    UnreachableError
        A position of ``m`` the arm cannot reach.
    MapError
        A set's values are not finite (as :class:`FieldMap` refuses them).
    """
    if m.kind == "postural":
        vals = batch.endpoint_force(m.positions_m)
    else:
        vel = np.asarray(m.velocity_m_per_s, dtype=float).reshape(2)
        vals = batch.field(m.positions_m, vel)[1]
    if not np.all(np.isfinite(vals)):
        raise MapError("values contains NaN or infinite entries.")
    return vals


def evaluate(
    arm: Arm,
    positions_m: ArrayLike,
    velocity_m_per_s: ArrayLike = (0.0, 0.0),
    with_potential: bool = True,
) -> ModelMaps:
    """Force, stiffness, damping (and potential) in one pass over the positions."""
    pos = np.asarray(positions_m, dtype=float)
    vel = np.asarray(velocity_m_per_s, dtype=float).reshape(2)
    f, k, b = arm.field(pos, vel)
    u = arm.potential(pos) if with_potential else None
    return ModelMaps(pos, f, k, b, u, (float(vel[0]), float(vel[1])))


def workspace_grid(
    arm: Arm,
    n: int = 50,
    bounds_m: tuple[float, float, float, float] | None = None,
) -> FloatArray:
    """Positions of an n×n grid that the arm reaches within its range of motion, (M, 2), m.

    ``bounds_m`` = (xmin, xmax, ymin, ymax); by default the bounding box of the hand over the
    range of motion.
    """
    if n < 2:
        raise MapError(f"grid size must be at least 2; got {n}.")
    if bounds_m is None:
        p = arm.params
        qs = np.stack(
            np.meshgrid(
                np.linspace(*p.shoulder_range_rad, 61), np.linspace(*p.elbow_range_rad, 61)
            ),
            axis=-1,
        ).reshape(-1, 2)
        hand = arm.fk(qs)
        bounds_m = (
            float(hand[:, 0].min()), float(hand[:, 0].max()),
            float(hand[:, 1].min()), float(hand[:, 1].max()),
        )
    xmin, xmax, ymin, ymax = bounds_m
    gx, gy = np.meshgrid(np.linspace(xmin, xmax, n), np.linspace(ymin, ymax, n))
    pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    return pts[arm.reachable(pts)]
