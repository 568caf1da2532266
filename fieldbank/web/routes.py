"""The seam between the workspace's core and the parts that add pages and API routes to it.

The core (:mod:`fieldbank.web.app`) owns accounts, sessions, CSRF, errors, static files and the
OpenAPI document; it knows nothing of what-ifs or robots. A part that adds routes - the
interventions' plan composer, the haptic wing's robot view - is a :class:`RouteProvider`: it
lists :class:`Route` values (method, path, the permission a caller needs, what the OpenAPI
document says) and the page scripts it ships (:class:`Asset`), and each handler receives a
:class:`Call` - the request with its caller, a database writing as that caller, and helpers to
read a bounded JSON body, run blocking work off the event loop and record a read of a patient's
data. The command line (``fieldbank serve``) composes the providers; none imports another.

A handler returns a JSON-able value (sent as ``application/json``) or an aiohttp response; it
raises :class:`ApiError` for an HTTP error, or lets a
:class:`~fieldbank.errors.FieldbankError` through, which becomes a 400 with the library's own
message - the words the command line prints.
"""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Awaitable, Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

from aiohttp import web

from fieldbank.errors import FieldbankError
from fieldbank.storage import Database

T = TypeVar("T")

#: What each permission allows (the roles' sets are in :mod:`fieldbank.web.accounts`).
PERMISSIONS = {
    "read": "read patients, sessions, maps, fits, models, plans; compute a what-if",
    "plan": "save a plan and mark it given; run the dose optimiser",
    "robot": "push models to the robot and drive it (switch, A/B/X, training, arm)",
    "manage": "add patients, ingest files, read the audit log",
}
#: Largest JSON body the API reads, bytes.
MAX_BODY = 256 * 1024
#: A read that repeats (``Call.record_read(once=…)``) is recorded once in this long, s.
READ_EVERY_S = 600.0


class ApiError(FieldbankError):
    """An HTTP error with a message for the page (and the API client) to show."""

    def __init__(self, status: int, message: str, retry_after_s: int | None = None) -> None:
        super().__init__(message)
        self.status = status
        self.retry_after_s = retry_after_s


@dataclass(frozen=True)
class Caller:
    """Who is asking: the account, its role and permissions, how it came (``session`` or
    ``token N``) and from where (the peer address)."""

    name: str
    role: str
    permissions: frozenset[str]
    via: str
    peer: str

    def may(self, permission: str) -> bool:
        return permission in self.permissions


class Call:
    """One request to a route, as its handler sees it.

    Attributes
    ----------
    request : aiohttp.web.Request
    caller : Caller or None
        None only on public routes.
    db : Database
        The database writing as the caller (every write audited with the account's name,
        the way it came and its address).
    """

    def __init__(self, request: web.Request, caller: Caller | None, db: Database,
                 reads: dict[tuple[str, ...], float] | None = None) -> None:
        self.request = request
        self.caller = caller
        self.db = db
        self._reads = reads if reads is not None else {}

    @property
    def user(self) -> Caller:
        if self.caller is None:
            raise ApiError(401, "log in first")
        return self.caller

    def match(self, name: str) -> str:
        return self.request.match_info[name]

    def match_int(self, name: str) -> int:
        text = self.request.match_info[name]
        if not text.isdigit() or len(text) > 12:
            raise ApiError(404, f"{name} must be a whole number; got {text!r}.")
        return int(text)

    def query(self, name: str, default: str | None = None) -> str | None:
        return self.request.query.get(name, default)

    async def json(self) -> dict[str, Any]:
        """The request's JSON object (bounded, strict: no NaN)."""
        if self.request.content_length is not None and self.request.content_length > MAX_BODY:
            raise ApiError(413, f"a request body is at most {MAX_BODY} bytes")
        raw = await self.request.content.read(MAX_BODY + 1)
        if len(raw) > MAX_BODY:
            raise ApiError(413, f"a request body is at most {MAX_BODY} bytes")
        try:
            doc = json.loads(raw.decode("utf-8") or "{}", parse_constant=_no_constant)
        except (UnicodeDecodeError, ValueError) as exc:
            raise ApiError(400, f"the request body is not JSON: {exc}") from None
        if not isinstance(doc, dict):
            raise ApiError(400, "the request body must be a JSON object")
        return doc

    async def run(self, fn: Callable[[], T]) -> T:
        """``fn()`` in a worker thread (database and numerical work never block the loop)."""
        return await asyncio.get_running_loop().run_in_executor(None, fn)

    def record_read(self, patient_code: str, what: str, once: str | None = None) -> None:
        """Record that the caller read ``what`` of the patient (audit log). ``once``: what
        repeats (a what-if as each dose changes) is recorded once per :data:`READ_EVERY_S`
        for the caller, the patient and this key."""
        if once is not None:
            key = (self.caller.name if self.caller else "", patient_code, once)
            now = time.monotonic()
            if now - self._reads.get(key, -READ_EVERY_S) < READ_EVERY_S:
                return
            self._reads[key] = now
            if len(self._reads) > 10_000:
                self._reads.clear()
        self.db.record_read(patient_code, what)


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number JSON allows")


Handler = Callable[[Call], Awaitable[Any]]


@dataclass(frozen=True)
class Param:
    """A path or query parameter as the OpenAPI document describes it."""

    name: str
    where: str = "path"  # 'path' or 'query'
    type: str = "string"
    description: str = ""
    required: bool = True


@dataclass(frozen=True)
class Route:
    """One route of a provider.

    Attributes
    ----------
    method, path : str
        aiohttp's form (``/api/patients/{code}``).
    handler : Handler
    permission : str or None
        What the caller must be allowed (:data:`PERMISSIONS`); None: public (login, the page
        shell, its scripts).
    summary : str
        One line for the OpenAPI document.
    params : tuple of Param
    body : dict, optional
        The JSON schema of the request body.
    response : dict, optional
        The JSON schema of the answer (``{"type": "object"}`` when not given).
    api : bool
        Part of the JSON API (listed in the OpenAPI document); False for pages and sockets.
    """

    method: str
    path: str
    handler: Handler
    permission: str | None
    summary: str
    params: tuple[Param, ...] = ()
    body: Mapping[str, Any] | None = None
    response: Mapping[str, Any] | None = None
    api: bool = True
    tags: tuple[str, ...] = field(default=())


@dataclass(frozen=True)
class Asset:
    """A file a provider ships for the page: served at ``/static/<provider>/<name>``.

    ``package`` and ``name`` locate it through :mod:`importlib.resources`; only listed assets
    are served (no path from a request ever reaches the file system)."""

    package: str
    name: str
    kind: str  # 'script' or 'style'


class RouteProvider(Protocol):
    """A part of the workspace: its name, routes and page assets."""

    name: str

    def routes(self) -> Sequence[Route]: ...

    def assets(self) -> Sequence[Asset]: ...


def need(doc: Mapping[str, Any], key: str, kind: type | tuple[type, ...], what: str = "") -> Any:
    """``doc[key]`` of type ``kind``, else a 400 naming the field."""
    if key not in doc:
        raise ApiError(400, f'"{key}" is missing{": " + what if what else ""}')
    v = doc[key]
    if not isinstance(v, kind) or (isinstance(v, bool) and bool not in (
            kind if isinstance(kind, tuple) else (kind,))):
        raise ApiError(400, f'"{key}" has the wrong type{": " + what if what else ""}')
    return v


def optional(doc: Mapping[str, Any], key: str, kind: type | tuple[type, ...],
             default: Any = None) -> Any:
    """``doc[key]`` of type ``kind`` when present and not null, else ``default``."""
    if doc.get(key) is None:
        return default
    return need(doc, key, kind)


def names(values: Sequence[object], what: str) -> list[str]:
    """A list of strings from a JSON array, else a 400."""
    if not isinstance(values, list) or not all(isinstance(v, str) for v in values):
        raise ApiError(400, f"{what} must be a list of names")
    return [str(v) for v in values]
