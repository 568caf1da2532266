"""What a running renderer tells other processes besides the per-tick snapshot.

* :func:`status` - what ``fieldbank haptic status`` shows: mode, what is felt, blend, force,
  the latched faults in words with what to do, why a re-arm would be refused now, whether a
  protocol is paused, the loop's timing over the last 10 s, the A/B/X trial and the training
  state;
* :func:`felt` - the renderer's true state in a few fields, the answer to ``switch`` and
  ``push``;
* :func:`info` - what a display needs once (the clinician's station): the models and their
  parameters, the arm geometry, the workspace, the A/B/X block and the training protocol.

Both are read in the caller's thread and compute nothing heavy. While the running activity is
blinded (an A/B/X block, a training assessment: :attr:`haptic.activities.base.Activity.blinded`),
which model is rendered is hidden: the blend reads "hidden", and so do the models and their
parameters.
"""

from __future__ import annotations

from typing import Any, Protocol

from fieldbank.haptic.activities.abx import AbxBlock
from fieldbank.haptic.activities.base import Activities
from fieldbank.haptic.activities.training import Training
from fieldbank.haptic.commandbase import Result
from fieldbank.haptic.loopstats import status_figures
from fieldbank.haptic.modelinfo import describe_text
from fieldbank.haptic.monitor import SafetyMonitor
from fieldbank.haptic.pair import ModelPair
from fieldbank.haptic.protocol import FaultCode
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.safety import Safety


class LoopView(Protocol):
    """The renderer as its read-outs see it (:class:`haptic.renderer.Renderer`)."""

    running: bool
    t_s: float
    ticks: int
    fx: float
    fy: float
    config: RendererConfig
    monitor: SafetyMonitor
    safety: Safety
    pair: ModelPair
    activities: Activities
    events: list[dict[str, Any]]
    metadata: dict[str, Any]

    def loop_stats(self, last: int | None = None) -> dict[str, Any]: ...


def _abx(rd: LoopView) -> AbxBlock | None:
    act = rd.activities.addressed(AbxBlock.kind)
    return act if isinstance(act, AbxBlock) else None


def _training(rd: LoopView) -> Training | None:
    act = rd.activities.addressed(Training.kind)
    return act if isinstance(act, Training) else None


def _felt_now(rd: LoopView) -> str:
    if rd.activities.blinded:
        return "hidden (blinded)"
    run = rd.activities.running
    if isinstance(run, Training):
        cur = run.session.current
        return "training arm" + (f": {cur.legend}" if cur is not None else "")
    w = rd.pair.blend.value
    return "A (before)" if w < 0.5 else "B (after)"


def fault_state(rd: LoopView) -> Result:
    """The faults latched now, each in words with what to do; why a re-arm would be refused
    now (empty when it would be accepted); whether a running protocol waits for a re-arm."""
    s = rd.safety
    armed = s.mode.name == "ARMED"
    return {
        "faults_now": [r.explained() for r in s.latched_records()],
        "rearm_refused_because": [] if armed else rd.monitor.problems(rd.running),
        "paused": rd.activities.running is not None and not armed,
    }


def felt(rd: LoopView) -> Result:
    """The renderer's true state in a few fields: mode, what is felt, the blend (hidden while
    blinded), the gain, whether pushed models are still being swapped in, and the faults."""
    w = rd.pair.blend
    blinded = rd.activities.blinded
    return {
        "mode": rd.safety.mode.name, "felt": _felt_now(rd),
        "blend": "hidden" if blinded else w.value,
        "blend_target": "hidden" if blinded else w.end,
        "gain": rd.pair.gain.value, "swapping": rd.pair.swapping,
        **fault_state(rd),
    }


def status(rd: LoopView) -> Result:
    """What ``fieldbank haptic status`` shows (the blend is hidden while blinded)."""
    s = rd.safety
    abx, tr = _abx(rd), _training(rd)
    st = rd.monitor.state
    return {
        "running": rd.running, "mode": s.mode.name, "t_s": round(rd.t_s, 4),
        "ticks": rd.ticks, "gain": rd.pair.gain.value,
        "blend": "hidden" if rd.activities.blinded else rd.pair.blend.value,
        "felt": _felt_now(rd), "swapping": rd.pair.swapping, **fault_state(rd),
        "force_n": [rd.fx, rd.fy],
        "handle_m": [st.x, st.y],
        "latched_faults": [c.name for c in FaultCode if s.latched & (1 << (c - 1))],
        "faults_logged": len(s.log_records),
        "loop_last_10s": status_figures(rd.loop_stats(last=10 * rd.config.rate_hz)),
        "abx_trial": None if abx is None else abx.trial,
        "models": models(rd),
        "training": None if tr is None else tr.state(rd.t_s),
    }


def models(rd: LoopView) -> dict[str, Any] | str:
    """What the renderer was told about models A and B (every field, None where unknown), or
    "hidden" while blinded."""
    if rd.activities.blinded:
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
    blinded = rd.activities.blinded
    params = rd.pair.params
    geometry = {}
    for k, p in zip(("A", "B"), params, strict=True):
        geometry[k] = {"upper_arm_m": p.upper_arm_length_m, "forearm_m": p.forearm_length_m,
                       "side": p.side, "shoulder_range_rad": list(p.shoulder_range_rad),
                       "elbow_range_rad": list(p.elbow_range_rad)}
    abx, tr = _abx(rd), _training(rd)
    abx_done = rd.activities.results.get(AbxBlock.kind)
    return {
        "running": rd.running, "mode": rd.safety.mode.name, "t_s": rd.t_s,
        "events": len(rd.events), "blinded": blinded, "felt": _felt_now(rd),
        **fault_state(rd),
        "models": models(rd),
        "params": None if blinded else {"A": params[0].to_dict(), "B": params[1].to_dict()},
        "geometry": geometry,
        "shoulder_offset_m": list(rd.config.shoulder_offset_m),
        "force_limit_n": rd.safety.config.force_limit_n,
        "safety_workspace_m": list(rd.safety.config.workspace_m),
        "abx": None if abx is None else abx.state(rd.t_s),
        "abx_last_result": abx_done[-1] if abx_done else None,
        "training": None if tr is None else tr.state(rd.t_s),
    }
