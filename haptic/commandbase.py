"""What every renderer command is built on: the :class:`RendererCommand` base, the renderer as
commands see it (:class:`CommandTarget`), and the bounded readers of a request's fields.

The commands themselves and the tables that name them are :mod:`haptic.commands`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar, Protocol

from fieldbank.haptic.activities.base import Activities, ActivityHost
from fieldbank.haptic.errors import CommandError

#: A command's answer: a JSON-able mapping.
Result = dict[str, Any]


class CommandTarget(ActivityHost, Protocol):
    """The renderer as its commands see it (:class:`haptic.renderer.Renderer`): the loop as
    its activities see it (:class:`~haptic.activities.base.ActivityHost`: time, safety state,
    models, events), its activities, arming and its read-outs."""

    running: bool
    activities: Activities

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
