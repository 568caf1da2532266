"""Host side of the robot link: a pyserial port speaking :mod:`haptic.protocol`.

:class:`RobotLink` wraps any port :func:`serial.serial_for_url` returns (a USB serial device, a
pty, ``socket://``, or the simulated robot ``sim://``). Reads never block the loop: each
:meth:`RobotLink.poll` takes the bytes that have arrived (on a POSIX port only those the
kernel holds ready: a read that finds bytes still in the tty layer's buffer waits for them),
reassembles frames, unpacks the newest STATE into its :class:`~haptic.port.HandleState`, and
counts what went wrong (CRC and other decode errors, frames lost to sequence gaps, duplicates,
device FAULT frames, STATE frames whose flags report a device fault or a tripped watchdog -
each frame counted, even when a newer STATE of the same read replaces it; the fault flag even
in a frame dropped as a duplicate). It is a :class:`~haptic.port.RobotPort` (and a
:class:`~haptic.port.SensingPort`: :meth:`sensor_on`); judging its counts is the safety
monitor's job (:mod:`haptic.monitor`); a port that fails raises :class:`LinkDown`.

Sequence numbers: a frame numbered behind the last one is a duplicate and dropped. One forged
or corrupted-but-valid frame far ahead would then make every genuine frame look old and blind
the host; so when :data:`RESYNC_FRAMES` frames in a row arrive in order from another point of
the sequence, the link resynchronises to them (counted in ``resyncs``). The jump itself is a
sequence gap, which the safety layer turns into a fault.
"""

from __future__ import annotations

import array
import os
import select
import time
from fcntl import ioctl
from termios import FIONREAD
from typing import Any

import serial

from fieldbank.haptic import protocol as P
from fieldbank.haptic.errors import HandshakeError, HapticError, LinkDown
from fieldbank.haptic.port import HandleState
from fieldbank.redact import mask_port, redact_port

# pyserial resolves a URL scheme X to the module <package>.protocol_X: sim:// -> protocol_sim
if "fieldbank.haptic" not in serial.protocol_handler_packages:
    serial.protocol_handler_packages.append("fieldbank.haptic")

#: Baud rate asked of real USB serial adapters (ignored by ptys and sim://).
DEFAULT_BAUDRATE = 1_000_000
#: Consecutive in-order frames from another point of the sequence that resynchronise it.
RESYNC_FRAMES = 3
#: Offset of the flags byte in a STATE payload (t_us u32, x, y, vx, vy f32).
STATE_FLAGS_AT = 20
# what every tick's receive and send paths use, as plain names (no enum look-up per frame)
_STATE, _SENSOR = int(P.MsgType.STATE), int(P.MsgType.SENSOR)
_HELLO_ACK, _FAULT = int(P.MsgType.HELLO_ACK), int(P.MsgType.FAULT)
_FLAG_FAULT, _FLAG_WATCHDOG = P.FLAG_FAULT, P.FLAG_WATCHDOG
_FORCE, _pack_force = int(P.MsgType.FORCE), P.FORCE_FMT.pack


class RobotLink:
    """Protocol endpoint on the host: a :class:`~haptic.port.RobotPort`.

    Attributes
    ----------
    state : HandleState
        The newest STATE (``t_us``, ``x``, ``y``, ``vx``, ``vy``, ``flags``, ``states``), the
        newest force-sensor reading once :meth:`sensor_on` was sent to a device that has one
        (``sensor_fx``, ``sensor_fy``: N, force of the hand on the handle; ``sensors``), and
        the fault evidence: ``crc_errors``, ``max_gap``, ``device_faults`` (FAULT frames),
        ``fault_flag_frames`` and ``watchdog_flag_frames`` (STATE frames with those flags).
    echo_seq : int
        The last FORCE sequence number the device applied (from the newest STATE).
    sensor_t_us : int, µs
        The device's time of the newest force-sensor reading.
    frames_rx, frames_tx, frames_lost, duplicates, resyncs, tx_dropped : int
        What went through and what went wrong on the wire; ``decode_errors`` by kind from the
        frame reader (``reader.errors``).
    """

    def __init__(self, port: serial.SerialBase) -> None:
        self.port = port
        self.reader = P.FrameReader()
        self._tx_seq = 0
        self._rx_seq = -1
        self.device: P.DeviceInfo | None = None
        self.state = HandleState()
        self.echo_seq = 0
        self.sensor_t_us = 0
        self.frames_rx = 0
        self.frames_tx = 0
        self.frames_lost = 0
        self.duplicates = 0
        self.resyncs = 0
        self._resync_next = -1
        self._resync_run = 0
        try:
            self._fd: int | None = port.fileno()
        except (AttributeError, OSError, ValueError, serial.SerialException):
            self._fd = None
        # Fast path: a POSIX serial port (or pty) that pyserial opened non-blocking is read and
        # written with one system call each; pyserial's write adds a select() per frame.
        self._raw_fd: int | None = None
        if self._fd is not None and type(port).__module__ == "serial.serialposix":
            self._raw_fd = self._fd
        self.tx_dropped = 0
        self._ready = array.array("i", [0])  # FIONREAD's answer: bytes ready to read

    @classmethod
    def open(cls, url: str, baudrate: int = DEFAULT_BAUDRATE,
             shown: str | None = None) -> RobotLink:
        """Open ``url`` (``sim://…``, ``/dev/ttyUSB0``, a pty path, ``socket://…``).

        ``shown``: the port as the user gave it, quoted in messages instead of ``url`` (a
        simulated robot's URL filled in with the details of the simulation)."""
        try:
            port = serial.serial_for_url(url, baudrate=baudrate, timeout=0, write_timeout=0.05)
        except (serial.SerialException, ValueError, OSError) as exc:
            why = redact_port(str(exc), url)
            if shown is not None and shown != url:
                why = why.replace(mask_port(url), mask_port(shown))
            raise HapticError(f"cannot open robot port {mask_port(shown or url)!r}: "
                              f"{why}") from None
        if hasattr(port, "set_low_latency_mode"):
            try:
                port.set_low_latency_mode(True)  # FTDI latency timer 16 ms -> 1 ms
            except (OSError, ValueError, serial.SerialException):
                pass
        return cls(port)

    @property
    def decode_errors(self) -> int:
        return sum(self.reader.errors.values())

    def counters(self) -> dict[str, Any]:
        """What went wrong on the link so far, and how much went through it."""
        return {"crc_errors": self.state.crc_errors, "decode_errors": dict(self.reader.errors),
                "frames_lost": self.frames_lost, "duplicates": self.duplicates,
                "states": self.state.states, "frames_tx": self.frames_tx}

    # --- sending ----------------------------------------------------------------------------
    def _send(self, msg_type: int, payload: bytes = b"") -> int:
        seq = self._tx_seq
        frame = P.encode_frame(msg_type, seq, payload)
        self._tx_seq = (seq + 1) & 0xFFFF
        fd = self._raw_fd
        try:
            if fd is not None:
                n = os.write(fd, frame)
                if n < len(frame):
                    self._write_rest(frame[n:])
            else:
                self.port.write(frame)
        except BlockingIOError:
            self.tx_dropped += 1  # the device is not reading (its input buffer is full)
        except (serial.SerialException, OSError) as exc:
            raise LinkDown(f"robot port write failed: {exc}") from None
        self.frames_tx += 1
        return seq

    def _write_rest(self, rest: bytes) -> None:
        assert self._raw_fd is not None
        deadline = time.perf_counter() + 0.005
        while rest:
            if time.perf_counter() > deadline:
                self.tx_dropped += 1
                return
            select.select([], [self._raw_fd], [], 0.001)
            try:
                rest = rest[os.write(self._raw_fd, rest):]
            except BlockingIOError:
                pass

    def send_force(self, fx_n: float, fy_n: float) -> int:
        """Send a FORCE frame; returns its sequence number."""
        return self._send(_FORCE, _pack_force(fx_n, fy_n))

    def arm(self) -> None:
        self._send(P.MsgType.ARM)

    def disarm(self) -> None:
        self._send(P.MsgType.DISARM)

    def sensor_on(self) -> None:
        """Ask the device for its force sensor: a SENSOR frame before every STATE."""
        self._send(P.MsgType.SENSOR_ON)

    def heartbeat(self) -> None:
        self._send(P.MsgType.HEARTBEAT)

    def send_fault(self, code: int, detail: int = 0) -> None:
        self._send(P.MsgType.FAULT, P.FAULT_FMT.pack(code, detail & 0xFFFF))

    # --- receiving --------------------------------------------------------------------------
    def poll(self) -> int:
        """Read what has arrived without blocking; return the number of new STATE frames.

        Every frame read is checked (CRC, sequence number) and counted, and the flags of every
        STATE frame are judged; of several STATE frames read at once (a backlog after a stall)
        only the newest is unpacked into :attr:`state`, the others have nothing the loop uses.
        """
        fd = self._raw_fd
        if fd is not None:
            try:
                # a read that finds bytes still on their way through the kernel's tty buffer
                # waits for them (≈ 25 µs of this thread's CPU, measured): read only what is
                # ready; the rest is there on the next poll
                ioctl(fd, FIONREAD, self._ready, True)
                if not self._ready[0]:
                    return 0
                data = os.read(fd, 4096)
            except BlockingIOError:
                return 0
            except OSError as exc:  # a hang-up: EIO
                raise LinkDown(f"robot port read failed: {exc}") from None
        else:
            port = self.port
            try:
                n = port.in_waiting
                data = port.read(n if n > 0 else 1)
            except (serial.SerialException, OSError) as exc:
                raise LinkDown(f"robot port read failed: {exc}") from None
        if not data:
            return 0
        frames = self.reader.feed(data)
        self.frames_rx += len(frames)
        new = 0
        newest = None
        st = self.state
        rx = self._rx_seq
        for t, seq, payload in frames:
            if t == _STATE and payload[STATE_FLAGS_AT] & _FLAG_FAULT:
                st.fault_flag_frames += 1  # every one counts, even a frame dropped below
            if rx >= 0:
                lost = (seq - rx - 1) & 0xFFFF
                if lost >= 0x8000:  # behind the last frame: a duplicate, unless a run of them
                    run = self._resync_run + 1 if seq == self._resync_next else 1
                    self._resync_next = (seq + 1) & 0xFFFF
                    self._resync_run = run
                    if run < RESYNC_FRAMES:
                        self.duplicates += 1
                        continue
                    self.resyncs += 1  # the stream continues from here: follow it
                    lost = 0
                self._resync_run = 0
                if lost:
                    self.frames_lost += lost
                    if lost > st.max_gap:
                        st.max_gap = lost
            rx = seq
            if t == _STATE:
                newest = payload
                new += 1
                if payload[STATE_FLAGS_AT] & _FLAG_WATCHDOG:
                    st.watchdog_flag_frames += 1
            elif t == _SENSOR:
                self.sensor_t_us, st.sensor_fx, st.sensor_fy = P.SENSOR_FMT.unpack(payload)
                st.sensors += 1
            elif t == _HELLO_ACK:
                self.device = P.DeviceInfo.from_payload(payload)
            elif t == _FAULT:
                st.device_faults += 1
                st.last_device_fault = P.FAULT_FMT.unpack(payload)[0]
        self._rx_seq = rx
        if newest is not None:
            (st.t_us, st.x, st.y, st.vx, st.vy, st.flags,
             self.echo_seq) = P.STATE_FMT.unpack(newest)
            st.states += new
        st.crc_errors = self.reader.errors.get("crc", 0)
        return new

    def wait_state(self, timeout_s: float, spin_s: float = 0.0) -> int:
        """Poll until at least one STATE arrives or ``timeout_s`` passes; return how many.

        For the first ``spin_s`` the wait busy-polls (a reply within a few hundred µs is seen
        at once, without the scheduler's wake-up latency of a blocking select), then it sleeps
        in select().
        """
        new = self.poll()
        if new or timeout_s <= 0:
            return new
        start = time.perf_counter()
        deadline = start + timeout_s
        spin_until = start + min(spin_s, timeout_s)
        while time.perf_counter() < spin_until:
            new = self.poll()
            if new:
                return new
        while True:
            left = deadline - time.perf_counter()
            if left <= 0:
                return 0
            if self._fd is not None:
                select.select([self._fd], [], [], left)
            else:
                time.sleep(min(left, 1e-4))
            new = self.poll()
            if new:
                return new

    # --- session ----------------------------------------------------------------------------
    def handshake(self, rate_hz: int, watchdog_ms: int, timeout_s: float = 1.0,
                  attempts: int = 3) -> P.DeviceInfo:
        """HELLO → HELLO_ACK; checks version and rate. Raises HandshakeError on failure."""
        for _ in range(attempts):
            self._send(P.MsgType.HELLO, P.HELLO_FMT.pack(P.PROTOCOL_VERSION, rate_hz, watchdog_ms))
            deadline = time.perf_counter() + timeout_s / attempts
            while time.perf_counter() < deadline:
                self.wait_state(min(0.01, max(0.0, deadline - time.perf_counter())))
                if self.device is not None:
                    break
                if self.state.device_faults:
                    raise HandshakeError(
                        f"the robot refused HELLO (protocol {P.PROTOCOL_VERSION}, {rate_hz} Hz): "
                        f"fault code {self.state.last_device_fault}"
                    )
            if self.device is not None:
                break
        info = self.device
        if info is None:
            raise HandshakeError(f"no HELLO_ACK from the robot within {timeout_s:g} s")
        if info.protocol_version != P.PROTOCOL_VERSION:
            raise HandshakeError(
                f"robot speaks protocol {info.protocol_version}, host {P.PROTOCOL_VERSION}"
            )
        if rate_hz > info.max_rate_hz:
            raise HandshakeError(f"robot accepts at most {info.max_rate_hz} Hz; asked {rate_hz} Hz")
        return info

    def close(self) -> None:
        try:
            self.port.close()
        except (serial.SerialException, OSError):
            pass
