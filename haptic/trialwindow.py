"""Whether a trial was felt: the loop's record of one trial's window (:class:`TrialWindow`).

A trial's answer counts only if the clinician felt the arm for the whole of it. The renderer
keeps two running figures cheaply every tick - the ticks it was not armed (force zero by
command: a fault, or disarmed) and the largest force it commanded since the window opened - and
its fault log. When a trial ends, its window is judged:

* **fault** - a fault tripped in the window, or the window opened in fault;
* **no force** - the robot was not armed for part of the window (its force was zero);
* **zero force** - nothing was felt: the largest force in the window stayed under
  :data:`ZERO_FORCE_N`.

A flagged trial is stored with its flags and shown, but left out of every accuracy
(:func:`haptic.training.summarise`, :meth:`haptic.abx.AbxSession.result`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from fieldbank.haptic.protocol import FaultCode
from fieldbank.haptic.safety import FaultRecord

#: A window whose largest commanded force stays under this, N, had nothing to feel.
ZERO_FORCE_N = 0.05


@dataclass(frozen=True)
class TrialWindow:
    """Where the renderer's running figures stood when a trial's window opened.

    Attributes
    ----------
    ticks, unarmed_ticks, faults : int
        The renderer's tick count, not-armed tick count and fault-log length then.
    in_fault : bool
        The renderer was in fault when the window opened.
    """

    ticks: int = 0
    unarmed_ticks: int = 0
    faults: int = 0
    in_fault: bool = False

    def judge(self, ticks: int, unarmed_ticks: int, fault_log: list[FaultRecord],
              peak_force_n: float, dt_s: float) -> dict[str, Any]:
        """The window's verdict now: ``flagged``, ``flags`` (reasons in words),
        ``peak_force_n``, ``unarmed_s``, ``faults`` (names)."""
        new = fault_log[self.faults:]
        unarmed = unarmed_ticks - self.unarmed_ticks
        flags: list[str] = []
        names = sorted({FaultCode(r.code).name for r in new})
        if new or self.in_fault:
            flags.append("fault during the trial" + (f" ({', '.join(names)})" if names else
                                                      " (it began in fault)"))
        if unarmed:
            flags.append(f"no force for {unarmed * dt_s:.2f} s (robot not armed)")
        elif ticks > self.ticks and peak_force_n < ZERO_FORCE_N:
            flags.append("zero force: nothing was felt")
        return {"flagged": bool(flags), "flags": flags,
                "peak_force_n": round(peak_force_n, 4) if math.isfinite(peak_force_n) else None,
                "unarmed_s": round(unarmed * dt_s, 4), "faults": names}
