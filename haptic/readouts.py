"""What a running renderer tells other processes besides the per-tick snapshot.

* :func:`status` - what ``fieldbank haptic status`` shows: mode, what is felt, blend, force,
  the latched faults in words with what to do, why a re-arm would be refused now, whether a
  protocol is paused, the loop's timing over the last 10 s, the A/B/X trial and the training
  state;
* :func:`felt` - the renderer's true state in a few fields, the answer to ``switch`` and
  ``push``;
* :func:`info` - what a display needs once (the clinician's station): the models and their
  parameters, the arm geometry, the workspace, the A/B/X block and the training protocol.

Both are read in the caller's thread and compute nothing heavy. While an A/B/X block or a
training assessment runs (:attr:`LoopView.blinded`), which model is rendered is hidden: the blend
reads "hidden", and so do the models and their parameters.
"""

from __future__ import annotations

from typing import Any, Protocol

from fieldbank.haptic.abx import AbxSession
from fieldbank.haptic.commands import Result
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.loopstats import status_figures
from fieldbank.haptic.modelinfo import describe_text
from fieldbank.haptic.pair import ModelPair
from fieldbank.haptic.protocol import FaultCode
from fieldbank.haptic.safety import Safety
from fieldbank.haptic.training import TrainingSession


class LoopView(Protocol):
    """The renderer as its read-outs see it (:class:`haptic.renderer.Renderer`)."""

    running: bool
    t_s: float
    ticks: int
    fx: float
    fy: float
    link: RobotLink
    safety: Safety
    pair: ModelPair
    events: list[dict[str, Any]]
    metadata: dict[str, Any]
    abx: AbxSession | None
    abx_results: list[dict[str, Any]]
    training: TrainingSession | None

    @property
    def blinded(self) -> bool: ...
    @property
    def rate_hz(self) -> int: ...
    @property
    def shoulder_offset_m(self) -> tuple[float, float]: ...
    def loop_stats(self, last: int | None = None) -> dict[str, Any]: ...
    def arm_problems(self) -> list[str]: ...


def _felt_now(rd: LoopView) -> str:
    tr = rd.training
    if rd.blinded:
        return "hidden (blinded)"
    if tr is not None and not tr.done:
        cur = tr.current
        return "training arm" + (f": {cur.legend}" if cur is not None else "")
    w = rd.pair.blend.value
    return "A (before)" if w < 0.5 else "B (after)"


def fault_state(rd: LoopView) -> Result:
    """The faults latched now, each in words with what to do; why a re-arm would be refused
    now (empty when it would be accepted); whether a running protocol waits for a re-arm."""
    s = rd.safety
    armed = s.mode.name == "ARMED"
    running = rd.abx is not None or (rd.training is not None and not rd.training.done)
    return {
        "faults_now": [r.explained() for r in s.latched_records()],
        "rearm_refused_because": [] if armed else rd.arm_problems(),
        "paused": running and not armed,
    }


def felt(rd: LoopView) -> Result:
    """The renderer's true state in a few fields: mode, what is felt, the blend (hidden while
    blinded), the gain, whether pushed models are still being swapped in, and the faults."""
    w = rd.pair.blend
    return {
        "mode": rd.safety.mode.name, "felt": _felt_now(rd),
        "blend": "hidden" if rd.blinded else w.value,
        "blend_target": "hidden" if rd.blinded else w.end,
        "gain": rd.pair.gain.value, "swapping": rd.pair.swapping,
        **fault_state(rd),
    }


def status(rd: LoopView) -> Result:
    """What ``fieldbank haptic status`` shows (the blend is hidden while blinded)."""
    s = rd.safety
    return {
        "running": rd.running, "mode": s.mode.name, "t_s": round(rd.t_s, 4),
        "ticks": rd.ticks, "gain": rd.pair.gain.value,
        "blend": "hidden" if rd.blinded else rd.pair.blend.value,
        "felt": _felt_now(rd), "swapping": rd.pair.swapping, **fault_state(rd),
        "force_n": [rd.fx, rd.fy],
        "handle_m": [rd.link.x, rd.link.y],
        "latched_faults": [c.name for c in FaultCode if s.latched & (1 << (c - 1))],
        "faults_logged": len(s.log_records),
        "loop_last_10s": status_figures(rd.loop_stats(last=10 * rd.rate_hz)),
        "abx_trial": None if rd.abx is None else rd.abx.trial,
        "models": models(rd),
        "training": None if rd.training is None else rd.training.state(rd.t_s),
    }


def models(rd: LoopView) -> dict[str, Any] | str:
    """What the renderer was told about models A and B (every field, None where unknown), or
    "hidden" while blinded."""
    if rd.blinded:
        return "hidden"
    known = rd.metadata.get("model_info") or {}
    ids = rd.metadata.get("model_ids") or {}
    out: dict[str, Any] = {}
    for k in ("A", "B"):
        d = {"label": None, "model_id": ids.get(k), "patient": None, "plan": None,
             "plan_id": None}
        d.update({f: v for f, v in dict(known.get(k) or {}).items() if v is not None})
        d["text"] = describe_text(d)
        out[k] = d
    return out


def info(rd: LoopView) -> Result:
    """What a display needs besides the snapshot (:class:`~haptic.commands.Info`)."""
    blinded = rd.blinded
    params = rd.pair.params
    geometry = {}
    for k, p in zip(("A", "B"), params, strict=True):
        geometry[k] = {"upper_arm_m": p.upper_arm_length_m, "forearm_m": p.forearm_length_m,
                       "side": p.side, "shoulder_range_rad": list(p.shoulder_range_rad),
                       "elbow_range_rad": list(p.elbow_range_rad)}
    abx = rd.abx
    return {
        "running": rd.running, "mode": rd.safety.mode.name, "t_s": rd.t_s,
        "events": len(rd.events), "blinded": blinded, "felt": _felt_now(rd),
        **fault_state(rd),
        "models": models(rd),
        "params": None if blinded else {"A": params[0].to_dict(), "B": params[1].to_dict()},
        "geometry": geometry,
        "shoulder_offset_m": list(rd.shoulder_offset_m),
        "force_limit_n": rd.safety.config.force_limit_n,
        "safety_workspace_m": list(rd.safety.config.workspace_m),
        "abx": None if abx is None else {"trial": abx.trial, "n_trials": abx.n_trials,
                                         "done": abx.done},
        "abx_last_result": rd.abx_results[-1] if rd.abx_results else None,
        "training": None if rd.training is None else rd.training.state(rd.t_s),
    }
