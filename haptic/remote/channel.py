"""The remote link's transport, its injected impairments, and one site's endpoint.

::

    site ─► Endpoint.send_state ─► SessionCipher.seal ─► Transport.send ─────────► network
    site ◄─ Endpoint.receive ◄─ release queue ◄─ Impairment ◄─ SessionCipher.open ◄─ Transport
                                                                 (the peer's address only)

* :class:`Transport` is the seam: :class:`UdpTransport` (a real UDP socket; what the two sites
  use) or :class:`MemoryTransport` (both ends in one process; what the benchmark and the
  simulated trainee use). Both carry bytes only; nothing that does not open under the
  session's keys (:mod:`haptic.remote.wire`) goes further.
* The endpoint exists once the handshake is done (:mod:`haptic.remote.handshake`): its peer's
  address is pinned then, and a datagram from any other address is refused unopened and
  counted (``address``; a HELLO from elsewhere as ``handshake``). At most
  :data:`MAX_PER_DRAIN` datagrams are read per tick, so a flood cannot hold up a tick (the
  socket's buffer, :data:`RECEIVE_BUFFER_BYTES`, keeps the rest). Refusals are logged at most
  once a second per reason, with their counts.
* :class:`Impairment` delays, jitters and drops STATE datagrams *as they arrive*, by the
  receiving site's clock: a datagram that arrives at t is released at t + delay + jitter
  (jitter uniform in ±``jitter_s``, never before it arrived, so datagrams may be reordered), or
  lost with probability ``loss``. Each site impairs what it receives, so a link with one-way
  delay T has both sites set to T. HELLO, WELCOME and BYE are not impaired. The draws come
  from a seeded generator: a lockstep run is repeatable.
* **Lockstep** (faster than real time, both sites on virtual clocks): every STATE carries its
  tick and its sender's virtual time; it is released one tick after it was sent plus the
  injected delay and jitter, all in virtual time, so a run is the same however fast or slow
  the processes go. Before its tick n a site waits until the peer's STATEs released by then
  have arrived (:meth:`Endpoint.wait_peer_tick`): the peer's tick n − 1 without delay, tick
  n − 1 − D with an injected delay of at least D ticks — so the two sites may run up to D ticks
  apart and wait on each other rarely. Real time: no waiting; a datagram is released the
  injected delay after it arrives, by the receiving machine's clock.

The endpoint also measures the link: the round trip from each STATE's echo of the newest
datagram the peer had received (and how long it held it), the datagrams lost (sequence gaps),
late (reordered) and refused (authentication), and when the peer was last heard from.
"""

from __future__ import annotations

import heapq
import logging
import math
import random
import select
import socket
import time
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.remote.wire import Datagram, Kind, SessionCipher, State, peek_kind
from fieldbank.validation import Interval, check_fields

log = logging.getLogger("fieldbank.haptic.remote")

#: Allowed range of each field of :class:`Impairment`.
IMPAIRMENT_BOUNDS: dict[str, Interval] = {
    "delay_s": Interval(0.0, 2.0, "s"),
    "jitter_s": Interval(0.0, 0.5, "s"),
    "loss": Interval(0.0, 0.5, "1"),
}
#: Largest UDP payload read.
MAX_DATAGRAM = 8192
#: Most datagrams read from the transport per tick (a site at 1 kHz gets one or two).
MAX_PER_DRAIN = 256
#: The UDP socket's receive buffer asked for, bytes (the kernel may grant less).
RECEIVE_BUFFER_BYTES = 4 << 20
#: Refusals of one reason are logged at most this often, s.
REFUSAL_LOG_EVERY_S = 1.0
Address = Any


@dataclass(frozen=True)
class Impairment:
    """What the receiving side does to arriving STATE datagrams (ranges in
    :data:`IMPAIRMENT_BOUNDS`).

    Attributes
    ----------
    delay_s : float, s
        One-way delay added to every datagram.
    jitter_s : float, s
        Each datagram's delay varies uniformly within ± this (never below zero).
    loss : float
        Probability that a datagram is dropped.
    seed : int
        Seeds the draws.
    """

    delay_s: float = 0.0
    jitter_s: float = 0.0
    loss: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        check_fields(self, IMPAIRMENT_BOUNDS, what="link impairment")

    @property
    def active(self) -> bool:
        return self.delay_s > 0 or self.jitter_s > 0 or self.loss > 0

    def to_dict(self) -> dict[str, float]:
        return {"delay_s": self.delay_s, "jitter_s": self.jitter_s, "loss": self.loss,
                "seed": self.seed}

    def describe(self) -> str:
        if not self.active:
            return "none"
        parts = [f"{self.delay_s * 1e3:g} ms one-way"]
        if self.jitter_s:
            parts.append(f"± {self.jitter_s * 1e3:g} ms jitter")
        if self.loss:
            parts.append(f"{self.loss:.0%} loss")
        return ", ".join(parts)


class Transport(Protocol):
    """Bytes to and from the peer; never blocks unless asked to wait."""

    def send(self, data: bytes) -> None: ...
    def send_to(self, data: bytes, address: Address) -> None: ...
    def receive(self, limit: int = MAX_PER_DRAIN) -> list[tuple[bytes, Address]]: ...
    def wait_readable(self, timeout_s: float) -> bool: ...
    def close(self) -> None: ...


class UdpTransport:
    """A UDP socket bound to ``bind``; sends to ``peer`` (a patient's site pins it once the
    handshake is confirmed: :meth:`set_peer`).

    Parameters
    ----------
    bind : (host, port)
        Local address (port 0: any free port; :attr:`address` says which).
    peer : (host, port), optional
    """

    def __init__(self, bind: tuple[str, int], peer: tuple[str, int] | None = None) -> None:
        family = socket.AF_INET6 if ":" in bind[0] else socket.AF_INET
        self.sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            self.sock.bind(bind)
        except OSError as exc:
            self.sock.close()
            raise HapticError(f"cannot bind the remote link to {bind[0]}:{bind[1]}: "
                              f"{exc.strerror or exc}") from None
        self.sock.setblocking(False)
        try:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
        except OSError:  # the kernel's default, then
            pass
        self.send_errors = 0
        try:
            self.peer: Address | None = None if peer is None else self.resolve(peer)
        except HapticError:
            self.sock.close()
            raise

    @property
    def address(self) -> tuple[str, int]:
        host, port = self.sock.getsockname()[:2]
        return str(host), int(port)

    def resolve(self, address: tuple[str, int]) -> Address:
        """``address`` as the socket reports senders (a name looked up once, here), so that
        what arrives can be compared with it."""
        try:
            infos = socket.getaddrinfo(address[0], address[1], self.sock.family,
                                       socket.SOCK_DGRAM)
        except (socket.gaierror, UnicodeError) as exc:
            raise HapticError(f"cannot find the remote site {address[0]}:{address[1]}: "
                              f"{exc}") from None
        return infos[0][4]

    def set_peer(self, peer: Address) -> None:
        self.peer = peer

    def send(self, data: bytes) -> None:
        if self.peer is not None:
            self.send_to(data, self.peer)

    def send_to(self, data: bytes, address: Address) -> None:
        try:
            self.sock.sendto(data, address)
        except (BlockingIOError, InterruptedError, ConnectionRefusedError, OSError):
            self.send_errors += 1  # a datagram is allowed to be lost; the watchdog judges

    def receive(self, limit: int = MAX_PER_DRAIN) -> list[tuple[bytes, Address]]:
        out: list[tuple[bytes, Address]] = []
        while len(out) < limit:
            try:
                out.append(self.sock.recvfrom(MAX_DATAGRAM))
            except (BlockingIOError, InterruptedError):
                return out
            except ConnectionRefusedError:  # an ICMP from an earlier send; nothing to read
                continue
        return out

    def wait_readable(self, timeout_s: float) -> bool:
        r, _, _ = select.select([self.sock], [], [], max(0.0, timeout_s))
        return bool(r)

    def close(self) -> None:
        self.sock.close()


class MemoryTransport:
    """One end of an in-process link (:meth:`pair`)."""

    def __init__(self) -> None:
        self.inbox: deque[bytes] = deque()
        self.other: MemoryTransport | None = None

    @classmethod
    def pair(cls) -> tuple[MemoryTransport, MemoryTransport]:
        a, b = cls(), cls()
        a.other, b.other = b, a
        return a, b

    def send(self, data: bytes) -> None:
        assert self.other is not None
        self.other.inbox.append(data)

    def send_to(self, data: bytes, address: Address) -> None:
        del address
        self.send(data)

    def receive(self, limit: int = MAX_PER_DRAIN) -> list[tuple[bytes, Address]]:
        out: list[tuple[bytes, Address]] = []
        while self.inbox and len(out) < limit:
            out.append((self.inbox.popleft(), "memory"))
        return out

    def wait_readable(self, timeout_s: float) -> bool:
        del timeout_s
        return bool(self.inbox)

    def close(self) -> None:
        self.inbox.clear()


@dataclass
class LinkCounters:
    """What the endpoint has seen of the link (cumulative)."""

    sent: int = 0
    arrived: int = 0           # authentic STATE datagrams that arrived
    dropped: int = 0           # of those, dropped by the injected loss
    delivered: int = 0         # released to the site
    lost: int = 0              # sequence numbers not (yet) seen, injected loss included
    stale: int = 0             # released after a newer one (reordered by jitter): not used
    used: int = 0              # released in order: what the site used
    rtt_s: float = math.nan    # newest round-trip measurement
    rtt_max_s: float = 0.0


def same_address(a: Address, b: Address) -> bool:
    """Whether two transport addresses are one (host and port; an IPv6 address's flow and
    scope fields aside)."""
    if isinstance(a, tuple) and isinstance(b, tuple):
        return a[:2] == b[:2]
    return bool(a == b)


class Endpoint:
    """One site's end of the link once the handshake is done: seals and sends, receives from
    its peer only, opens, impairs, measures.

    Parameters
    ----------
    transport : Transport
    cipher : SessionCipher
        The session's keys (:mod:`haptic.remote.handshake`).
    impairment : Impairment, optional
    lockstep : bool
        Virtual time (module docstring).
    tick_s : float, s
        The loop's period (lockstep: the least time a datagram takes).
    peer : address, optional
        The peer's address, pinned: anything from elsewhere is refused (None: the transport's
        own peer, or anyone — an in-memory link).
    """

    def __init__(self, transport: Transport, cipher: SessionCipher,
                 impairment: Impairment | None = None, lockstep: bool = False,
                 tick_s: float = 1e-3, peer: Address | None = None) -> None:
        self.transport = transport
        self.cipher = cipher
        self.peer = peer if peer is not None else getattr(transport, "peer", None)
        self.impairment = impairment or Impairment()
        self.lockstep = lockstep
        self.tick_s = tick_s
        #: lockstep: how many ticks behind the peer may be (the least injected delay)
        self.lead_ticks = max(0, int((self.impairment.delay_s - self.impairment.jitter_s)
                                     / tick_s + 1e-9)) if lockstep else 0
        self._rng = random.Random(self.impairment.seed * 2 + int(cipher.role))
        self._queue: list[tuple[float, int, Datagram]] = []
        self._order = 0
        self.counters = LinkCounters()
        self.peer_tick = -1             # newest peer STATE tick that arrived (barrier)
        self.last_heard_s = -math.inf   # when a STATE of the peer was last released
        self._echo_us = -1              # peer t_us of the newest released STATE
        self._echo_at_s = 0.0
        self._newest_seq = -1
        self.messages: deque[Datagram] = deque()  # CONFIRM / BYE, in arrival order
        self._held: list[tuple[float, int, Datagram]] = []  # lockstep: messages not yet due
        self.peer_silent = False        # lockstep: the peer stopped answering the barrier
        self.peer_gone = False          # the peer's final BYE arrived: it ticks no more
        self._told: dict[str, tuple[float, int]] = {}  # reason: (when logged, count then)
        #: datagrams read before the endpoint existed (the rest of the handshake's last read)
        self.backlog: list[tuple[bytes, Address]] = []

    # --- sending ------------------------------------------------------------------------------
    def send_state(self, st: State, now_s: float, flags: int = 0) -> None:
        hold = 0 if self._echo_us < 0 else round((now_s - self._echo_at_s) * 1e6)
        self.transport.send(self.cipher.seal_state(
            st, flags=flags, t_us=round(now_s * 1e6), echo_us=self._echo_us, hold_us=hold))
        self.counters.sent += 1

    def send_message(self, kind: Kind, message: Mapping[str, Any], now_s: float) -> None:
        self.transport.send(self.cipher.seal_json(kind, message, t_us=round(now_s * 1e6)))

    # --- receiving ----------------------------------------------------------------------------
    def _drain(self, now_s: float) -> None:
        cipher = self.cipher
        refused = sum(cipher.refused.values())
        batch = self.transport.receive()
        if self.backlog:
            batch, self.backlog = self.backlog + batch, []
        for data, addr in batch:
            kind = peek_kind(data)
            if self.peer is not None and not same_address(addr, self.peer):
                cipher.refuse("handshake" if kind == Kind.HELLO else "address")
                continue
            if kind == Kind.WELCOME:  # the peer's answer to a repeat of this session's HELLO
                continue
            d = cipher.open(data)
            if d is not None:
                self.deliver(d, now_s)
        if sum(cipher.refused.values()) != refused:
            self._tell_refusals()

    def _tell_refusals(self) -> None:
        """Log what was refused: each reason at its first refusal, then at most once every
        REFUSAL_LOG_EVERY_S with the count since."""
        now = time.monotonic()
        for reason, n in self.cipher.refused.items():
            at, told = self._told.get(reason, (-math.inf, 0))
            if n > told and now - at >= REFUSAL_LOG_EVERY_S:
                self._told[reason] = (now, n)
                log.warning("refused %d datagram(s) (%s) on the link to %s, %d in all",
                            n - told, reason, self.peer or "the peer", n)

    def deliver(self, d: Datagram, now_s: float) -> None:
        """Take an opened datagram (from the transport, or the one that confirmed the
        handshake): a STATE goes through the impairment to the release queue, the others to
        :attr:`messages`."""
        imp = self.impairment
        if d.kind != Kind.STATE:  # (the watchdog listens for STATEs only)
            if d.kind == Kind.BYE and (d.message or {}).get("final", True) is not False:
                self.peer_gone = True
            if self.lockstep:  # released at its virtual time, as a STATE is: repeatable
                self._order += 1
                heapq.heappush(self._held, (d.t_us * 1e-6 + self.tick_s, self._order, d))
            else:
                self.messages.append(d)
            return
        assert d.state is not None
        c = self.counters
        c.arrived += 1
        if d.state.tick > self.peer_tick:
            self.peer_tick = d.state.tick
        if imp.loss and self._rng.random() < imp.loss:
            c.dropped += 1
            return
        delay = imp.delay_s
        if imp.jitter_s:
            delay = max(0.0, delay + self._rng.uniform(-imp.jitter_s, imp.jitter_s))
        self._order += 1
        sent = d.t_us * 1e-6 + self.tick_s if self.lockstep else now_s
        heapq.heappush(self._queue, (sent + delay, self._order, d))

    def receive(self, now_s: float) -> State | None:
        """Drain the transport; the newest STATE released by ``now_s`` (None: nothing new);
        the messages due by then go to :attr:`messages`."""
        self._drain(now_s)
        held = self._held
        while held and held[0][0] <= now_s + 1e-12:
            self.messages.append(heapq.heappop(held)[2])
        q = self._queue
        newest: Datagram | None = None
        c = self.counters
        while q and q[0][0] <= now_s + 1e-12:
            d = heapq.heappop(q)[2]
            c.delivered += 1
            if d.seq <= self._newest_seq:
                c.stale += 1   # late, not lost: the gap it left was counted as lost
                c.lost = max(0, c.lost - 1)
                continue
            if self._newest_seq >= 0:
                c.lost += d.seq - self._newest_seq - 1
            self._newest_seq = d.seq
            c.used += 1
            newest = d
        if newest is None:
            return None
        self.last_heard_s = now_s
        self._echo_us, self._echo_at_s = newest.t_us, now_s
        if newest.echo_us >= 0:
            rtt = now_s - (newest.echo_us + newest.hold_us) * 1e-6
            c.rtt_s = rtt
            c.rtt_max_s = max(c.rtt_max_s, rtt)
        self.peer_flags = newest.flags
        return newest.state

    peer_flags: int = 0

    def wait_peer_tick(self, tick: int, now_s: float, timeout_s: float) -> bool:
        """Lockstep: wait until the peer's STATE of ``tick`` minus :attr:`lead_ticks` (or a
        later one) has arrived; False after ``timeout_s`` of wall time (the peer is then taken
        as silent, and no later tick waits until it is heard again).

        With a lead, a wait lasts until the peer is half the lead further on, and it sleeps
        instead of waiting on the socket: a waiter on the socket would be woken by each
        datagram, and waking it would cost the sender its time slice on every tick."""
        tick -= self.lead_ticks
        if self.peer_gone:
            self._drain(now_s)
            return False
        if tick < 0 or self.peer_tick >= tick:
            self.peer_silent = False
            return True
        if self.peer_silent:
            self._drain(now_s)
            if self.peer_tick >= tick:
                self.peer_silent = False
            return not self.peer_silent
        target = tick + self.lead_ticks // 2
        deadline = time.monotonic() + timeout_s
        while True:
            self._drain(now_s)
            if self.peer_tick >= target:
                return True
            if self.peer_gone:  # its final BYE: nothing more will come
                return False
            left = deadline - time.monotonic()
            if left <= 0:
                if self.peer_tick >= tick:
                    return True
                self.peer_silent = True
                return False
            if self.lead_ticks:
                time.sleep(min(left, 5e-4))
            else:
                self.transport.wait_readable(min(left, 0.05))

    def stats(self) -> dict[str, Any]:
        """The link's figures so far (JSON-able)."""
        c = self.counters
        expected = c.used + c.stale + c.lost
        return {"sent": c.sent, "arrived": c.arrived, "dropped_by_injection": c.dropped,
                "delivered": c.delivered, "lost": c.lost, "stale": c.stale,
                "used": c.used, "loss_fraction": (c.lost / expected) if expected else 0.0,
                "late_fraction": (c.stale / expected) if expected else 0.0,
                "rtt_ms": None if math.isnan(c.rtt_s) else round(c.rtt_s * 1e3, 3),
                "rtt_max_ms": round(c.rtt_max_s * 1e3, 3),
                "refused": dict(self.cipher.refused), "late_accepted": self.cipher.late,
                "impairment": self.impairment.to_dict()}

    def close(self) -> None:
        self.transport.close()
