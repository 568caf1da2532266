"""The control channel under attack: every hostile request gets an answer, and the server keeps
serving (bounded counts and sizes, malformed JSON, too many connections, idle connections,
model ids checked at push)."""

from __future__ import annotations

import json
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from fieldbank.haptic import commands as C
from fieldbank.haptic.client import MAX_REQUEST_BYTES
from fieldbank.haptic.commandbase import RendererCommand
from fieldbank.haptic.control import MAX_CONNECTIONS, ControlServer
from fieldbank.haptic.errors import CommandError
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.probe import sim_url
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from tests.haptic_util import severe_shoulder, unimpaired


@pytest.fixture()
def rd() -> Iterator[Renderer]:
    p = severe_shoulder()
    link = RobotLink.open(sim_url(p, "hold"))
    link.handshake(1000, 20)
    r = Renderer(link, p, p, RendererConfig(state_wait_s=0.05, realtime_priority=False))
    r.start()  # running (commands that need the loop are accepted), ticked by hand below
    yield r
    r.finish()
    link.close()


def _connect(path: Path) -> socket.socket:
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.settimeout(5.0)
    s.connect(str(path))
    return s


def _ask(s: socket.socket, line: bytes) -> dict[str, object]:
    s.sendall(line)
    buf = b""
    while not buf.endswith(b"\n"):
        chunk = s.recv(65536)
        if not chunk:
            break
        buf += chunk
    return json.loads(buf)


def _serve_in_ticks(r: Renderer, stop: threading.Event) -> None:
    while not stop.is_set():  # the loop applies queued commands at tick boundaries
        r.tick()
        time.sleep(1e-4)


@pytest.fixture()
def server(rd: Renderer, tmp_path: Path) -> Iterator[tuple[Renderer, ControlServer]]:
    srv = ControlServer(rd, tmp_path / "run" / "haptic.sock", idle_timeout_s=1.0).start()
    stop = threading.Event()
    th = threading.Thread(target=_serve_in_ticks, args=(rd, stop), daemon=True)
    th.start()
    yield rd, srv
    stop.set()
    th.join(5)
    srv.close()


HOSTILE = [
    (b"not json\n", "Expecting value"),
    (b"\xff\xfe\xfd\n", "utf-8"),
    (b"[1, 2]\n", '"cmd" string'),
    (b'"status"\n', '"cmd" string'),
    (b'{"cmd": 7}\n', '"cmd" string'),
    (b'{"cmd": "explode"}\n', "unknown control command"),
    (b"[" * 100_000 + b"\n", "nests too deep"),
    (b'{"cmd": "abx", "action": "start", "n_trials": 1e308}\n', "from 1 to 1000"),
    (b'{"cmd": "abx", "action": "start", "n_trials": 1000000000000000000000}\n', "from 1 to 1000"),
    (b'{"cmd": "abx", "action": "start", "n_trials": Infinity}\n', "from 1 to 1000"),
    (b'{"cmd": "abx", "action": "start", "n_trials": NaN}\n', "from 1 to 1000"),
    (b'{"cmd": "abx", "action": "start", "n_trials": -3}\n', "from 1 to 1000"),
    (b'{"cmd": "abx", "action": "start", "n_trials": true}\n', "from 1 to 1000"),
    (b'{"cmd": "abx", "action": "start", "n_trials": 2.5}\n', "from 1 to 1000"),
    (b'{"cmd": "abx", "action": "start", "seed": -1}\n', '"seed"'),
    (b'{"cmd": "abx", "action": "start", "hide_labels": "no"}\n', '"hide_labels"'),
    (b'{"cmd": "abx", "action": "present", "label": {"x": 1}}\n', "presents 'A', 'B' or 'X'"),
    (b'{"cmd": "abx", "action": "answer"}\n', "an A/B/X answer"),
    (b'{"cmd": "switch"}\n', "switch to"),
    (b'{"cmd": "push", "before": 3, "after": null}\n', "arm-parameter object"),
    (b'{"cmd": "train", "action": "start", "protocol": {"assessment_repetitions": 100000}}\n',
     "assessment_repetitions"),
    (b'{"cmd": "train", "action": "start", "protocol": {"familiarisation_rounds": 1e9}}\n',
     "familiarisation_rounds"),
    (b'{"cmd": "train", "action": "start", "protocol": {"shell": "rm"}}\n',
     "unknown training parameter"),
    (b'{"cmd": "train", "action": "start", "protocol": [1]}\n', "JSON object"),
    (b'{"cmd": "train", "action": "answer", "answer": "' + b"x" * 5000 + b'"}\n',
     "shoulder, elbow or both"),
    (b'{"cmd": "train", "action": "dance"}\n', "train action must be"),
]


def test_every_hostile_line_gets_an_error_reply_and_the_connection_lives(server) -> None:  # type: ignore[no-untyped-def]
    rd, srv = server
    s = _connect(srv.path)
    try:
        for line, message in HOSTILE:
            reply = _ask(s, line)
            assert reply["ok"] is False, line[:80]
            assert message in str(reply["error"]), (line[:80], reply)
        # the same connection still answers, and nothing changed in the renderer
        reply = _ask(s, b'{"cmd": "status"}\n')
        assert reply["ok"] is True and reply["result"]["running"] is True  # type: ignore[index]
        assert rd.activities.running is None and not rd.activities.newest
    finally:
        s.close()


def test_an_oversized_line_is_answered_then_the_connection_closes(server) -> None:  # type: ignore[no-untyped-def]
    _rd, srv = server
    s = _connect(srv.path)
    try:
        s.sendall(b'{"cmd": "status", "pad": "' + b"x" * (MAX_REQUEST_BYTES + 10))
        reply = json.loads(s.makefile("rb").readline())
        assert reply == {"ok": False, "error": "request too large"}
        assert s.recv(10) == b""  # closed by the server
    finally:
        s.close()
    s = _connect(srv.path)  # and the server still serves
    assert _ask(s, b'{"cmd": "status"}\n')["ok"] is True
    s.close()


def test_connection_limit_and_idle_timeout(server) -> None:  # type: ignore[no-untyped-def]
    _rd, srv = server
    idle = []
    for _ in range(MAX_CONNECTIONS):
        idle.append(_connect(srv.path))
        time.sleep(0.02)
    time.sleep(0.2)
    extra = _connect(srv.path)
    reply = json.loads(extra.makefile("rb").readline())
    assert reply["ok"] is False and "too many connections" in reply["error"]
    extra.close()
    # the idle ones are closed by the server after its idle timeout (1 s here) ...
    for s in idle:
        s.settimeout(5.0)
        assert s.recv(10) == b""
        s.close()
    # ... which frees their slots
    s = _connect(srv.path)
    assert _ask(s, b'{"cmd": "info"}\n')["ok"] is True
    s.close()


def test_a_connection_trickling_bytes_is_closed_at_the_idle_timeout(server) -> None:  # type: ignore[no-untyped-def]
    _rd, srv = server
    s = _connect(srv.path)
    t0 = time.monotonic()
    closed = False
    # 30 s is a hang guard, not a bound: a loaded machine may serve the timeout late, never early
    while time.monotonic() - t0 < 30.0:
        try:
            s.sendall(b" ")  # never a whole line
        except OSError:
            closed = True
            break
        s.settimeout(0.2)
        try:
            if s.recv(10) == b"":
                closed = True
                break
        except TimeoutError:
            pass
        except ConnectionResetError:
            closed = True
            break
    elapsed = time.monotonic() - t0
    s.close()
    # closed, and by the 1 s idle timeout: the trickle itself never ended the connection
    assert closed and elapsed >= 0.9


def test_push_checks_model_ids_and_descriptions() -> None:
    a, b = severe_shoulder().to_dict(), unimpaired().to_dict()
    for ids, message in [({"A": True}, "positive integer"), ({"A": -1}, "positive integer"),
                         ({"A": "3"}, "positive integer"), ({"A": 2.0}, "positive integer"),
                         ({"A": 2**70}, "positive integer"), ({"C": 1}, "model_ids"),
                         ([1, 2], "model_ids")]:
        with pytest.raises(CommandError, match=message):
            C.parse_request({"cmd": "push", "before": a, "after": b, "model_ids": ids})
    for info, message in [({"A": {"label": "x" * 500}}, "at most 200"),
                          ({"A": {"evil": 1}}, "keys label"),
                          ({"A": {"model_id": 0}}, "positive integer")]:
        with pytest.raises(CommandError, match=message):
            C.parse_request({"cmd": "push", "before": a, "after": b, "model_info": info})
    ok = C.parse_request({"cmd": "push", "before": a, "after": b, "model_ids": {"A": 4},
                          "model_info": {"A": {"label": "fitted", "model_id": 4}}})
    assert isinstance(ok, C.Push) and ok.model_ids == {"A": 4}


def test_a_vet_hook_refuses_pushed_ids_the_database_does_not_know(rd: Renderer,
                                                                  tmp_path: Path) -> None:
    def vet(cmd: RendererCommand) -> None:
        if isinstance(cmd, C.Push) and (cmd.model_ids or {}).get("A") not in (None, 1):
            raise CommandError(f"push: no model with id {cmd.model_ids['A']}")  # type: ignore[index]

    srv = ControlServer(rd, tmp_path / "v.sock", vet=vet)
    req = {"cmd": "push", "before": unimpaired().to_dict(), "after": unimpaired().to_dict(),
           "model_ids": {"A": 99, "B": None}}
    reply = srv.handle_line(json.dumps(req).encode())
    assert reply == {"ok": False, "error": "push: no model with id 99"}
    assert rd.commands.qsize() == 0  # refused before the renderer saw it
