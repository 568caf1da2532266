"""Which robot a URL names, opened ready for the loop (:func:`open_robot`).

* The project's own link (:class:`~haptic.link.RobotLink`, the wire protocol of
  ``docs/robot-protocol.md``) takes a device or pty path (``/dev/ttyUSB0``), every URL pyserial
  opens (``socket://host:port``, ``rfc2217://``, ``loop://`` …) and the simulated robot
  (``sim://``): :data:`BUILT_IN`.
* A robot that speaks something else is reached through an adapter installed beside fieldbank:
  a distribution that declares, in the entry point group :data:`GROUP` (``fieldbank.robots``),
  an entry point named by its URL scheme whose object is a factory::

      factory(url: str, *, rate_hz: int, watchdog_ms: int) -> RobotPort

  returning the robot connected, its handshake done, not armed, with its
  :class:`~haptic.protocol.DeviceInfo` (``docs/robot-adapters.md`` has a worked adapter). The
  built-in schemes cannot be taken by an adapter.

Every failure is a :class:`~haptic.errors.HapticError` that names the scheme, the distribution
and what went wrong, with the URL's secrets masked.

:func:`with_force_sensor` turns an open robot's force sensor on (what a measurement and the
patient's site of a remote assessment need), refusing in words a robot without one.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from importlib.metadata import EntryPoint, entry_points

from fieldbank.errors import FieldbankError
from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.port import RobotPort, SensingPort
from fieldbank.redact import mask_port, mask_url, redact_port

#: The entry point group robot adapters register in (name: URL scheme; object: factory).
GROUP = "fieldbank.robots"
#: URL schemes the project's own link serves (pyserial's and the simulated robot's).
BUILT_IN = ("sim", "socket", "rfc2217", "loop", "spy", "alt", "hwgrep", "cp2110")
_SCHEME = re.compile(r"^([A-Za-z][A-Za-z0-9+.-]*)://")


def scheme_of(url: str) -> str | None:
    """The URL's scheme in lower case; None for a device or pty path."""
    m = _SCHEME.match(url)
    return m.group(1).lower() if m else None


def adapters() -> dict[str, list[EntryPoint]]:
    """The installed robot adapters by scheme (more than one entry point for a scheme is an
    error when that scheme is opened)."""
    out: dict[str, list[EntryPoint]] = {}
    for ep in entry_points(group=GROUP):
        out.setdefault(ep.name.lower(), []).append(ep)
    return out


def _origin(ep: EntryPoint) -> str:
    dist = ep.dist
    return f"{ep.value!r} of {dist.name} {dist.version}" if dist is not None else repr(ep.value)


def adapter_for(url: str) -> EntryPoint | None:
    """The installed adapter that opens ``url`` (None: the project's own link does - a device
    path or a built-in scheme); a :class:`~haptic.errors.HapticError` when no adapter, or more
    than one, claims its scheme. Nothing is imported or opened: a configuration naming a robot
    is checked with it where it is made."""
    scheme = scheme_of(url)
    if scheme is None or scheme in BUILT_IN:
        return None
    found = adapters().get(scheme, [])
    if not found:
        known = ", ".join(f"{s}://" for s in sorted(adapters())) or "none"
        raise HapticError(f"no robot adapter for {scheme}:// is installed (robot "
                          f"{mask_port(url)!r}; adapters installed: {known}; built in: a "
                          f"device path, {', '.join(f'{s}://' for s in BUILT_IN)})")
    if len(found) > 1:
        raise HapticError(f"{len(found)} robot adapters claim {scheme}://: "
                          f"{'; '.join(_origin(ep) for ep in found)}; uninstall all but one")
    return found[0]


def open_robot(url: str, rate_hz: int, watchdog_ms: int,
               shown: str | None = None) -> RobotPort:
    """The robot ``url`` names, connected and its handshake done at ``rate_hz`` with the
    robot's watchdog asked for ``watchdog_ms``; not armed. Close it with ``close()``.
    ``shown``: the URL as the user gave it, for messages (a simulated robot's URL is filled in
    with the details of the simulation)."""
    ep = adapter_for(url)
    if ep is None:
        link = RobotLink.open(url, shown=shown)
        try:
            link.handshake(rate_hz, watchdog_ms)
        except BaseException:
            link.close()
            raise
        return link
    scheme = ep.name.lower()
    try:
        factory = ep.load()
    except Exception as exc:  # an adapter's import error, whatever it is
        raise HapticError(f"the robot adapter for {scheme}:// ({_origin(ep)}) failed to "
                          f"load: {type(exc).__name__}: {exc}") from None
    try:
        port = factory(url, rate_hz=rate_hz, watchdog_ms=watchdog_ms)
    except FieldbankError as exc:
        raise HapticError(redact_port(str(exc), url)) from None
    except Exception as exc:  # the adapter's own errors, in its words
        raise HapticError(f"the robot adapter for {scheme}:// ({_origin(ep)}) could not open "
                          f"{mask_port(url)!r}: "
                          f"{redact_port(f'{type(exc).__name__}: {exc}', url)}") from None
    problem = _refusal(port, rate_hz)
    if problem:
        close = getattr(port, "close", None)
        if callable(close):
            close()
        raise HapticError(f"the robot adapter for {scheme}:// ({_origin(ep)}): {problem}")
    return port


def _refusal(port: object, rate_hz: int) -> str | None:
    """Why ``port`` cannot be rendered on (None: it can)."""
    if not isinstance(port, RobotPort):
        members = [*RobotPort.__annotations__, *(n for n, v in vars(RobotPort).items()
                                                  if callable(v) and not n.startswith("_"))]
        missing = [m for m in members if not hasattr(port, m)]
        return (f"its factory returned {type(port).__name__}, not a robot port (missing: "
                f"{', '.join(missing)})")
    if port.device is None:
        return "the robot did not say what it is (its port has no device information)"
    if rate_hz > port.device.max_rate_hz:
        return f"the robot accepts at most {port.device.max_rate_hz} Hz; asked {rate_hz} Hz"
    return None


def with_force_sensor(robot: RobotPort, url: str, needed_by: str,
                      clock: Callable[[], float] = time.monotonic) -> SensingPort:
    """``robot`` (at ``url``) with its force sensor on and its first reading in, within 1 s of
    asking by ``clock``; a :class:`~haptic.errors.HapticError` saying that ``needed_by`` ("the
    patient's site", "measuring") needs one when its port has no sensor, the robot answers
    SENSOR_ON with a fault, or no reading arrives."""
    if not isinstance(robot, SensingPort):
        raise HapticError(f"the robot at {mask_url(url)} cannot report the force of the hand "
                          f"on its handle (its port has no force sensor); {needed_by} needs one")
    st = robot.state
    robot.sensor_on()
    deadline = clock() + 1.0
    while st.sensors == 0:
        robot.send_force(0.0, 0.0)
        robot.wait_state(0.01)
        if st.device_faults:
            raise HapticError(f"the robot at {mask_url(url)} has no force sensor (it answered "
                              f"SENSOR_ON with fault {st.last_device_fault}); {needed_by} "
                              "needs one")
        if clock() > deadline:
            raise HapticError(f"the robot at {mask_url(url)} sent no force-sensor reading "
                              f"within 1 s of SENSOR_ON; {needed_by} needs one")
    return robot
