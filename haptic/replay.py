"""Replaying a recorded session offline: the recorded handle motion through the recorded
models, tick by tick, to check that the trace reproduces (and to study it without a robot).

The replay resets both arms where the session did (``reset_arms`` events) and applies the
recorded blend and gain; sessions in which models were pushed mid-way replay only up to the
first push (the models before it are not in the trace).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fieldbank.haptic.pair import build_sim
from fieldbank.haptic.recording import Trace
from fieldbank.params import ArmParams


def rerun(trace: Trace) -> dict[str, Any]:
    """Recompute the model force of every tick; return the deviation from the recording."""
    if len(trace) == 0:
        return {"ticks": 0, "max_deviation_n": 0.0}
    dt = 1.0 / trace.rate_hz
    sims = [build_sim(ArmParams.from_dict(trace.models[k], where=f"trace model {k}"), dt)
            for k in ("A", "B")]
    ox, oy = trace.metadata.get("renderer", {}).get("shoulder_offset_m", (0.0, 0.0))
    resets = [e for e in trace.events if e["event"] == "reset_arms"]
    pushes = [e["t_s"] for e in trace.events if e["event"] == "push"]
    stop_t = min(pushes) if pushes else np.inf
    c = {n: trace.column(n).astype(float) for n in
         ("x_m", "y_m", "vx_m_per_s", "vy_m_per_s", "blend", "gain", "model_fx_n", "model_fy_n")}
    out = np.zeros((len(trace), 2))
    n = 0
    ri = 0
    for i in range(len(trace)):
        t = trace.t_s[i]
        if t >= stop_t:
            break
        while ri < len(resets) and resets[ri]["t_s"] <= t + 1e-12:
            hx, hy = resets[ri]["at_m"]
            for s in sims:
                s.reset_at_hand(hx, hy)
            ri += 1
        x, y = c["x_m"][i] - ox, c["y_m"][i] - oy
        if not (np.isfinite(x) and np.isfinite(y)):
            n += 1
            continue
        fa = sims[0].tick(x, y, c["vx_m_per_s"][i], c["vy_m_per_s"][i])
        fb = sims[1].tick(x, y, c["vx_m_per_s"][i], c["vy_m_per_s"][i])
        w, g = c["blend"][i], c["gain"][i]
        out[i] = (g * ((1 - w) * fa[0] + w * fb[0]), g * ((1 - w) * fa[1] + w * fb[1]))
        n += 1
    rec = np.c_[c["model_fx_n"], c["model_fy_n"]][:n]
    dev = np.linalg.norm(out[:n] - rec, axis=1)
    return {"ticks": n, "max_deviation_n": float(dev.max()) if n else 0.0,
            "rms_deviation_n": float(np.sqrt(np.mean(dev ** 2))) if n else 0.0,
            "stopped_at_push": bool(pushes)}
