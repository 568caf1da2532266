"""A recorded probing motion as the classifier reads it: :class:`Observation` (times,
positions, velocities and the force the arm exerts on the handle, in the shoulder frame, SI),
read from the trace CSV the robot writes, with the checks that name the file, row and field of
a bad value; and :func:`with_force_noise`, the sensor noise the classifier's likelihood assumes,
for simulated trials.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from fieldbank.errors import Problem, ValidationError
from fieldbank.evaluate.design import NoiseModel
from fieldbank.model import FloatArray

_COLUMNS = ("t_s", "x_m", "y_m", "fx_n", "fy_n")
_VELOCITY = ("vx_m_per_s", "vy_m_per_s")
_SIGNS = {"force on the handle": 1.0, "arm-on-handle": 1.0, "handle-on-arm": -1.0}


@dataclass(frozen=True, eq=False)
class Observation:
    """One recorded probing motion (shoulder frame, SI; force the arm exerts on the handle).

    Attributes
    ----------
    name : str
    times_s : ndarray, shape (T,), s (increasing)
    positions_m : ndarray, shape (T, 2), m
    velocities_m_per_s : ndarray, shape (T, 2), m/s
    force_n : ndarray, shape (T, 2), N
    force_limit_n : float or None, N
        Saturation of the force when it was rendered.
    reset_m : (x, y) or None, m
        Where the renderer put the virtual arm at rest (default: the first position).
    source : str
        Where the observation came from (file, database session).
    output_gain : ndarray, shape (T,), or None
        The renderer's output gain per sample (its arming ramp), applied to every prediction.
    counted : ndarray of bool, shape (T,), or None
        Samples the likelihood counts (default all); the others only carry the replay forward
        (e.g. while a renderer blended two models).
    """

    name: str
    times_s: FloatArray
    positions_m: FloatArray
    velocities_m_per_s: FloatArray
    force_n: FloatArray
    force_limit_n: float | None = None
    reset_m: tuple[float, float] | None = None
    source: str = ""
    output_gain: FloatArray | None = None
    counted: NDArray[np.bool_] | None = None

    @classmethod
    def from_arrays(cls, name: str, times_s: object, positions_m: object, force_n: object,
                    velocities_m_per_s: object | None = None, *,
                    force_limit_n: float | None = None,
                    reset_m: tuple[float, float] | None = None,
                    source: str = "", output_gain: object | None = None,
                    counted: object | None = None) -> Observation:
        """Check shapes and values; velocities by differentiating positions when not given."""
        where = source or name
        t = np.asarray(times_s, dtype=float)
        x = np.asarray(positions_m, dtype=float)
        f = np.asarray(force_n, dtype=float)
        problems = []
        if t.ndim != 1 or t.shape[0] < 3:
            problems.append(Problem(where, f"times_s must be a 1-D array of at least 3 samples; "
                                           f"got shape {t.shape}"))
        for label, a in (("positions_m", x), ("force_n", f)):
            if a.shape != (t.shape[0], 2):
                problems.append(Problem(where, f"{label} must have shape ({t.shape[0]}, 2); got "
                                               f"{a.shape}"))
        if problems:
            raise ValidationError(problems, f"Observation {name!r} is malformed:")
        v = None if velocities_m_per_s is None else np.asarray(velocities_m_per_s, dtype=float)
        if v is not None and v.shape != x.shape:
            raise ValidationError([Problem(where, f"velocities_m_per_s must have shape "
                                                  f"{x.shape}; got {v.shape}")])
        for label, arr in (("times_s", t), ("positions_m", x), ("velocities_m_per_s", v),
                           ("force_n", f)):
            if arr is None:
                continue
            bad = ~np.isfinite(arr.reshape(arr.shape[0], -1)).all(axis=1)
            if bad.any():
                problems.append(Problem(f"{where}: sample {int(np.argmax(bad))}",
                                        f"{label} is not finite ({int(bad.sum())} samples)"))
        if np.any(np.diff(t) <= 0):
            k = int(np.argmax(np.diff(t) <= 0)) + 1
            problems.append(Problem(f"{where}: sample {k}", "times_s must increase; "
                                                           f"{t[k]:g} s follows {t[k - 1]:g} s"))
        gain = None if output_gain is None else np.asarray(output_gain, dtype=float)
        mask = None if counted is None else np.asarray(counted, dtype=bool)
        for label, extra in (("output_gain", gain), ("counted", mask)):
            if extra is not None and extra.shape != t.shape:
                problems.append(Problem(where, f"{label} must have shape {t.shape}; got "
                                               f"{extra.shape}"))
        if mask is not None and mask.shape == t.shape and mask.sum() < 3:
            problems.append(Problem(where, f"at least 3 samples must count; {int(mask.sum())} "
                                           "do"))
        if problems:
            raise ValidationError(problems, f"Observation {name!r} is malformed:")
        if v is None:
            v = np.gradient(x, t, axis=0)
        return cls(name, t, x, v, f, force_limit_n, reset_m, source, gain, mask)

    @classmethod
    def from_csv(cls, path: str | Path, shoulder_offset_m: tuple[float, float] | None = None,
                 name: str | None = None) -> Observation:
        """Read a recorded probe from CSV: ``# key: value`` metadata lines, a header, one row a
        sample. Columns ``t_s,x_m,y_m,fx_n,fy_n`` (any order; ``vx_m_per_s,vy_m_per_s``
        optional, other columns ignored). ``# frame: shoulder`` or ``robot`` (then the shoulder
        offset comes from the argument, a ``# shoulder_offset_m: [x, y]`` line or the
        ``renderer`` metadata of an exported haptic trace); ``# sign: force on the handle`` (or
        ``arm-on-handle``) or ``handle-on-arm``. Every problem is reported with its row."""
        p = Path(path)
        try:
            lines = p.read_text(encoding="utf-8").splitlines()
        except (OSError, UnicodeDecodeError) as exc:
            raise ValidationError([Problem(str(p), f"cannot read: {exc}")]) from None
        meta: dict[str, str] = {}
        body: list[tuple[int, str]] = []
        for n, ln in enumerate(lines, start=1):
            if ln.startswith("#"):
                key, _, value = ln[1:].partition(":")
                meta[key.strip().lower()] = value.strip()
            elif ln.strip():
                body.append((n, ln))
        problems: list[Problem] = []
        if not body:
            raise ValidationError([Problem(str(p), "no header row and no samples")])
        header = [h.strip() for h in body[0][1].split(",")]
        missing = [c for c in _COLUMNS if c not in header]
        if missing:
            raise ValidationError([Problem(f"{p}:row {body[0][0]}",
                                           f"missing column(s) {', '.join(missing)}; got "
                                           f"{', '.join(header)}")])
        want = list(_COLUMNS) + [c for c in _VELOCITY if c in header]
        col = {c: header.index(c) for c in want}
        rows = []
        for n, ln in body[1:]:
            parts = ln.split(",")
            try:
                rows.append([float(parts[col[c]]) for c in want])
            except (ValueError, IndexError):
                problems.append(Problem(f"{p}:row {n}", f"expected numbers in "
                                                        f"{', '.join(want)}; got {ln!r}"))
        frame = meta.get("frame", "").split()[0].lower() if meta.get("frame") else ""
        if frame not in ("shoulder", "robot"):
            problems.append(Problem(str(p), f"'# frame:' must be shoulder or robot; got "
                                            f"{meta.get('frame')!r}"))
        sign_text = meta.get("sign", "").split("(")[0].strip().lower()
        if sign_text not in _SIGNS:
            problems.append(Problem(str(p), f"'# sign:' must be one of {', '.join(_SIGNS)}; got "
                                            f"{meta.get('sign')!r}"))
        offset = (0.0, 0.0)
        if frame == "robot":
            found = shoulder_offset_m or _offset_from_meta(meta)
            if found is None:
                problems.append(Problem(str(p), "positions are in the robot frame but the "
                                                "shoulder's position is unknown: give it "
                                                "(--shoulder-offset X,Y) or a "
                                                "'# shoulder_offset_m: [x, y]' line"))
            else:
                offset = found
        if len(rows) < 3 and not problems:
            problems.append(Problem(str(p), f"at least 3 samples needed; got {len(rows)}"))
        if problems:
            raise ValidationError(problems, f"{p}: not a usable probe recording:")
        a = np.array(rows)
        pos = a[:, 1:3] - np.asarray(offset)
        vel = a[:, 5:7] if len(want) == 7 else None
        limit = _force_limit_from_meta(meta)
        return cls.from_arrays(name or p.stem, a[:, 0], pos, _SIGNS[sign_text] * a[:, 3:5],
                               vel, force_limit_n=limit, source=str(p))

    @property
    def duration_s(self) -> float:
        return float(self.times_s[-1] - self.times_s[0])

    def weights(self, noise: NoiseModel) -> FloatArray:
        """Δt_k/τ per counted sample (trapezoid): how many independent samples each is worth."""
        dt = np.diff(self.times_s)
        w = np.zeros(self.times_s.shape)
        w[1:] += 0.5 * dt
        w[:-1] += 0.5 * dt
        if self.counted is not None:
            w = np.where(self.counted, w, 0.0)
        return w / noise.correlation_s

    def replace_force(self, force_n: FloatArray) -> Observation:
        """The same motion with another recorded force."""
        return Observation(self.name, self.times_s, self.positions_m, self.velocities_m_per_s,
                           force_n, self.force_limit_n, self.reset_m, self.source,
                           self.output_gain, self.counted)


def _json_value(text: str) -> object:
    try:
        return json.loads(text)
    except ValueError:
        return None


def _offset_from_meta(meta: dict[str, str]) -> tuple[float, float] | None:
    for raw in (meta.get("shoulder_offset_m"),
                _nested(meta.get("renderer"), "shoulder_offset_m")):
        if raw is None:
            continue
        val = _json_value(raw) if isinstance(raw, str) else raw
        if isinstance(val, list) and len(val) == 2 and all(
                isinstance(v, (int, float)) for v in val):
            return (float(val[0]), float(val[1]))
    return None


def _force_limit_from_meta(meta: dict[str, str]) -> float | None:
    raw = meta.get("force_limit_n")
    val = _json_value(raw) if raw is not None else _nested(meta.get("safety"), "force_limit_n")
    return float(val) if isinstance(val, (int, float)) and val > 0 else None


def _nested(raw: str | None, key: str) -> object:
    if raw is None:
        return None
    d = _json_value(raw)
    return d.get(key) if isinstance(d, dict) else None


def with_force_noise(obs: Observation, noise: NoiseModel, rng: np.random.Generator
                     ) -> Observation:
    """``obs`` with simulated sensor noise added: per axis Gaussian with SD σ, correlated as an
    Ornstein-Uhlenbeck process of time constant τ/2, whose integral time scale gives one
    independent sample per τ - the noise the likelihood assumes."""
    t = obs.times_s
    dt = np.diff(t, prepend=t[0])
    a = np.exp(-dt / (0.5 * noise.correlation_s))
    e = rng.standard_normal((len(t), 2)) * noise.force_sd_n
    out = np.empty_like(e)
    out[0] = e[0]
    scale = np.sqrt(1.0 - a * a)
    for k in range(1, len(t)):
        out[k] = a[k] * out[k - 1] + scale[k] * e[k]
    return obs.replace_force(obs.force_n + out)
