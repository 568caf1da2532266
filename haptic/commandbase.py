"""What every renderer command is built on: the :class:`RendererCommand` base, the renderer as
commands see it (:class:`CommandTarget`), and the bounded readers of a request's fields.

The commands themselves and the tables that name them are :mod:`haptic.commands`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar, Protocol, TypeAlias

from fieldbank.haptic.abx import AbxSession
from fieldbank.haptic.errors import CommandError
from fieldbank.haptic.modelinfo import ModelIds, ModelInfoPair
from fieldbank.haptic.training import TrainingSession
from fieldbank.params import ArmParams

if TYPE_CHECKING:  # typing only
    from fieldbank.armkernel import ArmPair

#: A command's answer: a JSON-able mapping.
Result = dict[str, Any]
#: Compiled arms A (before) and B (after), built outside the loop.
SimPair: TypeAlias = "ArmPair"


class CommandTarget(Protocol):
    """The renderer as its commands see it (:class:`haptic.renderer.Renderer`)."""

    running: bool
    t_s: float
    abx: AbxSession | None
    abx_results: list[dict[str, Any]]
    training: TrainingSession | None
    training_results: list[dict[str, Any]]

    @property
    def mode_name(self) -> str: ...
    def crossfade(self, weight: float) -> None: ...
    def log_event(self, kind: str, **data: Any) -> dict[str, Any]: ...
    def compile_pair(self, before: ArmParams, after: ArmParams) -> SimPair: ...
    def queue_models(self, sims: SimPair, params: tuple[ArmParams, ArmParams],
                     model_ids: ModelIds | None,
                     model_info: ModelInfoPair | None = None, session: bool = True) -> None: ...
    def require_armed(self, what: str) -> None: ...
    def open_window(self) -> None: ...
    def trial_window(self) -> dict[str, Any]: ...
    def begin_training(self) -> None: ...
    def end_training(self) -> None: ...
    def felt(self) -> Result: ...
    def arm(self) -> None: ...
    def disarm(self) -> None: ...
    def request_stop(self) -> None: ...
    def status(self) -> Result: ...
    def info(self) -> Result: ...


def int_field(req: Mapping[str, Any], key: str, default: int, lo: int, hi: int,
              where: str) -> int:
    """An integer field of a request, ``lo`` ≤ value ≤ ``hi`` (an integer or its digits;
    never a bool, a fraction, NaN or infinity)."""
    v = req.get(key, default)
    ok = not isinstance(v, bool) and isinstance(v, (int, str, float))
    n = None
    if ok:
        try:
            if isinstance(v, float):
                n = int(v) if v.is_integer() else None
            else:
                n = int(v)
        except (ValueError, OverflowError):
            n = None
    if n is None or not lo <= n <= hi:
        raise CommandError(f'{where}: "{key}" must be an integer from {lo} to {hi}; got {v!r}')
    return n


def bool_field(req: Mapping[str, Any], key: str, default: bool, where: str) -> bool:
    v = req.get(key, default)
    if v not in (True, False):  # also 0 and 1
        raise CommandError(f'{where}: "{key}" must be true or false; got {v!r}')
    return bool(v)


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
