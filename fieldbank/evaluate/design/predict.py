"""Predicted force: what each candidate puts on the handle along a path, executions of a
path within the motion noise, and which paths every candidate can follow.

The force a candidate puts on the handle along a path is what a hand moving the rigid arm along
it feels: the muscles' endpoint force at the path's positions and velocities
(:meth:`fieldbank.model.Arm.endpoint_force`: the reflex sees the velocity) plus the arm's
inertia, −J⁻ᵀ(H q̈ + C q̇) (:func:`fieldbank.dynamics.hand_inertial_force`), saturated at the
renderer's force limit. The inertia matters: on a stroke of 0.2 s it is as large as a severe
group's force, the same for every candidate, and hides their differences. The renderer's
virtual coupling (a spring and damper between handle and hand) is left out; the classifier
replays it (:mod:`fieldbank.evaluate.classify`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from fieldbank.armbatch import by_geometry
from fieldbank.dynamics import hand_inertial_force
from fieldbank.evaluate.design.candidates import Candidate
from fieldbank.evaluate.design.config import NoiseModel, ProbeLimits
from fieldbank.evaluate.probing import ProbeMotion
from fieldbank.model import Arm, FloatArray


def execution_deltas(noise: NoiseModel) -> list[tuple[float, float, float]]:
    """(rotation deg, length scale, speed scale) of the nominal execution and ±1 SD of each."""
    out = [(0.0, 1.0, 1.0)]
    if noise.direction_sd_deg > 0:
        out += [(noise.direction_sd_deg, 1.0, 1.0), (-noise.direction_sd_deg, 1.0, 1.0)]
    if noise.length_sd > 0:
        out += [(0.0, 1.0 + noise.length_sd, 1.0), (0.0, 1.0 - noise.length_sd, 1.0)]
    if noise.speed_sd > 0:
        out += [(0.0, 1.0, 1.0 + noise.speed_sd), (0.0, 1.0, 1.0 - noise.speed_sd)]
    return out


def execute_path(pos: FloatArray, vel: FloatArray, t: FloatArray,
                 deltas: Sequence[tuple[float, float, float]], closed: bool = False
                 ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Executions of S paths (S, K, ·) → (S, E, K, ·): each rotated about and scaled from its
    anchor - the first point of an open path (where the hand starts), the centre of a closed
    one (a circle around the equilibrium stays around it) - its speed scaled."""
    p0 = pos.mean(axis=1)[:, None, None, :] if closed else pos[:, None, :1, :]
    rel = pos[:, None, :, :] - p0
    pe, ve, te = [], [], []
    for rot, scale, speed in deltas:
        c, s = math.cos(math.radians(rot)), math.sin(math.radians(rot))
        r = np.array([[c, -s], [s, c]]) * scale
        pe.append(rel @ r.T)
        ve.append(vel[:, None] @ r.T * speed)
        te.append(t[:, None] / speed)
    return (p0 + np.concatenate(pe, axis=1), np.concatenate(ve, axis=1),
            np.concatenate(te, axis=1))


def executions(motion: ProbeMotion, noise: NoiseModel, closed: bool = False
               ) -> list[ProbeMotion]:
    """The nominal execution of ``motion`` and ±1 SD of each kind of motion noise."""
    deltas = execution_deltas(noise)
    pos, vel, t = execute_path(motion.positions_m[None], motion.velocities_m_per_s[None],
                           motion.times_s[None], deltas, closed)
    return [ProbeMotion(motion.name, t[0, e], pos[0, e], vel[0, e], motion.description)
            for e in range(len(deltas))]


def draw_execution(motion: ProbeMotion, noise: NoiseModel, rng: np.random.Generator,
                   closed: bool = False) -> ProbeMotion:
    """One execution of ``motion`` as an operator with ``noise`` performs it: direction, length
    and speed drawn from the noise model (truncated at ±2.5 SD, speed and length at ≥ 0.3)."""
    z = np.clip(rng.standard_normal(3), -2.5, 2.5)
    rot = float(z[0] * noise.direction_sd_deg)
    scale = max(0.3, 1.0 + float(z[1]) * noise.length_sd)
    speed = max(0.3, 1.0 + float(z[2]) * noise.speed_sd)
    pos, vel, t = execute_path(motion.positions_m[None], motion.velocities_m_per_s[None],
                           motion.times_s[None], [(rot, scale, speed)], closed)
    return ProbeMotion(motion.name, t[0, 0], pos[0, 0], vel[0, 0],
                       f"{motion.description} (executed: {rot:+.0f}°, length ×{scale:.2f}, "
                       f"speed ×{speed:.2f})")


def saturate(force_n: FloatArray, limit_n: float) -> FloatArray:
    """Force vectors (..., 2) scaled down to a norm of at most ``limit_n``, as the renderer."""
    mag = np.hypot(force_n[..., 0], force_n[..., 1])
    k = np.where(mag > limit_n, limit_n / np.maximum(mag, 1e-300), 1.0)
    return force_n * k[..., None]


def path_accelerations(velocities_m_per_s: FloatArray, times_s: FloatArray) -> FloatArray:
    """Accelerations (..., K, 2), m/s², of evenly sampled paths: velocities (..., K, 2), times
    (..., K)."""
    dt = times_s[..., 1] - times_s[..., 0]
    acc = np.gradient(velocities_m_per_s, axis=-2, edge_order=2)
    return np.asarray(acc / dt[..., None, None], dtype=float)


def predict(candidates: Sequence[Candidate], positions_m: FloatArray,
            velocities_m_per_s: FloatArray, force_limit_n: float | None,
            accelerations_m_per_s2: FloatArray | None = None) -> FloatArray:
    """Force each candidate puts on the handle, shape (n, ..., 2), N: the muscles' endpoint
    force, plus the rigid arm's inertia when the accelerations are given."""
    shape = positions_m.shape
    x = positions_m.reshape(-1, 2)
    v = velocities_m_per_s.reshape(-1, 2)
    acc = None if accelerations_m_per_s2 is None else accelerations_m_per_s2.reshape(-1, 2)
    arms = [c.arm for c in candidates]
    out = np.empty((len(arms), *shape))
    inertial: dict[tuple[object, ...], FloatArray] = {}
    for idx, batch in by_geometry(arms):  # the candidates of one geometry in one pass
        forces = batch.endpoint_force(x, v)
        for i, f in zip(idx, forces, strict=True):
            if acc is not None:
                key = _inertia_key(arms[i])
                if key not in inertial:
                    inertial[key] = hand_inertial_force(arms[i], x, v, acc)
                f = f + inertial[key]
            out[i] = f.reshape(shape)
    return out if force_limit_n is None else saturate(out, force_limit_n)


def _inertia_key(arm: Arm) -> tuple[object, ...]:
    p = arm.params
    return (arm.l1, arm.l2, arm.mirror, p.upper_arm_mass_kg, p.forearm_mass_kg,
            p.upper_arm_com_m, p.forearm_com_m, p.upper_arm_inertia_kg_m2,
            p.forearm_inertia_kg_m2)


def _geometry_key(arm: Arm) -> tuple[object, ...]:
    p = arm.params
    return (arm.l1, arm.l2, arm.mirror, p.shoulder_range_rad, p.elbow_range_rad)


def feasible(candidates: Sequence[Candidate], positions_m: FloatArray,
             velocities_m_per_s: FloatArray, limits: ProbeLimits) -> FloatArray:
    """Which of S paths (S, M, 2) respect the limits for every candidate: mask (S,)."""
    s_count = positions_m.shape[0]
    pts = positions_m.reshape(s_count, -1, 2)
    vel = velocities_m_per_s.reshape(s_count, -1, 2)
    ok = np.all(np.isfinite(pts), axis=(1, 2)) & np.all(np.isfinite(vel), axis=(1, 2))
    ok &= np.hypot(vel[..., 0], vel[..., 1]).max(axis=1) <= limits.max_speed_m_per_s * (1 + 1e-9)
    if limits.workspace_m is not None:
        x0, x1, y0, y1 = limits.workspace_m
        ok &= np.all((pts[..., 0] >= x0) & (pts[..., 0] <= x1) & (pts[..., 1] >= y0)
                     & (pts[..., 1] <= y1), axis=1)
    margin = math.radians(limits.rom_margin_deg)
    flat = pts.reshape(-1, 2)
    seen: set[tuple[object, ...]] = set()
    for c in candidates:
        key = _geometry_key(c.arm)
        if key in seen:
            continue
        seen.add(key)
        good = c.arm.reachable(flat)
        if margin > 0 and good.any():
            q = c.arm.ik(flat[good])
            p = c.arm.params
            (s0, s1), (e0, e1) = p.shoulder_range_rad, p.elbow_range_rad
            inside = ((q[:, 0] >= s0 + margin) & (q[:, 0] <= s1 - margin)
                      & (q[:, 1] >= e0 + margin) & (q[:, 1] <= e1 - margin))
            good[np.flatnonzero(good)] = inside
        ok &= good.reshape(s_count, -1).all(axis=1)
    return ok
