"""Scripted probing on a robot: run a motion, return the force profile the handle felt.

With the built-in simulated robot (``sim://``, lockstep) the run is faster than real time and
deterministic; the operator's hand follows the seed's probing motion through its own impedance
(:mod:`haptic.simrobot`). Any other robot URL runs in real time. The profile comes with the
static field prediction of the model at the handle positions (:meth:`Arm.endpoint_force`), so
the rendering can be checked against the model.

Any probe of :mod:`fieldbank.evaluate` - a designed stroke, the seed's pull or semi-ellipse -
runs the same way (:func:`probe_path`): its :class:`~fieldbank.probepath.ProbePath`
becomes the simulated operator's ``path`` motion, optionally with the hand's wander. A recorded
trace becomes an :class:`~fieldbank.evaluate.classify.Observation` for the classifier
(:func:`observation_from_trace`).
"""

from __future__ import annotations

import math
import urllib.parse
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fieldbank.errors import ParameterError
from fieldbank.evaluate.observation import Observation
from fieldbank.evaluate.probing import ProbeMotion
from fieldbank.haptic.clock import VirtualClock
from fieldbank.haptic.dbsink import SESSION_PREFIX, read_trace_db
from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.motions import LEAD_IN_S, MOTIONS, format_path, motion_duration_s
from fieldbank.haptic.recording import Trace, read_trace_h5
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.safety import SafetyConfig
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.probepath import ProbePath
from fieldbank.redact import mask_url
from fieldbank.storage import Database


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
            "rms_error_vs_static_n": float(np.sqrt(np.nanmean(np.sum(
                (f - self.predicted_n) ** 2, axis=1)))) if len(f) else 0.0,
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
            base: str = "sim://", seed: int = 0, extra: dict[str, str] | None = None) -> str:
    """A ``sim://`` URL whose operator starts the motion at the arm's rest hand position
    (``extra``: further :class:`~haptic.simrobot.SimRobotConfig` fields)."""
    parts = urllib.parse.urlsplit(base)
    query = dict(urllib.parse.parse_qsl(parts.query))
    x0, y0 = Arm.from_params(params).rest_position()
    query.setdefault("motion", motion)
    query.setdefault("x0_m", f"{float(x0) + offset_m[0]:.6f}")
    query.setdefault("y0_m", f"{float(y0) + offset_m[1]:.6f}")
    query.setdefault("seed", str(seed))
    for k, v in (extra or {}).items():
        query.setdefault(k, v)
    return "sim://?" + urllib.parse.urlencode(query)


def probe(params: ArmParams, motion: str = "pull", robot: str | None = None,
          rate_hz: int = 1000, duration_s: float | None = None, seed: int = 0,
          safety: SafetyConfig | None = None,
          offset_m: tuple[float, float] = (0.0, 0.0), path_text: str = "",
          wander_m: float = 0.0) -> ProbeResult:
    """Render ``params`` while the (simulated) operator performs ``motion`` (``path``: the
    polyline ``path_text`` of :func:`haptic.motions.format_path`, robot frame), its hand
    wandering by ``wander_m``."""
    if motion not in MOTIONS:
        raise ParameterError(f"unknown motion {motion!r}; known: {', '.join(MOTIONS)}")
    url = given = robot or "sim://"
    simulated = url.startswith("sim://")
    if simulated:
        extra = {"motion_path": path_text} if motion == "path" else {}
        if wander_m > 0:
            extra["operator_wander_m"] = f"{wander_m:g}"
        url = sim_url(params, motion, offset_m, url, seed, extra)
    lockstep = simulated and "mode=realtime" not in url
    link = RobotLink.open(url, shown=given)
    try:
        link.handshake(rate_hz, 20)
        cfg = RendererConfig(rate_hz=rate_hz, state_wait_s=0.05 if lockstep else 0.0,
                             shoulder_offset_m=offset_m, realtime_priority=not lockstep)
        rd = Renderer(link, params, params, cfg, safety=safety,
                      clock=VirtualClock() if lockstep else None)
        rd.metadata.update({"robot": mask_url(url), "motion": motion})
        # a lockstep device answered the handshake with its first STATE already
        trace = rd.run(duration_s if duration_s is not None
                       else motion_duration_s(motion, path_text=path_text),
                       first_state_timeout_s=0.05 if lockstep else 1.0)
    finally:
        link.close()
    pos = np.c_[trace.column("x_m") - offset_m[0], trace.column("y_m") - offset_m[1]]
    pos = pos.astype(float)
    arm = Arm.from_params(params)
    # where the operator pushed the handle beyond the arm's reach there is no static field
    pred = np.full((len(pos), 2), np.nan)
    ok = np.all(np.isfinite(pos), axis=1)
    ok[ok] = arm.reachable(pos[ok])
    if ok.any():
        pred[ok] = arm.endpoint_force(pos[ok])
    return ProbeResult(motion, trace, pred)


def probe_path(params: ArmParams, motion: ProbeMotion | ProbePath, robot: str | None = None,
               rate_hz: int = 1000, seed: int = 0, safety: SafetyConfig | None = None,
               offset_m: tuple[float, float] = (0.0, 0.0), wander_m: float = 0.0,
               settle_s: float = 0.2) -> ProbeResult:
    """Render ``params`` while the (simulated) operator follows a probe of
    :mod:`fieldbank.evaluate` (a :class:`ProbeMotion` in the shoulder frame, or its
    :class:`ProbePath` in the robot frame), after the lead-in and for ``settle_s`` after."""
    drawn = motion.path(offset_m) if isinstance(motion, ProbeMotion) else motion
    text = format_path([(t, x, y) for t, (x, y) in zip(drawn.times_s, drawn.points_m,
                                                       strict=True)])
    res = probe(params, "path", robot, rate_hz, LEAD_IN_S + drawn.duration_s + settle_s, seed,
                safety, offset_m, text, wander_m)
    res.trace.metadata["probe"] = drawn.to_dict()
    return ProbeResult(drawn.name, res.trace, res.predicted_n)


def observation_from_trace(trace: Trace, name: str = "trace", source: str = "",
                           model: str | None = None) -> Observation:
    """A recorded haptic trace as an :class:`Observation` for the classifier.

    Handle positions in the shoulder frame (minus the renderer's shoulder offset), the force
    commanded on the handle, the renderer's output gain and force limit, and where it last put
    the virtual arms at rest before the counted ticks (the replay starts there).

    Parameters
    ----------
    model : 'A' or 'B', optional
        Count only the ticks rendering this model alone (blend 0 for A, 1 for B). By default
        every tick when the trace rendered one model as both A and B, else model A's ticks.
    """
    if len(trace) < 3:
        raise HapticError(f"{source or name}: the trace has {len(trace)} ticks; at least 3 are "
                          "needed to classify it")
    if model is None:
        model = None if trace.models.get("A") == trace.models.get("B") else "A"
    if model not in (None, "A", "B"):
        raise HapticError(f"model must be 'A' or 'B'; got {model!r}")
    blend = trace.column("blend").astype(float)
    counted = np.ones(len(trace), dtype=bool) if model is None else \
        np.abs(blend - (0.0 if model == "A" else 1.0)) < 1e-6
    if counted.sum() < 3:
        raise HapticError(f"{source or name}: fewer than 3 ticks render model {model} alone; "
                          "nothing to classify")
    first = int(np.argmax(counted))
    resets = [e for e in trace.events
              if e.get("event") == "reset_arms" and e["t_s"] <= trace.t_s[first] + 1e-9]
    start, reset = 0, None
    if resets:
        start = int(np.searchsorted(trace.t_s, resets[-1]["t_s"] - 1e-9))
        hx, hy = resets[-1]["at_m"]
        reset = (float(hx), float(hy))
    ox, oy = trace.metadata.get("renderer", {}).get("shoulder_offset_m", (0.0, 0.0))
    limit = trace.metadata.get("safety", {}).get("force_limit_n")
    sl = slice(start, len(trace))
    col = {c: trace.column(c)[sl].astype(float) for c in
           ("x_m", "y_m", "vx_m_per_s", "vy_m_per_s", "fx_n", "fy_n", "gain")}
    return Observation.from_arrays(
        name, trace.t_s[sl], np.c_[col["x_m"] - ox, col["y_m"] - oy], np.c_[col["fx_n"],
                                                                          col["fy_n"]],
        np.c_[col["vx_m_per_s"], col["vy_m_per_s"]],
        force_limit_n=float(limit) if limit else None, reset_m=reset,
        source=source or name, output_gain=col["gain"], counted=counted[sl])


#: The largest id a stored row holds (PostgreSQL's ``integer``).
MAX_ID = 2**31 - 1


def read_observations(refs: Sequence[str], db_url: str | None = None, model: str | None = None,
                      offset_m: tuple[float, float] | None = None) -> list[Observation]:
    """The recorded probing motions ``refs`` name, for the classifier: a haptic trace file
    (``.h5``), a stored haptic session (``haptic_session:ID``, read from the database at
    ``db_url``) or an observation CSV (:meth:`Observation.from_csv`, ``offset_m`` its shoulder
    in the file's frame). ``model`` picks the ticks of a trace (:func:`observation_from_trace`).
    A reference that names nothing is refused with its text."""
    out = []
    for ref in refs:
        if ref.startswith(SESSION_PREFIX):
            text = ref[len(SESSION_PREFIX):].strip()
            if not (text.isascii() and text.isdigit() and 1 <= int(text) <= MAX_ID):
                raise ParameterError(f"{ref!r} names no haptic session: ids are whole numbers "
                                     f"from 1 to {MAX_ID}")
            with Database.open(db_url, create=False) as db:
                trace = read_trace_db(db, int(text))
            out.append(observation_from_trace(trace, ref, ref, model))
        elif not Path(ref).is_file():
            raise ParameterError(f"no trace file {ref!r} (nor {SESSION_PREFIX}ID)")
        elif Path(ref).suffix.lower() in (".h5", ".hdf5"):
            out.append(observation_from_trace(read_trace_h5(ref), Path(ref).stem, ref, model))
        else:
            out.append(Observation.from_csv(ref, offset_m))
    return out
