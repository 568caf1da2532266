"""Robot link wire protocol, version 1: COBS-framed messages with CRC-16 and sequence numbers.

One frame on the wire::

    COBS( version u8 | type u8 | seq u16 LE | payload | crc u16 LE ) 0x00

The CRC is CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, xorout 0; check value
of ``b"123456789"`` is 0x29B1) over version, type, seq and payload. Every sender numbers its own
frames, +1 per frame, wrapping at 65536. All multi-byte fields are little-endian; forces and
kinematics are IEEE-754 float32 in SI units (N, m, m/s). ``docs/robot-protocol.md`` is the
byte-level specification for the device side; this module is its host-side implementation.

COBS is written here (a dozen lines, no dependency); the CRC uses :func:`binascii.crc_hqx`,
which computes this exact CRC in C (``crc16_ccitt_false_reference`` is the bit-wise definition
the tests compare it against).
"""

from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple

from fieldbank.haptic.errors import FrameError

PROTOCOL_VERSION = 1
#: Largest encoded frame accepted by a decoder (bytes, before the delimiter).
MAX_FRAME_BYTES = 64
DEVICE_ID_BYTES = 16


class MsgType(IntEnum):
    """Message types (byte 1 of a decoded frame)."""

    HELLO = 0x01       # host -> device: protocol version, tick rate, watchdog request
    HELLO_ACK = 0x02   # device -> host: version, device id, max rate, force limit, watchdog
    STATE = 0x10       # device -> host: device time, handle position and velocity, flags
    SENSOR = 0x11      # device -> host: the handle's force sensor (after SENSOR_ON)
    FORCE = 0x20       # host -> device: force to apply to the handle
    ARM = 0x30         # host -> device: enable force output
    DISARM = 0x31      # host -> device: zero force and disable output
    SENSOR_ON = 0x32   # host -> device: send a SENSOR frame before every STATE from now on
    FAULT = 0x40       # either way: a fault code and detail
    HEARTBEAT = 0x50   # either way: keeps the link alive when no FORCE is due


class FaultCode(IntEnum):
    """Fault codes carried by FAULT frames and recorded in traces (bit index = code - 1)."""

    CRC = 1            # CRC errors over the threshold
    TIMEOUT = 2        # no STATE within the timeout
    SEQ_GAP = 3        # frames lost (sequence gap over the threshold)
    NAN = 4            # a non-finite number in the state or the computed force
    WORKSPACE = 5      # handle outside the workspace box
    SPEED = 6          # handle faster than the speed limit
    DISCONNECT = 7     # the port failed or closed
    DEVICE = 8         # the device reported a fault (or its watchdog tripped)
    MODEL = 9          # a virtual arm diverged
    OPERATOR = 10      # stop requested (emergency stop, control channel)


#: Each fault code in words (messages; the FAULT frame's code and the traces keep the number).
FAULT_WORDS: dict[int, str] = {
    FaultCode.CRC: "damaged frames (CRC errors)",
    FaultCode.TIMEOUT: "a timeout (no frame in time)",
    FaultCode.SEQ_GAP: "lost frames (a sequence gap)",
    FaultCode.NAN: "a value that is not a number",
    FaultCode.WORKSPACE: "the handle outside the workspace",
    FaultCode.SPEED: "the handle over the speed limit",
    FaultCode.DISCONNECT: "a lost connection",
    FaultCode.DEVICE: "a fault of its own",
    FaultCode.MODEL: "a diverged model",
    FaultCode.OPERATOR: "a stop asked for",
}

# flags in STATE
FLAG_ARMED = 0x01
FLAG_WATCHDOG = 0x02
FLAG_FAULT = 0x04


def device_report(fault_code: int, flags: int) -> str:
    """What the robot reported, in words: its watchdog (STATE flag bit 1), a fault of its own
    (bit 2), a FAULT frame's code - never "code 0, flags 2"."""
    parts = []
    if flags & FLAG_WATCHDOG:
        parts.append("its watchdog tripped (no force command reached it in time)")
    if flags & FLAG_FAULT:
        parts.append("it reports a fault of its own")
    if fault_code:
        words = FAULT_WORDS.get(fault_code, "an unknown fault")
        parts.append(f"it sent a FAULT frame: {words} (code {fault_code})")
    return "the robot stopped itself: " + ("; ".join(parts) if parts else
                                           "it reported a fault and gave no reason")

_HEADER = struct.Struct("<BBH")
_CRC = struct.Struct("<H")
HELLO_FMT = struct.Struct("<BHH")                 # version, rate_hz, watchdog_ms
HELLO_ACK_FMT = struct.Struct("<B16sHfH")         # version, device_id, max_rate_hz, limit, wd
STATE_FMT = struct.Struct("<IffffBH")             # t_us, x, y, vx, vy, flags, last force seq
FORCE_FMT = struct.Struct("<ff")                  # fx, fy
FAULT_FMT = struct.Struct("<BH")                  # code, detail
SENSOR_FMT = struct.Struct("<Iff")                # t_us, fx, fy (force of the hand on the handle)

#: FAULT detail a device answers SENSOR_ON with when it has no force sensor (code DEVICE).
FAULT_DETAIL_NO_SENSOR = 2

PAYLOAD_SIZES: dict[int, int] = {
    MsgType.HELLO: HELLO_FMT.size,
    MsgType.HELLO_ACK: HELLO_ACK_FMT.size,
    MsgType.STATE: STATE_FMT.size,
    MsgType.FORCE: FORCE_FMT.size,
    MsgType.ARM: 0,
    MsgType.DISARM: 0,
    MsgType.SENSOR: SENSOR_FMT.size,
    MsgType.SENSOR_ON: 0,
    MsgType.FAULT: FAULT_FMT.size,
    MsgType.HEARTBEAT: 0,
}

_SIZES = {int(k): v for k, v in PAYLOAD_SIZES.items()}


class Frame(NamedTuple):
    """A decoded frame: message type, sender's sequence number, raw payload bytes."""

    type: int
    seq: int
    payload: bytes


#: Builds a :class:`Frame` from a tuple in C (a named tuple's own constructor is a Python call).
_new_frame = tuple.__new__


# --- CRC --------------------------------------------------------------------------------------
def crc16_ccitt_false(data: bytes) -> int:
    """CRC-16/CCITT-FALSE of ``data`` (C implementation from the standard library)."""
    return binascii.crc_hqx(data, 0xFFFF)


def crc16_ccitt_false_reference(data: bytes) -> int:
    """Bit-wise definition of CRC-16/CCITT-FALSE, for cross-checking."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


# --- COBS -------------------------------------------------------------------------------------
def cobs_encode(data: bytes) -> bytes:
    """Consistent Overhead Byte Stuffing: the result contains no 0x00 byte.

    Each zero-free run of up to 254 bytes is preceded by a code byte (run length + 1); a code
    of 0xFF means a run of 254 bytes not followed by an implicit zero.
    """
    out = bytearray()
    for block in bytes(data).split(b"\x00"):
        while len(block) >= 254:
            out.append(0xFF)
            out += block[:254]
            block = block[254:]
        out.append(len(block) + 1)
        out += block
    return bytes(out)


def cobs_decode(data: bytes) -> bytes:
    """Inverse of :func:`cobs_encode`; raises :class:`FrameError` on malformed input."""
    n = len(data)
    if 0 in data:
        raise FrameError("cobs", "COBS data contains a zero byte")
    parts = []
    i = 0
    while i < n:
        code = data[i]
        end = i + code
        if end > n:
            raise FrameError("cobs", f"COBS code {code} at byte {i} runs past the end ({n} bytes)")
        parts.append(data[i + 1:end])
        if code != 0xFF and end < n:
            parts.append(b"\x00")
        i = end
    return b"".join(parts)


# --- frames -----------------------------------------------------------------------------------
def encode_frame(msg_type: int, seq: int, payload: bytes = b"") -> bytes:
    """Encode one frame, delimiter included."""
    body = _HEADER.pack(PROTOCOL_VERSION, msg_type, seq & 0xFFFF) + payload
    body += _CRC.pack(binascii.crc_hqx(body, 0xFFFF))
    return cobs_encode(body) + b"\x00"


def decode_frame(encoded: bytes) -> Frame:
    """Decode one frame (without its delimiter); raises :class:`FrameError`."""
    n = len(encoded)
    if n > MAX_FRAME_BYTES:
        raise FrameError("length", f"frame of {n} bytes exceeds {MAX_FRAME_BYTES}")
    # the common case, without a call: a frame with no zero inside is its code byte and its body
    body = bytes(encoded[1:]) if n and encoded[0] == n and 0 not in encoded else cobs_decode(
        encoded)
    end = len(body) - 2  # where the CRC starts (single bytes and slices: no struct call)
    if end < _HEADER.size:
        raise FrameError("length", f"frame of {len(body)} bytes is shorter than header + CRC")
    if binascii.crc_hqx(body[:end], 0xFFFF) != body[end] | body[end + 1] << 8:
        raise FrameError("crc", "CRC mismatch")
    version, msg_type = body[0], body[1]
    if version != PROTOCOL_VERSION:
        raise FrameError("version", f"protocol version {version}, expected {PROTOCOL_VERSION}")
    expected = _SIZES.get(msg_type)
    if expected is None:
        raise FrameError("type", f"unknown message type 0x{msg_type:02x}")
    if end - _HEADER.size != expected:
        raise FrameError("length", f"{MsgType(msg_type).name} payload of "
                                   f"{end - _HEADER.size} bytes, expected {expected}")
    return _new_frame(Frame, (msg_type, body[2] | body[3] << 8, body[_HEADER.size:end]))


class FrameReader:
    """Reassembles frames from a byte stream split at arbitrary points.

    Bytes are split at 0x00 delimiters; a partial frame is kept until its delimiter arrives; an
    over-long run without a delimiter is discarded (counted as a length error) so that garbage
    can never grow memory without bound.
    """

    __slots__ = ("_buf", "errors")

    def __init__(self) -> None:
        self._buf = bytearray()
        #: decode errors by kind ('cobs', 'crc', 'length', 'version', 'type')
        self.errors: dict[str, int] = {}

    def feed(self, data: bytes) -> list[Frame]:
        """Add bytes; return the frames completed by them (bad frames are counted, not raised)."""
        buf = self._buf
        if buf:  # the start of a frame from an earlier read
            buf += data
            data = bytes(buf)
            buf.clear()
        parts = data.split(b"\x00")
        rest = parts.pop()  # after the last delimiter: a frame still arriving
        if len(rest) > MAX_FRAME_BYTES:
            self.errors["length"] = self.errors.get("length", 0) + 1
        elif rest:
            buf += rest
        frames: list[Frame] = []
        for part in parts:
            if not part:
                continue  # back-to-back delimiters are idle fill
            try:
                frames.append(decode_frame(part))
            except FrameError as exc:
                self.errors[exc.kind] = self.errors.get(exc.kind, 0) + 1
        return frames

    def reset(self) -> None:
        self._buf.clear()


# --- payload helpers --------------------------------------------------------------------------
@dataclass(frozen=True)
class DeviceInfo:
    """What the device says about itself in HELLO_ACK."""

    protocol_version: int
    device_id: str
    max_rate_hz: int
    force_limit_n: float
    watchdog_ms: int

    @classmethod
    def from_payload(cls, payload: bytes) -> DeviceInfo:
        v, dev, rate, limit, wd = HELLO_ACK_FMT.unpack(payload)
        return cls(v, dev.rstrip(b"\x00").decode("ascii", "replace"), rate, limit, wd)

    def to_payload(self) -> bytes:
        return HELLO_ACK_FMT.pack(self.protocol_version,
                                  self.device_id.encode("ascii")[:DEVICE_ID_BYTES],
                                  self.max_rate_hz, self.force_limit_n, self.watchdog_ms)
