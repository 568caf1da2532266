"""The mechanism that keeps the loop on time on a busy machine (not its timing: no wall-clock
bound is asserted): the simulated device's own process runs at real-time priority in every
mode, pinned to a core other than the host loop's where there are two; the host loop thread
gets SCHED_FIFO and its own core inside ``realtime()`` and gives both back after; the waits
spin only a bounded time before they sleep; where the OS refuses, everything runs and says so.
"""

from __future__ import annotations

import gc
import os
import time

import pytest

from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic import clock
from fieldbank.haptic.clock import RealClock, cpu_plan, realtime
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.simrobot import PtyRobot, SimRobotConfig
from tests.haptic_util import pty_session

ROOT = os.geteuid() == 0 if hasattr(os, "geteuid") else False
TWO_CORES = len(os.sched_getaffinity(0)) >= 2 if hasattr(os, "sched_getaffinity") else False


@pytest.mark.parametrize("mode", ["lockstep", "realtime"])
def test_the_device_process_runs_real_time_on_its_own_core(mode: str) -> None:
    with PtyRobot(SimRobotConfig(mode=mode)) as robot:
        robot.start_process()
        assert robot.grant is not None and robot.pid is not None
        link = RobotLink.open(robot.port)
        link.handshake(1000, 20, timeout_s=5.0)  # it serves
        link.close()
        if ROOT:  # as in CI: granted, and the kernel agrees
            assert robot.grant.fifo and robot.grant.notes == ()
            assert os.sched_getscheduler(robot.pid) == os.SCHED_FIFO
            assert os.sched_getparam(robot.pid).sched_priority == robot.grant.priority
        if ROOT and TWO_CORES:
            host, device = cpu_plan()
            assert host != device and robot.grant.cpu == device
            assert os.sched_getaffinity(robot.pid) == {device}


def test_the_loop_thread_takes_priority_and_a_core_and_gives_them_back() -> None:
    before_policy = os.sched_getscheduler(0)
    before_mask = os.sched_getaffinity(0)
    host = cpu_plan()[0]
    with realtime() as g:
        if ROOT:
            assert g.fifo and os.sched_getscheduler(0) == os.SCHED_FIFO
        if ROOT and TWO_CORES:
            assert g.cpu == host and os.sched_getaffinity(0) == {host}
    assert os.sched_getscheduler(0) == before_policy
    assert os.sched_getaffinity(0) == before_mask


def test_refusals_are_said_and_the_loop_runs(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*a: object) -> None:
        raise PermissionError("not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    monkeypatch.setattr(os, "sched_setaffinity", refuse)
    monkeypatch.setattr(clock, "cpu_plan", lambda: (0, 1))
    with realtime() as g:
        assert not g.fifo and g.cpu is None
        assert any("SCHED_FIFO refused" in n for n in g.notes)
        assert any("core 0 refused" in n for n in g.notes)
    d = clock.enter_device_realtime(1)
    assert not d.fifo and d.cpu is None and len(d.notes) == 2
    assert "normal priority, any core" in d.text()


def test_waits_spin_a_bounded_time_then_sleep(monkeypatch: pytest.MonkeyPatch) -> None:
    """RealClock spins only the last spin_us before a deadline; before that it sleeps."""
    slept: list[float] = []
    real_sleep = time.sleep
    monkeypatch.setattr(time, "sleep", lambda s: (slept.append(s), real_sleep(s)))
    c = RealClock(spin_us=200.0)
    t0 = time.perf_counter_ns()
    c.sleep_until(t0 + 5_000_000)  # 5 ms ahead: sleeps about 4.8 ms, spins the rest
    assert slept and 4.0e-3 < slept[0] <= 4.8e-3 + 1e-9
    slept.clear()
    c.sleep_until(time.perf_counter_ns() + 100_000)  # inside the spin window: no sleep
    assert slept == []


def test_threads_sharing_the_interpreter_keep_up_with_a_real_time_loop() -> None:
    """A control thread holding the interpreter lock must not be preempted by a busy machine
    while the loop waits for the lock: it runs SCHED_FIFO below the loop while one runs."""
    seen: list[int] = []

    def work() -> None:
        clock.keep_up_with_the_loop()
        seen.append(os.sched_getscheduler(0))

    import threading

    with realtime() as g:
        th = threading.Thread(target=work)
        th.start()
        th.join()
    th = threading.Thread(target=work)
    th.start()
    th.join()
    if ROOT and g.fifo:
        assert seen == [os.SCHED_FIFO, os.SCHED_OTHER]


def test_the_loop_logs_without_writing(caplog: pytest.LogCaptureFixture) -> None:
    """Inside realtime() a fault logged by the loop thread is written by another thread, and
    every record is there, in order, when the context ends."""
    import logging
    import threading

    seen: list[tuple[str, str]] = []

    class Spy(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            seen.append((record.getMessage(), threading.current_thread().name))

    spy = Spy()
    logging.getLogger().addHandler(spy)
    try:
        log = logging.getLogger("fieldbank.haptic.safety")
        with caplog.at_level(logging.INFO), realtime(priority=False):
            for k in range(50):
                log.warning("fault %d", k)
        log.warning("after")
    finally:
        logging.getLogger().removeHandler(spy)
    assert [m for m, _ in seen] == [f"fault {k}" for k in range(50)] + ["after"]
    assert {t for m, t in seen[:-1]} != {threading.current_thread().name}
    assert seen[-1][1] == threading.current_thread().name


def test_threads_alive_when_the_loop_starts_are_raised_and_lowered_again() -> None:
    import threading

    ready, go = threading.Event(), threading.Event()
    th = threading.Thread(target=lambda: (ready.set(), go.wait(10)), daemon=True)
    th.start()
    ready.wait(5)
    assert th.native_id is not None
    with realtime() as g:
        inside = os.sched_getscheduler(th.native_id)
    after = os.sched_getscheduler(th.native_id)
    go.set()
    th.join(5)
    if ROOT and g.fifo:
        assert inside == os.SCHED_FIFO and after == os.SCHED_OTHER


def test_collector_off_freezes_disables_and_restores() -> None:
    assert gc.isenabled()
    with clock.collector_off():
        assert not gc.isenabled() and gc.get_freeze_count() > 0
    assert gc.isenabled() and gc.get_freeze_count() == 0


@pytest.mark.parametrize("motion, sim", [("explore", {}),
                                         ("hold", {"patient": "elbow=severe"})])
def test_the_loops_build_no_reference_cycles(monkeypatch: pytest.MonkeyPatch, motion: str,
                                             sim: dict[str, object]) -> None:
    """The renderer's loop and the simulated device run with the collector off (a collection
    takes longer than a watchdog): that is safe only while neither builds reference cycles,
    which nothing would ever free. Both run here in one process (device thread, lockstep) for
    3 s of ticks; the cycles made meanwhile are counted by a collection after the loop."""
    made: list[int] = []
    loop = Renderer._loop

    def counted(self: Renderer, n_ticks: int | None) -> None:
        gc.collect()  # what start() left behind: once per session, not per tick
        loop(self, n_ticks)
        made.append(gc.collect())

    monkeypatch.setattr(Renderer, "_loop", counted)
    with pty_session(synthesize({"elbow": "severe"}), motion=motion, **sim) as (rd, _):
        trace = rd.run(3.0)
    assert trace.stats["ticks"] == 3000 and not trace.faults
    assert made == [0]
