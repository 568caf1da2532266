"""Accounts of the workspace: roles, passwords (Argon2id) and API tokens.

Roles and what they may do (:data:`ROLE_PERMISSIONS`; the permissions are
:data:`fieldbank.web.routes.PERMISSIONS`):

============  =====================================================================
viewer        reads: patients, sessions, maps, fits, models, plans; computes a what-if
clinician     reads; plans (saves a plan, marks it given, runs the optimiser); drives the robot
data-manager  reads; manages patients and files (adds patients, ingests maps); reads the audit log
============  =====================================================================

Passwords are hashed with Argon2id through argon2-cffi (its default parameters, RFC 9106's
second recommended setting: 64 MiB, 3 passes); a hash made with older parameters is replaced at
the next successful login. An API token is 256 random bits shown once; the database keeps only
its SHA-256 (a token is not a password: with that much entropy a fast hash is enough, and a
lookup by hash finds its owner). A token is revoked, never deleted.
"""

from __future__ import annotations

import hashlib
import secrets
from collections.abc import Mapping

from argon2 import PasswordHasher
from argon2.exceptions import InvalidHashError, VerificationError, VerifyMismatchError

from fieldbank.errors import ParameterError
from fieldbank.storage import ApiTokenRecord, Database, UserRecord

ROLE_PERMISSIONS: Mapping[str, frozenset[str]] = {
    "viewer": frozenset({"read"}),
    "clinician": frozenset({"read", "plan", "robot"}),
    "data-manager": frozenset({"read", "manage"}),
}
ROLES = tuple(ROLE_PERMISSIONS)
#: Shortest password accepted, characters (NIST SP 800-63B asks for at least 8).
MIN_PASSWORD = 10
#: Longest password accepted, characters (a bound on the work one login asks for).
MAX_PASSWORD = 1024
#: What every token starts with, so a leaked one is recognisable in logs and scanners.
TOKEN_PREFIX = "fbt_"

_hasher = PasswordHasher()
#: A hash checked when no account has the name given, so a login takes as long either way.
_DUMMY = _hasher.hash(secrets.token_urlsafe(16))


def check_password(password: str) -> str:
    if not MIN_PASSWORD <= len(password) <= MAX_PASSWORD:
        raise ParameterError(f"A password must be {MIN_PASSWORD}-{MAX_PASSWORD} characters long; "
                             f"this one has {len(password)}.")
    if password.strip() != password:
        raise ParameterError("A password must not start or end with white space (a pasted "
                             "line end, most often).")
    return password


def hash_password(password: str) -> str:
    """The Argon2id PHC string of ``password`` (checked by :func:`check_password`)."""
    return _hasher.hash(check_password(password))


def add_user(db: Database, name: str, role: str, password: str) -> UserRecord:
    """A new account with a checked, hashed password."""
    if role not in ROLE_PERMISSIONS:
        raise ParameterError(f"role must be one of {', '.join(ROLES)}; got {role!r}.")
    return db.add_user(name, role, hash_password(password))


def set_password(db: Database, name: str, password: str) -> UserRecord:
    return db.set_user(name, password_hash=hash_password(password))


def verify_login(db: Database, name: str, password: str) -> UserRecord | None:
    """The account when ``password`` is its password (and it is not disabled), else None; the
    same work is done for an unknown name. A hash with outdated parameters is renewed."""
    user = db.find_user(name) if 0 < len(name) <= 64 else None
    if len(password) > MAX_PASSWORD:
        return None
    try:
        _hasher.verify(user.password_hash if user else _DUMMY, password)
    except (VerifyMismatchError, VerificationError, InvalidHashError):
        return None
    if user is None or user.disabled_at is not None:
        return None
    if _hasher.check_needs_rehash(user.password_hash):
        user = db.set_user(name, password_hash=_hasher.hash(password), why="rehash")
    return user


def token_sha256(token: str) -> str:
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


def new_token(db: Database, name: str, label: str = "") -> tuple[str, ApiTokenRecord]:
    """A new API token for account ``name``: (the token, shown once; its record)."""
    if len(label) > 128:
        raise ParameterError("A token label is at most 128 characters.")
    token = TOKEN_PREFIX + secrets.token_urlsafe(32)
    return token, db.add_token(name, token_sha256(token), label)


def token_owner(db: Database, token: str) -> tuple[UserRecord, int] | None:
    """The account and token id of a live token, else None."""
    if not token.startswith(TOKEN_PREFIX) or len(token) > 100:
        return None
    return db.user_for_token(token_sha256(token))
