"""Timing figures of the haptic loop: period error, overruns, tick cost, status read-outs.

The loop only appends integers (ns) to the ``array('q')`` buffers of
:class:`LoopTimes` — one wake time and one lateness per iteration, one total cost per tick, a
running sum per phase — and everything statistical happens here, outside the tick, on copies.

Figures (all in µs unless named otherwise):

- **period error**: |actual period between two wakes − nominal period|, p50/p99/max;
- **period**: the actual period, p50/p99/max;
- **wake lateness**: how late each iteration woke after its deadline; an **overrun** is an
  iteration that woke more than ``overrun_ms`` late (their times since the first wake, s);
- **tick cost**: the mean per phase (:data:`PHASES`) and the total's p50/p99/max (percentiles
  are robust to the few ticks preempted mid-way; the mean is not).
"""

from __future__ import annotations

import array
from typing import Any

import numpy as np

#: The phases of a tick, in order; the renderer sums the cost of each (ns) in this order.
PHASES = ("link_in", "checks", "models", "safety", "link_out", "record")

#: The figures ``status`` shows for the recent past of a running loop.
STATUS_KEYS = ("period_error_us", "overruns", "skipped_ticks", "tick_total_us",
               "realtime_scheduling", "realtime")


class LoopTimes:
    """Timing records of one renderer, appended by its loop.

    Attributes
    ----------
    wake_ns : array('q')
        Clock time of each iteration's wake-up, ns (restarted by :meth:`restart`).
    late_ns : array('q')
        How late each iteration woke after its deadline, ns (restarted by :meth:`restart`).
    tick_ns : array('q')
        Cost of each tick, ns.
    phase_ns : list of int, len(PHASES)
        Cost of each phase summed over all ticks, ns.
    skipped_ticks : int
        Ticks skipped because the loop woke a whole period late.
    """

    __slots__ = ("late_ns", "phase_ns", "skipped_ticks", "tick_ns", "wake_ns")

    def __init__(self) -> None:
        self.wake_ns: array.array[int] = array.array("q")
        self.late_ns: array.array[int] = array.array("q")
        self.tick_ns: array.array[int] = array.array("q")
        self.phase_ns = [0] * len(PHASES)
        self.skipped_ticks = 0

    def restart(self) -> None:
        """New wake and lateness records for a new run (tick costs keep accumulating)."""
        self.wake_ns = array.array("q")
        self.late_ns = array.array("q")


def _percentiles(x: np.ndarray, scale: float = 1.0) -> dict[str, float]:
    return {"p50": float(np.percentile(x, 50) / scale), "p99": float(np.percentile(x, 99) / scale),
            "max": float(x.max() / scale)}


def loop_stats(times: LoopTimes, *, ticks: int, rate_hz: int, overrun_ms: float,
               realtime_scheduling: bool | None, passivity_active_ticks: int,
               link: dict[str, Any], last: int | None = None,
               realtime: dict[str, Any] | None = None) -> dict[str, Any]:
    """The loop's figures (module docstring) over the whole session or its ``last`` iterations.

    Safe to call from another thread while the loop runs: it works on copies (a numpy view
    would stop the loop's arrays from growing).

    Parameters
    ----------
    times : LoopTimes
    ticks : int
        Ticks run so far.
    rate_hz : int, Hz
        Nominal tick rate.
    overrun_ms : float, ms
        Lateness above which an iteration counts as an overrun.
    realtime_scheduling : bool or None
        Whether SCHED_FIFO was granted (None: the loop has not run).
    passivity_active_ticks : int
        Ticks in which the passivity controller added damping.
    link : dict
        The robot port's counters (:meth:`haptic.port.RobotPort.counters`).
    last : int, optional
        Only the last this many iterations (the tick cost means are always whole-session).
    realtime : dict, optional
        What the OS granted the loop (:meth:`haptic.clock.Grant.to_dict`: SCHED_FIFO and its
        priority, the core it is pinned to, what was refused).
    """
    # the loop may append while this copies (wake before late): the same iterations of both,
    # up to the last one whose lateness is recorded
    end = len(times.late_ns)
    k = max(0, end - last) if last else 0
    wake = np.array(times.wake_ns[k:end], dtype=np.float64)
    late = np.array(times.late_ns[k:end], dtype=np.float64)
    tick_ns = np.array(times.tick_ns[-last if last else 0:], dtype=np.float64)
    out: dict[str, Any] = {"ticks": ticks, "rate_hz": rate_hz,
                           "realtime_scheduling": realtime_scheduling, "realtime": realtime}
    if late.size >= 2:
        periods_ns = np.diff(wake)
        out["period_error_us"] = _percentiles(np.abs(periods_ns - round(1e9 / rate_hz)), 1e3)
        out["period_us"] = _percentiles(periods_ns / 1e3)
        out["wake_late_us"] = _percentiles(late, 1e3)
        over = late > overrun_ms * 1e6
        out["overruns"] = int(over.sum())
        out["overrun_threshold_ms"] = overrun_ms
        out["skipped_ticks"] = times.skipped_ticks
        out["overrun_times_s"] = [float((wake[i] - wake[0]) / 1e9)
                                  for i in np.flatnonzero(over)[:100]]
    n = max(1, ticks)
    cost = times.phase_ns
    out["tick_cost_us"] = {name: cost[i] / n / 1e3 for i, name in enumerate(PHASES)}
    out["tick_cost_us"]["total"] = sum(cost) / n / 1e3
    if tick_ns.size:
        out["tick_total_us"] = _percentiles(tick_ns / 1e3)
    out["passivity_active_ticks"] = passivity_active_ticks
    out["link"] = link
    return out


def status_figures(stats: dict[str, Any]) -> dict[str, Any]:
    """The part of :func:`loop_stats` that ``status`` shows (:data:`STATUS_KEYS`)."""
    return {k: v for k, v in stats.items() if k in STATUS_KEYS}
