"""Client of a running renderer's control channel (:mod:`haptic.control` serves it).

One request per connection: a JSON line out, a JSON line back (the requests are listed in
:mod:`haptic.commands`)::

    {"cmd": "switch", "to": "B"}
    -> {"ok": true, "result": {...}}  or  {"ok": false, "error": "..."}

This module is what ``fieldbank haptic switch``, ``status``, ``arm``, ``abx …`` load: it
imports the standard library, :mod:`fieldbank.home` and the exception modules only, so a live
command answers at once (no numpy, no database layer).
"""

from __future__ import annotations

import json
import os
import socket
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fieldbank.haptic.errors import CommandError, ControlError
from fieldbank.home import data_home

if TYPE_CHECKING:  # typing only: push_models needs nothing of ArmParams but to_dict()
    from fieldbank.haptic.modelinfo import ModelInfoPair
    from fieldbank.params import ArmParams

#: Largest request or response line, bytes.
MAX_REQUEST_BYTES = 1 << 18
SOCKET_NAME = "haptic.sock"


def default_socket_path() -> Path:
    """``$FIELDBANK_HAPTIC_SOCKET``, else ``haptic.sock`` in :func:`data_home`."""
    env = os.environ.get("FIELDBANK_HAPTIC_SOCKET")
    if env:
        return Path(env)
    return data_home() / SOCKET_NAME


class ControlClient:
    """Talks to a renderer's control socket.

    Parameters
    ----------
    path : str or Path, optional
        The socket (default :func:`default_socket_path`).
    timeout_s : float, s
        Longest wait for the connection and the answer.
    """

    def __init__(self, path: str | Path | None = None, timeout_s: float = 10.0) -> None:
        self.path = Path(path) if path is not None else default_socket_path()
        self.timeout_s = timeout_s

    def request(self, cmd: str, **args: Any) -> Any:
        """Send one request; return its result.

        Raises
        ------
        ControlError
            No renderer on the socket, or the connection broke.
        CommandError
            The renderer refused the request (its message included).
        """
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        s.settimeout(self.timeout_s)
        try:
            try:
                s.connect(str(self.path))
            except OSError as exc:
                raise ControlError(
                    f"no renderer on {self.path} ({exc.strerror or exc}); start one with "
                    f"'fieldbank haptic serve'"
                ) from None
            s.sendall((json.dumps({"cmd": cmd, **args}) + "\n").encode())
            f = s.makefile("rb")
            line = f.readline(MAX_REQUEST_BYTES)
        except OSError as exc:
            raise ControlError(f"control channel {self.path}: {exc}") from None
        finally:
            s.close()
        if not line:
            raise ControlError(f"the renderer on {self.path} closed the connection")
        resp = json.loads(line)
        if not resp.get("ok"):
            raise CommandError(f"renderer refused {cmd!r}: {resp.get('error')}")
        return resp.get("result")


def push_models(before: ArmParams, after: ArmParams, path: str | Path | None = None,
                model_ids: tuple[int | None, int | None] | None = None,
                model_info: ModelInfoPair | None = None) -> Any:
    """Push a before/after pair to a running renderer (used by ``whatif … --render``).

    ``model_ids``: the pair's ids in the field database, if stored, so the session's trace
    refers to them. ``model_info``: what the station says about each
    (``{"A": ModelInfo, "B": ModelInfo}``, :mod:`haptic.modelinfo`).
    """
    args: dict[str, Any] = {"before": before.to_dict(), "after": after.to_dict()}
    if model_ids is not None:
        args["model_ids"] = {"A": model_ids[0], "B": model_ids[1]}
    if model_info is not None:
        args["model_info"] = {k: v.to_dict() for k, v in model_info.items()}
    return ControlClient(path).request("push", **args)
