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

    {"cmd": "push", "before": {ArmParams}, "after": {ArmParams}, "model_ids": {"A": id, "B": id}}
                                                                        -> Push
    {"cmd": "switch", "to": "A" | "B" | "before" | "after"}              -> Switch
    {"cmd": "abx", "action": "start", "n_trials": 10, "seed": 7, "hide_labels": true}
                                                                        -> AbxStart
    {"cmd": "abx", "action": "present", "label": "A" | "B" | "X"}       -> AbxPresent
    {"cmd": "abx", "action": "answer", "answer": "A" | "B"}             -> AbxAnswer
    {"cmd": "arm"} | {"cmd": "disarm"} | {"cmd": "stop"} | {"cmd": "status"}
                                                                        -> Arm, Disarm, Stop, Status
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

from fieldbank.haptic.abx import AbxSession
from fieldbank.haptic.errors import CommandError, HapticError
from fieldbank.params import ArmParams

if TYPE_CHECKING:  # typing only: compiled arms need numpy, which this table does not
    from fieldbank.sim import ArmSim

#: A command's answer: a JSON-able mapping.
Result = dict[str, Any]
#: Compiled arms A (before) and B (after), built outside the loop.
SimPair = tuple["ArmSim", "ArmSim"]
#: Database ids of the rendered models, ``{"A": id, "B": id}`` (None: not stored).
ModelIds = Mapping[str, "int | None"]


class CommandTarget(Protocol):
    """The renderer as its commands see it (:class:`haptic.renderer.Renderer`)."""

    running: bool
    t_s: float
    abx: AbxSession | None
    abx_results: list[dict[str, Any]]

    @property
    def mode_name(self) -> str: ...
    def crossfade(self, weight: float) -> None: ...
    def log_event(self, kind: str, **data: Any) -> dict[str, Any]: ...
    def compile_pair(self, before: ArmParams, after: ArmParams) -> SimPair: ...
    def queue_models(self, sims: SimPair, params: tuple[ArmParams, ArmParams],
                     model_ids: ModelIds | None) -> None: ...
    def arm(self) -> None: ...
    def disarm(self) -> None: ...
    def request_stop(self) -> None: ...
    def status(self) -> Result: ...


class RendererCommand:
    """Base of every command.

    Attributes
    ----------
    name : str
        The command's name (``Renderer.submit(name, **keywords)`` builds it from
        :data:`COMMANDS`).
    needs_running : bool
        Refused unless the loop runs.
    in_loop : bool
        Applied by the loop at a tick boundary (False: at once, in the caller's thread).
    """

    name: ClassVar[str]
    needs_running: ClassVar[bool] = True
    in_loop: ClassVar[bool] = True

    def prepare(self, target: CommandTarget) -> RendererCommand:
        """The command ready to apply; runs in the caller's thread (default: itself)."""
        del target
        return self

    def apply(self, target: CommandTarget) -> Result:
        raise NotImplementedError

    @classmethod
    def from_json(cls, req: Mapping[str, Any]) -> RendererCommand:
        """The command of a control-channel request (default: one without fields)."""
        del req
        return cls()


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
        return cls(req["to"])

    def apply(self, target: CommandTarget) -> Result:
        w = self.weight
        target.crossfade(w)
        target.log_event("switch", to=w)
        return {"blend_target": w}


@dataclass(frozen=True)
class Push(RendererCommand):
    """Swap in a new pair of models behind a fade (out, swap, in); compiled in ``prepare``."""

    name: ClassVar[str] = "push"
    needs_running: ClassVar[bool] = False
    before: ArmParams
    after: ArmParams
    model_ids: ModelIds | None = None
    sims: SimPair | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        ids = self.model_ids
        if ids is not None and not (isinstance(ids, Mapping) and set(ids) <= {"A", "B"}):
            raise CommandError('push: "model_ids" must be {"A": id, "B": id}')

    @classmethod
    def from_json(cls, req: Mapping[str, Any]) -> Push:
        return cls(ArmParams.from_dict(req["before"], where="push: before"),
                   ArmParams.from_dict(req["after"], where="push: after"),
                   req.get("model_ids"))

    def prepare(self, target: CommandTarget) -> Push:
        if self.sims is not None:
            return self
        return replace(self, sims=target.compile_pair(self.before, self.after))

    def apply(self, target: CommandTarget) -> Result:
        if self.sims is None:
            raise CommandError("push: the models were not compiled (submit it to the renderer)")
        target.queue_models(self.sims, (self.before, self.after), self.model_ids)
        target.log_event("push")
        return {"pushed": True}


@dataclass(frozen=True)
class Arm(RendererCommand):
    """Arm, or re-arm after a fault (refused while the handle state is unsafe)."""

    name: ClassVar[str] = "arm"

    def apply(self, target: CommandTarget) -> Result:
        target.arm()
        return {"mode": target.mode_name}


@dataclass(frozen=True)
class Disarm(RendererCommand):
    """Zero the force and disarm."""

    name: ClassVar[str] = "disarm"

    def apply(self, target: CommandTarget) -> Result:
        target.disarm()
        return {"mode": target.mode_name}


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


def _abx(target: CommandTarget) -> AbxSession:
    if target.abx is None:
        raise CommandError("no A/B/X block running; start one with abx_start")
    return target.abx


@dataclass(frozen=True)
class AbxStart(RendererCommand):
    """Start a block of ``n_trials`` blinded A/B/X trials (:class:`haptic.abx.AbxSession`)."""

    name: ClassVar[str] = "abx_start"
    n_trials: int = 10
    seed: int = 0
    hide_labels: bool = True

    @classmethod
    def from_json(cls, req: Mapping[str, Any]) -> AbxStart:
        return cls(int(req.get("n_trials", 10)), int(req.get("seed", 0)),
                   bool(req.get("hide_labels", True)))

    def apply(self, target: CommandTarget) -> Result:
        abx = AbxSession(self.n_trials, self.seed, self.hide_labels)
        target.abx = abx
        target.log_event("abx_start", n_trials=abx.n_trials, seed=abx.seed)
        return {"trial": 0, "n_trials": abx.n_trials}


@dataclass(frozen=True)
class AbxPresent(RendererCommand):
    """Crossfade to A, B or this trial's X."""

    name: ClassVar[str] = "abx_present"
    label: str

    @classmethod
    def from_json(cls, req: Mapping[str, Any]) -> AbxPresent:
        return cls(str(req["label"]))

    def apply(self, target: CommandTarget) -> Result:
        abx = _abx(target)
        label = str(self.label).upper()
        target.crossfade(float(abx.model_for(label)))
        target.log_event("abx_present", label=label, trial=abx.trial)
        return {"presenting": label, "trial": abx.trial}


@dataclass(frozen=True)
class AbxAnswer(RendererCommand):
    """Record that X felt like 'A' or 'B'; the block's result comes with its last answer."""

    name: ClassVar[str] = "abx_answer"
    answer: str

    @classmethod
    def from_json(cls, req: Mapping[str, Any]) -> AbxAnswer:
        return cls(str(req["answer"]))

    def apply(self, target: CommandTarget) -> Result:
        abx = _abx(target)
        rec = abx.answer(str(self.answer), target.t_s)
        target.log_event("abx_answer", trial=rec["trial"], answer=rec["answer"])
        out: Result = {"trial": rec["trial"] + 1, "done": abx.done}
        if abx.done:
            target.abx_results.append(abx.result())
            out["result"] = abx.result()
            target.abx = None
        return out


#: Every command by its name.
COMMANDS: dict[str, type[RendererCommand]] = {
    c.name: c for c in (Switch, Push, Arm, Disarm, Stop, Status, AbxStart, AbxPresent, AbxAnswer)
}
#: Control-channel ``cmd`` -> command (``abx`` goes by its ``action``: :data:`ABX_ACTIONS`).
WIRE: dict[str, type[RendererCommand]] = {
    "push": Push, "switch": Switch, "status": Status, "arm": Arm, "disarm": Disarm, "stop": Stop,
}
ABX_ACTIONS: dict[str, type[RendererCommand]] = {
    "start": AbxStart, "present": AbxPresent, "answer": AbxAnswer,
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
    if cmd == "abx":
        action = req.get("action")
        cls = ABX_ACTIONS.get(action) if isinstance(action, str) else None
        if cls is None:
            raise CommandError(f"abx action must be start, present or answer; got {action!r}")
        return cls.from_json(req)
    wire = WIRE.get(cmd)
    if wire is None:
        raise CommandError(f"unknown control command {cmd!r}; known: push, switch, abx, status, "
                           f"arm, disarm, stop")
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
