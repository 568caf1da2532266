"""The station's web server (aiohttp), run in its own process by :mod:`haptic.station.launch`.

It reads the loop's snapshot (:mod:`haptic.snapshot`) at the page's frame rate and never
touches the loop otherwise: everything it asks of the renderer goes through the renderer's
control socket (:mod:`haptic.client`), exactly like ``fieldbank haptic switch``.

Routes (each refuses a request without the session's token, 403)::

    GET /?token=T        the page (HTML with its script and style; no other resource)
    GET /ws?token=T      WebSocket: frames and info out, the page's commands in
    GET /stats?token=T   JSON: connected pages and the frame rate each one draws

Out on the WebSocket (JSON)::

    {"type": "frame", "t_s", "handle_m", "elbow_m", "hand_m", "force_n", "mode", "faults",
     "gain", "blend" (null when blinded), "blinded", "muscles_n" (6, null when blinded)}
    {"type": "info", ...}          models (or "hidden"), workspace, A/B/X and training state
    {"type": "reply", "id", "ok", "result" | "error"}

In (JSON): ``{"id": n, "cmd": "switch", "to": "A"|"B"}``, ``{"cmd": "abx", "action": …}``,
``{"cmd": "train", "action": …}``, ``{"cmd": "arm"}``, ``{"cmd": "disarm"}``,
``{"cmd": "page_stats", "fps": …}``. Nothing else is forwarded: the page cannot push models or
stop the session.

A station with a panel (:class:`~haptic.station.panel.Panel`: a remote assessment's desk,
:mod:`haptic.remote.deskstation`) also sends the panel's messages, answers the panel's commands
through the panel, and adds its script and style to the page; a panel may ask for frames
without muscle forces (the arm drawn from its geometry only).

Blinding: while the snapshot says an A/B/X block or a training assessment runs, frames carry no
blend and no muscle forces, and the info names no model (the renderer hides them too).
"""

from __future__ import annotations

import asyncio
import hmac
import json
import logging
import math
import secrets
from collections.abc import Awaitable, Callable, Mapping
from importlib import resources
from typing import Any

import numpy as np
from aiohttp import WSMsgType, web

from fieldbank.errors import FieldbankError
from fieldbank.evaluate.severity import MUSCLE_GROUP_NAMES
from fieldbank.haptic.client import ControlClient
from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.protocol import FaultCode
from fieldbank.haptic.safety import Mode
from fieldbank.haptic.snapshot import SnapshotReader
from fieldbank.haptic.station.config import StationConfig
from fieldbank.haptic.station.panel import Panel
from fieldbank.haptic.training import TrainingProtocol
from fieldbank.logthrottle import ThrottledLog
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.sanitize import printable

log = logging.getLogger("fieldbank.haptic.station")

#: Commands a page may send, and the actions allowed for the grouped ones.
PAGE_COMMANDS: dict[str, tuple[str, ...] | None] = {
    "switch": None, "arm": None, "disarm": None,
    "abx": ("start", "present", "answer"),
    "train": ("start", "next", "answer", "stop"),
}
#: Largest message a page may send, bytes.
MAX_PAGE_MESSAGE = 4096
#: Most pages connected at once.
MAX_PAGES = 8
#: How often the info is fetched even when nothing changed, s.
INFO_REFRESH_S = 2.0
#: Refused requests are logged at most this often per reason, with counts, s.
REFUSED_LOG_INTERVAL_S = 1.0


def _fault_names(mask: int) -> list[str]:
    return [c.name for c in FaultCode if mask & (1 << (c - 1))]


class Geometry:
    """The arms as drawn: segment lengths, side, and (unless blinded) the muscle models."""

    def __init__(self, info: Mapping[str, Any]) -> None:
        geo = info.get("geometry") or {}
        self.segments = {k: (float(g["upper_arm_m"]), float(g["forearm_m"]),
                             -1.0 if g.get("side") == "left" else 1.0)
                         for k, g in geo.items()}
        params = info.get("params") or {}
        self.arms: dict[str, Arm] = {}
        for k, d in params.items():
            try:
                self.arms[k] = Arm.from_params(ArmParams.from_dict(d, where=f"model {k}"))
            except FieldbankError as exc:  # drawn without muscle colours
                log.warning("model %s cannot be compiled for the display: %s", k, exc)

    def points(self, key: str, q1: float, q2: float) -> tuple[list[float], list[float]]:
        l1, l2, m = self.segments.get(key, (0.3, 0.35, 1.0))
        ex, ey = l1 * math.cos(q1), l1 * math.sin(q1)
        hx, hy = ex + l2 * math.cos(q1 + q2), ey + l2 * math.sin(q1 + q2)
        return [m * ex, ey], [m * hx, hy]

    def muscles(self, key: str, q: tuple[float, float], qd: tuple[float, float]) -> list[float]:
        """Tension of each muscle group (sf, se, ef, ee, bf, be), N: passive + reflex."""
        arm = self.arms.get(key)
        if arm is None:
            return []
        lam = arm.muscle_lengths(np.array([q]))
        psi, _ = arm.passive_forces(lam)
        phi = arm.reflex_forces(lam, arm.muscle_velocities(np.array([qd])))[0]
        return [round(float(v), 3) for v in (psi + phi)[0]]


def workspace_outline(info: Mapping[str, Any], key: str = "A",
                      samples: int = 24) -> list[list[float]]:
    """The hand positions reachable within the range of motion: the image of the boundary of
    the joint-range rectangle, shoulder frame, m."""
    g = (info.get("geometry") or {}).get(key)
    if not g:
        return []
    l1, l2 = float(g["upper_arm_m"]), float(g["forearm_m"])
    m = -1.0 if g.get("side") == "left" else 1.0
    (a0, a1), (b0, b1) = g["shoulder_range_rad"], g["elbow_range_rad"]
    lin = [k / samples for k in range(samples + 1)]
    edge = ([(a0 + (a1 - a0) * s, b0) for s in lin] + [(a1, b0 + (b1 - b0) * s) for s in lin]
            + [(a1 - (a1 - a0) * s, b1) for s in lin] + [(a0, b1 - (b1 - b0) * s) for s in lin])
    return [[round(m * (l1 * math.cos(q1) + l2 * math.cos(q1 + q2)), 5),
             round(l1 * math.sin(q1) + l2 * math.sin(q1 + q2), 5)] for q1, q2 in edge]


def page_info(info: Mapping[str, Any]) -> dict[str, Any]:
    """What the page is told: the renderer's info without model parameters."""
    out = {k: v for k, v in info.items() if k not in ("params", "geometry")}
    out["workspace_m"] = workspace_outline(info)
    out["side"] = ((info.get("geometry") or {}).get("A") or {}).get("side", "right")
    ox, oy = info.get("shoulder_offset_m") or (0.0, 0.0)
    box = info.get("safety_workspace_m")
    if box:
        out["safety_box_m"] = [box[0] - ox, box[1] - ox, box[2] - oy, box[3] - oy]
    return out


class Station:
    """The server's state: the snapshot, the latest frame and info, the connected pages, and
    the page's panel if it has one (:class:`~haptic.station.panel.Panel`)."""

    def __init__(self, config: StationConfig, control: Callable[..., Any] | None = None,
                 panel: Panel | None = None) -> None:
        self.config = config
        self.reader = SnapshotReader(config.snapshot_path)
        self.client = ControlClient(config.socket_path, timeout_s=5.0)
        self._control = control or self.client.request
        self.frame_json = ""
        self.frame_seq = -1.0
        self.info: dict[str, Any] = {}
        self.info_json = ""
        self.geometry: Geometry | None = None
        self._events = -1.0
        self._info_at = 0.0
        self.pages: dict[int, dict[str, Any]] = {}
        self._page_ids = 0
        self.frames_made = 0
        self.panel = panel
        #: the panel's newest message of each kind, as JSON
        self.extra: dict[str, str] = {}

    def publish(self, kind: str, message: Mapping[str, Any]) -> None:
        """The panel's newest message of ``kind``, sent to every page
        (:data:`haptic.station.panel.Publish`)."""
        self.extra[kind] = json.dumps(message)

    # --- the renderer, through its control socket -------------------------------------------
    async def request(self, cmd: str, **args: Any) -> Any:
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(None, lambda: self._control(cmd, **args))

    async def refresh_info(self) -> bool:
        """Fetch the renderer's info; True when what the page sees changed."""
        try:
            info = await self.request("info")
        except FieldbankError as exc:
            info = {"error": str(exc)}
        self._info_at = asyncio.get_running_loop().time()
        if "geometry" in info and (info.get("params") != self.info.get("params")
                                   or info.get("geometry") != self.info.get("geometry")
                                   or self.geometry is None):
            self.geometry = Geometry(info)
        self.info = info
        text = json.dumps({"type": "info", **page_info(info)})
        changed = text != self.info_json
        self.info_json = text
        return changed

    # --- frames -------------------------------------------------------------------------------
    def make_frame(self, s: Mapping[str, float]) -> dict[str, Any]:
        blinded = s["blinded"] >= 0.5
        ox, oy = self.info.get("shoulder_offset_m") or (0.0, 0.0)
        w = s["blend"]
        key = "B" if w >= 0.5 else "A"
        q = ((1.0 - w) * s["a_q1_rad"] + w * s["b_q1_rad"],
             (1.0 - w) * s["a_q2_rad"] + w * s["b_q2_rad"])
        qd = (s[f"{key.lower()}_qd1_rad_per_s"], s[f"{key.lower()}_qd2_rad_per_s"])
        geo = self.geometry
        elbow, hand = geo.points(key, *q) if geo else ([0.0, 0.0], [0.0, 0.0])
        muscles = None
        if not blinded and geo is not None and (self.panel is None or self.panel.muscles):
            qk = (s[f"{key.lower()}_q1_rad"], s[f"{key.lower()}_q2_rad"])
            muscles = geo.muscles(key, qk, qd) or None
        mode = int(s["mode"])
        return {
            "type": "frame", "seq": s["seq"], "t_s": round(s["t_s"], 4),
            "ticks": int(s["ticks"]),
            "handle_m": [round(s["x_m"] - ox, 5), round(s["y_m"] - oy, 5)],
            "elbow_m": [round(v, 5) for v in elbow], "hand_m": [round(v, 5) for v in hand],
            "force_n": [round(s["fx_n"], 3), round(s["fy_n"], 3)],
            "mode": Mode(mode).name if mode in (0, 1, 2) else str(mode),
            "faults": _fault_names(int(s["faults"])), "gain": round(s["gain"], 3),
            "blend": None if blinded else round(w, 3), "blinded": blinded,
            "muscles_n": muscles,
        }

    async def produce(self) -> None:
        """Read the snapshot at the frame rate; fetch the info when the renderer's events
        change (or every :data:`INFO_REFRESH_S`); keep the latest of both as JSON."""
        period = 1.0 / self.config.frame_hz
        loop = asyncio.get_running_loop()
        while True:
            t0 = loop.time()
            try:
                s = self.reader.read()
            except HapticError as exc:
                log.warning("%s", exc)
                await asyncio.sleep(period)
                continue
            if s["events"] != self._events or t0 - self._info_at > INFO_REFRESH_S:
                self._events = s["events"]
                await self.refresh_info()
            if s["seq"] != self.frame_seq:
                self.frame_seq = s["seq"]
                self.frame_json = json.dumps(self.make_frame(s))
                self.frames_made += 1
            await asyncio.sleep(max(0.0, period - (loop.time() - t0)))

    # --- one page -------------------------------------------------------------------------------
    async def pump(self, ws: web.WebSocketResponse) -> None:
        """Send the newest frame (when there is a new one) and any new info to one page."""
        period = 1.0 / self.config.frame_hz
        sent_frame = sent_info = ""
        sent_extra: dict[str, str] = {}
        while not ws.closed:
            if self.info_json and self.info_json != sent_info:
                sent_info = self.info_json
                await ws.send_str(sent_info)
            for kind, text in list(self.extra.items()):
                if sent_extra.get(kind) is not text:
                    sent_extra[kind] = text
                    await ws.send_str(text)
            if self.frame_json and self.frame_json is not sent_frame:
                sent_frame = self.frame_json
                await ws.send_str(sent_frame)
            await asyncio.sleep(period / 2)

    async def command(self, msg: Mapping[str, Any]) -> dict[str, Any]:
        """Forward one of the page's commands (:data:`PAGE_COMMANDS`) to the renderer."""
        cmd = msg.get("cmd")
        rid = msg.get("id")
        reply: dict[str, Any] = {"type": "reply", "id": rid if isinstance(rid, int) else None}
        panel = self.panel
        if panel is not None and isinstance(cmd, str) and cmd in panel.commands:
            try:
                return {**reply, "ok": True, "result": await panel.command(cmd, msg)}
            except FieldbankError as exc:
                return {**reply, "ok": False, "error": str(exc)}
        if not isinstance(cmd, str) or cmd not in PAGE_COMMANDS:
            return {**reply, "ok": False, "error": f"the station does not send {cmd!r}"}
        actions = PAGE_COMMANDS[cmd]
        args = {k: v for k, v in msg.items() if k not in ("id", "cmd")}
        if actions is not None and args.get("action") not in actions:
            return {**reply, "ok": False, "error": f"{cmd} action must be one of "
                                                   f"{', '.join(actions)}"}
        if cmd == "train" and args.get("action") == "start":
            proto = dict(self.config.training)
            if args.get("instruction") in ("instructed", "non-instructed"):
                proto["instruction"] = args["instruction"]
            proto["seed"] = secrets.randbelow(2**31)
            args = {"action": "start", "protocol": proto}
        if cmd == "abx" and args.get("action") == "start":
            args.setdefault("seed", secrets.randbelow(2**31))
        try:
            result = await self.request(cmd, **args)
            out = {**reply, "ok": True, "result": result}
        except FieldbankError as exc:
            out = {**reply, "ok": False, "error": str(exc)}
        await self.refresh_info()
        return out


def _authorised(request: web.Request, token: str) -> bool:
    given = request.query.get("token", "")
    return hmac.compare_digest(given.encode(), token.encode())


_REFUSED = """<!DOCTYPE html><html lang="en"><meta charset="utf-8"><title>Station: no access</title>
<body style="font-family:system-ui;margin:3rem;max-width:40rem;color:#1d2330">
<h1>No access</h1><p>This station needs the link that <code>fieldbank haptic serve
--station</code> printed, with its token. Ask the person running the session.</p></body></html>
"""

Handler = Callable[[web.Request], Awaitable[web.StreamResponse]]


def page_html(station: Station, extra: Mapping[str, Any] | None = None,
              nav: str = "") -> tuple[str, str]:
    """The station page (HTML with its script and style inline) and the
    Content-Security-Policy that lets exactly those run. ``extra`` goes into the page's
    configuration (the workspace's robot view: its WebSocket's path); ``nav``: markup for the
    top bar (a way back into the workspace), empty for the station on its own."""
    cfg = station.config
    pkg = resources.files("fieldbank.haptic.station")
    template = (pkg / "page.html").read_text("utf-8")
    script = (pkg / "station.js").read_text("utf-8")
    style = (pkg / "station.css").read_text("utf-8")
    panel = station.panel
    if panel is not None:  # the panel's own, in files of its own
        more_script, more_style = panel.assets()
        script += more_script
        style += more_style
    # what the page knows from the start: the view, what 'Start training' runs, the muscles
    proto = TrainingProtocol.from_dict(cfg.training or {})
    config = {
        "view": cfg.view,
        "training": {"name": proto.title, "n_trials": proto.n_trials},
        "muscles": [{"code": k, "name": v} for k, v in MUSCLE_GROUP_NAMES.items()],
        **(panel.page_config() if panel is not None else {}),
        **(extra or {}),
    }
    nonce = secrets.token_urlsafe(16)
    body = (template.replace("{{nonce}}", nonce).replace("{{style}}", style)
            .replace("{{nav}}", nav).replace("{{script}}", script)
            .replace("{{config}}", json.dumps(config).replace("<", "\\u003c")))
    csp = (f"default-src 'none'; script-src 'nonce-{nonce}'; style-src 'nonce-{nonce}'; "
           "connect-src 'self'; img-src 'self' data:; base-uri 'none'; form-action 'none'; "
           "frame-ancestors 'none'")
    return body, csp


def make_app(station: Station) -> web.Application:
    """The aiohttp application of ``station`` (routes in the module docstring)."""
    cfg = station.config

    # a flood of refused requests gives a line a second per reason, with counts
    refused = ThrottledLog(log, REFUSED_LOG_INTERVAL_S, schedule=lambda delay, fn: (
        asyncio.get_running_loop().call_later(delay, fn)))

    @web.middleware
    async def guard(request: web.Request, handler: Handler) -> web.StreamResponse:
        if request.path == "/favicon.ico":  # browsers ask without the token; nothing to give
            return web.Response(status=404)
        if not _authorised(request, cfg.token):
            refused.note("station request without a valid token refused",
                         f"{request.method} {printable(request.path)[:200]}")
            return web.Response(status=403, text=_REFUSED, content_type="text/html")
        resp = await handler(request)
        resp.headers["Referrer-Policy"] = "no-referrer"
        resp.headers["X-Content-Type-Options"] = "nosniff"
        resp.headers["Cache-Control"] = "no-store"
        return resp

    async def page(request: web.Request) -> web.Response:
        body, csp = page_html(station)
        resp = web.Response(text=body, content_type="text/html")
        resp.headers["Content-Security-Policy"] = csp
        resp.headers["X-Frame-Options"] = "DENY"
        return resp

    async def stats(request: web.Request) -> web.Response:
        return web.json_response({"pages": len(station.pages),
                                  "fps": [p.get("fps") for p in station.pages.values()],
                                  "frames_made": station.frames_made})

    async def socket(request: web.Request) -> web.StreamResponse:
        origin = request.headers.get("Origin")
        if origin is not None and origin != f"http://{request.host}":
            refused.note("station WebSocket from another origin refused",
                         printable(origin)[:200])
            return web.Response(status=403, text="cross-origin WebSocket refused")
        if len(station.pages) >= MAX_PAGES:
            return web.Response(status=503, text="too many station pages open")
        ws = web.WebSocketResponse(max_msg_size=MAX_PAGE_MESSAGE, heartbeat=10.0)
        await ws.prepare(request)
        station._page_ids += 1
        pid = station._page_ids
        station.pages[pid] = {"fps": None}
        pump = asyncio.create_task(station.pump(ws))
        try:
            async for msg in ws:
                if msg.type != WSMsgType.TEXT:
                    continue
                try:
                    data = json.loads(msg.data)
                except ValueError:
                    await ws.send_json({"type": "reply", "id": None, "ok": False,
                                        "error": "a station message is a JSON object"})
                    continue
                if not isinstance(data, dict):
                    continue
                if data.get("cmd") == "page_stats":
                    fps = data.get("fps")
                    if isinstance(fps, (int, float)) and math.isfinite(fps):
                        station.pages[pid]["fps"] = float(fps)
                    continue
                await ws.send_json(await station.command(data))
        finally:
            pump.cancel()
            station.pages.pop(pid, None)
        return ws

    app = web.Application(middlewares=[guard], client_max_size=MAX_PAGE_MESSAGE)
    app.router.add_get("/", page)
    app.router.add_get("/ws", socket)
    app.router.add_get("/stats", stats)

    async def start_producer(app: web.Application) -> None:
        app["producer"] = asyncio.create_task(station.produce())
        if station.panel is not None:
            app["panel"] = asyncio.create_task(station.panel.run(station.publish))

    async def stop_producer(app: web.Application) -> None:
        refused.flush()
        app["producer"].cancel()
        if "panel" in app:
            app["panel"].cancel()

    app.on_startup.append(start_producer)
    app.on_cleanup.append(stop_producer)
    return app


async def serve(config: StationConfig, ready: Callable[[str, int], None],
                panel: Panel | None = None) -> None:
    """Run the station (with ``panel``, if any) until cancelled; ``ready(host, port)`` once it
    listens."""
    station = Station(config, panel=panel)
    runner = web.AppRunner(make_app(station), access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, config.host, config.port)
    await site.start()
    server = site._server
    sockets = getattr(server, "sockets", None) or []
    port = sockets[0].getsockname()[1] if sockets else config.port
    ready(config.host, int(port))
    try:
        await asyncio.Event().wait()
    finally:
        await runner.cleanup()
        station.reader.close()
        if panel is not None:
            panel.close()
