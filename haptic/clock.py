"""Time for the haptic loop: clocks with absolute deadlines, and the real-time context.

A loop asks its :class:`Clock` for the time and sleeps until absolute deadlines, so lateness
never accumulates: :class:`RealClock` reads :func:`time.perf_counter_ns`, sleeps until
``spin_us`` before the deadline and spins the rest (the scheduler's wake-up latency is larger
than a tick's slack); :class:`VirtualClock` jumps to the deadline at once, so tests render a
minute of a lockstep simulation in a fraction of that.

:func:`realtime` prepares the process for a loop and restores it after: a full garbage
collection and ``gc.freeze()`` first (a collection can take longer than the device watchdog,
and nothing may stand between the ARM frame and the first FORCE), the collector disabled,
``SCHED_FIFO`` requested (a warning is logged when the OS refuses), and a short thread switch
interval, so another thread (the control channel) hands the interpreter back within a tick.
"""

from __future__ import annotations

import contextlib
import gc
import logging
import os
import sys
import time
from collections.abc import Iterator
from typing import Protocol

log = logging.getLogger("fieldbank.haptic.clock")

#: GIL switch interval while a loop runs, s (the default 5 ms would let another thread hold the
#: interpreter for several ticks).
SWITCH_INTERVAL_S = 1e-4
#: Highest SCHED_FIFO priority asked for: below the kernel's own real-time threads.
MAX_FIFO_PRIORITY = 80


class Clock(Protocol):
    """What a loop needs of time: nanoseconds, and sleeping until an absolute deadline."""

    def now_ns(self) -> int: ...
    def sleep_until(self, deadline_ns: int) -> None: ...


class RealClock:
    """Wall clock: sleep to ``spin_us`` before the deadline, then spin.

    Parameters
    ----------
    spin_us : float, µs
        How long before each deadline the clock stops sleeping and spins.
    """

    def __init__(self, spin_us: float = 200.0) -> None:
        self.spin_ns = int(spin_us * 1000)

    def now_ns(self) -> int:
        return time.perf_counter_ns()

    def sleep_until(self, deadline_ns: int) -> None:
        pc = time.perf_counter_ns
        rem = deadline_ns - pc()
        if rem > self.spin_ns:
            time.sleep((rem - self.spin_ns) * 1e-9)
        while pc() < deadline_ns:
            pass


class VirtualClock:
    """Simulated time, ns from 0: sleeping jumps to the deadline at once."""

    def __init__(self) -> None:
        self.t_ns = 0

    def now_ns(self) -> int:
        return self.t_ns

    def sleep_until(self, deadline_ns: int) -> None:
        if deadline_ns > self.t_ns:
            self.t_ns = deadline_ns


def _enter_fifo() -> tuple[int, os.sched_param] | None:
    """Ask for SCHED_FIFO; the policy to restore, or None when refused or unsupported."""
    if not hasattr(os, "sched_setscheduler"):
        return None
    try:
        old = (os.sched_getscheduler(0), os.sched_getparam(0))
        prio = max(1, min(MAX_FIFO_PRIORITY, os.sched_get_priority_max(os.SCHED_FIFO) - 10))
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(prio))
        return old
    except (PermissionError, OSError) as exc:
        log.warning("real-time scheduling (SCHED_FIFO) refused by the OS (%s); the loop runs "
                    "with normal priority and its timing will show more jitter", exc)
        return None


def _leave_fifo(old: tuple[int, os.sched_param] | None) -> None:
    if old is not None:
        try:
            os.sched_setscheduler(0, old[0], old[1])
        except OSError:
            pass


@contextlib.contextmanager
def realtime(priority: bool = True,
             switch_interval_s: float = SWITCH_INTERVAL_S) -> Iterator[bool]:
    """Run the enclosed loop with the collector frozen and off, SCHED_FIFO, a short switch
    interval; everything is restored on leaving, also on an exception.

    Parameters
    ----------
    priority : bool
        Ask for SCHED_FIFO (False: keep the normal policy, e.g. for a lockstep simulation).
    switch_interval_s : float, s
        The interpreter's thread switch interval inside.

    Yields
    ------
    bool
        Whether SCHED_FIFO was granted.
    """
    gc.collect()
    gc.freeze()
    gc_was_enabled = gc.isenabled()
    gc.disable()
    old_sched = _enter_fifo() if priority else None
    old_switch = sys.getswitchinterval()
    sys.setswitchinterval(switch_interval_s)
    try:
        yield old_sched is not None
    finally:
        sys.setswitchinterval(old_switch)
        if gc_was_enabled:
            gc.enable()
        gc.unfreeze()
        _leave_fifo(old_sched)
