"""The workspace's accounts and their API tokens: rows only, no cryptography.

What a password hash is and how a token is made is :mod:`fieldbank.web.accounts`' business;
this mixin stores what it is given - a name, a role, an Argon2id PHC string, the SHA-256 of a
token - and finds an account by name or a token by its hash. Every change is audited like any
other write (the actor is whoever runs the command or the logged-in user). An account is never
deleted: it is disabled, so the names in the audit log stay those of known accounts.
"""

from __future__ import annotations

import re

from sqlalchemy import select
from sqlalchemy.orm import Session

from fieldbank.errors import ParameterError, StorageError
from fieldbank.storage.core import DatabaseCore, now, to_utc, to_utc_opt
from fieldbank.storage.orm import ROLES, ApiTokenRow, UserRow
from fieldbank.storage.records import ApiTokenRecord, UserRecord

#: Account names: letters, digits and ``-_.@``, 1-64, starting with a letter or digit.
NAME_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.@-]{0,63}", re.ASCII)


def _user(r: UserRow) -> UserRecord:
    return UserRecord(r.id, r.name, r.role, r.password_hash, to_utc(r.created_at),
                      to_utc_opt(r.disabled_at))


def _token(r: ApiTokenRow, name: str) -> ApiTokenRecord:
    return ApiTokenRecord(r.id, name, r.label, to_utc(r.created_at), to_utc_opt(r.revoked_at))


def check_role(role: str) -> str:
    if role not in ROLES:
        raise ParameterError(f"role must be one of {', '.join(ROLES)}; got {role!r}.")
    return role


class Accounts(DatabaseCore):
    """Users and API tokens of :class:`~fieldbank.storage.Database`."""

    def _user_row(self, s: Session, name: str) -> UserRow:
        row = s.scalar(select(UserRow).where(UserRow.name == name))
        if row is None:
            names = list(s.scalars(select(UserRow.name).order_by(UserRow.name)))
            held = (f"its accounts: {', '.join(names)}" if names else
                    "it has no accounts yet ('fieldbank users add NAME --role ROLE')")
            raise StorageError(f"No account named {name!r} in {self.url_masked}; {held}.")
        return row

    def add_user(self, name: str, role: str, password_hash: str) -> UserRecord:
        """A new account (``password_hash``: an Argon2id PHC string)."""
        if not NAME_RE.fullmatch(name):
            raise ParameterError(
                f"Account name {name!r} must be 1-64 letters, digits or '-_.@', starting with "
                "a letter or digit.")
        check_role(role)
        with self._write() as s:
            if s.scalar(select(UserRow.id).where(UserRow.name == name)) is not None:
                raise StorageError(f"An account named {name!r} already exists.")
            row = UserRow(name=name, role=role, password_hash=password_hash, created_at=now())
            s.add(row)
            s.flush()
            self._audit(s, "add", "user", row.id, {"name": name, "role": role})
            return _user(row)

    def find_user(self, name: str) -> UserRecord | None:
        """The account ``name``, or None (a login must not say which names exist)."""
        with self._read() as s:
            row = s.scalar(select(UserRow).where(UserRow.name == name))
            return None if row is None else _user(row)

    def get_user(self, name: str) -> UserRecord:
        with self._read() as s:
            return _user(self._user_row(s, name))

    def list_users(self) -> list[UserRecord]:
        with self._read() as s:
            return [_user(r) for r in s.scalars(select(UserRow).order_by(UserRow.name))]

    def set_user(self, name: str, *, role: str | None = None, password_hash: str | None = None,
                 disabled: bool | None = None, why: str = "") -> UserRecord:
        """Change an account's role, password hash or whether it is disabled (audited; the
        hash itself never goes into the audit log). ``why``: recorded with the change."""
        with self._write() as s:
            row = self._user_row(s, name)
            changed: dict[str, object] = {}
            if role is not None and role != row.role:
                changed["role"] = [row.role, check_role(role)]
                row.role = role
            if password_hash is not None and password_hash != row.password_hash:
                row.password_hash = password_hash
                changed["password"] = "changed"
            if disabled is not None and disabled != (row.disabled_at is not None):
                row.disabled_at = now() if disabled else None
                changed["disabled"] = disabled
            if changed:
                if why:
                    changed["why"] = why
                self._audit(s, "change", "user", row.id, {"name": name, **changed})
            return _user(row)

    def record_login(self, name: str, ok: bool) -> None:
        """Append a ``login`` (or ``login-refused``) entry for the name given; the actor is
        the name too, the address comes with the context."""
        with self._write() as s:
            uid = s.scalar(select(UserRow.id).where(UserRow.name == name))
            self._audit(s, "login" if ok else "login-refused", "user",
                        "-" if uid is None else uid, {"name": name[:64]})

    # --- API tokens ---------------------------------------------------------------------------
    def add_token(self, name: str, token_sha256: str, label: str = "") -> ApiTokenRecord:
        """Record a new token of account ``name`` by its SHA-256."""
        with self._write() as s:
            user = self._user_row(s, name)
            if user.disabled_at is not None:
                raise StorageError(f"Account {name!r} is disabled: it gets no tokens.")
            row = ApiTokenRow(user_id=user.id, token_sha256=token_sha256, label=label,
                              created_at=now())
            s.add(row)
            s.flush()
            self._audit(s, "add", "api_token", row.id, {"user": name, "label": label})
            return _token(row, name)

    def list_tokens(self, name: str | None = None) -> list[ApiTokenRecord]:
        with self._read() as s:
            q = (select(ApiTokenRow, UserRow.name).join(UserRow, ApiTokenRow.user_id == UserRow.id)
                 .order_by(ApiTokenRow.id))
            if name is not None:
                q = q.where(UserRow.id == self._user_row(s, name).id)
            return [_token(r, n) for r, n in s.execute(q)]

    def revoke_token(self, token_id: int) -> tuple[ApiTokenRecord, bool]:
        """Revoke token ``token_id``; (the token, whether it changed: False when it already
        was revoked)."""
        with self._write() as s:
            row = s.get(ApiTokenRow, token_id)
            if row is None:
                raise self._no_row(s, ApiTokenRow, "API token", token_id)
            name = s.scalar(select(UserRow.name).where(UserRow.id == row.user_id)) or "?"
            if row.revoked_at is not None:
                return _token(row, name), False
            row.revoked_at = now()
            self._audit(s, "revoke", "api_token", row.id, {"user": name})
            return _token(row, name), True

    def user_for_token(self, token_sha256: str) -> tuple[UserRecord, int] | None:
        """The account holding the live token with this SHA-256, and the token's id; None for
        an unknown or revoked token, or a disabled account."""
        with self._read() as s:
            got = s.execute(select(ApiTokenRow, UserRow)
                            .join(UserRow, ApiTokenRow.user_id == UserRow.id)
                            .where(ApiTokenRow.token_sha256 == token_sha256)).first()
            if got is None:
                return None
            tok, user = got
            if tok.revoked_at is not None or user.disabled_at is not None:
                return None
            return _user(user), int(tok.id)
