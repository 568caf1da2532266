"""Local control channel of a running renderer: JSON lines over a Unix domain socket (server).

Only the same user on the same machine can talk to the renderer: the socket lives in a
directory of mode 0700, is created with mode 0600, and every connection's peer credentials
(``SO_PEERCRED``) must carry this process's user id. There is no network listener.

One request per line, one response per line; the requests and the commands they become are
listed in :mod:`haptic.commands`, which parses them (:func:`~haptic.commands.parse_request`)::

    -> {"ok": true, "result": {...}}  or  {"ok": false, "error": "message"}

Whatever arrives, the server answers and keeps serving: a line that is not JSON, nests too
deep, carries an out-of-range number or names an unknown command gets an error reply; a line
longer than :data:`~haptic.client.MAX_REQUEST_BYTES` gets one and the connection is closed; at
most :data:`MAX_CONNECTIONS` connections are served at once (the next is told so and closed),
and a connection that sends no whole line for :data:`IDLE_TIMEOUT_S` is closed. A ``vet``
callable given to the server sees every command before the renderer does (the session uses it
to check pushed model ids against the database).

Pushed models are compiled in the connection's thread, never in the loop; the loop swaps them in
at a tick boundary behind a fade. The client side, :class:`~haptic.client.ControlClient` and
:func:`~haptic.client.push_models`, is :mod:`haptic.client` (kept apart so the live commands load
nothing heavy).
"""

from __future__ import annotations

import json
import logging
import os
import socket
import stat
import struct
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Protocol

from fieldbank.errors import FieldbankError
from fieldbank.haptic.client import MAX_REQUEST_BYTES, default_socket_path
from fieldbank.haptic.clock import keep_up_with_the_loop
from fieldbank.haptic.commandbase import RendererCommand, Result
from fieldbank.haptic.commands import Request, parse_request
from fieldbank.haptic.errors import CommandError, ControlError

__all__ = ["CommandSink", "ControlServer"]

log = logging.getLogger("fieldbank.haptic.control")

#: Connections served at once; one more is answered with an error and closed.
MAX_CONNECTIONS = 8
#: A connection that sends no whole request line for this long is closed, s.
IDLE_TIMEOUT_S = 30.0
#: Checks a command before the renderer sees it (raises to refuse it).
Vet = Callable[[RendererCommand], None]


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
    vet : callable(RendererCommand), optional
        Sees every parsed command first, in the connection's thread; raising refuses it.
    max_connections : int
        Connections served at once.
    idle_timeout_s : float, s
        How long a connection may wait between whole request lines.
    """

    def __init__(self, renderer: CommandSink, path: str | Path | None = None,
                 vet: Vet | None = None, max_connections: int = MAX_CONNECTIONS,
                 idle_timeout_s: float = IDLE_TIMEOUT_S) -> None:
        self.renderer = renderer
        self.path = Path(path) if path is not None else default_socket_path()
        self.vet = vet
        self.idle_timeout_s = idle_timeout_s
        self._slots = threading.BoundedSemaphore(max_connections)
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
        sock.listen(MAX_CONNECTIONS + 8)
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
            if not self._slots.acquire(blocking=False):
                log.warning("control connection refused: %d already open", MAX_CONNECTIONS)
                _reply_and_close(conn, {"ok": False, "error": "too many connections to the "
                                        "renderer's control channel; try again"})
                continue
            threading.Thread(target=self._client, args=(conn,), daemon=True).start()

    def _client(self, conn: socket.socket) -> None:
        try:
            with conn:
                uid = _peer_uid(conn)
                if uid is not None and uid != os.getuid():
                    log.warning("control connection from uid %s refused", uid)
                    conn.sendall(b'{"ok": false, "error": "permission denied"}\n')
                    return
                lines = _LineReader(conn, MAX_REQUEST_BYTES, self.idle_timeout_s)
                while True:
                    line = lines.next()
                    if line is None:
                        return
                    keep_up_with_the_loop()  # it will hold the interpreter the loop needs
                    if len(line) > MAX_REQUEST_BYTES:
                        conn.sendall(b'{"ok": false, "error": "request too large"}\n')
                        return
                    conn.sendall((json.dumps(self.handle_line(line)) + "\n").encode())
        except OSError:  # the peer went away mid-answer
            pass
        finally:
            self._slots.release()

    def handle_line(self, line: bytes) -> dict[str, Any]:
        """Answer one request line (never raises)."""
        try:
            try:
                text = line.decode("utf-8")
            except UnicodeDecodeError as exc:
                raise CommandError(f"a request line is JSON in utf-8: {exc}") from None
            req = json.loads(text)
            if not isinstance(req, dict):
                raise CommandError('a request is a JSON object with a "cmd" string')
            return {"ok": True, "result": self.handle(req)}
        except (FieldbankError, ValueError, KeyError, TypeError) as exc:
            return {"ok": False, "error": str(exc) or type(exc).__name__}
        except RecursionError:
            return {"ok": False, "error": "request nests too deep"}
        except Exception as exc:  # a reply, never a dead connection thread
            log.exception("control request failed")
            return {"ok": False, "error": f"request failed: {type(exc).__name__}: {exc}"}

    def handle(self, req: Mapping[str, Any]) -> Result:
        """The renderer's answer to one parsed request (raises its error)."""
        cmd = parse_request(req)
        if self.vet is not None:
            self.vet(cmd)
        return self.renderer.submit(cmd).wait()


class _LineReader:
    """Request lines from a connection, each within ``timeout_s`` of the previous one."""

    def __init__(self, conn: socket.socket, limit: int, timeout_s: float) -> None:
        self.conn = conn
        self.limit = limit
        self.timeout_s = timeout_s
        self.buf = bytearray()

    def next(self) -> bytes | None:
        """The next line (with its newline; longer than ``limit`` if too long), or None when
        the peer closed or stayed silent too long."""
        deadline = time.monotonic() + self.timeout_s
        while True:
            i = self.buf.find(b"\n")
            if i >= 0:
                line = bytes(self.buf[:i + 1])
                del self.buf[:i + 1]
                return line
            if len(self.buf) > self.limit:
                return bytes(self.buf)
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            self.conn.settimeout(left)
            try:
                chunk = self.conn.recv(65536)
            except TimeoutError:
                return None
            if not chunk:
                return None
            self.buf += chunk


def _reply_and_close(conn: socket.socket, reply: dict[str, Any]) -> None:
    try:
        conn.settimeout(1.0)
        conn.sendall((json.dumps(reply) + "\n").encode())
    except OSError:
        pass
    finally:
        conn.close()


def _alive(path: Path) -> bool:
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        s.connect(str(path))
        return True
    except OSError:
        return False
    finally:
        s.close()
