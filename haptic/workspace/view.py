"""The robot view inside the workspace: the station's page, behind the workspace's login.

A :class:`fieldbank.web.routes.RouteProvider`. ``/robot`` serves the clinician's station page
(:func:`haptic.station.server.page_html`: the arm drawn from the loop's snapshot, A ↔ B, A/B/X,
training) with a way back to the patient; its WebSocket is ``/robot/ws``, authenticated by the
workspace's session instead of the station's token, and the origin checked like every other
socket. Anyone who may read watches; only a role that may drive the robot sends commands
(:data:`haptic.station.server.PAGE_COMMANDS`: switch, A/B/X, training, arm, disarm). The frames
come from a :class:`~haptic.station.server.Station` over the running renderer of the
:class:`~haptic.workspace.host.RendererHost`; when the host starts another renderer, open pages
are disconnected and reconnect to it.

API routes: ``GET /api/robot`` (status), ``POST /api/robot/push`` (stored models by id, as
``haptic push``), ``POST /api/robot/stop`` (end the session; its trace is recorded).
"""

from __future__ import annotations

import asyncio
import contextlib
import html
import json
from collections.abc import Sequence
from typing import Any

from aiohttp import WSMsgType, web

from fieldbank import modelsource
from fieldbank.haptic.station.config import StationConfig, new_token
from fieldbank.haptic.station.server import MAX_PAGE_MESSAGE, MAX_PAGES, Station, page_html
from fieldbank.haptic.training import TrainingProtocol
from fieldbank.haptic.workspace.host import RendererHost
from fieldbank.web.robot import FeelPair
from fieldbank.web.routes import ApiError, Asset, Call, Route, need, optional

#: How often an open page checks that its renderer is still the current one, s.
WATCH_S = 0.25
_IDLE = """<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>fieldbank robot view</title><link rel="stylesheet" href="/static/core/app.css"></head>
<body><main class="idle-robot"><h1>Robot view</h1><p>No session is running on the robot
({robot}). Open a patient's plan composer and choose <b>Feel it</b>: the robot starts with
the model before (A) and the model after (B).</p><p><a href="/">Back to the workspace</a></p>
</main></body></html>"""


class RobotViewRoutes:
    """The robot view's routes over a :class:`RendererHost`."""

    name = "robot"

    def __init__(self, host: RendererHost) -> None:
        self.host = host
        self._station: Station | None = None
        self._generation = -1
        self._producer: asyncio.Task[None] | None = None
        self._pages = 0

    def assets(self) -> Sequence[Asset]:
        return ()

    def routes(self) -> Sequence[Route]:
        t = ("robot",)
        return [
            Route("GET", "/robot", self.page, "read", "The robot view (page)", api=False),
            Route("GET", "/robot/ws", self.socket, "read", "The robot view's socket",
                  api=False),
            Route("GET", "/api/robot", self.status, "read",
                  "Whether a session runs on the robot, for which patient, its state", tags=t),
            Route("POST", "/api/robot/push", self.push, "robot",
                  "Push stored models A (before) and B (after) to the robot, starting its "
                  "renderer (a simulated robot when none is configured)",
                  body={"type": "object", "required": ["a_model_id"],
                        "properties": {"a_model_id": {"type": "integer"},
                                       "b_model_id": {"type": "integer"}}}, tags=t),
            Route("POST", "/api/robot/stop", self.stop, "robot",
                  "End the session on the robot (its trace is written and recorded)", tags=t),
        ]

    # --- the station over the current renderer ------------------------------------------------
    def _current(self) -> Station | None:
        run = self.host.current
        if run is None:
            self._drop()
            return None
        if self._station is None or self._generation != run.generation:
            self._drop()
            proto = TrainingProtocol.seed_protocol().to_dict()
            cfg = StationConfig(str(run.snapshot_path), str(run.socket_path), new_token(),
                                training=proto)
            self._station = Station(cfg)
            self._generation = run.generation
        return self._station

    def _drop(self) -> None:
        if self._producer is not None:
            self._producer.cancel()
            self._producer = None
        if self._station is not None:
            self._station.reader.close()
            self._station = None

    def _nav(self) -> str:
        run = self.host.current
        where = (f"/#/patients/{run.patient}/compose" if run is not None and run.patient
                 else "/")
        return (f'<nav class="app-nav" aria-label="workspace"><a href="{html.escape(where)}">'
                "← back to the plan</a></nav>")

    async def page(self, call: Call) -> web.StreamResponse:
        station = self._current()
        if station is None:
            return web.Response(text=_IDLE.replace("{robot}", html.escape(self.host.robot_shown)),
                                content_type="text/html")
        body, csp = page_html(station, {"ws_path": "/robot/ws",
                                        "can_drive": call.user.may("robot")}, self._nav())
        resp = web.Response(text=body, content_type="text/html")
        resp.headers["Content-Security-Policy"] = csp
        return resp

    async def socket(self, call: Call) -> web.StreamResponse:
        station = self._current()
        if station is None:
            raise ApiError(409, "no session is running on the robot")
        if self._pages >= MAX_PAGES:
            raise ApiError(503, "too many robot views open")
        ws = web.WebSocketResponse(max_msg_size=MAX_PAGE_MESSAGE, heartbeat=10.0)
        await ws.prepare(call.request)
        self._pages += 1
        if self._producer is None or self._producer.done():
            self._producer = asyncio.create_task(station.produce())
        generation = self._generation
        pump = asyncio.create_task(station.pump(ws))
        watch = asyncio.create_task(self._watch(ws, generation))
        may_drive = call.user.may("robot")
        try:
            async for msg in ws:
                if msg.type != WSMsgType.TEXT:
                    continue
                try:
                    data = json.loads(msg.data)
                except ValueError:
                    continue
                if not isinstance(data, dict):
                    continue
                if data.get("cmd") == "page_stats":
                    continue
                if not may_drive:
                    await ws.send_json({"type": "reply", "id": data.get("id") if isinstance(
                        data.get("id"), int) else None, "ok": False,
                        "error": f"a {call.user.role} may watch the robot but not drive it"})
                    continue
                await ws.send_json(await station.command(data))
        finally:
            pump.cancel()
            watch.cancel()
            self._pages -= 1
            if self._pages == 0 and self._producer is not None:
                self._producer.cancel()
                self._producer = None
        return ws

    async def _watch(self, ws: web.WebSocketResponse, generation: int) -> None:
        """Close the page's socket when its renderer is no longer the current one (the page
        reconnects to the next)."""
        while not ws.closed:
            await asyncio.sleep(WATCH_S)
            run = self.host.current
            if run is None or run.generation != generation:
                with contextlib.suppress(ConnectionError, RuntimeError):
                    await ws.close(code=1012, message=b"the robot's session changed")
                return

    # --- API ------------------------------------------------------------------------------------
    async def status(self, call: Call) -> Any:
        return await call.run(self.host.status)

    async def push(self, call: Call) -> Any:
        body = await call.json()
        a_id = need(body, "a_model_id", int, "the stored model before (A)")
        b_id = optional(body, "b_model_id", int, a_id)
        actor = call.user.name

        def work() -> dict[str, Any]:
            a = modelsource.stored(call.db, a_id)
            b = modelsource.stored(call.db, b_id)
            if a.patient_code != b.patient_code:
                raise ApiError(400, f"models {a_id} and {b_id} belong to different patients")
            plans = [p for p in call.db.list_plans(b.patient_code)
                     if p.result_model_id == b_id]
            pair = FeelPair(a.params, b.params, (a_id, b_id), a.patient_code,
                            (a.description, b.description),
                            plans[-1].label if plans else "",
                            plans[-1].id if plans else None, actor)
            return self.host.feel(pair)

        return await call.run(work)

    async def stop(self, call: Call) -> Any:
        return await call.run(self.host.stop)

