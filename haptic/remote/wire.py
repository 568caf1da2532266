"""The remote link's datagrams: fixed layout, sequence numbers, every byte after the handshake
encrypted and authenticated (AES-256-GCM), the replay window; the session key file.

Every datagram is one UDP payload, all little-endian::

    header  magic "FBR2" | kind u8 | role u8 | session u64 | seq u64       (22 bytes, in clear,
                                                                             authenticated)
    sealed  AEAD(key of the sender's direction, nonce = role u8 ‖ 3 zero bytes ‖ seq u64,
                 plaintext = flags u8 | t_us i64 | echo_us i64 | hold_us i64 | body,
                 associated data = header)                                 (+ 16-byte tag)

``role`` is the sender's site (1 clinician, 2 patient); each direction has its own key and
``seq`` counts every datagram a site seals (64 bits: it never wraps), so no (key, nonce) pair is
ever used twice. ``session`` is drawn by the clinician and carried by every datagram of the
session. ``t_us`` is the sender's clock, ``echo_us`` the newest peer ``t_us`` it had received
(−1: none) and ``hold_us`` how long before sending that one arrived (the round trip).

Bodies by kind:

* WELCOME, CONFIRM, BYE: a UTF-8 JSON object of at most :data:`MAX_JSON_BYTES`;
* STATE (either, every tick): ``tick u64``, then float64 ``x, y, vx, vy`` (the sender's port
  position and velocity, shoulder frame of the patient, m and m/s), ``fx, fy`` (the force at
  the sender's port, N: the clinician's displayed force, or the force the patient's hand puts
  on the patient's handle), ``e_in, e_out, e_sent`` (the energy that has entered and left the
  link at the sender's port since the session began, and what the sender's energy tank has
  handed to the other side, J: :mod:`haptic.remote.passivity`).

HELLO and REFUSE precede the session keys; their layout and the key schedule are in
:mod:`haptic.remote.handshake`.

Opening (:meth:`SessionCipher.open`): the header is read first (length, magic, role: a site
accepts only the other role; session; kind: a handshake kind is refused once the session is
keyed), then the replay window is consulted without changing it (a sequence number already
accepted, or more than :data:`REPLAY_WINDOW` behind the newest, is refused unopened), then the
AEAD tag is checked and the plaintext decoded — lengths, finite numbers, JSON — and only a
datagram that passed all of it marks its sequence number as seen. A refused datagram (forged,
garbled, NaN) therefore never consumes the number of a genuine one. Refusals are counted by
reason and never raise into the loop.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import stat
import struct
from collections.abc import Mapping
from dataclasses import dataclass
from enum import IntEnum
from pathlib import Path
from typing import Any

from cryptography.exceptions import InvalidTag
from cryptography.hazmat.primitives.ciphers.aead import AESGCM

from fieldbank.haptic.errors import HapticError

MAGIC = b"FBR2"
#: Bytes of the AEAD tag (GCM's full 128 bits).
TAG_BYTES = 16
#: Bytes of a session key (the shared key file) and of each derived key.
KEY_BYTES = 32
#: Datagrams this far behind the newest are refused outright; nearer ones once each.
REPLAY_WINDOW = 64
#: Largest JSON body of WELCOME, CONFIRM, BYE (and of HELLO and REFUSE).
MAX_JSON_BYTES = 4096

HEADER = struct.Struct("<4sBBQQ")
INNER = struct.Struct("<Bqqq")
STATE = struct.Struct("<Q9d")
_NONCE = struct.Struct("<B3xQ")


class Kind(IntEnum):
    HELLO = 1
    WELCOME = 2
    STATE = 3
    BYE = 4
    CONFIRM = 5
    REFUSE = 6


#: Kinds that belong to the handshake, before the session keys: refused once a session is keyed.
HANDSHAKE_KINDS = frozenset({Kind.HELLO, Kind.REFUSE})


class Role(IntEnum):
    CLINICIAN = 1
    PATIENT = 2

    @property
    def peer(self) -> Role:
        return Role.PATIENT if self is Role.CLINICIAN else Role.CLINICIAN


#: STATE flag bits.
FLAG_ARMED = 0x01      # the sender's robot is ready (armed, fault-free, on time) and engaged
FLAG_LINK_LOST = 0x02  # the sender has not heard from its peer for its watchdog time
FLAG_FAULT = 0x04      # the sender's safety layer holds a fault


@dataclass(frozen=True)
class State:
    """One STATE body: the sender's port at one tick (shoulder frame of the patient, SI)."""

    tick: int
    x: float
    y: float
    vx: float
    vy: float
    fx: float
    fy: float
    e_in: float
    e_out: float
    e_sent: float


@dataclass(frozen=True)
class Datagram:
    """A datagram that was opened: authentic, of this session, not a replay, well formed."""

    kind: Kind
    role: Role
    flags: int
    session: int
    seq: int
    t_us: int
    echo_us: int
    hold_us: int
    state: State | None = None
    message: Mapping[str, Any] | None = None


def read_key(path: str | Path) -> bytes:
    """The session key in ``path`` (64 hexadecimal digits, one line), refused when the file
    is readable by anyone but its owner or is not a regular file."""
    p = Path(path)
    try:
        st = p.stat()
    except OSError as exc:
        raise HapticError(f"{p}: cannot read the session key: {exc.strerror or exc}") from None
    if not stat.S_ISREG(st.st_mode):
        raise HapticError(f"{p}: the session key must be a regular file")
    if st.st_mode & 0o077:
        raise HapticError(f"{p}: the session key is readable by others (mode "
                          f"{stat.S_IMODE(st.st_mode):o}); chmod 600 it")
    text = p.read_text(encoding="ascii", errors="replace").strip()
    try:
        key = bytes.fromhex(text)
    except ValueError:
        key = b""
    if len(key) != KEY_BYTES:
        raise HapticError(f"{p}: a session key is {2 * KEY_BYTES} hexadecimal digits on one "
                          f"line (fieldbank haptic remote key writes one)")
    return key


def new_key() -> bytes:
    """A fresh random session key."""
    return os.urandom(KEY_BYTES)


def write_key(path: str | Path, key: bytes) -> Path:
    """Write ``key`` to a new file readable by its owner only (never over an existing file,
    never through a link)."""
    p = Path(path)
    try:
        fd = os.open(p, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0),
                     0o600)
    except FileExistsError:
        raise HapticError(f"{p}: exists; a session key is never written over a file") from None
    except OSError as exc:
        raise HapticError(f"{p}: cannot write the session key: {exc.strerror or exc}") from None
    with os.fdopen(fd, "w", encoding="ascii") as f:
        f.write(key.hex() + "\n")
        f.flush()
        os.fsync(f.fileno())
    return p


def key_fingerprint(key: bytes) -> str:
    """What may be shown and stored about a key: 16 hex digits of its SHA-256."""
    return hashlib.sha256(b"fieldbank-remote-fingerprint" + key).hexdigest()[:16]


def json_body(kind: Kind, message: Mapping[str, Any]) -> bytes:
    """``message`` as the JSON body of a ``kind`` datagram (refused above MAX_JSON_BYTES)."""
    body = json.dumps(message, separators=(",", ":"), allow_nan=False).encode()
    if len(body) > MAX_JSON_BYTES:
        raise HapticError(f"a {kind.name} message is at most {MAX_JSON_BYTES} bytes; "
                          f"this one is {len(body)}")
    return body


def parse_json(payload: bytes) -> dict[str, Any] | None:
    """The JSON object in ``payload`` (None: not one)."""
    if len(payload) > MAX_JSON_BYTES:
        return None
    try:
        obj = json.loads(payload.decode()) if payload else {}
    except (UnicodeDecodeError, ValueError):
        return None
    return obj if isinstance(obj, dict) else None


def peek_kind(data: bytes) -> int:
    """The kind byte of a datagram's header (0: not one of ours), without opening it."""
    if len(data) < HEADER.size or data[:4] != MAGIC:
        return 0
    return data[4]


class SessionCipher:
    """Seals this site's datagrams and opens the peer's, under the session's two keys.

    Parameters
    ----------
    role : Role
        This site's role.
    session : int
        The session id.
    send_key, receive_key : bytes
        The keys of this site's direction and of the peer's (:mod:`haptic.remote.handshake`
        derives them; :data:`KEY_BYTES` each).
    """

    def __init__(self, role: Role, session: int, send_key: bytes, receive_key: bytes) -> None:
        if len(send_key) != KEY_BYTES or len(receive_key) != KEY_BYTES:
            raise HapticError(f"a session's keys are {KEY_BYTES} bytes each")
        self.role = role
        self.session = session
        self._send = AESGCM(send_key)
        self._receive = AESGCM(receive_key)
        self.seq = 0
        self.newest = -1          # newest peer seq accepted
        self._seen = 0            # bitmap: bit k = seq (newest - k) was accepted
        #: refused datagrams by reason
        self.refused: dict[str, int] = {}
        self.accepted = 0
        self.late = 0             # accepted but older than the newest (reordered)

    # --- sending ------------------------------------------------------------------------------
    def header(self, kind: Kind) -> bytes:
        """The next datagram's header (takes its sequence number)."""
        self.seq += 1
        return HEADER.pack(MAGIC, int(kind), int(self.role), self.session, self.seq)

    def seal(self, kind: Kind, body: bytes, *, flags: int = 0, t_us: int = 0, echo_us: int = -1,
             hold_us: int = 0, prefix: bytes = b"") -> bytes:
        """One datagram of ``kind`` with ``body``, numbered, encrypted and tagged; ``prefix``
        (clear, authenticated) goes between the header and the ciphertext."""
        head = self.header(kind) + prefix
        plain = INNER.pack(flags & 0xFF, t_us, echo_us, hold_us) + body
        return head + self._send.encrypt(_NONCE.pack(int(self.role), self.seq), plain, head)

    def seal_state(self, st: State, *, flags: int = 0, t_us: int = 0, echo_us: int = -1,
                   hold_us: int = 0) -> bytes:
        return self.seal(Kind.STATE, STATE.pack(st.tick, st.x, st.y, st.vx, st.vy, st.fx, st.fy,
                                                st.e_in, st.e_out, st.e_sent),
                         flags=flags, t_us=t_us, echo_us=echo_us, hold_us=hold_us)

    def seal_json(self, kind: Kind, message: Mapping[str, Any], **kw: Any) -> bytes:
        return self.seal(kind, json_body(kind, message), **kw)

    # --- receiving ----------------------------------------------------------------------------
    def refuse(self, reason: str) -> None:
        """Count a refusal (also for refusals decided outside: the endpoint's address check)."""
        self.refused[reason] = self.refused.get(reason, 0) + 1

    def open(self, data: bytes, prefix_bytes: int = 0) -> Datagram | None:
        """The datagram in ``data`` if it opens (module docstring); None otherwise, counted in
        :attr:`refused`. ``prefix_bytes``: clear bytes after the header (a WELCOME's)."""
        if len(data) < HEADER.size + prefix_bytes + INNER.size + TAG_BYTES:
            self.refuse("short")
            return None
        magic, kind, role, session, seq = HEADER.unpack_from(data)
        if magic != MAGIC:
            self.refuse("version")
            return None
        if role != self.role.peer:
            self.refuse("role")
            return None
        if session != self.session:
            self.refuse("session")
            return None
        try:
            k = Kind(kind)
        except ValueError:
            self.refuse("kind")
            return None
        if k in HANDSHAKE_KINDS:
            self.refuse("handshake")  # a HELLO into a keyed session: never a new session
            return None
        why = self._window(seq)
        if why:
            self.refuse(why)
            return None
        split = HEADER.size + prefix_bytes
        try:
            plain = self._receive.decrypt(_NONCE.pack(role, seq), data[split:], data[:split])
        except InvalidTag:
            self.refuse("aead")
            return None
        flags, t_us, echo_us, hold_us = INNER.unpack_from(plain)
        payload = plain[INNER.size:]
        st = None
        msg: Mapping[str, Any] | None = None
        if k == Kind.STATE:
            if len(payload) != STATE.size:
                self.refuse("length")
                return None
            tick, *vals = STATE.unpack(payload)
            if not all(math.isfinite(v) for v in vals):
                self.refuse("nan")
                return None
            st = State(tick, *vals)
        else:
            msg = parse_json(payload)
            if msg is None:
                self.refuse("json")
                return None
        self._mark(seq)  # only now: a refused datagram never takes a genuine one's number
        self.accepted += 1
        return Datagram(k, Role(role), flags, session, seq, t_us, echo_us, hold_us, st, msg)

    def _window(self, seq: int) -> str:
        """Why ``seq`` cannot be accepted ('' when it can), the window unchanged."""
        if seq > self.newest:
            return ""
        back = self.newest - seq
        if back >= REPLAY_WINDOW:
            return "old"
        return "replay" if self._seen & (1 << back) else ""

    def _mark(self, seq: int) -> None:
        if seq > self.newest:
            shift = seq - self.newest
            self._seen = ((self._seen << shift) | 1) & ((1 << REPLAY_WINDOW) - 1) \
                if self.newest >= 0 and shift < REPLAY_WINDOW else 1
            self.newest = seq
            return
        self._seen |= 1 << (self.newest - seq)
        self.late += 1
