"""A raw recording of an arm on a robot handle: samples, channels and trials.

:class:`Recording` is what every source of raw data becomes before the estimator sees it — the
robot's own measurement (:mod:`fieldbank.haptic.measure`), a C3D file, an NWB file: hand
position, velocity and force sampled in time, in SI, in the shoulder frame, the force as the
arm exerts it on the handle (BRIEF §3, §11), with the channel each came from and its unit, and
the trials (which stretch of time is which hold or pass). Nothing here is estimated.

A :class:`Trial` is one hold or one pass:

* ``base`` — the hand held at a posture of the grid (the postural force, and the reference of
  the stiffness regression);
* ``displaced`` — held a few millimetres from its posture's base (a stiffness perturbation);
* ``pass`` — moved through the posture at a set velocity (a moving stiffness measurement).

``window_s`` is the part of the trial the estimator reads (a hold after its transient, a pass
on its constant-velocity plateau); ``status`` is empty for a trial the source kept and a reason
when the source itself dropped it (a safety fault during the trial, the force limit reached).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy.signal import savgol_filter

from fieldbank.errors import MapError
from fieldbank.model import FloatArray

ROLES = ("base", "displaced", "pass")


class ChannelProblems(MapError):
    """Every problem found in a raw file's channels at once (each a sentence naming the
    channel); the message joins them."""

    def __init__(self, reasons: list[str]) -> None:
        self.reasons = list(reasons)
        super().__init__("; ".join(self.reasons))


@dataclass(frozen=True)
class Trial:
    """One hold or pass of a recording (see the module docstring). Times in s."""

    index: int
    role: str
    posture: int
    start_s: float
    stop_s: float
    window_s: tuple[float, float]
    velocity_m_per_s: tuple[float, float] = (0.0, 0.0)
    label: str = ""
    status: str = ""

    def __post_init__(self) -> None:
        if self.role not in ROLES:
            raise MapError(f"trial {self.index}: role must be one of {', '.join(ROLES)}; got "
                           f"{self.role!r}")
        w0, w1 = self.window_s
        if not (self.start_s <= w0 <= w1 <= self.stop_s):
            raise MapError(f"trial {self.index}: window {w0:g}–{w1:g} s must lie inside the "
                           f"trial {self.start_s:g}–{self.stop_s:g} s")

    def to_json_dict(self) -> dict[str, object]:
        return {"index": self.index, "role": self.role, "posture": self.posture,
                "start_s": self.start_s, "stop_s": self.stop_s,
                "window_s": list(self.window_s),
                "velocity_m_per_s": list(self.velocity_m_per_s), "label": self.label,
                "status": self.status}


@dataclass(frozen=True, eq=False)
class Recording:
    """Samples of hand position, velocity and force with the trials that cut them.

    Parameters
    ----------
    t_s : ndarray, shape (N,), s
    position_m : ndarray, shape (N, 2), m, shoulder frame
    velocity_m_per_s : ndarray, shape (N, 2), m/s
    force_n : ndarray, shape (N, 2), N, arm on handle
    trials : tuple of Trial
    channels : mapping of str to str
        Role ('x', 'y', 'vx', 'vy', 'fx', 'fy') → the source's channel name and unit, e.g.
        ``'Right_HandX (m)'``.
    source : str
        Free text: the file or robot, software and version.
    velocity_derived : bool
        The velocity was differentiated from the position (the source had none).
    """

    t_s: FloatArray
    position_m: FloatArray
    velocity_m_per_s: FloatArray
    force_n: FloatArray
    trials: tuple[Trial, ...]
    channels: Mapping[str, str] = field(default_factory=dict)
    source: str = ""
    velocity_derived: bool = False

    def __post_init__(self) -> None:
        t = np.asarray(self.t_s, dtype=float)
        n = t.shape[0]
        if t.ndim != 1 or n < 2:
            raise MapError(f"a recording needs at least 2 samples; got shape {t.shape}")
        for name in ("position_m", "velocity_m_per_s", "force_n"):
            a = np.asarray(getattr(self, name), dtype=float)
            if a.shape != (n, 2):
                raise MapError(f"{name} must have shape ({n}, 2); got {a.shape}")
            object.__setattr__(self, name, a)
        if np.any(np.diff(t) <= 0):
            raise MapError("sample times must increase strictly")
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "trials", tuple(self.trials))
        object.__setattr__(self, "channels", dict(self.channels))

    @property
    def n(self) -> int:
        return int(self.t_s.shape[0])

    @property
    def rate_hz(self) -> float:
        """Median sample rate, Hz."""
        return float(1.0 / np.median(np.diff(self.t_s)))

    def span(self, start_s: float, stop_s: float) -> slice:
        """Sample indices with start ≤ t < stop."""
        i0 = int(np.searchsorted(self.t_s, start_s, side="left"))
        i1 = int(np.searchsorted(self.t_s, stop_s, side="left"))
        return slice(i0, i1)


def derive_velocity(t_s: FloatArray, position_m: FloatArray) -> FloatArray:
    """Velocity from positions, m/s: a Savitzky–Golay derivative (quadratic, over ≈ 31 ms),
    so that encoder noise of a few micrometres does not read as centimetres per second."""
    n = len(t_s)
    dt = float(np.median(np.diff(t_s)))
    win = max(5, round(0.031 / dt) | 1)
    if n <= win:
        return np.asarray(np.gradient(position_m, t_s, axis=0), dtype=float)
    return np.asarray(savgol_filter(position_m, win, 2, deriv=1, delta=dt, axis=0),
                      dtype=float)


def in_convention(rec: Recording, shoulder_m: tuple[float, float] = (0.0, 0.0),
                  handle_on_arm: bool = False) -> Recording:
    """``rec`` with the shoulder's position (in the file's coordinates) subtracted and, for a
    file whose force is the handle's on the arm, the force turned to the arm's on the handle."""
    if shoulder_m == (0.0, 0.0) and not handle_on_arm:
        return rec
    sign = -1.0 if handle_on_arm else 1.0
    return Recording(rec.t_s, rec.position_m - np.asarray(shoulder_m, dtype=float),
                     rec.velocity_m_per_s, sign * rec.force_n, rec.trials, rec.channels,
                     rec.source, rec.velocity_derived)
