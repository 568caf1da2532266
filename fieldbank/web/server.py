"""Serving the workspace: where it binds, TLS, and the run until Ctrl-C.

:class:`ServeConfig` is checked before anything binds: an address other machines can reach
(anything but the loopback) is refused without ``tls_cert`` and ``tls_key`` - a login, its
session cookie and a patient's data never cross a network in clear text - and the certificate
and key are loaded into a TLS context then too, so a missing or mismatched file is refused
before a socket exists. Under TLS the cookies are marked Secure and the answers carry HSTS
(:func:`fieldbank.web.app.make_app`).
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import signal
import ssl
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from aiohttp import web

from fieldbank.errors import ParameterError
from fieldbank.validation import Interval, check_fields

#: Where the workspace listens unless told otherwise.
DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8470


def is_loopback(host: str) -> bool:
    """True for ``localhost`` and loopback addresses (127.0.0.0/8, ::1)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


@dataclass(frozen=True)
class ServeConfig:
    """Where and how the workspace listens.

    Attributes
    ----------
    host : str
        Address to bind; beyond the loopback only with TLS.
    port : int
        0: any free port (the one chosen is reported).
    tls_cert, tls_key : str or None
        PEM certificate (chain) and private key; both or neither.
    """

    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT
    tls_cert: str | None = None
    tls_key: str | None = None

    BOUNDS: ClassVar[dict[str, Interval]] = {"port": Interval.whole(0, 65535)}

    def __post_init__(self) -> None:
        check_fields(self, self.BOUNDS, what="serve setting")
        if (self.tls_cert is None) != (self.tls_key is None):
            raise ParameterError("TLS needs both --tls-cert and --tls-key.")
        if not self.tls and not is_loopback(self.host):
            raise ParameterError(
                f"--host {self.host} is reachable from other machines: the workspace binds "
                "beyond the loopback only with TLS (give --tls-cert CERT.pem --tls-key "
                "KEY.pem), so passwords, session cookies and patients' data never cross the "
                "network in clear text. Nothing was bound.")

    @property
    def tls(self) -> bool:
        return self.tls_cert is not None

    def ssl_context(self) -> ssl.SSLContext | None:
        """The server's TLS context (TLS 1.2 at least), or None without TLS; a missing,
        unreadable or mismatched certificate or key is refused here, before binding."""
        if self.tls_cert is None or self.tls_key is None:
            return None
        for name, path in (("--tls-cert", self.tls_cert), ("--tls-key", self.tls_key)):
            if not Path(path).is_file():
                raise ParameterError(f"{name} {path}: no such file. Nothing was bound.")
        ctx = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
        ctx.minimum_version = ssl.TLSVersion.TLSv1_2
        try:
            ctx.load_cert_chain(self.tls_cert, self.tls_key)
        except (ssl.SSLError, OSError) as exc:
            raise ParameterError(f"--tls-cert {self.tls_cert} / --tls-key {self.tls_key}: "
                                 f"not a certificate and its key ({exc}). Nothing was "
                                 "bound.") from None
        return ctx

    def url(self, port: int) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{'https' if self.tls else 'http'}://{host}:{port}/"


async def serve(config: ServeConfig, app: web.Application,
                ready: Callable[[str], None]) -> None:
    """Run ``app`` until cancelled; ``ready(url)`` once it listens."""
    ctx = config.ssl_context()  # before binding: a bad file binds nothing
    loop = asyncio.get_running_loop()
    task = asyncio.current_task()
    if task is not None:  # SIGTERM ends it like Ctrl-C: the renderer and files are cleaned up
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(signal.SIGTERM, task.cancel)
    runner = web.AppRunner(app, access_log=None)
    await runner.setup()
    try:
        site = web.TCPSite(runner, config.host, config.port, ssl_context=ctx)
        await site.start()
        sockets = getattr(site._server, "sockets", None) or []
        port = sockets[0].getsockname()[1] if sockets else config.port
        ready(config.url(int(port)))
        await asyncio.Event().wait()
    finally:
        await runner.cleanup()


def run(config: ServeConfig, app: web.Application, ready: Callable[[str], None]) -> None:
    """:func:`serve` until Ctrl-C (or SIGTERM)."""
    config.ssl_context()
    with contextlib.suppress(KeyboardInterrupt, asyncio.CancelledError):
        asyncio.run(serve(config, app, ready))
