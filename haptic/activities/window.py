"""Whether a trial was felt: the running figures of one trial's window (:class:`TrialWindow`).

A trial's answer counts only if the clinician felt the arm for the whole of it. While an
activity runs, the loop hands it every tick's commanded force and whether it was armed (its
tick hook, :meth:`haptic.activities.base.Activity.tick`); the activity's window keeps two
figures cheaply - the ticks it was not armed (force zero by command: a fault, or disarmed) and
the largest force commanded since the window opened. When a trial ends, its window is judged
against the fault log:

* **fault** - a fault tripped in the window, or the window opened in fault;
* **no force** - the robot was not armed for part of the window (its force was zero);
* **zero force** - nothing was felt: the largest force in the window stayed under
  :data:`ZERO_FORCE_N`.

A flagged trial is stored with its flags and shown, but left out of every accuracy
(:func:`haptic.training.summarise`, :meth:`haptic.activities.abx.AbxSession.result`).
"""

from __future__ import annotations

import math
from typing import Any

from fieldbank.haptic.protocol import FaultCode
from fieldbank.haptic.safety import Mode, Safety

#: A window whose largest commanded force stays under this, N, had nothing to feel.
ZERO_FORCE_N = 0.05


class TrialWindow:
    """One trial's window: opened at its start, fed every tick, judged at its end.

    Attributes
    ----------
    ticks, unarmed_ticks : int
        Ticks since the window opened, and those on which the loop was not armed.
    peak_force_n2 : float, N²
        Largest ‖F‖² commanded in the window.
    faults : int
        Length of the fault log when the window opened.
    in_fault : bool
        The loop was in fault when the window opened.
    """

    __slots__ = ("faults", "in_fault", "peak_force_n2", "ticks", "unarmed_ticks")

    def __init__(self, safety: Safety | None = None) -> None:
        self.open(safety)

    def open(self, safety: Safety | None) -> None:
        """Start a window now (``safety``: the loop's, whose fault log it is judged against)."""
        self.ticks = self.unarmed_ticks = 0
        self.peak_force_n2 = 0.0
        self.faults = 0 if safety is None else len(safety.log_records)
        self.in_fault = safety is not None and safety.mode == Mode.FAULT

    def tick(self, fx: float, fy: float, armed: bool) -> None:
        """One tick of the loop: the force it commanded, and whether it was armed."""
        self.ticks += 1
        f2 = fx * fx + fy * fy
        if f2 > self.peak_force_n2:
            self.peak_force_n2 = f2
        if not armed:
            self.unarmed_ticks += 1

    def judge(self, safety: Safety, dt_s: float) -> dict[str, Any]:
        """The window's verdict now: ``flagged``, ``flags`` (reasons in words),
        ``peak_force_n``, ``unarmed_s``, ``faults`` (names)."""
        new = safety.log_records[self.faults:]
        unarmed = self.unarmed_ticks
        peak = math.sqrt(self.peak_force_n2)
        flags: list[str] = []
        names = sorted({FaultCode(r.code).name for r in new})
        if new or self.in_fault:
            flags.append("fault during the trial" + (f" ({', '.join(names)})" if names else
                                                      " (it began in fault)"))
        if unarmed:
            flags.append(f"no force for {unarmed * dt_s:.2f} s (robot not armed)")
        elif self.ticks and peak < ZERO_FORCE_N:
            flags.append("zero force: nothing was felt")
        return {"flagged": bool(flags), "flags": flags,
                "peak_force_n": round(peak, 4) if math.isfinite(peak) else None,
                "unarmed_s": round(unarmed * dt_s, 4), "faults": names}
