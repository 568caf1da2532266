"""Time for the haptic loop: clocks with absolute deadlines, and the real-time context.

A loop asks its :class:`Clock` for the time and sleeps until absolute deadlines, so lateness
never accumulates: :class:`RealClock` reads :func:`time.perf_counter_ns`, sleeps until
``spin_us`` before the deadline and spins the rest (the scheduler's wake-up latency is larger
than a tick's slack); :class:`VirtualClock` jumps to the deadline at once, so tests render a
minute of a lockstep simulation in a fraction of that.

:func:`realtime` prepares the process for a loop and restores it after: a full garbage
collection and ``gc.freeze()`` first (:func:`collector_off`, which a simulated device's process
uses too) (a collection can take longer than the device watchdog,
and nothing may stand between the ARM frame and the first FORCE), the collector disabled,
``SCHED_FIFO`` requested for the loop's thread, the thread pinned to a core of its own where the
machine has two or more (:func:`cpu_plan`: the host loop on one, a simulated device process on
another, so neither waits for the other or for a busy neighbour's time slice), and a short
thread switch interval, so another thread (the control channel) hands the interpreter back
within a tick, and every other thread of the process (control channel, log writer) runs at
SCHED_FIFO below the loop meanwhile, so a busy machine cannot preempt one while it holds the
interpreter lock the loop needs. Where the OS refuses priority or affinity, the loop runs
anyway: a warning is logged and the loop's statistics say so (:class:`Grant`). Log records
are written by a thread of their own meanwhile (:func:`logging_off_the_loop`): the loop thread
does no I/O but the robot's.

The loop never spins unboundedly: :class:`RealClock` sleeps until ``spin_us`` before each
deadline and spins only the rest, and a lockstep wait for the device's reply spins at most as
long before it sleeps in ``select`` (:meth:`haptic.link.RobotLink.wait_state`), so a real-time
loop cannot starve a device process that shares its core.
"""

from __future__ import annotations

import contextlib
import gc
import logging
import logging.handlers
import os
import queue
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Protocol

log = logging.getLogger("fieldbank.haptic.clock")

#: GIL switch interval while a loop runs, s (the default 5 ms would let another thread hold the
#: interpreter for several ticks).
SWITCH_INTERVAL_S = 1e-4
#: Highest SCHED_FIFO priority asked for: below the kernel's own real-time threads.
MAX_FIFO_PRIORITY = 80
#: How far below the maximum the host loop and a simulated device ask for SCHED_FIFO, and the
#: threads that share the loop's interpreter (:func:`keep_up_with_the_loop`).
HOST_PRIORITY_BELOW_MAX = 10
DEVICE_PRIORITY_BELOW_MAX = 20
SHARER_PRIORITY_BELOW_MAX = 30

#: SCHED_FIFO priority of the real-time loop running in this process (None: none runs).
_loop_priority: int | None = None
_thread_state = threading.local()


def keep_up_with_the_loop() -> None:
    """For a thread that shares the loop's interpreter (the control channel), before each
    piece of work: while a real-time loop runs in this process, run at SCHED_FIFO below the
    loop and the device; else at the normal policy again.

    Why: a thread holding the interpreter lock that a busy machine preempts (load above the
    core count) holds the loop up until the scheduler runs it again - tens of ms, more than the
    device watchdog allows. At SCHED_FIFO no ordinary process preempts it, and its work is
    short (requests are bounded), so it hands the lock back at once. (:func:`realtime` raises
    the threads that exist when the loop starts; this covers those started later by a thread
    that was not raised.)
    """
    want = _loop_priority
    have = getattr(_thread_state, "priority", None)
    if want == have or not hasattr(os, "sched_setscheduler"):
        return
    try:
        if want is None:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        else:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(_sharer_priority(want)))
        _thread_state.priority = want
    except OSError:
        _thread_state.priority = want  # refused: the loop's own grant already says so


@contextlib.contextmanager
def collector_off() -> Iterator[None]:
    """Keep the garbage collector out of a loop: a full collection, then everything that
    exists is frozen (never scanned again) and automatic collection is off; restored on
    leaving.

    Why: in a process that has imported numpy a full collection takes ≈ 15 ms and a young one
    0.1-0.6 ms (measured on a 2-core workstation), longer than a device watchdog or the host's
    STATE timeout allows. The loops that run inside (the haptic tick, the simulated device)
    build no reference cycles, so nothing accumulates while it is off
    (``tests/test_haptic_realtime.py`` counts them).
    """
    gc.collect()
    gc.freeze()
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()
        gc.unfreeze()


@dataclass(frozen=True)
class Grant:
    """What the OS granted a real-time loop (or a device process).

    Attributes
    ----------
    fifo : bool
        SCHED_FIFO was granted.
    priority : int or None
        Its priority.
    cpu : int or None
        The core the thread is pinned to (None: not pinned - one core only, or refused).
    notes : tuple of str
        What was refused, and why, in words.
    """

    fifo: bool = False
    priority: int | None = None
    cpu: int | None = None
    notes: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, object]:
        return {"fifo": self.fifo, "priority": self.priority, "cpu": self.cpu,
                "notes": list(self.notes)}

    @classmethod
    def from_dict(cls, d: dict[str, object]) -> Grant:
        prio, cpu, notes = d.get("priority"), d.get("cpu"), d.get("notes")
        return cls(bool(d.get("fifo")), prio if isinstance(prio, int) else None,
                   cpu if isinstance(cpu, int) else None,
                   tuple(str(n) for n in notes) if isinstance(notes, list) else ())

    def text(self) -> str:
        """In words: "SCHED_FIFO priority 79, core 1" (and what was refused)."""
        out = f"SCHED_FIFO priority {self.priority}" if self.fifo else "normal priority"
        out += f", core {self.cpu}" if self.cpu is not None else ", any core"
        return out + (f" ({'; '.join(self.notes)})" if self.notes else "")


def cpu_plan() -> tuple[int | None, int | None]:
    """(host loop's core, simulated device's core): two different cores this process may run
    on, where it may run on two or more; (None, None) otherwise (nothing is pinned then)."""
    try:
        cpus = sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return None, None
    if len(cpus) < 2:
        return None, None
    return cpus[-1], cpus[-2]


def _pin(cpu: int | None) -> tuple[set[int] | None, str | None]:
    """Pin the calling thread to ``cpu``: (the mask to restore, or None; a note if refused)."""
    if cpu is None:
        return None, None
    try:
        old = os.sched_getaffinity(0)
        os.sched_setaffinity(0, {cpu})
        return old, None
    except (AttributeError, OSError) as exc:
        log.warning("pinning the loop to core %s refused by the OS (%s); it runs on any core",
                    cpu, exc)
        return None, f"core {cpu} refused: {exc}"


def _unpin(old: set[int] | None) -> None:
    if old is not None:
        try:
            os.sched_setaffinity(0, old)
        except OSError:
            pass


def enter_device_realtime(cpu: int | None) -> Grant:
    """For a simulated device's own process: SCHED_FIFO one step below the host loop, pinned
    to ``cpu``; refusals are logged and returned as notes (the device runs anyway)."""
    notes = []
    prio = None
    fifo = False
    if hasattr(os, "sched_setscheduler"):
        try:
            prio = max(1, min(MAX_FIFO_PRIORITY, os.sched_get_priority_max(os.SCHED_FIFO))
                       - DEVICE_PRIORITY_BELOW_MAX)
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(prio))
            fifo = True
        except OSError as exc:
            prio = None
            notes.append(f"SCHED_FIFO refused: {exc}")
            log.warning("simulated device: SCHED_FIFO refused by the OS (%s)", exc)
    else:
        notes.append("SCHED_FIFO not offered by this OS")
    _, note = _pin(cpu)
    if note:
        notes.append(note)
    return Grant(fifo, prio, cpu if note is None else None, tuple(notes))


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


def _enter_fifo() -> tuple[tuple[int, os.sched_param] | None, int | None, str | None]:
    """Ask for SCHED_FIFO: (the policy to restore or None, the priority, a note if refused)."""
    if not hasattr(os, "sched_setscheduler"):
        return None, None, "SCHED_FIFO not offered by this OS"
    try:
        old = (os.sched_getscheduler(0), os.sched_getparam(0))
        prio = max(1, min(MAX_FIFO_PRIORITY, os.sched_get_priority_max(os.SCHED_FIFO)
                          - HOST_PRIORITY_BELOW_MAX))
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(prio))
        return old, prio, None
    except (PermissionError, OSError) as exc:
        log.warning("real-time scheduling (SCHED_FIFO) refused by the OS (%s); the loop runs "
                    "with normal priority and its timing will show more jitter", exc)
        return None, None, f"SCHED_FIFO refused: {exc}"


def _leave_fifo(old: tuple[int, os.sched_param] | None) -> None:
    if old is not None:
        try:
            os.sched_setscheduler(0, old[0], old[1])
        except OSError:
            pass


def _sharer_priority(loop_priority: int) -> int:
    return max(1, loop_priority - (SHARER_PRIORITY_BELOW_MAX - HOST_PRIORITY_BELOW_MAX))


def _raise_sharers(loop_priority: int | None) -> list[int]:
    """Every other thread of this process (the control channel's, the log writer, …) to
    SCHED_FIFO below the loop, so none is preempted while it holds the interpreter lock; the
    threads they start inherit it. The native ids raised."""
    if loop_priority is None or not hasattr(os, "sched_setscheduler"):
        return []
    me = threading.get_native_id()
    out = []
    for th in threading.enumerate():
        tid = th.native_id
        if tid is None or tid == me:
            continue
        try:
            os.sched_setscheduler(tid, os.SCHED_FIFO,
                                  os.sched_param(_sharer_priority(loop_priority)))
            out.append(tid)
        except OSError:  # refused, or the thread has just ended
            pass
    return out


def _lower_sharers(tids: list[int]) -> None:
    for tid in tids:
        try:
            os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))
        except OSError:  # the thread has ended
            pass


@contextlib.contextmanager
def logging_off_the_loop(name: str = "fieldbank.haptic") -> Iterator[None]:
    """Inside, records of logger ``name`` (and its children) are queued by the thread that logs
    them and written by a thread of their own: a fault logged in the loop never waits for a
    terminal or a disk (a write to a busy disk can take 100 ms, five device watchdogs). The
    records go to the handlers they went to before (the root's), in order, all of them by the
    time the context ends."""
    logger = logging.getLogger(name)
    target = logger.handlers or logging.getLogger().handlers
    if not target:  # nothing would write them: nothing to move
        yield
        return
    q: queue.SimpleQueue[logging.LogRecord] = queue.SimpleQueue()
    listener = logging.handlers.QueueListener(q, *target, respect_handler_level=True)
    handler = logging.handlers.QueueHandler(q)
    old_handlers, old_propagate = logger.handlers[:], logger.propagate
    logger.handlers = [handler]
    logger.propagate = False
    listener.start()
    try:
        yield
    finally:
        logger.handlers = old_handlers
        logger.propagate = old_propagate
        listener.stop()


@contextlib.contextmanager
def realtime(priority: bool = True, switch_interval_s: float = SWITCH_INTERVAL_S,
             pin: bool | None = None, cpu: int | None = None) -> Iterator[Grant]:
    """Run the enclosed loop with the collector frozen and off, SCHED_FIFO, the thread pinned
    to the host's core of :func:`cpu_plan`, a short switch interval; everything is restored on
    leaving, also on an exception.

    Parameters
    ----------
    priority : bool
        Ask for SCHED_FIFO (False: keep the normal policy, e.g. for a lockstep simulation).
    switch_interval_s : float, s
        The interpreter's thread switch interval inside.
    pin : bool, optional
        Pin the thread to a core of its own (default: when ``priority``).
    cpu : int, optional
        That core (default: the host loop's of :func:`cpu_plan`; a second loop on the same
        machine — the patient's site of a remote session tried on one machine — takes the
        other).

    Yields
    ------
    Grant
        What was granted (``bool(grant.fifo)``: whether SCHED_FIFO was).
    """
    logs = logging_off_the_loop()
    logs.__enter__()  # its writer thread is one of the sharers raised below
    collector = collector_off()
    collector.__enter__()
    notes: list[str] = []
    old_sched, prio, note = _enter_fifo() if priority else (None, None, None)
    if note:
        notes.append(note)
    if not (priority if pin is None else pin):
        cpu = None
    elif cpu is None:
        cpu = cpu_plan()[0]
    old_mask, note = _pin(cpu)
    if note:
        notes.append(note)
        cpu = None
    old_switch = sys.getswitchinterval()
    sys.setswitchinterval(switch_interval_s)
    global _loop_priority
    _loop_priority = prio if old_sched is not None else None
    raised = _raise_sharers(_loop_priority)
    try:
        yield Grant(old_sched is not None, prio, cpu, tuple(notes))
    finally:
        _loop_priority = None
        _lower_sharers(raised)
        sys.setswitchinterval(old_switch)
        collector.__exit__(None, None, None)
        _leave_fifo(old_sched)
        _unpin(old_mask)
        logs.__exit__(None, None, None)
