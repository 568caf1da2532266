"""What the loop needs of a robot: :class:`RobotPort`, and the handle's state it reads
(:class:`HandleState`).

The renderer (:mod:`haptic.renderer`) and its safety monitor (:mod:`haptic.monitor`) talk to a
robot through this seam only. Three kinds of robot stand behind it:

* :class:`~haptic.link.RobotLink` - the project's wire protocol (:mod:`haptic.protocol`) over a
  USB serial port, a pty or TCP (``socket://``); the simulated robot is reached the same way
  (``sim://`` in process, or a device process on a pty), so every byte of the protocol is
  exercised in the tests;
* a robot adapter installed beside fieldbank: a distribution that registers a factory for a URL
  scheme in the entry point group ``fieldbank.robots`` (:mod:`haptic.robots`;
  ``docs/robot-adapters.md`` has a worked adapter);
* anything else that has the members below (a test's scripted robot).

Both sites of a remote assessment (:mod:`haptic.remote`) drive their robots through this seam
too; the patient's site needs a robot that can also report the force of the hand on its handle
(:class:`SensingPort`).

A port is driven by one thread, the loop's. Per tick the loop calls :meth:`RobotPort.poll` (or
:meth:`RobotPort.wait_state` for a robot that answers each force with one state), reads
:attr:`RobotPort.state`, and calls :meth:`RobotPort.send_force` once. A port whose robot is gone
raises :class:`~haptic.errors.LinkDown` from any call; the monitor turns that into a DISCONNECT
fault. Everything a port counts as evidence of a fault (garbled frames, lost frames, the robot's
own fault reports) is a counter of its :class:`HandleState`; judging the counters is the
monitor's job, never the port's.

This module imports only the wire's :class:`~haptic.protocol.DeviceInfo`: an adapter may import
it without loading the loop.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Protocol, runtime_checkable

from fieldbank.haptic.protocol import DeviceInfo


@dataclass(slots=True, eq=False)
class HandleState:
    """The newest state of the handle as of the port's last poll, and the evidence of faults.

    The port updates this one record in place on every poll (the loop reads it between polls
    without allocating); copy it (:meth:`copy`) to keep a state. Robot frame, SI.

    Attributes
    ----------
    x, y : float, m
        Handle position.
    vx, vy : float, m/s
        Handle velocity.
    t_us : int, µs
        The robot's timestamp of the state.
    flags : int
        The robot's status bits of the newest state (:data:`haptic.protocol.FLAG_ARMED`,
        ``FLAG_WATCHDOG``, ``FLAG_FAULT``).
    states : int
        States received so far (the monitor's TIMEOUT counts polls that brought none).
    sensor_fx, sensor_fy : float, N
        The force of the hand on the handle, from a force sensor (robots that have one, once
        asked); ``sensors`` readings so far.
    crc_errors : int
        Frames the port could not trust (a bad checksum), so far.
    max_gap : int
        Largest number of reports lost in one gap since :meth:`take_gap` was last called.
    device_faults, last_device_fault : int
        Fault reports the robot sent so far, and the code of the newest.
    fault_flag_frames, watchdog_flag_frames : int
        States whose ``flags`` carried the fault or the watchdog bit, so far: every such report
        counts, also one a newer state of the same poll replaced.

    A port with no such evidence (no checksum, no sequence numbers) leaves the counter at 0.
    """

    x: float = 0.0
    y: float = 0.0
    vx: float = 0.0
    vy: float = 0.0
    t_us: int = 0
    flags: int = 0
    states: int = 0
    sensor_fx: float = 0.0
    sensor_fy: float = 0.0
    sensors: int = 0
    crc_errors: int = 0
    max_gap: int = 0
    device_faults: int = 0
    last_device_fault: int = 0
    fault_flag_frames: int = 0
    watchdog_flag_frames: int = 0

    def take_gap(self) -> int:
        """Largest gap since the last call (and reset it): read by the monitor once a tick."""
        g = self.max_gap
        self.max_gap = 0
        return g

    def copy(self) -> HandleState:
        """A copy that the port's next poll leaves as it is."""
        return replace(self)


@runtime_checkable
class RobotPort(Protocol):
    """A robot the loop can render on: connected, its handshake done, not yet armed.

    Attributes
    ----------
    state : HandleState
        The newest handle state and the fault evidence, updated in place by every poll.
    device : DeviceInfo or None
        What the robot says about itself (name, rate, force limit, watchdog): recorded with
        the session.
    """

    state: HandleState
    device: DeviceInfo | None

    def poll(self) -> int:
        """Take what the robot has reported, without blocking; the number of new states."""
        ...

    def wait_state(self, timeout_s: float, spin_s: float = 0.0) -> int:
        """Poll until a state arrives or ``timeout_s`` passes (busy-polling the first
        ``spin_s``); the number of new states."""
        ...

    def send_force(self, fx_n: float, fy_n: float) -> object:
        """Command the force on the handle, N, robot frame (already limited by the loop)."""
        ...

    def heartbeat(self) -> None:
        """Tell the robot that the host is alive while no force is due (a robot with a
        watchdog restarts it; one without has nothing to do)."""
        ...

    def arm(self) -> None:
        """Let the robot apply forces (the loop ramps them in)."""
        ...

    def disarm(self) -> None:
        """Zero the robot's force and stop applying commands until the next :meth:`arm`."""
        ...

    def counters(self) -> dict[str, Any]:
        """What went wrong on the way and how much went through, for the session's figures
        (JSON-able; :func:`haptic.loopstats.loop_stats` keeps it as ``link``)."""
        ...

    def close(self) -> None:
        """Release the robot (called once, after the session)."""
        ...


@runtime_checkable
class SensingPort(RobotPort, Protocol):
    """A robot with a force sensor at its handle (the patient's site of a remote assessment
    needs one: it tells the clinician what the patient's arm does)."""

    def sensor_on(self) -> None:
        """Ask the robot to report the force of the hand on the handle with every state
        (:attr:`HandleState.sensor_fx`, ``sensor_fy``; :attr:`HandleState.sensors` counts the
        readings). A robot without a sensor refuses with a fault report
        (:attr:`HandleState.device_faults`) or never sends a reading."""
        ...
