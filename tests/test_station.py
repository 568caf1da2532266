"""The clinician's station: the loop's snapshot, the web server's locks (token, origin, what a
page may send), and the page itself in a real headless browser (Debian's Chromium driven by
Playwright) beside a real serve process.

The browser test is skipped only when no ``chromium`` is on PATH and FIELDBANK_REQUIRE_BROWSER
is not "1" (CI sets it, so there a missing browser fails instead of skipping).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import re
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import numpy as np
import pytest

from fieldbank.haptic.client import ControlClient
from fieldbank.haptic.control import ControlServer
from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.probe import sim_url
from fieldbank.haptic.recording import read_trace_h5
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.snapshot import FIELDS, SnapshotReader, SnapshotWriter
from fieldbank.haptic.station.launch import StationProcess
from fieldbank.storage import Database
from tests.browser_util import chromium
from tests.haptic_util import ServeProcess, severe_shoulder

CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage"]


# --- the snapshot ---------------------------------------------------------------------------
def _hammer(directory: str, ready: object, stop: object) -> None:
    """Another process publishing records whose fields all carry the same number."""
    with SnapshotWriter(directory) as w:
        ready.set()  # type: ignore[attr-defined]
        k = 0.0
        while not stop.is_set():  # type: ignore[attr-defined]
            k += 1.0
            w.publish(*([k] * len(FIELDS)))


def test_snapshot_round_trip_and_never_a_torn_record(tmp_path: Path) -> None:
    import multiprocessing as mp

    with SnapshotWriter() as w:
        r = SnapshotReader(w.path)
        assert (w.path.stat().st_mode & 0o777) == 0o600
        assert (w.directory.stat().st_mode & 0o777) == 0o700
        w.publish(*[float(i) for i in range(len(FIELDS))])
        rec = r.read()
        assert [rec[f] for f in FIELDS] == [float(i) for i in range(len(FIELDS))]
        r.close()
    assert not w.path.exists() and not w.directory.exists()
    # a writer in another process, truly concurrent: a reader that mixed two records would
    # see different numbers in one
    ctx = mp.get_context("fork")
    ready, stop = ctx.Event(), ctx.Event()
    child = ctx.Process(target=_hammer, args=(str(tmp_path), ready, stop))
    child.start()
    try:
        assert ready.wait(10)
        r = SnapshotReader(tmp_path / "loop.snapshot")
        seen = set()
        t_end = time.monotonic() + 2.0
        while time.monotonic() < t_end:
            rec = r.read(timeout_s=5.0)
            assert len({rec[f] for f in FIELDS}) == 1, rec
            seen.add(rec["t_s"])
        r.close()
    finally:
        stop.set()
        child.join(10)
    assert len(seen) > 10  # the reader saw the writer move on, record after record
    assert r.retries > 0, r.retries  # and caught it mid-write, and read again


def test_snapshot_reader_refuses_other_files(tmp_path: Path) -> None:
    with pytest.raises(HapticError, match="no loop snapshot"):
        SnapshotReader(tmp_path / "none")
    bad = tmp_path / "bad"
    bad.write_bytes(b"x" * 4096)
    with pytest.raises(HapticError, match="not a loop snapshot"):
        SnapshotReader(bad)


def test_the_renderer_publishes_each_tick() -> None:
    p = severe_shoulder()
    link = RobotLink.open(sim_url(p, "circle"))
    link.handshake(1000, 20)
    rd = Renderer(link, p, p, RendererConfig(state_wait_s=0.05, realtime_priority=False))
    with SnapshotWriter() as w:
        rd.snapshot = w
        reader = SnapshotReader(w.path)
        rd.start()
        for _ in range(300):
            rd.tick()
        rec = reader.read()
        assert rec["ticks"] == 299 and rec["t_s"] == pytest.approx(0.299)
        assert (rec["x_m"], rec["y_m"]) == (link.state.x, link.state.y)
        assert (rec["fx_n"], rec["fy_n"]) == (rd.fx, rd.fy)
        assert rec["a_q1_rad"] == rd.pair.sims[0].state.q1 and rec["mode"] == 1.0
        assert rec["blinded"] == 0.0
        rd.submit("abx_start", n_trials=2)
        rd.tick()
        assert reader.read()["blinded"] == 1.0
        rd.finish()
        reader.close()
    link.close()


# --- the server's locks -----------------------------------------------------------------------
@contextlib.contextmanager
def _station(tmp_path: Path, stderr: IO[Any] | None = None
             ) -> Iterator[tuple[StationProcess, Renderer]]:
    """A station process over a (not running) renderer's snapshot and control socket."""
    p = severe_shoulder()
    link = RobotLink.open(sim_url(p, "hold"))
    link.handshake(1000, 20)
    rd = Renderer(link, p, p, RendererConfig(state_wait_s=0.05, realtime_priority=False))
    snap = SnapshotWriter()
    rd.snapshot = snap
    server = ControlServer(rd, tmp_path / "run" / "h.sock").start()
    proc = StationProcess(str(snap.path), str(server.path)).start(stderr=stderr)
    try:
        yield proc, rd
    finally:
        proc.stop()
        server.close()
        snap.close()
        link.close()


@pytest.fixture()
def station(tmp_path: Path) -> Iterator[tuple[StationProcess, Renderer]]:
    with _station(tmp_path) as s:
        yield s


def _get(url: str, headers: dict[str, str] | None = None) -> tuple[int, str, dict[str, str]]:
    req = urllib.request.Request(url, headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, r.read().decode(), dict(r.headers)
    except urllib.error.HTTPError as e:
        return e.code, e.read().decode(), dict(e.headers)


def test_the_station_refuses_every_request_without_its_token(station) -> None:  # type: ignore[no-untyped-def]
    proc, _rd = station
    base = f"http://127.0.0.1:{proc.port}"
    assert proc.url.startswith(f"{base}/?token=") and len(proc.config.token) >= 32
    for path in ("/", "/?token=", "/?token=wrong", "/ws", "/stats", "/stats?token=x"):
        code, body, _ = _get(base + path)
        assert code == 403, path
        assert "No access" in body
    code, body, headers = _get(proc.url)
    assert code == 200 and "<canvas" in body
    csp = headers["Content-Security-Policy"]
    nonce = re.search(r"'nonce-([^']+)'", csp).group(1)  # type: ignore[union-attr]
    assert f'<script nonce="{nonce}">' in body and "default-src 'none'" in csp
    assert headers["Referrer-Policy"] == "no-referrer"
    code, body, _ = _get(f"{base}/stats?token={proc.config.token}")
    assert code == 200 and json.loads(body)["pages"] == 0


def test_the_station_websocket_locks(station) -> None:  # type: ignore[no-untyped-def]
    import aiohttp

    proc, rd = station
    token = proc.config.token
    base = f"http://127.0.0.1:{proc.port}"

    async def talk() -> dict[str, object]:
        out: dict[str, object] = {}
        async with aiohttp.ClientSession() as s:
            for url, headers in ((f"{base}/ws", {}),
                                 (f"{base}/ws?token={token}", {"Origin": "http://evil.example"})):
                try:
                    async with s.ws_connect(url, headers=headers):
                        out["refused"] = False
                except aiohttp.WSServerHandshakeError as exc:
                    out.setdefault("codes", []).append(exc.status)  # type: ignore[union-attr]
            async with s.ws_connect(f"{base}/ws?token={token}") as ws:
                first = await ws.receive_json(timeout=10)
                out["first"] = first["type"]
                for cmd in ({"id": 1, "cmd": "stop"}, {"id": 2, "cmd": "push"},
                            {"id": 3, "cmd": "abx", "action": "reveal"}):
                    await ws.send_json(cmd)
                    while True:
                        m = await ws.receive_json(timeout=10)
                        if m["type"] == "reply":
                            out[f"reply{cmd['id']}"] = m
                            break
                await ws.send_json({"id": 4, "cmd": "switch", "to": "B"})
                while True:
                    m = await ws.receive_json(timeout=10)
                    if m["type"] == "reply":
                        out["reply4"] = m
                        break
                await ws.send_str("x" * 10_000)  # larger than a page may send
                m = await ws.receive(timeout=10)
                while m.type == aiohttp.WSMsgType.TEXT:  # frames and info sent before it
                    m = await ws.receive(timeout=10)
                out["big"] = m.type
        return out

    out = asyncio.run(talk())
    assert out["codes"] == [403, 403] and "refused" not in out
    assert out["first"] == "info"
    for k in ("reply1", "reply2"):
        assert out[k]["ok"] is False and "does not send" in out[k]["error"]  # type: ignore[index]
    assert "must be one of start, present, answer" in out["reply3"]["error"]  # type: ignore[index]
    assert out["reply4"]["ok"] is True  # type: ignore[index]
    assert rd.pair.blend.end == 1.0  # the switch reached the renderer
    assert out["big"] in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED,
                          aiohttp.WSMsgType.CLOSING, aiohttp.WSMsgType.ERROR)


def test_a_flood_of_refused_requests_logs_a_line_a_second_with_counts(tmp_path: Path) -> None:
    import aiohttp

    n, origin_n = 2500, 40
    log_path = tmp_path / "station.log"
    with log_path.open("w") as log, _station(tmp_path, stderr=log) as (proc, _rd):
        base = f"http://127.0.0.1:{proc.port}"
        token = proc.config.token

        async def flood() -> list[int]:
            paths = ("/", "/ws", "/stats?token=x", "/?token=wrong", "/%0aforged line")
            codes: list[int] = []
            async with aiohttp.ClientSession() as s:
                async def one(k: int) -> None:
                    async with s.get(base + paths[k % len(paths)]) as r:
                        codes.append(r.status)

                for start in range(0, n, 50):
                    await asyncio.gather(*(one(k) for k in range(start, min(n, start + 50))))
                for _ in range(origin_n):
                    try:
                        async with s.ws_connect(f"{base}/ws?token={token}",
                                                headers={"Origin": "http://evil.example"}):
                            codes.append(101)
                    except aiohttp.WSServerHandshakeError as exc:
                        codes.append(exc.status)
            return codes

        t0 = time.monotonic()
        codes = asyncio.run(flood())
        proc.stop()  # what is still held is written as it stops
        elapsed = time.monotonic() - t0
    assert codes == [403] * (n + origin_n)
    lines = log_path.read_text().splitlines()
    token_lines = [ln for ln in lines if "without a valid token refused" in ln]
    origin_lines = [ln for ln in lines if "from another origin refused" in ln]
    assert proc.config.token not in log_path.read_text()

    def counted(rows: list[str]) -> int:
        return sum(int(m.group(1).replace(",", "")) if (m := re.search(
            r"refused ([\d,]+) more times? in", ln)) else 1 for ln in rows)

    # every refusal counted once; at most a line a second per reason (the first, then one
    # per second of the flood, then what was held when the station stopped)
    assert counted(token_lines) == n and counted(origin_lines) == origin_n
    assert 1 < len(token_lines) <= elapsed / 1.0 + 2
    assert 1 <= len(origin_lines) <= elapsed / 1.0 + 2
    assert not any("forged line" in ln and not ln.startswith("station ") for ln in lines)


def test_the_station_binds_locally_unless_told(tmp_path: Path) -> None:
    with pytest.raises(HapticError, match="--station-allow-remote"):
        StationProcess(str(tmp_path / "s"), str(tmp_path / "c"), host="0.0.0.0")
    assert StationProcess(str(tmp_path / "s"), str(tmp_path / "c"), host="0.0.0.0",
                          allow_remote=True).config.host == "0.0.0.0"
    assert StationProcess(str(tmp_path / "s"), str(tmp_path / "c"),
                          host="::1").config.host == "::1"


# --- the page in a real browser ---------------------------------------------------------------
class Serve(ServeProcess):
    """``fieldbank haptic serve --station`` on the simulated robot in its own process."""

    def __init__(self, tmp: Path, *args: str) -> None:
        super().__init__(tmp, "sim://?mode=realtime&motion=explore", *args)

    def stop(self) -> dict[str, object]:
        if self.proc.poll() is None:
            try:
                ControlClient(self.sock).request("stop")
            except HapticError:
                pass
        out, _ = self.proc.communicate(timeout=60)
        self._reader.join(5)
        assert self.proc.returncode == 0, "\n".join(self.lines)
        return json.loads(out)


def _wait(page, expr: str, timeout_s: float = 10.0) -> object:  # type: ignore[no-untyped-def]
    deadline = time.time() + timeout_s
    while time.time() < deadline:
        v = page.evaluate(expr)
        if v:
            return v
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {expr}")


def test_the_station_page_in_chromium(tmp_path: Path) -> None:
    exe = chromium()
    from playwright.sync_api import sync_playwright

    serve = Serve(tmp_path)
    client = ControlClient(serve.sock)
    assert serve.url is not None and serve.url.startswith("http://127.0.0.1:")
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=exe, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1280, "height": 800})
            # without the token: refused
            resp = page.goto(serve.url.split("?")[0])
            assert resp is not None and resp.status == 403 and "No access" in page.content()
            # with it: the page draws the arm from the loop's snapshot
            page.goto(serve.url)
            _wait(page, "window.fb && window.fb.drawn > 30")
            # it keeps drawing as the handle moves (the frame rate itself is a figure of
            # benchmarks/bench_station.py, not a bound here: a loaded machine would break it)
            d0 = page.evaluate("window.fb.drawn")
            _wait(page, f"window.fb.drawn > {d0 + 60}", timeout_s=60.0)
            # the hand is drawn where the handle is: the handle's colour under the reported pixel
            px = page.evaluate("""() => { const c = document.getElementById('arm');
                const l = window.fb.last, d = window.devicePixelRatio || 1;
                return Array.from(c.getContext('2d').getImageData(
                    Math.round(l.px * d), Math.round(l.py * d), 1, 1).data); }""")
            # (its yellow centre: Okabe & Ito's yellow, #F0E442, a colour no muscle band has)
            assert abs(px[0] - 240) < 30 and abs(px[1] - 228) < 30 and px[2] < 120, px
            assert "elbow severe" in page.inner_text("#model-info")
            # click B: the renderer switches (status), the page says so
            assert client.request("status")["blend"] == 0.0
            page.click("#btn-b")
            deadline = time.time() + 5
            while client.request("status")["blend"] < 1.0 and time.time() < deadline:
                time.sleep(0.05)
            assert client.request("status")["blend"] == 1.0
            _wait(page, "document.getElementById('rendering').textContent.includes('B')")
            # an A/B/X block of two trials, answered from the page
            page.fill("#abx-n", "2")
            page.click("#abx-start")
            _wait(page, "!document.getElementById('abx-run').hidden")
            assert client.request("status")["blend"] == "hidden"
            assert "hidden" in page.inner_text("#model-info")
            _wait(page, "window.fb.last && window.fb.frames.slice(-1)[0]")
            for answer in ("A", "B"):
                page.click(".abx-present[data-label='X']")
                time.sleep(0.3)
                page.click(f".abx-answer[data-answer='{answer}']")
                time.sleep(0.3)
            _wait(page, "document.getElementById('abx-result').textContent.includes('of 2')")
            assert "correct" in page.inner_text("#abx-result")
            # training, instructed: the legend names the arm, the probing paths are drawn
            page.select_option("#train-instruction", "instructed")
            page.click("#train-start")
            _wait(page, "!document.getElementById('legend').hidden")
            assert "Unimpaired arm" in page.inner_text("#legend")
            paths = page.evaluate("window.fb.info.training.paths.map(p => p.name)")
            assert paths == ["pull", "semi-ellipse"]
            time.sleep(1.0)
            shot = tmp_path / "station.png"
            page.screenshot(path=str(shot))
            page.click("#train-stop")
            _wait(page, "document.getElementById('train-run').hidden")
            frames = page.evaluate("window.fb.frames")
            browser.close()
    finally:
        doc = serve.stop()
    _looks_like_a_page(shot)
    # the drawn hand followed the simulated robot: every drawn frame is the trace's handle
    trace = read_trace_h5(str(doc["trace"]))
    t = trace.t_s
    xs, ys = trace.column("x_m"), trace.column("y_m")
    matched = 0
    for f in frames:
        i = int(np.searchsorted(t, f["t_s"] - 1e-6))
        assert i < len(t) and abs(t[i] - f["t_s"]) < 1e-4, f
        assert abs(xs[i] - f["x"]) < 2e-5 and abs(ys[i] - f["y"]) < 2e-5, (f, xs[i], ys[i])
        matched += 1
    assert matched >= 100
    assert np.ptp([f["x"] for f in frames]) + np.ptp([f["y"] for f in frames]) > 0.01
    # the answers given on the page are stored with the session
    with Database.open(serve.db_url) as db:
        (sess,) = db.list_haptic_sessions()
        trials = db.list_haptic_trials(sess.id)
    abx = [tr for tr in trials if tr.kind == "abx"]
    assert [(tr.trial, tr.answer) for tr in abx] == [(0, "A"), (1, "B")]
    assert all(tr.correct is not None and tr.response_time_s is not None for tr in abx)
    training = [tr for tr in trials if tr.kind == "training"]
    assert training and training[0].condition == "unimpaired"
    assert training[0].detail["instruction"] == "instructed"


def _looks_like_a_page(path: Path) -> None:
    from PIL import Image  # a matplotlib dependency

    with Image.open(path) as im:
        px = np.asarray(im.convert("RGB"), dtype=np.int32)
    assert px.shape[:2] == (800, 1280)
    assert (px.sum(axis=2) < 200).mean() > 0.002           # dark arm and text
    yellow = (px[..., 0] > 210) & (abs(px[..., 1] - 228) < 30) & (px[..., 2] < 120)
    assert yellow.sum() > 50                               # the handle's centre
    assert px.std() > 20
