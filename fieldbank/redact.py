"""Secrets in URLs: the one function that masks them, and what it hides.

Database and robot URLs may carry a password: ``postgresql+psycopg://user:pw@host/db``,
``…/db?password=pw``, ``socket://user:pw@robot:4000``. Every place that prints, stores or
embeds a URL (messages, ``db current``, haptic session records and statistics, trace files,
``haptic replay --csv``) goes through :func:`mask_url`; reports do not embed the database URL at
all. Error texts from drivers that may quote a URL's parts go through :func:`redact`.

What is secret, decided in one place (:func:`_secret_spans`):

* the password of the user information: after ``scheme://user:`` up to the **last** ``@`` of
  the text. Users type passwords unencoded, with ``/``, ``@``, ``:``, ``%``, ``?`` or ``#`` in
  them; a URL parser stops at the first ``@`` or ``/`` and leaves the rest of the password in
  the host name. Taking the last ``@`` hides too much rather than too little when a query
  value holds an ``@`` too;
* the value of every query parameter whose name says it is a secret (``password``, ``passwd``,
  ``pwd``, ``secret``, ``token``, ``auth``, ``credential``, ``apikey``, …), up to the next
  ``&`` or the end (a ``#`` inside it is part of the value, not a fragment).

Each is replaced by ``***``. The user name, host, port, database and other parameters stay
readable. This module imports nothing heavy, so light commands (the haptic client) can use it.
"""

from __future__ import annotations

import re
from urllib.parse import unquote

MASK = "***"

_SCHEME = re.compile(r"[A-Za-z][A-Za-z0-9+.\-]*://")
_SECRET_KEY = re.compile(r"pass|pwd|secret|token|auth|credential|api_?key|private",
                         re.IGNORECASE)
_QUERY_ITEM = re.compile(r"[?&;]([^=&;?#]*)=([^&]*)")


def _as_text(url: object) -> str:
    """URL text; a SQLAlchemy ``URL`` object renders itself (password included, to be masked
    here like any other text)."""
    render = getattr(url, "render_as_string", None)
    if callable(render):
        return str(render(hide_password=False))
    return str(url)


def _userinfo_password(text: str) -> tuple[int, int] | None:
    """Span of the password in ``scheme://user:password@…`` (to the last ``@``), if any."""
    m = _SCHEME.match(text)
    if m is None:
        return None
    start = m.end()
    at = text.rfind("@")
    if at < start:
        return None
    colon = text.find(":", start, at)
    if colon < 0:
        return None
    if any(c in text[start:colon] for c in "/?#@"):
        return None  # not a user name: a path such as sqlite:////tmp/a:b@c.db
    return colon + 1, at


def _secret_spans(text: str) -> list[tuple[int, int]]:
    """Every secret part of ``text`` as (start, end), sorted, not overlapping."""
    spans: list[tuple[int, int]] = []
    user = _userinfo_password(text)
    if user is not None:
        spans.append(user)
    after = user[1] if user is not None else 0
    q = text.find("?", after)
    if q >= 0:
        for m in _QUERY_ITEM.finditer(text, q):
            if _SECRET_KEY.search(m.group(1)) and m.end(2) > m.start(2):
                spans.append((m.start(2), m.end(2)))
    spans.sort()
    merged: list[tuple[int, int]] = []
    for s, e in spans:
        if merged and s <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(e, merged[-1][1]))
        else:
            merged.append((s, e))
    return merged


def mask_url(url: object) -> str:
    """``url`` (text or a SQLAlchemy ``URL``) with every secret replaced by ``***``.

    >>> mask_url("postgresql://ana:p@ss/w:rd@db.example/fb?sslmode=require&password=x")
    'postgresql://ana:***@db.example/fb?sslmode=require&password=***'
    """
    text = _as_text(url)
    out = []
    pos = 0
    for s, e in _secret_spans(text):
        out.append(text[pos:s])
        out.append(MASK)
        pos = e
    out.append(text[pos:])
    return "".join(out)


def blank_password(text: str) -> str:
    """URL text with its user-information password replaced by as many ``x`` (same length),
    so the rest of the URL can be read without mistaking a ``?``, ``&`` or ``#`` of the
    password for the query or the fragment."""
    span = _userinfo_password(text)
    if span is None:
        return text
    s, e = span
    return text[:s] + "x" * (e - s) + text[e:]


def quote_password(text: str) -> str:
    """URL text with each ``@`` inside its user-information password percent-encoded, so that
    a URL parser (SQLAlchemy's stops at the first ``@``) reads the password the user meant
    instead of taking its tail for the host name."""
    span = _userinfo_password(text)
    if span is None:
        return text
    s, e = span
    return text[:s] + text[s:e].replace("@", "%40") + text[e:]


def url_secrets(url: object) -> list[str]:
    """The secrets :func:`mask_url` hides, as typed and percent-decoded, longest first."""
    text = _as_text(url)
    found: set[str] = set()
    for s, e in _secret_spans(text):
        raw = text[s:e]
        found.update(x for x in (raw, unquote(raw), unquote(raw.replace("+", " "))) if x)
        if "@" in raw:  # the part a URL parser would have taken for the host
            found.update(p for p in raw.split("@")[1:] if p)
    return sorted(found, key=lambda x: (-len(x), x))


def redact(message: str, *urls: object) -> str:
    """``message`` with every secret of ``urls`` replaced by ``***`` (for driver errors that
    may quote a host, a user or a connection option)."""
    for url in urls:
        if url is None:
            continue
        for secret in url_secrets(url):
            message = message.replace(secret, MASK)
    return message


def mask_port(port: str) -> str:
    """A robot port as messages may show it: a URL (``socket://``, ``sim://``) as
    :func:`mask_url` shows it (its secrets masked); a device path whole (``/dev/ttyUSB9``):
    it holds no secret, and a mistyped one must be seen to be corrected."""
    if "://" in port:
        return mask_url(port)
    return port


def redact_port(message: str, port: str) -> str:
    """``message`` with a URL port's secrets masked (:func:`mask_port`)."""
    if "://" in port:
        return redact(message, port)
    return message
