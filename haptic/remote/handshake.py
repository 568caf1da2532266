"""The remote link's handshake: both sites contribute fresh random values, the session keys come
from the shared key and both through HKDF, and the clinician proves the key over the patient's
fresh nonce before the patient's site accepts anything else.

::

    clinician (initiator)                                           patient (responder)
    HELLO    header | Nc | Ec | AEAD(kh_c, {rate, clock mode, wall time})           ──►
                      opens it with kh_c (only a holder of the key made it); checks the rate,
                      the clock mode and the time; draws Np, Ep; derives the session keys
         ◄── WELCOME  header | Np | Ep | AEAD(k_pc, seq 1, {the arm's geometry, rest hand, …})
    derives the session keys and opens the WELCOME (the patient holds the key and answered
    this HELLO, not an old one)
    CONFIRM  header | AEAD(k_cp, seq 1, {})                                          ──►
                      opens it: the clinician holds the key and saw Np, so this is no
                      recording — the session is engaged and the clinician's address pinned
    STATE … both ways under k_cp and k_pc; BYE under the same keys ends it

Keys (HKDF with SHA-256, RFC 5869; X25519, RFC 7748; AES-256-GCM, NIST SP 800-38D; all from the
``cryptography`` package)::

    kh_c ‖ kh_p = HKDF(ikm = K, salt = Nc, info = "fieldbank-remote-2 hello")
    k_cp ‖ k_pc = HKDF(ikm = K ‖ X25519(ec, Ep), salt = Nc ‖ Np,
                       info = "fieldbank-remote-2 session" ‖ SHA-256(HELLO ‖ WELCOME's header,
                                                                     Np and Ep))

K is the shared key of the key file, Nc and Np 32 random bytes each site draws for this
session, Ec and Ep the public halves of X25519 key pairs each draws for it (their private
halves never leave memory and are dropped with the session). kh_c seals only the one HELLO it
was derived for and kh_p only the refusal of that HELLO (REFUSE: why the patient's site will not
serve it), each with an all-zero nonce: their keys are never used for anything else.

What it gives: a recorded HELLO replayed later earns only a WELCOME that nobody without the
session's fresh values can open, and the recorded CONFIRM and STATEs open under no later
session's keys; the HELLO's settings cannot be altered (the keys depend on the whole HELLO); the
X25519 exchange keeps recorded sessions unreadable to whoever steals the key file later
(forward secrecy). A responder keeps at most :data:`MAX_PENDING` unconfirmed handshakes, one per
address, so a replayed HELLO from elsewhere does not push out the genuine clinician's.
"""

from __future__ import annotations

import hashlib
import os
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from cryptography.exceptions import InvalidTag
from cryptography.hazmat.primitives import hashes
from cryptography.hazmat.primitives.asymmetric.x25519 import X25519PrivateKey, X25519PublicKey
from cryptography.hazmat.primitives.ciphers.aead import AESGCM
from cryptography.hazmat.primitives.kdf.hkdf import HKDF

from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.remote.wire import (
    HEADER,
    KEY_BYTES,
    MAGIC,
    TAG_BYTES,
    Datagram,
    Kind,
    Role,
    SessionCipher,
    json_body,
    parse_json,
)

#: Bytes of each site's fresh nonce and of an X25519 public key.
NONCE_BYTES = 32
PUBLIC_BYTES = 32
#: Clear bytes after the header of a HELLO and a WELCOME: the nonce and the public key.
PREFIX_BYTES = NONCE_BYTES + PUBLIC_BYTES
#: Unconfirmed handshakes a patient's site keeps (one per address; the oldest goes first).
MAX_PENDING = 8
_ZERO_NONCE = bytes(12)
_HELLO_INFO = b"fieldbank-remote-2 hello"
_SESSION_INFO = b"fieldbank-remote-2 session"
Address = Any


def _hkdf(ikm: bytes, salt: bytes, info: bytes) -> tuple[bytes, bytes]:
    okm = HKDF(algorithm=hashes.SHA256(), length=2 * KEY_BYTES, salt=salt,
               info=info).derive(ikm)
    return okm[:KEY_BYTES], okm[KEY_BYTES:]


def _check_key(key: bytes) -> None:
    if len(key) != KEY_BYTES:
        raise HapticError(f"a session key is {KEY_BYTES} bytes; got {len(key)}")


def _session_ciphers(key: bytes, role: Role, session: int, private: X25519PrivateKey,
                     peer_public: bytes, nonce_c: bytes, nonce_p: bytes, hello: bytes,
                     welcome_head: bytes) -> SessionCipher | None:
    """This site's cipher of the session (None: the peer's public value is unusable)."""
    try:
        shared = private.exchange(X25519PublicKey.from_public_bytes(peer_public))
    except ValueError:  # a low-order point: the exchange would give all zeros
        return None
    transcript = hashlib.sha256(hello + welcome_head).digest()
    k_cp, k_pc = _hkdf(key + shared, nonce_c + nonce_p, _SESSION_INFO + transcript)
    if role is Role.CLINICIAN:
        return SessionCipher(role, session, k_cp, k_pc)
    return SessionCipher(role, session, k_pc, k_cp)


class Initiator:
    """The clinician's side of one handshake.

    Parameters
    ----------
    key : bytes
        The shared key.
    session : int
        The session id (random, 63 bits).
    message : mapping
        What the HELLO tells the patient's site (rate, clock mode, wall time).
    """

    def __init__(self, key: bytes, session: int, message: Mapping[str, Any]) -> None:
        _check_key(key)
        self._key = key
        self.session = session
        self._private = X25519PrivateKey.generate()
        self.nonce = os.urandom(NONCE_BYTES)
        public = self._private.public_key().public_bytes_raw()
        head = HEADER.pack(MAGIC, int(Kind.HELLO), int(Role.CLINICIAN), session, 0)
        prefix = head + self.nonce + public
        kh_c, self._kh_p = _hkdf(key, self.nonce, _HELLO_INFO)
        #: the HELLO, sealed once: a repeat sends these same bytes
        self.hello = prefix + AESGCM(kh_c).encrypt(
            _ZERO_NONCE, json_body(Kind.HELLO, message), prefix)
        self.refused: dict[str, int] = {}

    def _refuse(self, reason: str) -> None:
        self.refused[reason] = self.refused.get(reason, 0) + 1

    def answer(self, data: bytes) -> tuple[SessionCipher, Datagram] | str | None:
        """The patient's answer to this HELLO: (this site's cipher, the opened WELCOME), or the
        reason it was refused (a REFUSE), or None (not an answer to this HELLO: counted)."""
        if len(data) < HEADER.size + TAG_BYTES or data[:4] != MAGIC:
            self._refuse("short" if len(data) < HEADER.size + TAG_BYTES else "version")
            return None
        _, kind, role, session, _ = HEADER.unpack_from(data)
        if role != Role.PATIENT or session != self.session:
            self._refuse("role" if role != Role.PATIENT else "session")
            return None
        if kind == Kind.REFUSE:
            head = data[:HEADER.size]
            try:
                plain = AESGCM(self._kh_p).decrypt(_ZERO_NONCE, data[HEADER.size:],
                                                            head)
            except InvalidTag:
                self._refuse("aead")
                return None
            msg = parse_json(plain) or {}
            return str(msg.get("reason") or "no reason given")
        if kind != Kind.WELCOME or len(data) < HEADER.size + PREFIX_BYTES + TAG_BYTES:
            self._refuse("kind")
            return None
        split = HEADER.size + PREFIX_BYTES
        nonce_p = data[HEADER.size:HEADER.size + NONCE_BYTES]
        cipher = _session_ciphers(self._key, Role.CLINICIAN, self.session, self._private,
                                  data[HEADER.size + NONCE_BYTES:split], self.nonce, nonce_p,
                                  self.hello, data[:split])
        if cipher is None:
            self._refuse("handshake")
            return None
        d = cipher.open(data, prefix_bytes=PREFIX_BYTES)
        if d is None or d.kind != Kind.WELCOME:
            self._refuse("aead" if d is None else "kind")
            return None
        return cipher, d

    @staticmethod
    def confirm(cipher: SessionCipher, t_us: int = 0) -> bytes:
        """The CONFIRM: sealed under the session's keys, the proof the patient waits for."""
        return cipher.seal_json(Kind.CONFIRM, {"site": "clinician"}, t_us=t_us)


@dataclass(frozen=True)
class Hello:
    """A HELLO that opened (its maker holds the key; it may still be a recording)."""

    session: int
    nonce: bytes
    public: bytes
    message: Mapping[str, Any]
    raw: bytes
    refuse_key: bytes


@dataclass
class _Pending:
    nonce_c: bytes
    welcome: bytes
    cipher: SessionCipher


class Responder:
    """The patient's side: opens HELLOs, answers each with a WELCOME or a REFUSE, and engages on
    the first datagram that opens under a pending handshake's keys (:meth:`confirm`).

    Parameters
    ----------
    key : bytes
        The shared key.
    """

    def __init__(self, key: bytes) -> None:
        _check_key(key)
        self._key = key
        self.pending: OrderedDict[Address, _Pending] = OrderedDict()
        #: refused datagrams by reason (before the session is engaged)
        self.refused: dict[str, int] = {}

    def _refuse(self, reason: str) -> None:
        self.refused[reason] = self.refused.get(reason, 0) + 1

    def open_hello(self, data: bytes) -> Hello | None:
        """The HELLO in ``data`` if it opens under the key (None: counted)."""
        if len(data) < HEADER.size + PREFIX_BYTES + TAG_BYTES or data[:4] != MAGIC:
            self._refuse("short")
            return None
        _, kind, role, session, _ = HEADER.unpack_from(data)
        if kind != Kind.HELLO or role != Role.CLINICIAN:
            self._refuse("kind" if kind != Kind.HELLO else "role")
            return None
        split = HEADER.size + PREFIX_BYTES
        nonce_c = data[HEADER.size:HEADER.size + NONCE_BYTES]
        kh_c, kh_p = _hkdf(self._key, nonce_c, _HELLO_INFO)
        try:
            plain = AESGCM(kh_c).decrypt(_ZERO_NONCE, data[split:], data[:split])
        except InvalidTag:
            self._refuse("aead")
            return None
        msg = parse_json(plain)
        if msg is None:
            self._refuse("json")
            return None
        return Hello(session, nonce_c, data[HEADER.size + NONCE_BYTES:split], msg, data, kh_p)

    @staticmethod
    def refusal(hello: Hello, reason: str) -> bytes:
        """A REFUSE of ``hello`` saying why (only its sender can open it)."""
        head = HEADER.pack(MAGIC, int(Kind.REFUSE), int(Role.PATIENT), hello.session, 0)
        return head + AESGCM(hello.refuse_key).encrypt(
            _ZERO_NONCE, json_body(Kind.REFUSE, {"reason": reason}), head)

    def welcome(self, hello: Hello, address: Address, message: Mapping[str, Any]) -> bytes:
        """The WELCOME answering ``hello`` from ``address`` (the same bytes again for a repeat
        of the same HELLO); the handshake waits for its proof (:meth:`confirm`)."""
        old = self.pending.get(address)
        if old is not None and old.nonce_c == hello.nonce:
            self.pending.move_to_end(address)
            return old.welcome
        private = X25519PrivateKey.generate()
        nonce_p = os.urandom(NONCE_BYTES)
        public = private.public_key().public_bytes_raw()
        head = HEADER.pack(MAGIC, int(Kind.WELCOME), int(Role.PATIENT), hello.session, 1)
        cipher = _session_ciphers(self._key, Role.PATIENT, hello.session, private, hello.public,
                                  hello.nonce, nonce_p, hello.raw, head + nonce_p + public)
        if cipher is None:
            self._refuse("handshake")
            return b""
        data = cipher.seal_json(Kind.WELCOME, message, prefix=nonce_p + public)
        assert data[:HEADER.size] == head
        self.pending[address] = _Pending(hello.nonce, data, cipher)
        self.pending.move_to_end(address)
        while len(self.pending) > MAX_PENDING:
            self.pending.popitem(last=False)
        return data

    def confirm(self, data: bytes, address: Address) -> tuple[SessionCipher, Datagram] | None:
        """The session's cipher and the datagram that proved the key over this site's nonce
        (a CONFIRM, or the clinician's first STATE when the CONFIRM was lost), when ``data``
        from ``address`` opens under its pending handshake; None otherwise (counted)."""
        p = self.pending.get(address)
        if p is None:
            self._refuse("address")
            return None
        d = p.cipher.open(data)
        if d is None:
            return None
        if d.kind == Kind.BYE:  # the clinician gave up on this handshake
            del self.pending[address]
            return None
        for reason, n in self.refused.items():
            p.cipher.refused[reason] = p.cipher.refused.get(reason, 0) + n
        self.pending.clear()
        return p.cipher, d
