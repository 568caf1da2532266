"""Login sessions, CSRF tokens and the login throttle of the workspace (in memory).

A session is a random 256-bit id in an HttpOnly, SameSite=Strict cookie (Secure under TLS)
mapped, in this process only, to the account and a CSRF token. The page receives the CSRF token
in its shell and sends it back in ``X-CSRF-Token`` with every change; a request that changes
anything without it is refused (synchronizer token, OWASP's CSRF cheat sheet). An anonymous
session (no account yet) carries the CSRF token of the login form itself.

Session fixation: the server only ever accepts ids it made, and a login always issues a new id
(the anonymous one is dropped), so an id planted in a browser before the login is worth
nothing after it. Sessions end after :data:`IDLE_S` without a request or :data:`MAX_AGE_S` in
all, on logout, and when the server stops (they are not stored: a restart logs everyone out).

The throttle counts failed logins per account name (and, more leniently, per address): after
:data:`FREE_FAILURES` failures in a row, each further attempt waits twice as long as the one
before (1 s, 2 s, 4 s … up to :data:`MAX_LOCK_S`), and an attempt during the wait is refused
without checking the password (HTTP 429 with Retry-After).
"""

from __future__ import annotations

import hmac
import secrets
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field

#: A session ends after this long without a request, s.
IDLE_S = 30 * 60.0
#: … and after this long in all, s.
MAX_AGE_S = 12 * 3600.0
#: Most sessions (anonymous ones included) kept; the least recently used go first.
MAX_SESSIONS = 10_000
#: Failed logins in a row allowed before the waits start.
FREE_FAILURES = 5
#: Longest wait after failed logins, s.
MAX_LOCK_S = 900.0
#: Most names and addresses the throttle remembers.
MAX_THROTTLED = 10_000

Clock = Callable[[], float]


@dataclass
class WebSession:
    """One browser's session: its id (the cookie), CSRF token, account (None before login)."""

    id: str
    csrf: str
    user: str | None
    created: float
    seen: float

    def csrf_ok(self, given: str | None) -> bool:
        return given is not None and bool(given) and hmac.compare_digest(given.encode(),
                                                                         self.csrf.encode())


class SessionStore:
    """The sessions of one server process (module docstring)."""

    def __init__(self, clock: Clock = time.monotonic) -> None:
        self._clock = clock
        self._sessions: OrderedDict[str, WebSession] = OrderedDict()

    def _new(self, user: str | None) -> WebSession:
        t = self._clock()
        s = WebSession(secrets.token_urlsafe(32), secrets.token_urlsafe(32), user, t, t)
        self._sessions[s.id] = s
        while len(self._sessions) > MAX_SESSIONS:
            self._sessions.popitem(last=False)
        return s

    def get(self, sid: str | None) -> WebSession | None:
        """The live session with this id (its idle time restarts), else None."""
        if not sid or len(sid) > 100:
            return None
        s = self._sessions.get(sid)
        if s is None:
            return None
        t = self._clock()
        if t - s.seen > IDLE_S or t - s.created > MAX_AGE_S:
            del self._sessions[sid]
            return None
        s.seen = t
        self._sessions.move_to_end(sid)
        return s

    def anonymous(self, sid: str | None) -> WebSession:
        """The session of ``sid`` if live, else a new anonymous one (for the login form)."""
        return self.get(sid) or self._new(None)

    def login(self, old: WebSession | None, user: str) -> WebSession:
        """A NEW session for ``user``; the old one (anonymous or not) is dropped."""
        if old is not None:
            self._sessions.pop(old.id, None)
        return self._new(user)

    def logout(self, s: WebSession) -> None:
        self._sessions.pop(s.id, None)

    def end_user(self, user: str) -> int:
        """End every session of ``user`` (a disabled account); how many."""
        gone = [k for k, s in self._sessions.items() if s.user == user]
        for k in gone:
            del self._sessions[k]
        return len(gone)

    def __len__(self) -> int:
        return len(self._sessions)


@dataclass
class _Count:
    failures: int = 0
    until: float = 0.0


@dataclass
class LoginThrottle:
    """Failed logins per key (an account name, or an address) and the wait they impose;
    ``free``: failures in a row before the waits start."""

    free: int = FREE_FAILURES
    clock: Clock = time.monotonic
    _keys: OrderedDict[str, _Count] = field(default_factory=OrderedDict)

    def wait_s(self, *keys: str) -> float:
        """Seconds until an attempt for these keys is heard again (0: now)."""
        t = self.clock()
        return max([0.0] + [c.until - t for k in keys if (c := self._keys.get(k))])

    def failed(self, *keys: str) -> None:
        t = self.clock()
        for k in keys:
            c = self._keys.setdefault(k, _Count())
            self._keys.move_to_end(k)
            c.failures += 1
            if c.failures >= self.free:
                c.until = t + min(MAX_LOCK_S, 2.0 ** (c.failures - self.free))
        while len(self._keys) > MAX_THROTTLED:
            self._keys.popitem(last=False)

    def succeeded(self, *keys: str) -> None:
        for k in keys:
            self._keys.pop(k, None)
