"""A what-if in three lines: what changes most, what the grades do, the warnings that matter.

The clinician reads these first (``fieldbank whatif`` opens with them; ``--json`` carries them
as ``summary``):

1. **what changes most**, in words and units: of every joint-stretch read-out (the resisting
   torque against a slow 5°/s and a fast 180°/s stretch of each joint and direction, and its
   velocity-dependent part) and the field's RMS force at rest and moving, the one with the
   largest relative change (ignoring changes below :data:`MIN_CHANGE`); for a stretch, its
   velocity-dependent part alongside, with the 95% interval of the change when the fit has
   samples;
2. **the grades**: the spasticity (dynamic) and contracture (passive) grades that change, per
   muscle group, or that none does;
3. **the warnings**: how many, and the first (a step acting on a parameter the fit did not
   identify, a poor fit accepted, a botulinum session above the limit), or none.

"No change" is said only when no read-out moves by :data:`MIN_CHANGE`; a plan that moves only
what these read-outs do not show is then named as such, never reported as changing nothing.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from fieldbank.evaluate.compare import Comparison
from fieldbank.interventions.guesses import Guesses
from fieldbank.params import GROUP_NAMES

#: Relative change below which a read-out counts as unchanged (1%), and the absolute floors:
#: N·m for torques, N for forces (a 1% change of a near-zero torque is no change a hand feels).
MIN_CHANGE = 0.01
MIN_TORQUE_N_M = 0.05
MIN_FORCE_N = 0.05


@dataclass(frozen=True)
class Change:
    """One read-out before and after (SI-based clinical units: N·m, N)."""

    what: str
    unit: str
    before: float
    after: float

    @property
    def relative(self) -> float:
        return (self.after - self.before) / self.before if abs(self.before) > 1e-12 else 0.0

    def text(self) -> str:
        return (f"{self.before:.2f} → {self.after:.2f} {self.unit} "
                f"({100.0 * self.relative:+.0f}%)")

    def to_dict(self) -> dict[str, Any]:
        return {"what": self.what, "unit": self.unit, "before": self.before,
                "after": self.after, "relative": self.relative}


@dataclass(frozen=True)
class WhatIfSummary:
    """The three lines and the change they lead with (None: nothing changed)."""

    lines: tuple[str, str, str]
    largest: Change | None

    def to_dict(self) -> dict[str, Any]:
        return {"lines": list(self.lines),
                "largest_change": None if self.largest is None else self.largest.to_dict()}


def _moved(c: Change, floor: float) -> bool:
    return abs(c.after - c.before) >= floor and abs(c.relative) >= MIN_CHANGE


def _change_line(c: Comparison, guesses: Guesses | None) -> tuple[str, Change | None]:
    candidates: list[tuple[Change, str]] = []
    for name, b, a in c.stretch_rows():
        stretched = ", ".join(b.stretched)
        fast = Change(f"{name} at {b.speed_deg_s:.0f}°/s", "N·m", b.peak_torque_n_m,
                      a.peak_torque_n_m)
        reflex = Change(f"{name} velocity-dependent part", "N·m", b.reflex_torque_n_m,
                        a.reflex_torque_n_m)
        slow = Change(f"{name} at {b.slow_speed_deg_s:.0f}°/s", "N·m", b.slow_torque_n_m,
                      a.slow_torque_n_m)
        iv = _interval(guesses, f"{name} peak torque")
        if _moved(fast, MIN_TORQUE_N_M) or _moved(reflex, MIN_TORQUE_N_M):
            text = (f"Resistance to a fast ({b.speed_deg_s:.0f}°/s) {name} stretch (it lengthens "
                    f"{stretched}): {fast.text()}{iv}; its velocity-dependent part "
                    f"{reflex.text()}.")
            candidates.append((max(fast, reflex, key=lambda x: abs(x.relative)), text))
        if _moved(slow, MIN_TORQUE_N_M):
            candidates.append((slow, f"Resistance to a slow ({b.slow_speed_deg_s:.0f}°/s) "
                                     f"{name} stretch (position-dependent; it lengthens "
                                     f"{stretched}): {slow.text()}."))
    for f in c.fields:
        ch = Change(f"field RMS force at {f.speed_m_per_s:g} m/s", "N", f.force_rms_before_n,
                    f.force_rms_after_n)
        if _moved(ch, MIN_FORCE_N):
            state = "at rest" if f.speed_m_per_s == 0 else f"moving at {f.speed_m_per_s:g} m/s"
            candidates.append((ch, f"Force the arm exerts {state} (RMS over the workspace): "
                                   f"{ch.text()}."))
    if not candidates:
        return ("No joint-stretch resistance or field force changes by 1% or more: the plan "
                "does not change what these read-outs measure.", None)
    best, text = max(candidates, key=lambda t: abs(t[0].relative))
    return "Most change: " + text[0].lower() + text[1:], best


def _interval(guesses: Guesses | None, metric: str) -> str:
    if guesses is None:
        return ""
    for i in guesses.intervals:
        if i.metric == metric:
            return f", change {i.change:+.2f} N·m [95% {i.change_low:+.2f} … {i.change_high:+.2f}]"
    return ""


def _grade_line(c: Comparison) -> str:
    moves: list[str] = []
    for g, sb, sa in c.severity_rows():
        for kind, word in (("dynamic", "spasticity"), ("passive", "contracture")):
            b, a = sb.component(kind), sa.component(kind)
            if b.text() != a.text():
                moves.append(f"{g} ({GROUP_NAMES.get(g, g)}) {word} {b.text()} → {a.text()}")
    if not moves:
        return "Grades: no spasticity (dynamic) or contracture (passive) grade changes."
    return "Grades: " + "; ".join(moves) + "."


def _warning_line(warnings: Sequence[str]) -> str:
    if not warnings:
        return "Warnings: none."
    first = warnings[0].rstrip(".")
    more = f" (and {len(warnings) - 1} more below)" if len(warnings) > 1 else ""
    return f"WARNING{'S' if len(warnings) > 1 else ''}: {first}{more}."


def summarise(c: Comparison, guesses: Guesses | None,
              warnings: Sequence[str]) -> WhatIfSummary:
    """The three summary lines of a what-if (module docstring); ``warnings``: every warning
    of the result (:meth:`fieldbank.interventions.whatif.WhatIf.all_warnings`)."""
    line1, largest = _change_line(c, guesses)
    return WhatIfSummary((line1, _grade_line(c), _warning_line(warnings)), largest)
