"""The workspace's web application: accounts at the door, the providers' routes behind it.

:func:`make_app` builds the aiohttp application from one :class:`~fieldbank.storage.Database`
and the :class:`~fieldbank.web.routes.RouteProvider` values the command line composes. What the
core does for every route, in order:

1. **who**: ``Authorization: Bearer <token>`` (an API client; :func:`~fieldbank.web.accounts.
   token_owner`) or the session cookie (:mod:`fieldbank.web.sessions`); the account is read
   again on each request, so a disabled account or a changed role counts at once;
2. **may they**: a route's permission against the role's (401 without a caller, 403 without
   the permission);
3. **CSRF**: a change (any method but GET/HEAD) made with the session cookie needs the
   session's token in ``X-CSRF-Token`` and, when the browser sends an Origin, this server's
   own; a token-authenticated client sends no cookie, so it needs neither;
4. **as whom**: the handler's database writes as the account (every audit entry names it, how
   it came and from where);
5. **errors**: JSON ``{"error": message}`` - a library error with its own words (400), an
   :class:`~fieldbank.web.routes.ApiError` with its status, anything else 500 with nothing of
   its insides;
6. **headers**: a strict Content-Security-Policy (scripts and styles only from this server; a
   page that sets its own keeps it), no framing, no sniffing, no referrer, no caching of API
   answers, HSTS under TLS.

Public routes: the page shell ``/``, the listed static assets, ``/api/session``,
``/api/login``, ``/api/logout`` and ``/api/openapi.json``.
"""

from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import Awaitable, Callable, Sequence
from importlib import resources
from typing import Any

from aiohttp import web

from fieldbank.errors import FieldbankError
from fieldbank.storage import Database
from fieldbank.web.accounts import ROLE_PERMISSIONS, token_owner, verify_login
from fieldbank.web.openapi import openapi_document
from fieldbank.web.routes import ApiError, Asset, Call, Caller, Route, RouteProvider
from fieldbank.web.sessions import LoginThrottle, SessionStore, WebSession

log = logging.getLogger("fieldbank.web")

COOKIE = "fb_session"
CSRF_HEADER = "X-CSRF-Token"
SAFE_METHODS = ("GET", "HEAD", "OPTIONS")
#: Failed logins from one address before its waits start (an account name: 5).
FREE_FAILURES_PER_ADDRESS = 20
CSP = ("default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' blob: data:; "
       "connect-src 'self'; base-uri 'none'; form-action 'self'; frame-ancestors 'none'")
CONTENT_TYPES = {"script": "text/javascript", "style": "text/css"}
CORE_ASSETS = (Asset("fieldbank.web", "app.js", "script"),
               Asset("fieldbank.web", "app.css", "style"))

Handler = Callable[[web.Request], Awaitable[web.StreamResponse]]


def _json(status: int, doc: Any) -> web.Response:
    return web.Response(status=status, text=json.dumps(doc), content_type="application/json")


def error_response(status: int, message: str, **extra: Any) -> web.Response:
    return _json(status, {"error": message, **extra})


class Workspace:
    """The application's state: database, sessions, throttles, assets, providers."""

    def __init__(self, db: Database, providers: Sequence[RouteProvider], secure: bool) -> None:
        self.db = db
        self.providers = list(providers)
        self.secure = secure
        self.sessions = SessionStore()
        self.names = LoginThrottle()
        self.addresses = LoginThrottle(free=FREE_FAILURES_PER_ADDRESS)
        self.reads: dict[tuple[str, ...], float] = {}  # repeated reads recorded once a while
        self.assets: dict[tuple[str, str], tuple[bytes, str, str]] = {}
        for owner, list_ in [("core", CORE_ASSETS)] + [(p.name, p.assets())
                                                       for p in self.providers]:
            for a in list_:
                data = (resources.files(a.package) / a.name).read_bytes()
                self.assets[(owner, a.name)] = (data, CONTENT_TYPES[a.kind], a.kind)

    # --- who is asking ------------------------------------------------------------------------
    def _caller(self, user_name: str, role: str, via: str, peer: str) -> Caller:
        return Caller(user_name, role, ROLE_PERMISSIONS.get(role, frozenset()), via, peer)

    async def identify(self, request: web.Request) -> tuple[Caller | None, WebSession | None]:
        peer = request.remote or "-"
        auth = request.headers.get("Authorization")
        if auth is not None:
            scheme, _, token = auth.partition(" ")
            if scheme.lower() != "bearer" or not token.strip():
                raise ApiError(401, "Authorization must be 'Bearer TOKEN' (a token from "
                                    "'fieldbank users token NAME')")
            owner = await _run(lambda: token_owner(self.db, token.strip()))
            if owner is None:
                raise ApiError(401, "the API token is unknown or revoked, or its account is "
                                    "disabled")
            user, tid = owner
            return self._caller(user.name, user.role, f"token {tid}", peer), None
        sess = self.sessions.get(request.cookies.get(COOKIE))
        if sess is None or sess.user is None:
            return None, sess
        name = sess.user
        user = await _run(lambda: self.db.find_user(name))
        if user is None or user.disabled_at is not None:
            self.sessions.logout(sess)
            return None, None
        return self._caller(user.name, user.role, "session", peer), sess

    def set_cookie(self, resp: web.StreamResponse, sess: WebSession) -> None:
        resp.set_cookie(COOKIE, sess.id, httponly=True, samesite="Strict", path="/",
                        secure=self.secure)

    # --- a route, guarded ---------------------------------------------------------------------
    def guarded(self, route: Route) -> Handler:
        async def handle(request: web.Request) -> web.StreamResponse:
            caller, sess = await self.identify(request)
            if route.permission is not None:
                if caller is None:
                    if not route.api and request.method == "GET":
                        raise web.HTTPSeeOther("/")
                    raise ApiError(401, "log in first (or send Authorization: Bearer TOKEN)")
                if not caller.may(route.permission):
                    raise ApiError(403, f"a {caller.role} may not do this (it needs the "
                                        f"'{route.permission}' permission)")
            if caller is not None and sess is not None:
                check_origin(request)
                if request.method not in SAFE_METHODS and not sess.csrf_ok(
                        request.headers.get(CSRF_HEADER)):
                    raise ApiError(403, "this change carries no valid CSRF token: reload the "
                                        "page and try again")
            db = self.db if caller is None else self.db.acting_as(
                caller.name, via=caller.via, **{"from": caller.peer})
            out = await route.handler(Call(request, caller, db, self.reads))
            return out if isinstance(out, web.StreamResponse) else _json(200, out)

        return handle


def check_origin(request: web.Request) -> None:
    """A browser's request from another site is refused (its Origin must be this server)."""
    origin = request.headers.get("Origin")
    if request.method in SAFE_METHODS and request.headers.get("Upgrade", "").lower() != \
            "websocket":
        return
    if origin is not None and origin != str(request.url.origin()):
        raise ApiError(403, "a request from another site is refused")


async def _run(fn: Callable[[], Any]) -> Any:
    return await asyncio.get_running_loop().run_in_executor(None, fn)


def _shell(ws: Workspace, sess: WebSession) -> str:
    template = (resources.files("fieldbank.web") / "index.html").read_text("utf-8")
    tags = []
    for (owner, name), (_, _, kind) in ws.assets.items():
        src = f"/static/{owner}/{name}"
        tags.append(f'<link rel="stylesheet" href="{src}">' if kind == "style" else
                    f'<script src="{src}" defer></script>')
    return (template.replace("{{csrf}}", sess.csrf)
            .replace("{{assets}}", "\n".join(tags)))


def make_app(db: Database, providers: Sequence[RouteProvider], *,
             secure: bool = False) -> web.Application:
    """The application over ``db`` with the routes of ``providers``; ``secure``: served over
    TLS (cookies marked Secure, HSTS)."""
    ws = Workspace(db, providers, secure)

    @web.middleware
    async def edge(request: web.Request, handler: Handler) -> web.StreamResponse:
        try:
            resp = await handler(request)
        except ApiError as exc:
            resp = error_response(exc.status, str(exc))
            if exc.retry_after_s is not None:
                resp.headers["Retry-After"] = str(exc.retry_after_s)
        except FieldbankError as exc:
            resp = error_response(400, str(exc))
        except web.HTTPException as exc:
            if not request.path.startswith("/api/") or exc.status < 400:
                raise
            resp = error_response(exc.status, exc.reason)
        except Exception:
            log.exception("%s %s failed", request.method, request.path)
            resp = error_response(500, "the server failed on this request (its log says why)")
        if not resp.prepared:
            h = resp.headers
            h.setdefault("Content-Security-Policy", CSP)
            h.setdefault("X-Frame-Options", "DENY")
            h["X-Content-Type-Options"] = "nosniff"
            h["Referrer-Policy"] = "no-referrer"
            h.setdefault("Cache-Control", "no-store")
            if secure:
                h["Strict-Transport-Security"] = "max-age=31536000"
        return resp

    async def shell(request: web.Request) -> web.StreamResponse:
        sess = ws.sessions.anonymous(request.cookies.get(COOKIE))
        resp = web.Response(text=_shell(ws, sess), content_type="text/html")
        ws.set_cookie(resp, sess)
        return resp

    async def static(request: web.Request) -> web.StreamResponse:
        found = ws.assets.get((request.match_info["owner"], request.match_info["name"]))
        if found is None:
            raise web.HTTPNotFound()
        data, ctype, _ = found
        resp = web.Response(body=data, content_type=ctype)
        resp.headers["Cache-Control"] = "no-cache"
        return resp

    async def session(call: Call) -> Any:
        sess = ws.sessions.get(call.request.cookies.get(COOKIE))
        c = call.caller
        return {"user": None if c is None else {"name": c.name, "role": c.role,
                                                "permissions": sorted(c.permissions)},
                "csrf": sess.csrf if sess is not None else None}

    async def login(call: Call) -> Any:
        request = call.request
        sess = ws.sessions.get(request.cookies.get(COOKIE))
        check_origin(request)
        if sess is None or not sess.csrf_ok(request.headers.get(CSRF_HEADER)):
            raise ApiError(403, "the login form has expired or came from another site: "
                                "reload the page")
        body = await call.json()
        name, password = body.get("name"), body.get("password")
        if not isinstance(name, str) or not isinstance(password, str):
            raise ApiError(400, '"name" and "password" are needed, as text')
        peer = request.remote or "-"
        wait = max(ws.names.wait_s("name:" + name), ws.addresses.wait_s("addr:" + peer))
        if wait > 0:
            raise ApiError(429, f"too many failed logins: try again in {wait:.0f} s",
                           retry_after_s=max(1, round(wait)))
        user = await _run(lambda: verify_login(db, name, password))
        who = db.acting_as(name[:64], via="session", **{"from": peer})
        if user is None:
            ws.names.failed("name:" + name)
            ws.addresses.failed("addr:" + peer)
            await _run(lambda: who.record_login(name, False))
            raise ApiError(401, "wrong account name or password")
        ws.names.succeeded("name:" + name)
        await _run(lambda: who.record_login(user.name, True))
        new = ws.sessions.login(sess, user.name)
        resp = _json(200, {"user": {"name": user.name, "role": user.role, "permissions":
                                    sorted(ROLE_PERMISSIONS.get(user.role, ()))},
                           "csrf": new.csrf})
        ws.set_cookie(resp, new)
        return resp

    async def logout(call: Call) -> Any:
        sess = ws.sessions.get(call.request.cookies.get(COOKIE))
        if sess is not None:
            ws.sessions.logout(sess)
        fresh = ws.sessions.anonymous(None)
        resp = _json(200, {"user": None, "csrf": fresh.csrf})
        ws.set_cookie(resp, fresh)
        return resp

    routes: list[Route] = [
        Route("GET", "/api/session", session, None, "Who is logged in, and the CSRF token "
              "the page sends with each change", tags=("accounts",)),
        Route("POST", "/api/login", login, None, "Log in with an account name and password "
              "(needs the CSRF token of the login form)", body={
                  "type": "object", "required": ["name", "password"],
                  "properties": {"name": {"type": "string"}, "password": {"type": "string"}}},
              tags=("accounts",)),
        Route("POST", "/api/logout", logout, "read", "Log out (the session ends)",
              tags=("accounts",)),
    ]
    for p in ws.providers:
        routes.extend(p.routes())

    async def openapi(call: Call) -> Any:
        return doc

    routes.append(Route("GET", "/api/openapi.json", openapi, None,
                        "This document", tags=("accounts",)))
    doc = openapi_document(routes)
    app = web.Application(middlewares=[edge], client_max_size=8 * 1024 * 1024)
    app.router.add_get("/", shell)
    app.router.add_get("/static/{owner}/{name}", static)
    for r in routes:
        app.router.add_route(r.method, r.path, ws.guarded(r))
    return app

