"""A backlog of frames read in one poll over a real pty: every frame is still checked and
counted as if each had been read on its own (a FAULT frame, a fault or watchdog flag, a damaged
frame, a sequence gap, a duplicate in the middle), and the handle state is the newest STATE's.
The renderer trips on the tick that reads such a backlog, before any force goes out.

The robot's side is the pty's other end, written by the test: each case is exact.
"""

from __future__ import annotations

import array
import fcntl
import os
import termios
import time
import tty
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from fieldbank.haptic import protocol as P
from fieldbank.haptic.clock import VirtualClock
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.protocol import FaultCode
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.safety import Mode
from tests.haptic_util import rest_hand, severe_shoulder

# The fields of the link's state and counters a safety check or a read-out uses.
FIELDS = ("x", "y", "vx", "vy", "t_us", "flags", "states", "crc_errors", "max_gap",
          "device_faults", "last_device_fault", "fault_flag_frames", "watchdog_flag_frames")


@contextmanager
def pty_link() -> Iterator[tuple[int, RobotLink]]:
    """The robot's end of a pty (raw) and a link opened on the other end by its path."""
    robot, host = os.openpty()
    tty.setraw(robot)
    tty.setraw(host)
    link = RobotLink.open(os.ttyname(host))
    os.close(host)
    assert link._raw_fd is not None  # the read path a USB serial adapter takes
    try:
        yield robot, link
    finally:
        link.close()
        os.close(robot)


def deliver(robot: int, link: RobotLink, frames: list[bytes]) -> None:
    """Write ``frames`` at once and wait until the kernel holds all of them ready for the
    host (one poll then reads them together)."""
    data = b"".join(frames)
    os.write(robot, data)
    ready = array.array("i", [0])
    assert link._raw_fd is not None
    deadline = time.monotonic() + 5.0
    while True:
        fcntl.ioctl(link._raw_fd, termios.FIONREAD, ready, True)
        if ready[0] >= len(data) or time.monotonic() > deadline:
            break
        time.sleep(1e-4)
    assert ready[0] == len(data)


class Robot:
    """Frames as a robot numbers them; damage, gaps and duplicates on request."""

    def __init__(self) -> None:
        self.seq = 0

    def frame(self, msg_type: int, payload: bytes, seq: int | None = None) -> bytes:
        if seq is None:
            seq, self.seq = self.seq, (self.seq + 1) & 0xFFFF
        return P.encode_frame(msg_type, seq, payload)

    def state(self, k: float, flags: int = P.FLAG_ARMED, seq: int | None = None) -> bytes:
        payload = P.STATE_FMT.pack(int(1000 * k), 0.3 + 0.001 * k, 0.2 - 0.002 * k,
                                   0.01 * k, -0.01 * k, flags, int(k))
        return self.frame(P.MsgType.STATE, payload, seq)

    def fault(self, code: int = FaultCode.DEVICE, detail: int = 7) -> bytes:
        return self.frame(P.MsgType.FAULT, P.FAULT_FMT.pack(code, detail))

    def damaged(self, k: float) -> bytes:
        """A STATE frame with one payload bit flipped (its CRC no longer matches)."""
        body = bytearray(P.cobs_decode(self.state(k)[:-1]))
        body[6] ^= 0x10
        return P.cobs_encode(bytes(body)) + b"\x00"

    def skip(self, n: int) -> None:
        self.seq = (self.seq + n) & 0xFFFF


def backlogs() -> dict[str, list[bytes]]:
    """Backlogs of eight frames with something in the middle a safety check needs."""
    out = {}
    cases = {
        "fault frame": lambda r, k: r.fault(),
        "fault flag": lambda r, k: r.state(k, P.FLAG_ARMED | P.FLAG_FAULT),
        "watchdog flag": lambda r, k: r.state(k, P.FLAG_WATCHDOG),
        "bad crc": lambda r, k: r.damaged(k),
        "sequence gap": lambda r, k: (r.skip(5), r.state(k))[1],
        "duplicate": lambda r, k: r.state(k, seq=(r.seq - 2) & 0xFFFF),
        "flag on a duplicate": lambda r, k: r.state(k, P.FLAG_FAULT, seq=(r.seq - 2) & 0xFFFF),
    }
    for name, middle in cases.items():
        r = Robot()
        frames = [r.state(0)]  # the frame before the backlog: the sequence is known
        frames += [r.state(k) for k in range(1, 4)]
        frames.append(middle(r, 4))
        frames += [r.state(k) for k in range(5, 9)]
        out[name] = frames
    return out


def observed(link: RobotLink) -> dict[str, object]:
    st = link.state
    seen: dict[str, object] = {f: getattr(st, f) for f in FIELDS}
    seen.update(echo_seq=link.echo_seq, frames_rx=link.frames_rx, frames_lost=link.frames_lost,
                duplicates=link.duplicates, resyncs=link.resyncs)
    return seen


@pytest.mark.parametrize("case", sorted(backlogs()))
def test_a_backlog_counts_every_frame_as_frame_by_frame_reads_do(case: str) -> None:
    frames = backlogs()[case]
    # the reference: the same frames, one poll each
    with pty_link() as (robot, one_by_one):
        news = []
        for f in frames:
            deliver(robot, one_by_one, [f])
            news.append(one_by_one.poll())
        reference = observed(one_by_one)
    with pty_link() as (robot, link):
        deliver(robot, link, frames[:1])
        first = link.poll()
        deliver(robot, link, frames[1:])
        backlog = link.poll()  # the eight frames of the backlog in one read
        assert link.poll() == 0  # nothing was left behind
        assert first + backlog == sum(news)
        assert observed(link) == reference
    # what the case puts in the middle is really there (the comparison is not vacuous)
    expect = {"fault frame": ("device_faults", 1), "fault flag": ("fault_flag_frames", 1),
              "watchdog flag": ("watchdog_flag_frames", 1), "bad crc": ("crc_errors", 1),
              "sequence gap": ("max_gap", 5), "duplicate": ("duplicates", 1),
              "flag on a duplicate": ("fault_flag_frames", 1)}[case]
    assert reference[expect[0]] == expect[1]
    # the handle state is the newest STATE's, as sent (float32 on the wire)
    t_us, x, y, vx, vy, flags, echo = P.STATE_FMT.unpack(
        P.STATE_FMT.pack(8000, 0.3 + 0.008, 0.2 - 0.016, 0.08, -0.08, P.FLAG_ARMED, 8))
    assert (reference["t_us"], reference["x"], reference["y"], reference["vx"],
            reference["vy"], reference["flags"], reference["echo_seq"]) == (
        t_us, x, y, vx, vy, flags, echo)


@pytest.mark.parametrize(("case", "code"), [
    ("fault frame", FaultCode.DEVICE), ("fault flag", FaultCode.DEVICE),
    ("sequence gap", FaultCode.SEQ_GAP)])
def test_the_renderer_trips_on_the_tick_that_reads_the_backlog(case: str, code: int) -> None:
    p = severe_shoulder()
    x, y = rest_hand(p)
    r = Robot()

    def at_hand(k: int, flags: int = P.FLAG_ARMED) -> bytes:  # off the rest position: a force
        return r.frame(P.MsgType.STATE, P.STATE_FMT.pack(k, x + 0.03, y - 0.02, 0.0, 0.0,
                                                         flags, 0))

    with pty_link() as (robot, link):
        rd = Renderer(link, p, p, RendererConfig(rate_hz=1000, realtime_priority=False),
                      clock=VirtualClock())
        deliver(robot, link, [at_hand(0)])
        rd.start(expected_ticks=1000)
        for k in range(1, 401):  # one frame a tick, past the arming ramp
            deliver(robot, link, [at_hand(k)])
            rd.tick()
        assert rd.safety.mode == Mode.ARMED and abs(rd.fx) + abs(rd.fy) > 0.01
        backlog = [at_hand(k) for k in range(401, 404)]
        if case == "fault frame":
            backlog.append(r.frame(P.MsgType.FAULT, P.FAULT_FMT.pack(FaultCode.DEVICE, 3)))
        elif case == "fault flag":
            backlog.append(at_hand(404, P.FLAG_ARMED | P.FLAG_FAULT))
        else:
            r.skip(5)
        backlog += [at_hand(k) for k in range(405, 409)]  # the newest frames are clean
        deliver(robot, link, backlog)
        rd.tick()
        assert rd.safety.mode == Mode.FAULT and (rd.fx, rd.fy) == (0.0, 0.0)
        assert rd.safety.latched & (1 << (code - 1))
        rd.finish()
