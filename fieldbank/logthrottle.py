"""Log lines that come in floods - refused requests, refused datagrams - at most one per
interval per reason, with counts.

A server that logs every refusal turns a flood of refused requests into a flood of log lines
(thousands a second, drowning what matters and filling the disk). :class:`ThrottledLog` writes
the first refusal of a reason at once, then holds the others and writes one line per interval
saying how many there were and the latest one::

    station request without a valid token refused: GET /ws
    station request without a valid token refused 1,243 more times in 1.0 s (latest: GET /)

Held counts are written when the interval has passed: by the next refusal of that reason, by
the timer the caller's event loop runs (``schedule``), or by :meth:`ThrottledLog.flush` when
the server stops - so every refusal is counted in some line, and the counts add up.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

#: Runs a function after a delay in seconds (``loop.call_later``).
Schedule = Callable[[float, Callable[[], None]], object]


@dataclass
class _Held:
    count: int = 0
    latest: str = ""
    since: float = 0.0


class ThrottledLog:
    """At most one line per ``interval_s`` per reason on ``log``.

    Parameters
    ----------
    log : logging.Logger
    interval_s : float
        Shortest time between two lines of one reason, s.
    level : int
        Level of the lines (WARNING).
    schedule : callable, optional
        ``schedule(delay_s, fn)`` runs ``fn`` later (an event loop's ``call_later``), so that
        counts held at the end of a flood are written within an interval; without it they
        wait for the next line of their reason or :meth:`flush`.
    clock : callable
        Monotonic time, s.
    """

    def __init__(self, log: logging.Logger, interval_s: float = 1.0, level: int = logging.WARNING,
                 schedule: Schedule | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.log = log
        self.interval_s = interval_s
        self.level = level
        self._schedule = schedule
        self._clock = clock
        self._last: dict[str, float] = {}
        self._held: dict[str, _Held] = {}
        #: every note per reason since the start (what the lines add up to)
        self.totals: dict[str, int] = {}

    def note(self, reason: str, detail: str = "") -> None:
        """One more event of ``reason`` (``detail``: this one's particulars, e.g. the path)."""
        now = self._clock()
        self.totals[reason] = self.totals.get(reason, 0) + 1
        last = self._last.get(reason)
        held = self._held.get(reason)
        if last is None or now - last >= self.interval_s:
            self._last[reason] = now
            if held is None:
                self.log.log(self.level, "%s: %s", reason, detail)
            else:  # this one joins the count still held: one line
                held.count += 1
                held.latest = detail
                self._write(reason, now)
            return
        if held is None:
            held = self._held[reason] = _Held(since=last)
            if self._schedule is not None:
                self._schedule(last + self.interval_s - now, lambda: self._due(reason, last))
        held.count += 1
        held.latest = detail

    def flush(self) -> None:
        """Write every count held (a server stopping)."""
        now = self._clock()
        for reason in list(self._held):
            self._write(reason, now)

    def _due(self, reason: str, since: float) -> None:
        """The timer of the count held since ``since``: written unless a line has been
        written since (a later count has a timer of its own)."""
        held = self._held.get(reason)
        if held is None or held.since != since:
            return
        now = self._clock()
        self._write(reason, now)
        self._last[reason] = now

    def _write(self, reason: str, now: float) -> bool:
        held = self._held.pop(reason, None)
        if held is None or held.count == 0:
            return False
        self.log.log(self.level, "%s %s more time%s in %.1f s (latest: %s)", reason,
                     f"{held.count:,}", "" if held.count == 1 else "s", now - held.since,
                     held.latest)
        return True
