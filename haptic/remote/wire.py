"""The remote link's datagrams: fixed layout, sequence numbers, timestamps, a MAC on each.

Every datagram is one UDP payload::

    header  magic "FBR1" | version u8 | kind u8 | role u8 | flags u8 | session u64 | seq u64
            | t_us i64 (sender's clock) | echo_us i64 (newest peer t_us received, −1: none)
            | hold_us i64 (how long ago, when sending, that datagram arrived)
    body    kind-specific (below)
    tag     16 bytes: HMAC-SHA256(key, "fieldbank-remote-1" ‖ header ‖ body), first 16 bytes

All little-endian. ``role`` is the sender's site (1 clinician, 2 patient): a site accepts only
the other role, so a datagram reflected back to its sender is refused. ``seq`` counts every
datagram a site sends (64 bits: it never wraps); ``session`` is drawn at random by the
clinician's HELLO and carried by every later datagram of the session.

Kinds and bodies:

* HELLO (clinician → patient), WELCOME (patient → clinician), BYE (either): a UTF-8 JSON
  object of at most :data:`MAX_JSON_BYTES` (what each site tells the other: rate, clock mode,
  the patient's arm geometry and rest hand, …);
* STATE (either, every tick): ``tick u64``, then float64 ``x, y, vx, vy`` (the sender's port
  position and velocity, shoulder frame of the patient, m and m/s), ``fx, fy`` (the force at
  the sender's port, N: the clinician's displayed force, or the force the patient's hand puts
  on the patient's handle), ``e_in, e_out, e_sent`` (the energy that has entered and left the
  link at the sender's port since the session began, and what the sender's energy tank has
  handed to the other side, J: :mod:`haptic.remote.passivity`).

Authentication (:class:`Authenticator`): the MAC is checked in constant time before anything
else is read; then the role, the session, and the replay window: a datagram whose ``seq`` was
seen, or is more than :data:`REPLAY_WINDOW` behind the newest, is refused (a copy sent again by
anyone is dropped; a late one under jitter is counted). Refusals are counted by reason and
never raise into the loop.
"""

from __future__ import annotations

import hashlib
import hmac
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

from fieldbank.haptic.errors import HapticError

MAGIC = b"FBR1"
VERSION = 1
#: Bytes of the truncated HMAC-SHA256 tag (128 bits; RFC 2104 allows truncation to half).
TAG_BYTES = 16
#: Bytes of a session key.
KEY_BYTES = 32
#: Domain separation of the MAC (a key reused elsewhere cannot forge these datagrams).
_MAC_LABEL = b"fieldbank-remote-1"
#: Datagrams this far behind the newest are refused outright; nearer ones once each.
REPLAY_WINDOW = 64
#: Largest JSON body of HELLO, WELCOME and BYE.
MAX_JSON_BYTES = 4096

HEADER = struct.Struct("<4sBBBBQQqqq")
STATE = struct.Struct("<Q9d")


class Kind(IntEnum):
    HELLO = 1
    WELCOME = 2
    STATE = 3
    BYE = 4


class Role(IntEnum):
    CLINICIAN = 1
    PATIENT = 2

    @property
    def peer(self) -> Role:
        return Role.PATIENT if self is Role.CLINICIAN else Role.CLINICIAN


#: STATE flag bits.
FLAG_ARMED = 0x01      # the sender's robot is armed and its side engaged
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
    """A datagram that passed authentication."""

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


class Authenticator:
    """Signs this site's datagrams and checks the peer's.

    Parameters
    ----------
    key : bytes
        The shared session key (:data:`KEY_BYTES`).
    role : Role
        This site's role.
    session : int, optional
        The session id (the clinician draws it; the patient learns it from a HELLO).
    """

    def __init__(self, key: bytes, role: Role, session: int | None = None) -> None:
        if len(key) != KEY_BYTES:
            raise HapticError(f"a session key is {KEY_BYTES} bytes; got {len(key)}")
        self._key = key
        self.role = role
        self.session = session
        self.seq = 0
        self.newest = -1          # newest peer seq accepted
        self._seen = 0            # bitmap: bit k = seq (newest - k) was accepted
        #: refused datagrams by reason
        self.refused: dict[str, int] = {}
        self.accepted = 0
        self.late = 0             # accepted but older than the newest (reordered)

    def _mac(self, data: bytes) -> bytes:
        return hmac.new(self._key, _MAC_LABEL + data, hashlib.sha256).digest()[:TAG_BYTES]

    # --- sending ------------------------------------------------------------------------------
    def seal(self, kind: Kind, body: bytes, *, flags: int = 0, t_us: int = 0, echo_us: int = -1,
             hold_us: int = 0, session: int | None = None) -> bytes:
        """One datagram of ``kind`` with ``body``, numbered and tagged."""
        sess = self.session if session is None else session
        if sess is None:
            raise HapticError("no session yet: a patient site answers only after a HELLO")
        self.seq += 1
        head = HEADER.pack(MAGIC, VERSION, int(kind), int(self.role), flags & 0xFF, sess,
                           self.seq, t_us, echo_us, hold_us)
        data = head + body
        return data + self._mac(data)

    def seal_state(self, st: State, **kw: int) -> bytes:
        return self.seal(Kind.STATE, STATE.pack(st.tick, st.x, st.y, st.vx, st.vy, st.fx, st.fy,
                                                st.e_in, st.e_out, st.e_sent), **kw)

    def seal_json(self, kind: Kind, message: Mapping[str, Any], **kw: int) -> bytes:
        body = json.dumps(message, separators=(",", ":"), allow_nan=False).encode()
        if len(body) > MAX_JSON_BYTES:
            raise HapticError(f"a {kind.name} message is at most {MAX_JSON_BYTES} bytes; "
                              f"this one is {len(body)}")
        return self.seal(kind, body, **kw)

    # --- receiving ----------------------------------------------------------------------------
    def _refuse(self, reason: str) -> None:
        self.refused[reason] = self.refused.get(reason, 0) + 1

    def open(self, data: bytes, accept_hello: bool = False) -> Datagram | None:
        """The datagram in ``data`` if it is authentic, from the peer role, of this session
        (a HELLO opens one when ``accept_hello``) and not a replay; None otherwise (counted in
        :attr:`refused`)."""
        if len(data) < HEADER.size + TAG_BYTES:
            self._refuse("short")
            return None
        body, tag = data[:-TAG_BYTES], data[-TAG_BYTES:]
        if not hmac.compare_digest(self._mac(body), tag):
            self._refuse("mac")
            return None
        (magic, version, kind, role, flags, session, seq, t_us, echo_us,
         hold_us) = HEADER.unpack_from(body)
        if magic != MAGIC or version != VERSION:
            self._refuse("version")
            return None
        if role != self.role.peer:
            self._refuse("role")
            return None
        try:
            k = Kind(kind)
        except ValueError:
            self._refuse("kind")
            return None
        if session != self.session:
            if not (accept_hello and k == Kind.HELLO):
                self._refuse("session")
                return None
            self.session = session  # a new session: its numbering starts afresh
            self.newest = -1
            self._seen = 0
        if not self._fresh(seq):
            return None
        payload = body[HEADER.size:]
        st = None
        msg: Mapping[str, Any] | None = None
        if k == Kind.STATE:
            if len(payload) != STATE.size:
                self._refuse("length")
                return None
            tick, *vals = STATE.unpack(payload)
            if not all(math.isfinite(v) for v in vals):
                self._refuse("nan")
                return None
            st = State(tick, *vals)
        else:
            try:
                obj = json.loads(payload.decode()) if payload else {}
            except (UnicodeDecodeError, ValueError):
                obj = None
            if not isinstance(obj, dict):
                self._refuse("json")
                return None
            msg = obj
        self.accepted += 1
        return Datagram(k, Role(role), flags, session, seq, t_us, echo_us, hold_us, st, msg)

    def _fresh(self, seq: int) -> bool:
        """Replay window: accept each seq once, and none more than REPLAY_WINDOW behind."""
        if seq > self.newest:
            shift = seq - self.newest
            self._seen = ((self._seen << shift) | 1) & ((1 << REPLAY_WINDOW) - 1) \
                if self.newest >= 0 and shift < REPLAY_WINDOW else 1
            self.newest = seq
            return True
        back = self.newest - seq
        if back >= REPLAY_WINDOW:
            self._refuse("old")
            return False
        bit = 1 << back
        if self._seen & bit:
            self._refuse("replay")
            return False
        self._seen |= bit
        self.late += 1
        return True
