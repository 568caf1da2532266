"""Shared set-up of the workspace tests: a database with SYN-001 fitted and three accounts, a
real ``fieldbank serve`` process on a free loopback port, and a small HTTP client that keeps
its cookies and CSRF token like the page does."""

from __future__ import annotations

import http.client
import json
import os
import re
import select
import signal
import ssl
import subprocess
import sys
import time
import urllib.parse
from http.cookies import SimpleCookie
from pathlib import Path
from typing import Any

PASSWORDS = {"alice": "alice's long password", "victor": "victor's long password",
             "dana": "dana's long password"}
ROLES = {"alice": "clinician", "victor": "viewer", "dana": "data-manager"}
ROOT = Path(__file__).resolve().parents[1]


def build_db(root: Path) -> str:
    """SYN-001's samples ingested and fitted, its demo plans stored, and the three accounts:
    the URL of the SQLite file."""
    from fieldbank.cli.demo import populate
    from fieldbank.storage import Database
    from fieldbank.web.accounts import add_user

    url = f"sqlite:///{root / 'db' / 'fieldbank.sqlite3'}"
    with Database.open(url) as db:
        populate(db, root / "samples", patients=("SYN-001",))
        for name, role in ROLES.items():
            add_user(db, name, role, PASSWORDS[name])
    return url


class Workspace:
    """``fieldbank serve`` in its own process, as a clinic starts it (``args`` added to its
    command line); its address read from its standard error."""

    def __init__(self, db_url: str, *args: str, timeout_s: float = 120.0) -> None:
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "fieldbank.cli", "serve", "--port", "0", "--db", db_url,
             *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
        self.lines: list[str] = []
        self.url = ""
        deadline = time.monotonic() + timeout_s
        assert self.proc.stderr is not None
        fd = self.proc.stderr.fileno()
        buf = b""
        while time.monotonic() < deadline and not self.url:
            if not select.select([fd], [], [], 0.5)[0]:
                if self.proc.poll() is not None:
                    break
                continue
            chunk = os.read(fd, 4096)
            if not chunk:
                break
            buf += chunk
            *done, buf = buf.split(b"\n")
            for line in done:
                text = line.decode("utf-8", "replace")
                self.lines.append(text)
                m = re.search(r"workspace: (\S+)", text)
                if m:
                    self.url = m.group(1)
        if not self.url:
            self.stop()
            raise RuntimeError("fieldbank serve did not start: " + " | ".join(self.lines)
                               + buf.decode("utf-8", "replace"))
        parts = urllib.parse.urlsplit(self.url)
        self.host, self.port, self.tls = parts.hostname or "", int(parts.port or 0), \
            parts.scheme == "https"

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(90)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        for f in (self.proc.stdout, self.proc.stderr):
            if f is not None:
                f.close()
        return int(self.proc.returncode)

    def client(self, context: ssl.SSLContext | None = None) -> Client:
        return Client(self.host, self.port, context if self.tls else None)

    def __enter__(self) -> Workspace:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


class Client:
    """One browser's worth of state: cookies and the CSRF token, over plain http.client."""

    def __init__(self, host: str, port: int, context: ssl.SSLContext | None = None) -> None:
        self.host, self.port, self.context = host, port, context
        self.cookies: dict[str, str] = {}
        self.set_cookie_headers: list[str] = []
        self.csrf = ""

    def request(self, method: str, path: str, body: Any = None, *, csrf: bool = True,
                headers: dict[str, str] | None = None, raw: bytes | None = None,
                cookies: bool = True) -> tuple[int, Any, http.client.HTTPResponse, bytes]:
        conn: http.client.HTTPConnection = (
            http.client.HTTPSConnection(self.host, self.port, context=self.context, timeout=120)
            if self.context is not None else
            http.client.HTTPConnection(self.host, self.port, timeout=120))
        h = dict(headers or {})
        if cookies and self.cookies:
            h["Cookie"] = "; ".join(f"{k}={v}" for k, v in self.cookies.items())
        if csrf and self.csrf and method not in ("GET", "HEAD"):
            h["X-CSRF-Token"] = self.csrf
        data = raw
        if body is not None:
            data = json.dumps(body).encode()
            h["Content-Type"] = "application/json"
        conn.request(method, path, body=data, headers=h)
        resp = conn.getresponse()
        payload = resp.read()
        conn.close()
        for v in resp.headers.get_all("Set-Cookie") or []:
            self.set_cookie_headers.append(v)
            c = SimpleCookie()
            c.load(v)
            for k, morsel in c.items():
                self.cookies[k] = morsel.value
        try:
            doc = json.loads(payload)
        except ValueError:
            doc = None
        if isinstance(doc, dict) and isinstance(doc.get("csrf"), str):
            self.csrf = doc["csrf"]
        return resp.status, doc, resp, payload

    def open_page(self) -> str:
        """GET / as a browser does: the anonymous session and the login form's CSRF token."""
        _, _, _, body = self.request("GET", "/")
        text = body.decode()
        m = re.search(r'name="csrf-token" content="([^"]+)"', text)
        assert m, text[:300]
        self.csrf = m.group(1)
        return text

    def login(self, name: str, password: str | None = None) -> int:
        if not self.csrf:
            self.open_page()
        status, _, _, _ = self.request("POST", "/api/login",
                                       {"name": name, "password": password or PASSWORDS[name]})
        return status
