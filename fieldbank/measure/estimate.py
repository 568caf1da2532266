"""Maps from a raw recording: the postural force and the stiffness by least squares, with sd.

The method is Mussa-Ivaldi, Hogan & Bizzi (1985, J. Neurosci. 5:2732–2743): the robot holds
the relaxed hand at a posture, displaces it by a few millimetres in several directions and
holds it; after the transient the restoring force is steady, and the endpoint stiffness K is
the least-squares solution of ΔF = −K Δx over the displacements (their eq. 2; 8 directions of
5–8 mm in the paper). Here, per posture and per component of the force:

    F_k = c − K (x_k − x̄),    k over the trial windows (base and displaced holds)

with x_k, F_k the mean position and force over the window of hold k (the hold after
``transient_s``), x̄ the mean base position, c the force at x̄. The regression's residuals
give σ² = RSS / (n − 3) and the sd of each element of K from σ² (AᵀA)⁻¹ (ordinary least
squares; the paper reports the residual fit the same way). The symmetric part of K is what a
potential field can explain; the antisymmetric part stays in the map.

The postural force at a posture is the mean force over its base holds; its sd is the spread
of the hold means over √k when there are three holds or more (the stiffness protocol returns
to the base after every displacement), else the batch-means sd of the one window (10 blocks),
which does not assume white noise.

Moving stiffness (the stretch part, BRIEF §16): the samples of the passes made at one velocity
whose window (the constant-velocity plateau) comes within ``pass_radius_m`` of a posture enter
the same regression, sample by sample. Before that, the force the arm's own inertia puts on
the handle along the pass — −J⁻ᵀ(H q̈ + C q̇) of the patient's segments (Winter anthropometry;
:func:`fieldbank.dynamics.hand_inertial_force`) — is subtracted, with the acceleration from a
Savitzky–Golay derivative of the velocity: at 1 m/s it is several newtons, which a map of the
muscles' forces must not contain. The reflex makes the force steep in the velocity, so only
the samples within ``sample_speed_tolerance`` (4 %) of the pass's velocity are read. Static
holds need no correction (the hand is at rest).

Trials are dropped, each with its reason, when the source marked them (a safety fault, the
force limit), when the window is shorter than ``min_window_s`` or holds a non-finite sample,
when a hold did not settle (RMS speed over ``settle_speed_m_per_s``), when a displaced hold is
under ``min_displacement_m`` or over ``max_displacement_m`` from its base, and when a pass ran
more than ``speed_tolerance`` off its velocity. A posture whose kept holds cannot determine K
(fewer than 6 windows, or displacements that do not span both directions) gets no stiffness,
with the reason. Everything dropped is listed in :class:`Estimate`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.signal import savgol_filter

from fieldbank.dynamics import hand_inertial_force
from fieldbank.errors import MapError, ParameterError
from fieldbank.maps import FieldMap
from fieldbank.measure.recording import Recording, Trial
from fieldbank.model import Arm, FloatArray
from fieldbank.validation import Interval, check_fields

ESTIMATOR = ("least squares ΔF = −K Δx over held displacements (Mussa-Ivaldi, Hogan & Bizzi "
             "1985); postural force = mean over base holds")


#: The range of each threshold of :class:`EstimatorConfig`.
ESTIMATOR_BOUNDS: dict[str, Interval] = {
    "min_window_s": Interval(0.0, 5.0, "s", low_closed=False),
    "min_pass_window_s": Interval(0.0, 5.0, "s", low_closed=False),
    "settle_speed_m_per_s": Interval(0.0, 1.0, "m/s", low_closed=False),
    "min_displacement_m": Interval(0.0, 0.1, "m"),
    "max_displacement_m": Interval(0.0, 0.2, "m", low_closed=False),
    "speed_tolerance": Interval(0.0, 1.0, low_closed=False),
    "pass_radius_m": Interval(0.0, 0.2, "m", low_closed=False),
    "sample_speed_tolerance": Interval(0.0, 1.0, low_closed=False),
    "posture_radius_m": Interval(0.0, 0.2, "m", low_closed=False),
    "blocks": Interval.whole(1, 1000),
}


@dataclass(frozen=True)
class EstimatorConfig:
    """Thresholds of trial selection (see the module docstring); SI."""

    min_window_s: float = 0.08
    min_pass_window_s: float = 0.02
    settle_speed_m_per_s: float = 0.01
    min_displacement_m: float = 0.001
    max_displacement_m: float = 0.03
    speed_tolerance: float = 0.15
    pass_radius_m: float = 0.012
    sample_speed_tolerance: float = 0.04
    posture_radius_m: float = 0.004
    blocks: int = 10

    def __post_init__(self) -> None:
        check_fields(self, ESTIMATOR_BOUNDS, what="estimator setting")
        if self.min_displacement_m >= self.max_displacement_m:
            raise ParameterError(f"min_displacement_m ({self.min_displacement_m:g} m) must be "
                                 f"less than max_displacement_m ({self.max_displacement_m:g} m)")


@dataclass(frozen=True)
class Dropped:
    """A trial (or posture) left out, and why."""

    what: str
    reason: str

    def to_json_dict(self) -> dict[str, str]:
        return {"what": self.what, "reason": self.reason}


@dataclass(frozen=True)
class Estimate:
    """Maps estimated from one recording, with what was used and what was left out."""

    maps: tuple[FieldMap, ...]
    kept: tuple[int, ...]
    dropped: tuple[Dropped, ...]
    postures_m: FloatArray
    n_directions: dict[int, int] = field(default_factory=dict)


@dataclass
class _Window:
    trial: Trial
    position: FloatArray   # (2,)
    force: FloatArray      # (2,)
    samples: slice


def _trial_name(t: Trial) -> str:
    return f"trial {t.index}" + (f" ({t.label})" if t.label else "")


def _check_window(rec: Recording, t: Trial, cfg: EstimatorConfig) -> tuple[slice, str]:
    """The window's samples, and a reason to drop the trial ('' to keep it)."""
    if t.status:
        return slice(0, 0), t.status
    sl = rec.span(*t.window_s)
    n = sl.stop - sl.start
    dur = t.window_s[1] - t.window_s[0]
    least = cfg.min_pass_window_s if t.role == "pass" else cfg.min_window_s
    if dur < least or n < 5:
        return sl, (f"window of {dur:.3f} s and {n} samples is shorter than "
                    f"{least:g} s (or 5 samples)")
    block = np.concatenate([rec.position_m[sl], rec.velocity_m_per_s[sl], rec.force_n[sl]],
                           axis=1)
    if not np.all(np.isfinite(block)):
        return sl, "non-finite samples in the window"
    v = rec.velocity_m_per_s[sl]
    if t.role != "pass":
        rms = float(np.sqrt(np.mean(np.sum(v * v, axis=1))))
        if rms > cfg.settle_speed_m_per_s:
            return sl, (f"the hand did not settle: RMS speed {rms * 1000:.1f} mm/s in the "
                        f"window, over {cfg.settle_speed_m_per_s * 1000:g} mm/s")
    else:
        want = np.asarray(t.velocity_m_per_s, dtype=float)
        speed = float(np.hypot(*want))
        if speed <= 0:
            return sl, "a pass without a velocity"
        off = float(np.max(np.hypot(*(v - want).T))) / speed
        if off > cfg.speed_tolerance:
            return sl, (f"velocity up to {off:.0%} off the pass's "
                        f"({want[0]:.2f}, {want[1]:.2f}) m/s, over {cfg.speed_tolerance:.0%}")
    return sl, ""


def _batch_sd(f: FloatArray, blocks: int) -> FloatArray:
    """sd of the mean of ``f`` (n, 2) by batch means."""
    n = f.shape[0]
    k = max(2, min(blocks, n // 5))
    parts = np.array_split(f, k)
    means = np.array([p.mean(axis=0) for p in parts])
    return np.asarray(means.std(axis=0, ddof=1) / math.sqrt(k), dtype=float)


def _regress(dx: FloatArray, f: FloatArray, dv: FloatArray | None = None
             ) -> tuple[Any, Any, Any, Any]:
    """F = c − K dx (− B dv) by least squares: (c, K, sd_c, sd_K)."""
    cols = [np.ones(len(dx)), dx] + ([dv] if dv is not None else [])
    a = np.column_stack(cols)
    coef, *_ = np.linalg.lstsq(a, f, rcond=None)          # rows c, −K[:,0], −K[:,1] (, −B)
    res = f - a @ coef
    dof = max(1, len(dx) - a.shape[1])
    s2 = (res * res).sum(axis=0) / dof                    # per force component
    cov = np.linalg.inv(a.T @ a)
    c = coef[0]
    k = -coef[1:3].T                                      # K[i, j] = −∂F_i/∂x_j
    sd_c = np.sqrt(cov[0, 0] * s2)
    sd_k = np.sqrt(np.outer(s2, np.diag(cov)[1:3]))
    return c, k, sd_c, sd_k


def _span_problem(dx: FloatArray) -> str:
    if len(dx) < 6:
        return f"{len(dx)} windows kept, fewer than the 6 a 2×2 stiffness with sd needs"
    sv = np.linalg.svd(dx - dx.mean(axis=0), compute_uv=False)
    spread = float(sv[-1] / math.sqrt(len(dx)))
    if spread < 1e-3:
        return (f"the displacements do not span both directions (smallest spread "
                f"{spread * 1000:.2f} mm)")
    return ""


def estimate(rec: Recording, arm: Arm | None = None,
             postures_m: Sequence[Sequence[float]] | FloatArray | None = None,
             config: EstimatorConfig | None = None, source: str = "",
             provenance: dict[str, str] | None = None) -> Estimate:
    """Estimate every map the recording holds (see the module docstring).

    Parameters
    ----------
    rec : Recording
    arm : Arm, optional
        The patient's arm, for the inertial correction of passes (required when the recording
        has passes).
    postures_m : array (P, 2), m, optional
        Nominal postures (the plan's grid): passes are read near them, and holds without a
        base are placed by them. Default: the mean base position of each posture.
    source, provenance
        Written into every map (``source``; metadata keys).
    """
    cfg = config or EstimatorConfig()
    dropped: list[Dropped] = []
    kept: list[int] = []
    windows: dict[int, list[_Window]] = {}
    passes: dict[tuple[float, float], list[tuple[Trial, slice]]] = {}
    for t in rec.trials:
        sl, why = _check_window(rec, t, cfg)
        if why:
            dropped.append(Dropped(_trial_name(t), why))
            continue
        if t.role == "pass":
            key = (round(t.velocity_m_per_s[0], 2), round(t.velocity_m_per_s[1], 2))
            passes.setdefault(key, []).append((t, sl))
            kept.append(t.index)
            continue
        windows.setdefault(t.posture, []).append(
            _Window(t, rec.position_m[sl].mean(axis=0), rec.force_n[sl].mean(axis=0), sl))
    base_pos: dict[int, FloatArray] = {}
    for p, ws in windows.items():
        bases = [w for w in ws if w.trial.role == "base"]
        if bases:
            base_pos[p] = np.mean([w.position for w in bases], axis=0)
        elif postures_m is not None and 0 <= p < len(postures_m):
            base_pos[p] = np.asarray(postures_m[p], dtype=float)
    # displaced holds: distance from their base
    for p, ws in windows.items():
        keep = []
        for w in ws:
            if w.trial.role == "displaced":
                if p not in base_pos:
                    dropped.append(Dropped(_trial_name(w.trial), f"posture {p} has no base "
                                           "hold to measure the displacement from"))
                    continue
                d = float(np.hypot(*(w.position - base_pos[p])))
                if d < cfg.min_displacement_m or d > cfg.max_displacement_m:
                    dropped.append(Dropped(_trial_name(w.trial), (
                        f"displacement {d * 1000:.1f} mm outside "
                        f"{cfg.min_displacement_m * 1000:g}–{cfg.max_displacement_m * 1000:g} "
                        "mm")))
                    continue
            keep.append(w)
            kept.append(w.trial.index)
        windows[p] = keep
    common = {"estimator": ESTIMATOR, **(provenance or {})}
    maps: list[FieldMap] = []
    postures = sorted(p for p in windows if p in base_pos)
    # postural map
    pos_p, f_p, sd_p = [], [], []
    for p in postures:
        bases = [w for w in windows[p] if w.trial.role == "base"]
        if not bases:
            continue
        means = np.array([w.force for w in bases])
        if len(bases) >= 3:
            sd = means.std(axis=0, ddof=1) / math.sqrt(len(bases))
        else:
            f = np.concatenate([rec.force_n[w.samples] for w in bases])
            sd = _batch_sd(f, cfg.blocks)
        pos_p.append(np.mean([w.position for w in bases], axis=0))
        f_p.append(means.mean(axis=0))
        sd_p.append(sd)
    if pos_p:
        maps.append(FieldMap("postural", np.array(pos_p), np.array(f_p), np.array(sd_p),
                             source=source, metadata={
                                 **common, "postures": json.dumps(
                                     [p for p in postures if any(
                                         w.trial.role == "base" for w in windows[p])])}))
    # static stiffness map
    pos_k, k_k, sd_k = [], [], []
    n_dirs: dict[int, int] = {}
    used_postures = []
    for p in postures:
        ws = windows[p]
        if not any(w.trial.role == "displaced" for w in ws):
            continue
        x0 = base_pos[p]
        dx = np.array([w.position - x0 for w in ws])
        why = _span_problem(dx)
        if why:
            dropped.append(Dropped(f"posture {p} stiffness", why))
            continue
        f = np.array([w.force for w in ws])
        _, k, _, sdk = _regress(dx, f)
        pos_k.append(x0)
        k_k.append(k)
        sd_k.append(sdk)
        n_dirs[p] = sum(w.trial.role == "displaced" for w in ws)
        used_postures.append(p)
    if pos_k:
        maps.append(FieldMap("stiffness", np.array(pos_k), np.array(k_k), np.array(sd_k),
                             source=source, metadata={
                                 **common, "postures": json.dumps(used_postures),
                                 "directions": json.dumps(n_dirs)}))
    # moving stiffness maps, one per pass velocity
    if passes:
        if arm is None:
            raise MapError("passes need the patient's arm for the inertial correction")
        centres = (np.asarray(postures_m, dtype=float) if postures_m is not None
                   else np.array([base_pos[p] for p in sorted(base_pos)]))
        for vel, group in sorted(passes.items()):
            m = _moving_map(rec, arm, group, centres, vel, cfg, dropped)
            if m is not None:
                pts, ks, sds, used = m
                maps.append(FieldMap("stiffness", pts, ks, sds, velocity_m_per_s=vel,
                                     source=source, metadata={
                                         **common, "postures": json.dumps(used),
                                         "inertia": "arm segment inertia subtracted "
                                                    "(Winter anthropometry)",
                                         "passes": str(len(group))}))
    return Estimate(tuple(maps), tuple(sorted(kept)), tuple(dropped),
                    np.array([base_pos[p] for p in postures]) if postures else np.zeros((0, 2)),
                    n_dirs)


def _moving_map(rec: Recording, arm: Arm, group: list[tuple[Trial, slice]],
                centres: FloatArray, vel: tuple[float, float], cfg: EstimatorConfig,
                dropped: list[Dropped]) -> tuple[FloatArray, FloatArray, FloatArray,
                                                 list[int]] | None:
    xs, fs, vs = [], [], []
    dt = 1.0 / rec.rate_hz
    for t, sl in group:
        whole = rec.span(t.start_s, t.stop_s)
        v = rec.velocity_m_per_s[whole]
        win = max(5, round(0.02 / dt) | 1)
        if len(v) <= win:
            dropped.append(Dropped(_trial_name(t), "pass too short to differentiate"))
            continue
        acc = savgol_filter(v, win, 2, deriv=1, delta=dt, axis=0)
        i0, i1 = sl.start - whole.start, sl.stop - whole.start
        x = rec.position_m[sl]
        f = rec.force_n[sl] - hand_inertial_force(arm, x, v[i0:i1], acc[i0:i1])
        # the reflex makes the force steep in the velocity: read only samples on the speed
        on = (np.hypot(*(v[i0:i1] - np.asarray(vel)).T)
              <= cfg.sample_speed_tolerance * math.hypot(*vel))
        xs.append(x[on])
        fs.append(f[on])
        vs.append(v[i0:i1])
    if not xs:
        return None
    x_all = np.concatenate(xs)
    f_all = np.concatenate(fs)
    pts, ks, sds, used = [], [], [], []
    for p, c in enumerate(centres):
        near = np.hypot(*(x_all - c).T) <= cfg.pass_radius_m
        if near.sum() < 10:
            continue
        dx = x_all[near] - c
        why = _span_problem(dx)
        if why:
            dropped.append(Dropped(f"posture {p} stiffness at ({vel[0]:g}, {vel[1]:g}) m/s",
                                   why))
            continue
        _, k, _, sdk = _regress(dx, f_all[near])
        pts.append(c)
        ks.append(k)
        sds.append(sdk)
        used.append(p)
    if not pts:
        return None
    return np.array(pts), np.array(ks), np.array(sds), used
