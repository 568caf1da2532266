"""Local control channel of a running renderer: JSON lines over a Unix domain socket (server).

Only the same user on the same machine can talk to the renderer: the socket lives in a
directory of mode 0700, is created with mode 0600, and every connection's peer credentials
(``SO_PEERCRED``) must carry this process's user id. There is no network listener.

One request per line, one response per line; the requests and the commands they become are
listed in :mod:`haptic.commands`, which parses them (:func:`~haptic.commands.parse_request`)::

    -> {"ok": true, "result": {...}}  or  {"ok": false, "error": "message"}

Pushed models are compiled in the connection's thread, never in the loop; the loop swaps them in
at a tick boundary behind a fade. The client side is :mod:`haptic.client` (kept apart so the
live commands load nothing heavy); :func:`push_models` and :class:`ControlClient` are re-exported
here for callers of this module.
"""

from __future__ import annotations

import json
import logging
import os
import socket
import stat
import struct
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Protocol

from fieldbank.errors import FieldbankError
from fieldbank.haptic.client import (
    MAX_REQUEST_BYTES,
    ControlClient,
    data_home,
    default_socket_path,
    push_models,
)
from fieldbank.haptic.commands import RendererCommand, Request, Result, parse_request
from fieldbank.haptic.errors import CommandError, ControlError

__all__ = [
    "CommandSink",
    "ControlClient",
    "ControlServer",
    "data_home",
    "default_socket_path",
    "push_models",
]

log = logging.getLogger("fieldbank.haptic.control")


class CommandSink(Protocol):
    """What the server serves: a renderer's :meth:`~haptic.renderer.Renderer.submit`."""

    def submit(self, command: RendererCommand, /) -> Request: ...


def _peer_uid(conn: socket.socket) -> int | None:
    if not hasattr(socket, "SO_PEERCRED"):
        return None
    creds = conn.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i"))
    _pid, uid, _gid = struct.unpack("3i", creds)
    return int(uid)


class ControlServer:
    """Serves requests for ``renderer`` on a Unix socket at ``path`` in a daemon thread.

    Parameters
    ----------
    renderer : CommandSink
        The running renderer.
    path : str or Path, optional
        The socket (default :func:`~haptic.client.default_socket_path`).
    """

    def __init__(self, renderer: CommandSink, path: str | Path | None = None) -> None:
        self.renderer = renderer
        self.path = Path(path) if path is not None else default_socket_path()
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._closing = False

    def start(self) -> ControlServer:
        path = self.path
        if len(str(path).encode()) > 100:
            raise ControlError(f"control socket path too long for a Unix socket: {path}")
        path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
        st = path.parent.stat()
        if st.st_uid == os.getuid() and stat.S_IMODE(st.st_mode) & 0o077:
            os.chmod(path.parent, 0o700)
            st = path.parent.stat()
        if st.st_uid != os.getuid() or stat.S_IMODE(st.st_mode) & 0o077:
            raise ControlError(
                f"control socket directory {path.parent} must belong to this user with "
                f"mode 0700; it has uid {st.st_uid}, mode {oct(stat.S_IMODE(st.st_mode))}"
            )
        if path.exists() or path.is_symlink():
            if _alive(path):
                raise ControlError(f"a renderer is already serving on {path}")
            path.unlink()
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        old = os.umask(0o177)
        try:
            sock.bind(str(path))
        finally:
            os.umask(old)
        os.chmod(path, 0o600)
        sock.listen(4)
        self._sock = sock
        self._thread = threading.Thread(target=self._serve, name="haptic-control", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        self._closing = True
        if self._sock is not None:
            try:
                self._sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            self._sock.close()
            self._sock = None
        try:
            self.path.unlink()
        except FileNotFoundError:
            pass

    def __enter__(self) -> ControlServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _serve(self) -> None:
        while not self._closing and self._sock is not None:
            try:
                conn, _ = self._sock.accept()
            except OSError:
                return
            threading.Thread(target=self._client, args=(conn,), daemon=True).start()

    def _client(self, conn: socket.socket) -> None:
        with conn:
            uid = _peer_uid(conn)
            if uid is not None and uid != os.getuid():
                log.warning("control connection from uid %s refused", uid)
                conn.sendall(b'{"ok": false, "error": "permission denied"}\n')
                return
            f = conn.makefile("rwb")
            while True:
                line = f.readline(MAX_REQUEST_BYTES + 1)
                if not line:
                    return
                if len(line) > MAX_REQUEST_BYTES:
                    f.write(b'{"ok": false, "error": "request too large"}\n')
                    f.flush()
                    return
                f.write((json.dumps(self.handle_line(line)) + "\n").encode())
                f.flush()

    def handle_line(self, line: bytes) -> dict[str, Any]:
        """Answer one request line (never raises)."""
        try:
            req = json.loads(line)
            if not isinstance(req, dict):
                raise CommandError('a request is a JSON object with a "cmd" string')
            return {"ok": True, "result": self.handle(req)}
        except (FieldbankError, ValueError, KeyError, TypeError) as exc:
            return {"ok": False, "error": str(exc) or type(exc).__name__}

    def handle(self, req: Mapping[str, Any]) -> Result:
        """The renderer's answer to one parsed request (raises its error)."""
        return self.renderer.submit(parse_request(req)).wait()


def _alive(path: Path) -> bool:
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        s.connect(str(path))
        return True
    except OSError:
        return False
    finally:
        s.close()
