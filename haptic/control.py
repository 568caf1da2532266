"""Local control channel of a running renderer: JSON lines over a Unix domain socket.

Only the same user on the same machine can talk to the renderer: the socket lives in a
directory of mode 0700, is created with mode 0600, and every connection's peer credentials
(``SO_PEERCRED``) must carry this process's user id. There is no network listener.

One request per line, one response per line::

    {"cmd": "push", "before": {<ArmParams dict>}, "after": {<ArmParams dict>}}
    {"cmd": "switch", "to": "A" | "B" | "before" | "after"}
    {"cmd": "abx", "action": "start", "n_trials": 10, "seed": 7, "hide_labels": true}
    {"cmd": "abx", "action": "present", "label": "X"}
    {"cmd": "abx", "action": "answer", "answer": "A"}
    {"cmd": "status"} | {"cmd": "arm"} | {"cmd": "disarm"} | {"cmd": "stop"}

    -> {"ok": true, "result": {...}}  or  {"ok": false, "error": "message"}

Models are compiled in the connection's thread, never in the loop; the loop swaps them in at
a tick boundary behind a fade (:meth:`haptic.renderer.Renderer.push_params`).
"""

from __future__ import annotations

import json
import logging
import os
import socket
import stat
import struct
import threading
from pathlib import Path
from typing import Any

from fieldbank.errors import FieldbankError
from fieldbank.haptic.errors import HapticError
from fieldbank.params import ArmParams

log = logging.getLogger("fieldbank.haptic.control")

MAX_REQUEST_BYTES = 1 << 20
SOCKET_NAME = "haptic.sock"


def data_home() -> Path:
    """fieldbank's data directory: ``$FIELDBANK_HOME``, else the platform's user data dir
    (the same rule as the storage layer's ``fieldbank.storage.config.data_home``)."""
    env = os.environ.get("FIELDBANK_HOME")
    if env:
        return Path(env).expanduser()
    import platformdirs

    return Path(platformdirs.user_data_dir("fieldbank", appauthor=False))


def default_socket_path() -> Path:
    """``$FIELDBANK_HAPTIC_SOCKET``, else ``haptic.sock`` in :func:`data_home`."""
    env = os.environ.get("FIELDBANK_HAPTIC_SOCKET")
    if env:
        return Path(env)
    return data_home() / SOCKET_NAME


def _peer_uid(conn: socket.socket) -> int | None:
    if not hasattr(socket, "SO_PEERCRED"):
        return None
    creds = conn.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i"))
    _pid, uid, _gid = struct.unpack("3i", creds)
    return int(uid)


class ControlServer:
    """Serves requests for ``renderer`` on a Unix socket at ``path`` in a daemon thread."""

    def __init__(self, renderer: Any, path: str | Path | None = None) -> None:
        self.renderer = renderer
        self.path = Path(path) if path is not None else default_socket_path()
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._closing = False

    def start(self) -> ControlServer:
        path = self.path
        if len(str(path).encode()) > 100:
            raise HapticError(f"control socket path too long for a Unix socket: {path}")
        path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
        st = path.parent.stat()
        if st.st_uid == os.getuid() and stat.S_IMODE(st.st_mode) & 0o077:
            os.chmod(path.parent, 0o700)
            st = path.parent.stat()
        if st.st_uid != os.getuid() or stat.S_IMODE(st.st_mode) & 0o077:
            raise HapticError(
                f"control socket directory {path.parent} must belong to this user with "
                f"mode 0700; it has uid {st.st_uid}, mode {oct(stat.S_IMODE(st.st_mode))}"
            )
        if path.exists() or path.is_symlink():
            if _alive(path):
                raise HapticError(f"a renderer is already serving on {path}")
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
            if not isinstance(req, dict) or not isinstance(req.get("cmd"), str):
                raise HapticError('a request is a JSON object with a "cmd" string')
            return {"ok": True, "result": self.handle(req)}
        except (FieldbankError, ValueError, KeyError, TypeError) as exc:
            return {"ok": False, "error": str(exc) or type(exc).__name__}

    def handle(self, req: dict[str, Any]) -> Any:
        rd = self.renderer
        cmd = req["cmd"]
        if cmd == "push":
            before = ArmParams.from_dict(req["before"], where="push: before")
            after = ArmParams.from_dict(req["after"], where="push: after")
            ids = req.get("model_ids")
            if ids is not None and not (isinstance(ids, dict) and set(ids) <= {"A", "B"}):
                raise HapticError('push: "model_ids" must be {"A": id, "B": id}')
            return rd.push_params(before, after, ids).wait()
        if cmd == "switch":
            return rd.submit("switch", target=req["to"]).wait()
        if cmd == "abx":
            action = req.get("action")
            if action == "start":
                return rd.submit("abx_start", n_trials=int(req.get("n_trials", 10)),
                                 seed=int(req.get("seed", 0)),
                                 hide_labels=bool(req.get("hide_labels", True))).wait()
            if action == "present":
                return rd.submit("abx_present", label=str(req["label"])).wait()
            if action == "answer":
                return rd.submit("abx_answer", answer=str(req["answer"])).wait()
            raise HapticError(f"abx action must be start, present or answer; got {action!r}")
        if cmd in ("arm", "disarm", "stop"):
            return rd.submit(cmd).wait()
        if cmd == "status":
            return rd.status()
        raise HapticError(f"unknown control command {cmd!r}; known: push, switch, abx, status, "
                          f"arm, disarm, stop")


def _alive(path: Path) -> bool:
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        s.connect(str(path))
        return True
    except OSError:
        return False
    finally:
        s.close()


class ControlClient:
    """Talks to a renderer's control socket."""

    def __init__(self, path: str | Path | None = None, timeout_s: float = 10.0) -> None:
        self.path = Path(path) if path is not None else default_socket_path()
        self.timeout_s = timeout_s

    def request(self, cmd: str, **args: Any) -> Any:
        """Send one request; return its result or raise HapticError with the server's message."""
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        s.settimeout(self.timeout_s)
        try:
            try:
                s.connect(str(self.path))
            except OSError as exc:
                raise HapticError(
                    f"no renderer on {self.path} ({exc.strerror or exc}); start one with "
                    f"'fieldbank haptic serve'"
                ) from None
            s.sendall((json.dumps({"cmd": cmd, **args}) + "\n").encode())
            f = s.makefile("rb")
            line = f.readline(MAX_REQUEST_BYTES)
        except OSError as exc:
            raise HapticError(f"control channel {self.path}: {exc}") from None
        finally:
            s.close()
        if not line:
            raise HapticError(f"the renderer on {self.path} closed the connection")
        resp = json.loads(line)
        if not resp.get("ok"):
            raise HapticError(f"renderer refused {cmd!r}: {resp.get('error')}")
        return resp.get("result")


def push_models(before: ArmParams, after: ArmParams, path: str | Path | None = None,
                model_ids: tuple[int | None, int | None] | None = None) -> Any:
    """Push a before/after pair to a running renderer (used by ``whatif … --render``).

    ``model_ids``: the pair's ids in the field database, if stored, so the session's trace
    refers to them.
    """
    args: dict[str, Any] = {"before": before.to_dict(), "after": after.to_dict()}
    if model_ids is not None:
        args["model_ids"] = {"A": model_ids[0], "B": model_ids[1]}
    return ControlClient(path).request("push", **args)
