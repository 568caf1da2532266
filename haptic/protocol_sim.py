"""pyserial URL handler for ``sim://``: the simulated robot inside this process.

``serial.serial_for_url("sim://?mode=lockstep&motion=pull&x0_m=0.05&y0_m=0.4")`` returns a port
whose far end is a :class:`haptic.simrobot.SimDevice` (options: the fields of
:class:`haptic.simrobot.SimRobotConfig`). Writes are fed to the device at once; in realtime mode
the device's physics and watchdog advance to the wall clock whenever the port is read or polled.
Importing :mod:`haptic.link` registers the handler (``serial.protocol_handler_packages``).
"""

from __future__ import annotations

import time
import urllib.parse

from serial.serialutil import PortNotOpenError, SerialBase, SerialException

from fieldbank.haptic.simrobot import SimDevice, SimRobotConfig


class Serial(SerialBase):
    """A serial port connected to a simulated robot."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        self.device: SimDevice | None = None
        self._rx = bytearray()
        self.unplugged = False
        super().__init__(*args, **kwargs)

    def open(self) -> None:
        if self.is_open:  # type: ignore[has-type]
            raise SerialException("Port is already open.")
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        parts = urllib.parse.urlsplit(str(self.port))
        if parts.scheme != "sim":
            raise SerialException(f"expected a sim:// URL; got {self.port!r}")
        try:
            cfg = SimRobotConfig.from_query(parts.query)
        except ValueError as exc:
            raise SerialException(f"bad sim:// URL {self.port!r}: {exc}") from None
        self.device = SimDevice(cfg)
        self._rx.clear()
        self.is_open = True

    def close(self) -> None:
        self.is_open = False
        super().close()

    def _reconfigure_port(self, *args: object, **kwargs: object) -> None:
        pass  # baud rate and line settings mean nothing to the simulation

    def unplug(self) -> None:
        """Simulate a pulled cable: every later read or write fails."""
        self.unplugged = True

    def _pump(self) -> None:
        if not self.is_open:
            raise PortNotOpenError()
        if self.unplugged:
            raise SerialException("device disconnected (simulated unplug)")
        assert self.device is not None
        if self.device.config.mode == "realtime":
            self.device.poll_realtime(time.perf_counter())
        self._rx += self.device.take_output()

    @property
    def in_waiting(self) -> int:
        self._pump()
        return len(self._rx)

    def read(self, size: int = 1) -> bytes:
        self._pump()
        deadline = None if not self._timeout else time.perf_counter() + self._timeout
        while not self._rx and deadline is not None and time.perf_counter() < deadline:
            time.sleep(1e-4)
            self._pump()
        data = bytes(self._rx[:size])
        del self._rx[:size]
        return data

    def write(self, data: bytes) -> int:
        if not self.is_open:
            raise PortNotOpenError()
        if self.unplugged:
            raise SerialException("device disconnected (simulated unplug)")
        assert self.device is not None
        self.device.feed(bytes(data))
        return len(data)

    def reset_input_buffer(self) -> None:
        self._rx.clear()

    def reset_output_buffer(self) -> None:
        pass

    @property
    def out_waiting(self) -> int:
        return 0

    def _update_rts_state(self) -> None:
        pass

    def _update_dtr_state(self) -> None:
        pass

    def _update_break_state(self) -> None:
        pass

    @property
    def cts(self) -> bool:
        return True

    @property
    def dsr(self) -> bool:
        return True

    @property
    def ri(self) -> bool:
        return False

    @property
    def cd(self) -> bool:
        return True
