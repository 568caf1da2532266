"""What a panel of the station page is: computed in the station's process beside the arm, with
its own messages, commands and page assets (:class:`Panel`).

The station (:mod:`haptic.station.server`) draws the arm from the loop's snapshot and forwards
the page's commands to the renderer. A panel adds what a particular kind of session shows
besides: a remote assessment's link figures and posterior (:mod:`haptic.remote.deskstation`).
The station knows panels only through this protocol; a panel's process is started by naming
its program (:attr:`haptic.station.launch.StationOptions.program`), whose ``main`` hands its
panel to :func:`haptic.station.__main__.main`, and it reads its settings from
:attr:`haptic.station.config.StationConfig.panel`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, Protocol

#: Sends the newest message of a kind to every page (``publish(kind, message)``; the message
#: is a JSON-able mapping with ``"type": kind``); a page receives each message once, and only
#: the newest of a kind when it connects.
Publish = Callable[[str, Mapping[str, Any]], None]


class Panel(Protocol):
    """A panel of the station page (module docstring).

    Attributes
    ----------
    commands : tuple of str
        The page's commands the panel answers itself (never forwarded to the renderer).
    muscles : bool
        Whether frames carry the models' muscle forces (False: the arm is drawn from its
        geometry only).
    """

    commands: tuple[str, ...]
    muscles: bool

    def assets(self) -> tuple[str, str]:
        """The script and the style appended to the station page's own."""
        ...

    def page_config(self) -> dict[str, Any]:
        """What the page knows from the start (merged into the page's configuration)."""
        ...

    async def run(self, publish: Publish) -> None:
        """Produce the panel's messages until cancelled."""
        ...

    async def command(self, cmd: str, args: Mapping[str, Any]) -> Any:
        """Answer one of :attr:`commands` (a :class:`~fieldbank.errors.FieldbankError` in the
        page's words when it cannot)."""
        ...

    def close(self) -> None:
        """Release what the panel holds (the station stops)."""
        ...
