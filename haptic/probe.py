"""Scripted probing on a robot: run a motion, return the force profile the handle felt.

With the built-in simulated robot (``sim://``, lockstep) the run is faster than real time and
deterministic; the operator's hand follows the seed's probing motion through its own impedance
(:mod:`haptic.simrobot`). Any other robot URL runs in real time. The profile comes with the
static field prediction of the model at the handle positions (:meth:`Arm.endpoint_force`), so
the rendering can be checked against the model.
"""

from __future__ import annotations

import math
import urllib.parse
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fieldbank.haptic.clock import VirtualClock
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.motions import MOTIONS, motion_duration_s
from fieldbank.haptic.recording import Trace
from fieldbank.haptic.renderer import Renderer, RendererConfig
from fieldbank.haptic.safety import SafetyConfig
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.redact import mask_url


@dataclass(frozen=True)
class ProbeResult:
    """Force profile of one probing motion (robot frame; force on the handle, N)."""

    motion: str
    trace: Trace
    predicted_n: NDArray[np.float64]     # (N, 2) static field at the handle positions

    def table(self, every: int = 1) -> list[dict[str, float]]:
        t = self.trace
        rows = []
        for i in range(0, len(t), every):
            rows.append({"t_s": float(t.t_s[i]), "x_m": float(t.column("x_m")[i]),
                         "y_m": float(t.column("y_m")[i]), "fx_n": float(t.column("fx_n")[i]),
                         "fy_n": float(t.column("fy_n")[i]),
                         "static_fx_n": float(self.predicted_n[i, 0]),
                         "static_fy_n": float(self.predicted_n[i, 1])})
        return rows

    def summary(self) -> dict[str, Any]:
        t = self.trace
        f = np.c_[t.column("fx_n"), t.column("fy_n")].astype(float)
        mag = np.hypot(f[:, 0], f[:, 1])
        i = int(np.argmax(mag)) if len(mag) else 0
        pos = np.c_[t.column("x_m"), t.column("y_m")].astype(float)
        return {
            "motion": self.motion,
            "duration_s": float(len(t) / t.rate_hz),
            "peak_force_n": float(mag[i]) if len(mag) else 0.0,
            "peak_at_s": float(t.t_s[i]) if len(mag) else 0.0,
            "peak_direction_deg": float(math.degrees(math.atan2(f[i, 1], f[i, 0])))
            if len(mag) else 0.0,
            "path_length_m": float(np.sum(np.hypot(*np.diff(pos, axis=0).T))) if len(pos) > 1
            else 0.0,
            "rms_error_vs_static_n": float(np.sqrt(np.mean(np.sum((f - self.predicted_n) ** 2,
                                                                  axis=1)))) if len(f) else 0.0,
            "faults": t.faults,
        }

    def to_csv(self) -> str:
        cols = ["t_s", "x_m", "y_m", "fx_n", "fy_n", "static_fx_n", "static_fy_n"]
        lines = [f"# motion: {self.motion}", "# frame: robot", "# sign: force on the handle",
                 ",".join(cols)]
        for r in self.table():
            lines.append(",".join(f"{r[c]:.6g}" for c in cols))
        return "\n".join(lines) + "\n"


def sim_url(params: ArmParams, motion: str, offset_m: tuple[float, float] = (0.0, 0.0),
            base: str = "sim://", seed: int = 0) -> str:
    """A ``sim://`` URL whose operator starts the motion at the arm's rest hand position."""
    parts = urllib.parse.urlsplit(base)
    query = dict(urllib.parse.parse_qsl(parts.query))
    x0, y0 = Arm.from_params(params).rest_position()
    query.setdefault("motion", motion)
    query.setdefault("x0_m", f"{float(x0) + offset_m[0]:.6f}")
    query.setdefault("y0_m", f"{float(y0) + offset_m[1]:.6f}")
    query.setdefault("seed", str(seed))
    return "sim://?" + urllib.parse.urlencode(query)


def probe(params: ArmParams, motion: str = "pull", robot: str | None = None,
          rate_hz: int = 1000, duration_s: float | None = None, seed: int = 0,
          safety: SafetyConfig | None = None,
          offset_m: tuple[float, float] = (0.0, 0.0)) -> ProbeResult:
    """Render ``params`` while the (simulated) operator performs ``motion``."""
    if motion not in MOTIONS:
        raise ValueError(f"unknown motion {motion!r}; known: {', '.join(MOTIONS)}")
    url = robot or "sim://"
    simulated = url.startswith("sim://")
    if simulated:
        url = sim_url(params, motion, offset_m, url, seed)
    lockstep = simulated and "mode=realtime" not in url
    link = RobotLink.open(url)
    try:
        link.handshake(rate_hz, 20)
        cfg = RendererConfig(rate_hz=rate_hz, state_wait_s=0.05 if lockstep else 0.0,
                             shoulder_offset_m=offset_m, realtime_priority=not lockstep)
        rd = Renderer(link, params, params, cfg, safety=safety,
                      clock=VirtualClock() if lockstep else None)
        rd.metadata.update({"robot": mask_url(url), "motion": motion})
        trace = rd.run(duration_s if duration_s is not None else motion_duration_s(motion))
    finally:
        link.close()
    pos = np.c_[trace.column("x_m") - offset_m[0], trace.column("y_m") - offset_m[1]]
    pred = Arm.from_params(params).endpoint_force(pos.astype(float)) if len(pos) else \
        np.zeros((0, 2))
    return ProbeResult(motion, trace, np.asarray(pred, dtype=float))
