"""The renderer's commands: one typed table for the control channel and for callers in process.

Every request to a renderer is one of the frozen values below. A command

1. is built from keywords (``Switch(target="B")``, ``AbxStart(n_trials=10, seed=7)``) or parsed
   from its control-channel request by :func:`parse_request` (each class's ``from_json``);
   malformed input raises :class:`~fieldbank.haptic.errors.CommandError` or the core's
   ``ParameterError``, naming the field;
2. is prepared in the caller's thread (:meth:`RendererCommand.prepare`: slow work such as
   compiling pushed models, never in the loop);
3. is applied by the loop at the start of a tick (:meth:`RendererCommand.apply`), so the loop's
   state has one owner; a command that only reads (``in_loop = False``: status) is applied at
   once in the caller's thread instead, so it never costs the loop a tick.

The renderer answers each through a :class:`Request` (``wait()`` returns the result or raises
the command's error).

Control-channel requests (JSON lines, :mod:`haptic.control`) and the command each becomes::

    {"cmd": "push", "before": {ArmParams}, "after": {ArmParams}, "model_ids": {"A": id, "B": id},
     "model_info": {"A": {"label": …, "model_id": …, "patient": …, "plan": …}, "B": {…}}}
                                                                        -> Push
    {"cmd": "switch", "to": "A" | "B" | "before" | "after"}              -> Switch
    {"cmd": "abx", "action": "start", "n_trials": 10, "seed": 7}
                                                                        -> AbxStart
    {"cmd": "abx", "action": "present", "label": "A" | "B" | "X"}       -> AbxPresent
    {"cmd": "abx", "action": "answer", "answer": "A" | "B"}             -> AbxAnswer
    {"cmd": "abx", "action": "stop"}                                    -> AbxStop
    {"cmd": "train", "action": "start", "protocol": {TrainingProtocol}} -> TrainStart
    {"cmd": "train", "action": "next"}                                  -> TrainNext
    {"cmd": "train", "action": "answer", "answer": "shoulder" | "elbow" | "both"}
                                                                        -> TrainAnswer
    {"cmd": "train", "action": "stop"}                                  -> TrainStop
    {"cmd": "arm"} | {"cmd": "disarm"} | {"cmd": "stop"} | {"cmd": "status"} | {"cmd": "info"}
                                                                  -> Arm, Disarm, Stop, Status, Info

Every number that arrives is bounded (trial counts, seeds, model ids): a request can make the
renderer do only a bounded amount of work.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

from fieldbank.haptic.activities.abx import MAX_ABX_TRIALS, AbxBlock
from fieldbank.haptic.activities.base import Activity
from fieldbank.haptic.activities.training import NextTrial, Training
from fieldbank.haptic.commandbase import CommandTarget, RendererCommand, Result, int_field
from fieldbank.haptic.errors import CommandError, HapticError
from fieldbank.haptic.modelinfo import (
    ModelIds,
    ModelInfoPair,
    check_model_ids,
    model_info_pair,
)
from fieldbank.haptic.pair import SimPair
from fieldbank.haptic.safety import Mode
from fieldbank.haptic.training import TrainingProtocol
from fieldbank.params import ArmParams

_SWITCH_WEIGHTS: dict[object, float] = {"A": 0.0, "B": 1.0, "before": 0.0, "after": 1.0,
                                        0: 0.0, 1: 1.0}


@dataclass(frozen=True)
class Switch(RendererCommand):
    """Crossfade to model A (before) or B (after): ``target`` 'A'/'before'/0 or 'B'/'after'/1."""

    name: ClassVar[str] = "switch"
    needs_running: ClassVar[bool] = False
    target: object

    def __post_init__(self) -> None:
        try:
            known = self.target in _SWITCH_WEIGHTS
        except TypeError:  # an unhashable JSON value
            known = False
        if not known:
            raise CommandError(f"switch to 'before'/'A' or 'after'/'B'; got {self.target!r}")

    @property
    def weight(self) -> float:
        """Blend weight of the target: 0 = A, 1 = B."""
        return _SWITCH_WEIGHTS[self.target]

    @classmethod
    def from_json(cls, req: Mapping[str, Any]) -> Switch:
        return cls(req.get("to"))

    def apply(self, target: CommandTarget) -> Result:
        if target.safety.mode == Mode.FAULT:
            target.safety.require_armed("switch")
        run = target.activities.running
        if run is not None and run.owns_blend:
            raise CommandError("switch refused: a blinded block or a training protocol runs; "
                               "it chooses what is felt")
        w = self.weight
        target.pair.crossfade(w)
        target.log_event("switch", to=w)
        return {"blend_target": w, **target.felt()}


@dataclass(frozen=True)
class Push(RendererCommand):
    """Swap in a new pair of models behind a fade (out, swap, in); compiled in ``prepare``."""

    name: ClassVar[str] = "push"
    needs_running: ClassVar[bool] = False
    before: ArmParams
    after: ArmParams
    model_ids: ModelIds | None = None
    model_info: ModelInfoPair | None = None
    sims: SimPair | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        check_model_ids(self.model_ids)
        # records, or their wire dictionaries when built in process: records from here on
        object.__setattr__(self, "model_info", model_info_pair(self.model_info))

    @classmethod
    def from_json(cls, req: Mapping[str, Any]) -> Push:
        for k in ("before", "after"):
            if not isinstance(req.get(k), Mapping):
                raise CommandError(f'push: "{k}" must be an arm-parameter object')
        return cls(ArmParams.from_dict(req["before"], where="push: before"),
                   ArmParams.from_dict(req["after"], where="push: after"),
                   check_model_ids(req.get("model_ids")), model_info_pair(req.get("model_info")))

    def prepare(self, target: CommandTarget) -> Push:
        if self.sims is not None:
            return self
        return replace(self, sims=target.pair.compile(self.before, self.after))

    def apply(self, target: CommandTarget) -> Result:
        if self.sims is None:
            raise CommandError("push: the models were not compiled (submit it to the renderer)")
        run = target.activities.running
        if run is not None and run.owns_models:
            raise CommandError(f"push refused: {run.title} is running (stop it first)")
        if target.safety.mode == Mode.FAULT:
            target.safety.require_armed("push")
        target.queue_models(self.sims, (self.before, self.after), self.model_ids,
                            self.model_info)
        target.log_event("push", model_ids=dict(self.model_ids or {}))
        return {"pushed": True, **target.felt()}


@dataclass(frozen=True)
class Arm(RendererCommand):
    """Arm, or re-arm after a fault (refused while the handle state is unsafe)."""

    name: ClassVar[str] = "arm"

    def apply(self, target: CommandTarget) -> Result:
        target.arm()
        return {"mode": target.safety.mode.name}


@dataclass(frozen=True)
class Disarm(RendererCommand):
    """Zero the force and disarm."""

    name: ClassVar[str] = "disarm"

    def apply(self, target: CommandTarget) -> Result:
        target.disarm()
        return {"mode": target.safety.mode.name}


@dataclass(frozen=True)
class Stop(RendererCommand):
    """End the session after this tick."""

    name: ClassVar[str] = "stop"
    needs_running: ClassVar[bool] = False

    def apply(self, target: CommandTarget) -> Result:
        target.request_stop()
        target.log_event("stop")
        return {"stopping": True}


@dataclass(frozen=True)
class Status(RendererCommand):
    """Mode, blend, force, faults and the recent loop figures (read in the caller's thread)."""

    name: ClassVar[str] = "status"
    needs_running: ClassVar[bool] = False
    in_loop: ClassVar[bool] = False

    def apply(self, target: CommandTarget) -> Result:
        return target.status()


@dataclass(frozen=True)
class Info(RendererCommand):
    """What a display shows besides the loop's snapshot: the models (unless blinded), the arm
    geometry, the A/B/X block and the training protocol (read in the caller's thread, cheap)."""

    name: ClassVar[str] = "info"
    needs_running: ClassVar[bool] = False
    in_loop: ClassVar[bool] = False

    def apply(self, target: CommandTarget) -> Result:
        return target.info()


#: Why an A/B/X step or a training step was refused: none is running.
NO_ABX = ("no A/B/X block running; start one with 'fieldbank haptic abx start' (or the "
          "station's A/B/X button)")
NO_TRAINING = "no training protocol running; start one with train start"


def _abx(target: CommandTarget) -> AbxBlock:
    act = target.activities.addressed(AbxBlock.kind)
    if not isinstance(act, AbxBlock):
        raise CommandError(NO_ABX)
    return act


def _training(target: CommandTarget) -> Training:
    act = target.activities.addressed(Training.kind)
    if not isinstance(act, Training):
        raise CommandError(NO_TRAINING)
    return act


def _stepped(target: CommandTarget, act: Activity, out: Result) -> Result:
    """``out``, once the activity's finished result is kept (if this step finished it)."""
    target.activities.after_step(act)
    return out


@dataclass(frozen=True)
class AbxStart(RendererCommand):
    """Start a block of ``n_trials`` blinded A/B/X trials (:class:`haptic.activities.abx.AbxBlock`):
    A is always before and B after; only X is hidden. A block still running is closed first,
    its answers kept."""

    name: ClassVar[str] = "abx_start"
    n_trials: int = 10
    seed: int = 0

    def __post_init__(self) -> None:
        int_field({"n_trials": self.n_trials}, "n_trials", 10, 1, MAX_ABX_TRIALS, "abx start")
        int_field({"seed": self.seed}, "seed", 0, 0, 2**63 - 1, "abx start")

    @classmethod
    def from_json(cls, req: Mapping[str, Any]) -> AbxStart:
        if req.get("hide_labels"):
            raise CommandError('abx start: "hide_labels" is not offered: A is always the model '
                               "before and B the one after; only X is hidden")
        return cls(int_field(req, "n_trials", 10, 1, MAX_ABX_TRIALS, "abx start"),
                   int_field(req, "seed", 0, 0, 2**63 - 1, "abx start"))

    def apply(self, target: CommandTarget) -> Result:
        return target.activities.start(AbxBlock(self.n_trials, self.seed), target)


@dataclass(frozen=True)
class AbxPresent(RendererCommand):
    """Crossfade to A, B or this trial's X."""

    name: ClassVar[str] = "abx_present"
    label: str

    def __post_init__(self) -> None:
        if not isinstance(self.label, str) or self.label.upper() not in ("A", "B", "X"):
            raise CommandError(f"A/B/X presents 'A', 'B' or 'X'; got {self.label!r}")

    @classmethod
    def from_json(cls, req: Mapping[str, Any]) -> AbxPresent:
        return cls(req.get("label"))  # type: ignore[arg-type]  # checked when made

    def apply(self, target: CommandTarget) -> Result:
        return _abx(target).present(target, self.label)


@dataclass(frozen=True)
class AbxAnswer(RendererCommand):
    """Record that X felt like 'A' or 'B'; the block's result comes with its last answer."""

    name: ClassVar[str] = "abx_answer"
    answer: str

    def __post_init__(self) -> None:
        if not isinstance(self.answer, str) or self.answer.upper() not in ("A", "B"):
            raise CommandError(f"an A/B/X answer is 'A' or 'B'; got {self.answer!r}")

    @classmethod
    def from_json(cls, req: Mapping[str, Any]) -> AbxAnswer:
        return cls(req.get("answer"))  # type: ignore[arg-type]  # checked when made

    def apply(self, target: CommandTarget) -> Result:
        act = _abx(target)
        return _stepped(target, act, act.answer(target, self.answer))


@dataclass(frozen=True)
class AbxStop(RendererCommand):
    """End the A/B/X block early; the answers so far are kept and scored."""

    name: ClassVar[str] = "abx_stop"

    def apply(self, target: CommandTarget) -> Result:
        act = _abx(target)
        return _stepped(target, act, act.stop(target))


@dataclass(frozen=True)
class TrainStart(RendererCommand):
    """Start the seed's training protocol (:mod:`haptic.activities.training`); ``train_next``
    presents the first trial."""

    name: ClassVar[str] = "train_start"
    protocol: TrainingProtocol = field(default_factory=TrainingProtocol)

    @classmethod
    def from_json(cls, req: Mapping[str, Any]) -> TrainStart:
        return cls(TrainingProtocol.from_dict(req.get("protocol") or {}))

    def apply(self, target: CommandTarget) -> Result:
        return target.activities.start(Training(self.protocol), target)


@dataclass(frozen=True)
class TrainNext(RendererCommand):
    """Present the next trial's arm (compiled in the caller's thread, swapped in behind the push
    fade); after the last trial, close the protocol."""

    name: ClassVar[str] = "train_next"
    activity: Training | None = field(default=None, compare=False, repr=False)
    trial: NextTrial | None = field(default=None, compare=False, repr=False)

    def prepare(self, target: CommandTarget) -> TrainNext:
        act = _training(target)
        return replace(self, activity=act, trial=act.prepare(target))

    def apply(self, target: CommandTarget) -> Result:
        act = _training(target)
        if self.activity is not act or self.trial is None:
            raise CommandError("train next: the training protocol changed; ask again")
        return _stepped(target, act, act.next(target, self.trial))


@dataclass(frozen=True)
class TrainAnswer(RendererCommand):
    """Record the answer to the current assessment trial: 'shoulder', 'elbow' or 'both'."""

    name: ClassVar[str] = "train_answer"
    answer: str

    def __post_init__(self) -> None:
        if not isinstance(self.answer, str) or len(self.answer) > 16:
            raise CommandError(f"a training answer is shoulder, elbow or both; got "
                               f"{self.answer!r}")

    @classmethod
    def from_json(cls, req: Mapping[str, Any]) -> TrainAnswer:
        return cls(req.get("answer"))  # type: ignore[arg-type]  # checked when made

    def apply(self, target: CommandTarget) -> Result:
        act = _training(target)
        return _stepped(target, act, act.answer(target, self.answer))


@dataclass(frozen=True)
class TrainStop(RendererCommand):
    """End the training protocol early; the trials so far are kept (marked abandoned)."""

    name: ClassVar[str] = "train_stop"

    def apply(self, target: CommandTarget) -> Result:
        act = _training(target)
        return _stepped(target, act, act.stop(target))


#: Every command by its name.
COMMANDS: dict[str, type[RendererCommand]] = {
    c.name: c for c in (Switch, Push, Arm, Disarm, Stop, Status, Info, AbxStart, AbxPresent,
                        AbxAnswer, AbxStop, TrainStart, TrainNext, TrainAnswer, TrainStop)
}
#: Control-channel ``cmd`` -> command (``abx`` and ``train`` go by their ``action``).
WIRE: dict[str, type[RendererCommand]] = {
    "push": Push, "switch": Switch, "status": Status, "info": Info, "arm": Arm,
    "disarm": Disarm, "stop": Stop,
}
ABX_ACTIONS: dict[str, type[RendererCommand]] = {
    "start": AbxStart, "present": AbxPresent, "answer": AbxAnswer, "stop": AbxStop,
}
TRAIN_ACTIONS: dict[str, type[RendererCommand]] = {
    "start": TrainStart, "next": TrainNext, "answer": TrainAnswer, "stop": TrainStop,
}


def from_name(name: str, args: Mapping[str, Any]) -> RendererCommand:
    """The command ``name`` built from keywords (``from_name("switch", {"target": "B"})``)."""
    cls = COMMANDS.get(name)
    if cls is None:
        raise CommandError(f"unknown renderer command {name!r}; known: {', '.join(COMMANDS)}")
    return cls(**args)


def parse_request(req: Mapping[str, Any]) -> RendererCommand:
    """The command of one control-channel request (module docstring)."""
    cmd = req.get("cmd")
    if not isinstance(cmd, str):
        raise CommandError('a request is a JSON object with a "cmd" string')
    for group, actions in (("abx", ABX_ACTIONS), ("train", TRAIN_ACTIONS)):
        if cmd == group:
            action = req.get("action")
            cls = actions.get(action) if isinstance(action, str) else None
            if cls is None:
                *first, last = actions
                raise CommandError(f"{group} action must be {', '.join(first)} or {last}; got "
                                   f"{action!r}")
            return cls.from_json(req)
    wire = WIRE.get(cmd)
    if wire is None:
        raise CommandError(f"unknown control command {cmd!r}; known: push, switch, abx, train, "
                           f"status, info, arm, disarm, stop")
    return wire.from_json(req)


class Request:
    """A submitted command; :meth:`wait` returns its result or raises its error.

    Set once, by the thread that applies the command (the loop, or the submitter for commands
    applied at once); read by the submitter.
    """

    __slots__ = ("command", "done", "error", "name", "result")

    def __init__(self, name: str, command: RendererCommand | None = None) -> None:
        self.name = name
        self.command = command
        self.done = threading.Event()
        self.result: Result | None = None
        self.error: Exception | None = None

    def run(self, target: CommandTarget) -> None:
        """Apply the command to ``target`` and answer (a bad command never raises out)."""
        try:
            if self.command is None:
                raise CommandError(f"renderer command {self.name!r} was not built")
            self.result = self.command.apply(target)
        except Exception as exc:  # answered to the submitter, never raised into the loop
            self.error = exc
        self.done.set()

    def fail(self, error: Exception) -> Request:
        """Answer with ``error`` without running."""
        self.error = error
        self.done.set()
        return self

    def wait(self, timeout_s: float = 2.0) -> Result:
        """The command's result, or its error raised; HapticError after ``timeout_s`` s."""
        if not self.done.wait(timeout_s):
            raise HapticError(f"the renderer did not answer {self.name!r} within {timeout_s} s")
        if self.error is not None:
            raise self.error
        assert self.result is not None
        return self.result
