"""What a remote session did, in words: when an end rendered, and when and why it did not.

From a port's log (its gain, tick by tick) and its events (:mod:`haptic.remote.supervision`),
:func:`account` finds every span after the first engagement in which the force was held at
zero, with its cause — the event that began it: a fault of this site's robot (its fault code's
name), the link's own fault (PEER: the peer's data refused as implausible), a fault the peer's
robot reported, the link lost, this loop falling behind, the peer's end — and says each in one
line, as both sites print at the end::

    fault DEVICE at t = 0.34 s: force zero for the remaining 13.7 s
    link lost at t = 3.44 s: force ramped to zero by t = 3.64 s, zero for 1.02 s

A session rendered what was asked (:attr:`Account.complete`) when it engaged, never held the
force at zero after that but where its operator disarmed, and ended as asked (its duration or
its operator; at the patient's site, the clinician's BYE). The commands exit with a non-zero
status otherwise.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

#: Events that can start a span of zero force, and how the account names them.
_CAUSES = ("fault", "peer_fault", "link_lost", "not_ready", "peer_ended", "closing")


@dataclass(frozen=True)
class Span:
    """A span of zero force after the first engagement.

    Attributes
    ----------
    cause : str
        In words: "fault DEVICE", "link lost", …
    cause_t_s, start_s : float, s
        When the cause happened, and when the force was zero (a fault of this site's robot
        zeroes it at once; everything else ramps it out).
    end_s : float or None, s
        When the force came back (None: it never did).
    benign : bool
        Asked for (the operator disarmed): not a failure of the session.
    """

    cause: str
    cause_t_s: float
    start_s: float
    end_s: float | None
    benign: bool = False

    def line(self, end_t_s: float) -> str:
        if self.end_s is None:
            zero = f"the remaining {end_t_s - self.start_s:.1f} s"
        else:
            zero = f"{self.end_s - self.start_s:.2f} s, back at t = {self.end_s:.2f} s"
        if self.start_s == self.cause_t_s:
            return f"{self.cause} at t = {self.cause_t_s:.2f} s: force zero for {zero}"
        return (f"{self.cause} at t = {self.cause_t_s:.2f} s: force ramped to zero by "
                f"t = {self.start_s:.2f} s, zero for {zero}")

    def to_dict(self) -> dict[str, Any]:
        return {"cause": self.cause, "cause_t_s": self.cause_t_s, "start_s": self.start_s,
                "end_s": self.end_s, "benign": self.benign}


@dataclass(frozen=True)
class Account:
    """One end's session in words (module docstring)."""

    engaged_at_s: float | None
    rendered_s: float
    duration_s: float
    spans: tuple[Span, ...]
    ended: str
    asked: bool

    @property
    def complete(self) -> bool:
        return (self.engaged_at_s is not None and self.asked
                and all(s.benign for s in self.spans))

    def lines(self) -> list[str]:
        out = []
        if self.engaged_at_s is None:
            out.append("never engaged: no force was rendered")
        out += [s.line(self.duration_s) for s in self.spans]
        out.append(f"ended at t = {self.duration_s:.2f} s: {self.ended}"
                   + ("" if self.asked else " (not as asked)"))
        return out

    def to_dict(self) -> dict[str, Any]:
        return {"complete": self.complete, "engaged_at_s": self.engaged_at_s,
                "rendered_s": self.rendered_s, "duration_s": self.duration_s,
                "spans": [s.to_dict() for s in self.spans], "ended": self.ended,
                "asked": self.asked, "lines": self.lines()}


def _cause(ev: Mapping[str, Any], peer_name: str) -> tuple[str, bool, bool]:
    """(the cause in words, whether the force went to zero at once, whether it was asked)."""
    kind = ev["event"]
    if kind == "fault":
        local = ev.get("name") != "PEER"
        return f"fault {ev.get('name')}", local, False
    if kind == "peer_fault":
        return f"{peer_name} reported a fault of its robot", False, False
    if kind == "link_lost":
        return "link lost", False, False
    if kind == "peer_ended":
        return f"{peer_name} ended the session ({ev.get('reason')})", False, False
    if kind == "closing":
        return f"the session's end ({ev.get('reason')})", False, True
    why = str(ev.get("why", ""))
    return f"not ready ({why})", False, why == "disarmed"


def account(t_s: np.ndarray, gain: np.ndarray, events: Sequence[Mapping[str, Any]], *,
            ended: str, asked: bool, peer_name: str) -> Account:
    """The account of one end from its log's ``t_s`` and ``gain`` columns and its events.

    Parameters
    ----------
    t_s, gain : ndarray, shape (n,)
        Session time (s) and the port's gain of each tick.
    events : sequence of mapping
        The port's events (``t_s``, ``event``, …).
    ended : str
        Why the session ended, in words.
    asked : bool
        It ended as asked (its duration, its operator; at the patient's, the clinician's BYE).
    peer_name : str
        The other site in words.
    """
    n = len(t_s)
    end_t = float(t_s[-1]) if n else 0.0
    full = np.flatnonzero(gain >= 1.0 - 1e-9)
    if not len(full):
        return Account(None, 0.0, end_t, (), ended, asked)
    first = int(full[0])
    dt = float(np.median(np.diff(t_s))) if n > 1 else 0.0
    rendered = float(np.count_nonzero(gain[first:] >= 1.0 - 1e-9)) * dt
    zero = gain[first:] <= 0.0
    edges = np.diff(np.concatenate(([0], zero.astype(np.int8), [0])))
    starts, stops = np.flatnonzero(edges == 1) + first, np.flatnonzero(edges == -1) + first
    causes = [e for e in events if e["event"] in _CAUSES]
    spans = []
    lower = float(t_s[first])
    for a, b in zip(starts, stops, strict=True):
        ta = float(t_s[a])
        before = [e for e in causes if lower <= e["t_s"] <= ta + 1e-9]
        ev = before[-1] if before else None
        tb = None if b >= n else float(t_s[b])
        lower = ta if tb is None else tb
        if ev is None:
            spans.append(Span("force held at zero", ta, ta, tb))
            continue
        words, at_once, benign = _cause(ev, peer_name)
        if ev["event"] in ("peer_ended", "closing") and asked and tb is None:
            continue  # the closing ramp of a session that ended as asked
        tc = float(ev["t_s"])
        spans.append(Span(words, tc, tc if at_once else ta, tb, benign))
    return Account(float(t_s[first]), rendered, end_t, tuple(spans), ended, asked)
