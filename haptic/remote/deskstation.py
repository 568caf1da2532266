"""The clinician's station of a remote assessment: the station with the desk as its panel.

``python -m fieldbank.haptic.remote.deskstation`` is the station's process of a remote session
(the clinician's site names it: :attr:`haptic.station.launch.StationOptions.program`): the
ordinary station (:mod:`haptic.station`) with :class:`DeskPanel`, a
:class:`~haptic.station.panel.Panel` over the :class:`~haptic.remote.desk.Desk`. The panel
sends ``{"type": "link", …}`` (delay, loss, the passivity controller, warnings) every
:data:`LINK_EVERY_S` and ``{"type": "posterior", …}`` after each probe, answers the page's
``{"cmd": "prior", "groups", "levels", "unimpaired"}`` and
``{"cmd": "assess_answer", "group", "level", "note"}`` itself, adds ``desk.js`` and
``desk.css`` to the page, and asks for frames without muscle forces (the patient's arm is drawn
from its geometry only: its muscles stay at the patient's site).
"""

from __future__ import annotations

import asyncio
import logging
import sys
from collections.abc import Mapping
from importlib import resources
from typing import Any

from fieldbank.errors import FieldbankError
from fieldbank.haptic.errors import AssessError, HapticError
from fieldbank.haptic.remote.desk import Desk
from fieldbank.haptic.station.__main__ import main as station_main
from fieldbank.haptic.station.config import StationConfig
from fieldbank.haptic.station.panel import Publish

log = logging.getLogger("fieldbank.haptic.station")

#: The page's commands the desk answers.
DESK_COMMANDS = ("prior", "assess_answer")
#: How often the desk reads the link's tap, s, and sends the link's figures.
DESK_POLL_S = 0.1
LINK_EVERY_S = 0.25


class DeskPanel:
    """The desk as the station's panel (module docstring)."""

    commands: tuple[str, ...] = DESK_COMMANDS
    muscles: bool = False

    def __init__(self, desk: Desk) -> None:
        self.desk = desk
        self._publish: Publish | None = None

    def assets(self) -> tuple[str, str]:
        pkg = resources.files("fieldbank.haptic.remote")
        return (pkg / "desk.js").read_text("utf-8"), (pkg / "desk.css").read_text("utf-8")

    def page_config(self) -> dict[str, Any]:
        return {"remote": True, "assess": {"groups": self.desk.groups,
                                           "levels": self.desk.levels}}

    async def run(self, publish: Publish) -> None:
        """Read the link's tap, send its figures; classify each probe that ended (in a worker
        thread: the page keeps drawing meanwhile)."""
        self._publish = publish
        desk = self.desk
        loop = asyncio.get_running_loop()
        link_at = 0.0
        while True:
            try:
                ended = desk.poll()
            except (HapticError, ValueError, IndexError) as exc:
                log.warning("link tap: %s", exc)
                ended = []
            if ended:
                await self.reclassify()
            now = loop.time()
            if desk.link and now - link_at >= LINK_EVERY_S:
                link_at = now
                publish("link", desk.link_message())
            await asyncio.sleep(DESK_POLL_S)

    async def reclassify(self) -> None:
        """The posterior of every probe so far, to the page and the assessment log."""
        desk, publish = self.desk, self._publish
        if not desk.probes or publish is None:
            return
        loop = asyncio.get_running_loop()
        try:
            cl = await loop.run_in_executor(None, desk.classify)
        except (FieldbankError, ValueError) as exc:
            log.warning("classification failed: %s", exc)
            publish("posterior", {"type": "posterior", "error": str(exc)})
            return
        if cl is not None:
            publish("posterior", desk.posterior_message(cl))

    async def command(self, cmd: str, args: Mapping[str, Any]) -> Any:
        """``prior`` and ``assess_answer``, in the page's words when refused."""
        desk = self.desk
        if cmd == "prior":
            def names(key: str) -> list[str]:
                v = args.get(key)
                if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
                    raise FieldbankError(f'prior: "{key}" must be a list of names')
                return v
            try:
                desk.set_prior(names("groups"), names("levels"), bool(args.get("unimpaired")))
            except AssessError as exc:
                raise FieldbankError(f"prior: {exc}") from None
            await self.reclassify()
            return {"weights": desk.weights}
        group, level, note = args.get("group"), args.get("level"), args.get("note", "")
        for k, v in (("group", group), ("level", level)):
            if v is not None and not isinstance(v, str):
                raise FieldbankError(f'assess_answer: "{k}" must be a name or null')
        if not isinstance(note, str):
            raise FieldbankError('assess_answer: "note" must be text')
        try:
            return desk.answer(group, level, note)
        except AssessError as exc:
            raise FieldbankError(f"assess_answer: {exc}") from None

    def close(self) -> None:
        self.desk.close()


def desk_panel(config: StationConfig) -> DeskPanel:
    """The panel of the station configured by ``config`` (its ``panel``: the desk's settings)."""
    return DeskPanel(Desk(config.panel))


def main() -> int:
    return station_main(desk_panel)


if __name__ == "__main__":
    sys.exit(main())
