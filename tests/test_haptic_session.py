"""Recording, replay, A/B/X, the control channel, the CLI, and real-time runs on a pty."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import serial
from click.testing import CliRunner

from fieldbank.cli.haptic import haptic
from fieldbank.cli.main import cli
from fieldbank.errors import ParameterError, StorageError
from fieldbank.evaluate.severity import parse_severity_options, synthesize
from fieldbank.haptic import motions
from fieldbank.haptic.activities.abx import AbxBlock, AbxSession
from fieldbank.haptic.client import ControlClient, push_models
from fieldbank.haptic.clock import VirtualClock
from fieldbank.haptic.control import ControlServer
from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.probe import probe, sim_url
from fieldbank.haptic.recording import COLUMNS, Hdf5TraceSink, read_trace_h5, write_trace_h5
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.replay import rerun
from fieldbank.haptic.safety import Mode
from fieldbank.haptic.simrobot import PtyRobot, SimRobotConfig
from fieldbank.probepath import ProbePath, probes_document
from tests.haptic_util import rest_hand, severe_shoulder, unimpaired


# --- recording ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def probe_result():  # type: ignore[no-untyped-def]
    return probe(severe_shoulder(), "fastpull")


def test_trace_h5_round_trip_with_units(probe_result, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    trace = probe_result.trace
    sink = Hdf5TraceSink(tmp_path)
    ref = sink.write_trace(trace, "s1")
    back = read_trace_h5(ref)
    assert np.array_equal(back.t_s, trace.t_s)
    assert np.array_equal(back.data, trace.data)
    assert back.models == json.loads(json.dumps(trace.models))
    assert back.events == json.loads(json.dumps(trace.events))
    assert back.rate_hz == trace.rate_hz
    import h5py

    with h5py.File(ref) as h:
        for name, unit in COLUMNS:
            assert h[f"columns/{name}"].attrs["unit"] == unit
            assert h[f"columns/{name}"].fletcher32
    assert len(sink.sha256[ref]) == 64
    # write-once: a second write under the same name is refused and the first is untouched
    before = Path(ref).read_bytes()
    with pytest.raises(StorageError, match="write-once"):
        sink.write_trace(trace, "s1")
    assert Path(ref).read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["s1.h5"]  # no temp file left behind


def test_failed_trace_write_leaves_nothing(probe_result, tmp_path: Path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    import errno

    def boom(*a: object, **k: object) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "link", boom)  # the last step: the file goes into place
    with pytest.raises(StorageError, match="No space left"):
        write_trace_h5(probe_result.trace, tmp_path / "x.h5")
    assert list(tmp_path.iterdir()) == []


def test_read_trace_refuses_other_files(tmp_path: Path) -> None:
    import h5py

    with h5py.File(tmp_path / "other.h5", "w") as h:
        h.attrs["format"] = "something else"
    with pytest.raises(StorageError, match="not a haptic trace"):
        read_trace_h5(tmp_path / "other.h5")
    (tmp_path / "junk.h5").write_bytes(b"not hdf5")
    with pytest.raises(StorageError, match=r"junk\.h5"):
        read_trace_h5(tmp_path / "junk.h5")


def test_replay_reproduces_the_session(probe_result) -> None:  # type: ignore[no-untyped-def]
    r = rerun(probe_result.trace)
    assert r["ticks"] == len(probe_result.trace)
    assert r["max_deviation_n"] < 1e-4  # float32 storage of the recorded force
    # and it is a real check: replaying with the other model deviates
    t = probe_result.trace
    other = type(t)(t_s=t.t_s, data=t.data, rate_hz=t.rate_hz,
                    models={"A": unimpaired().to_dict(), "B": unimpaired().to_dict()},
                    events=t.events, metadata=t.metadata)
    assert rerun(other)["max_deviation_n"] > 1.0


def test_trace_csv_export(probe_result) -> None:  # type: ignore[no-untyped-def]
    text = probe_result.trace.to_csv()
    lines = [ln for ln in text.splitlines() if not ln.startswith("#")]
    assert lines[0].split(",") == ["t_s"] + [c for c, _ in COLUMNS]
    assert len(lines) == len(probe_result.trace) + 1


# --- A/B/X ----------------------------------------------------------------------------------
def test_abx_is_seeded_balanced_and_scored() -> None:
    a = AbxSession(n_trials=10, seed=4)
    b = AbxSession(n_trials=10, seed=4)
    assert a.x_labels == b.x_labels and a.label_model == b.label_model
    assert sorted(a.x_labels) == ["A"] * 5 + ["B"] * 5
    assert AbxSession(n_trials=10, seed=5).x_labels != a.x_labels or \
        AbxSession(n_trials=10, seed=6).x_labels != a.x_labels
    # one meaning of A and B everywhere: A is before, B after, whatever the seed
    assert {tuple(AbxSession(n_trials=2, seed=s).label_model.items())
            for s in range(20)} == {(("A", 0), ("B", 1))}
    for i in range(10):
        x = a.model_for("X")
        truth = "A" if x == a.label_model["A"] else "B"
        a.answer(truth if i % 2 else ("B" if truth == "A" else "A"), t_s=float(i))
    res = a.result()
    assert res["answered"] == 10 and res["correct"] == 5 and res["counted"] == 10
    assert {r["x_was"] for r in res["answers"]} == {"before", "after"}
    assert all(r["x_was"] == ("before" if r["x_is"] == "A" else "after")
               for r in res["answers"])
    # a flagged answer (a fault or no force in its window) is kept and not scored
    c = AbxSession(n_trials=2, seed=4)
    c.answer(c.x_labels[0], 1.0, {"flagged": True, "flags": ["fault during the trial"]})
    c.answer(c.x_labels[1], 2.0, {"flagged": False, "flags": []})
    r = c.result()
    assert (r["answered"], r["counted"], r["flagged"], r["correct"]) == (2, 1, 1, 1)
    with pytest.raises(HapticError, match="finished"):
        a.answer("A", 11.0)
    with pytest.raises(HapticError):
        AbxSession(n_trials=2).answer("C", 0.0)


def test_abx_through_the_renderer_hides_and_records() -> None:
    p = severe_shoulder()
    link = RobotLink.open(sim_url(p, "hold"))
    link.handshake(1000, 20)
    rd = Renderer(link, p, unimpaired(), RendererConfig(state_wait_s=0.05), clock=VirtualClock())
    rd.start(expected_ticks=3000)
    cmds = [rd.submit("abx_start", n_trials=2, seed=3)]
    rd.tick()
    assert rd.status()["blend"] == "hidden"
    for ans in ("A", "B"):
        cmds.append(rd.submit("abx_present", label="X"))
        for _ in range(600):
            rd.tick()
        abx = rd.activities.running
        assert isinstance(abx, AbxBlock)
        expected_w = float(abx.session.model_for("X"))
        assert rd.pair.blend.value == pytest.approx(expected_w)
        cmds.append(rd.submit("abx_answer", answer=ans))
        rd.tick()
    for c in cmds:
        c.wait()
    trace = rd.finish()
    link.close()
    res = trace.metadata["abx"][0]
    assert res["answered"] == 2 and len(res["answers"]) == 2
    assert [e["event"] for e in trace.events].count("abx_answer") == 2


# --- control channel ------------------------------------------------------------------------
@pytest.fixture()
def served(tmp_path: Path):  # type: ignore[no-untyped-def]
    """A renderer on the in-process simulated robot (real time) with its control socket.

    The device's watchdog is 1 s here: these tests are about the control channel, and on a
    loaded test machine a thread of this process can stall longer than the 20 ms a real
    session allows (which then trips, as it should: tests/test_haptic_faults.py)."""
    p = severe_shoulder()
    link = RobotLink.open(sim_url(p, "circle", base="sim://?mode=realtime&watchdog_ms=1000"))
    link.handshake(1000, 1000)
    rd = Renderer(link, p, p, RendererConfig(realtime_priority=False))
    sock = tmp_path / "run" / "haptic.sock"
    server = ControlServer(rd, sock).start()
    th = threading.Thread(target=rd.run, kwargs={"duration_s": 30.0}, daemon=True)
    th.start()
    while not rd.running:
        time.sleep(0.01)
    yield rd, sock
    if rd.running:
        rd.submit("stop")
    th.join(5)
    server.close()
    link.close()


def test_control_socket_is_private(served) -> None:  # type: ignore[no-untyped-def]
    _rd, sock = served
    assert stat.S_IMODE(sock.stat().st_mode) == 0o600
    assert stat.S_IMODE(sock.parent.stat().st_mode) == 0o700
    assert stat.S_ISSOCK(sock.stat().st_mode)


def test_control_push_switch_status_stop(served) -> None:  # type: ignore[no-untyped-def]
    rd, sock = served
    c = ControlClient(sock)
    st = c.request("status")
    assert st["running"] and st["mode"] == "ARMED"
    before, after = unimpaired(), synthesize({"elbow": "severe"})
    pushed = push_models(before, after, sock)
    # the answer is the renderer's true state: armed, fading to the new pair
    assert pushed["pushed"] is True and pushed["mode"] == "ARMED" and pushed["swapping"]
    deadline = time.time() + 3
    while rd.pair.params[1] != after and time.time() < deadline:
        time.sleep(0.01)
    assert rd.pair.params == (before, after)  # swapped in by the loop after the fade-out
    sw = c.request("switch", to="B")
    assert sw["blend_target"] == 1.0 and sw["mode"] == "ARMED" and sw["faults_now"] == []
    with pytest.raises(HapticError, match="switch to"):
        c.request("switch", to="C")
    with pytest.raises(HapticError, match="unknown control command"):
        c.request("explode")
    with pytest.raises(HapticError, match="km_n_per_m"):
        c.request("push", before={**before.to_dict(), "km_n_per_m": [-1] * 6},
                  after=after.to_dict())
    c.request("stop")
    deadline = time.time() + 3
    while rd.trace is None and time.time() < deadline:
        time.sleep(0.01)
    assert not rd.running
    assert rd.trace is not None and [e["event"] for e in rd.trace.events].count("push") == 1


def test_control_rejects_malformed_lines(served) -> None:  # type: ignore[no-untyped-def]
    rd, sock = served
    server = ControlServer(rd, sock.parent / "unused.sock")
    assert server.handle_line(b"not json")["ok"] is False
    assert server.handle_line(b"[1, 2]")["ok"] is False
    assert "cmd" in server.handle_line(b'{"x": 1}')["error"]


def test_client_without_server_says_so(tmp_path: Path) -> None:
    with pytest.raises(HapticError, match="no renderer on"):
        ControlClient(tmp_path / "none.sock").request("status")


def test_second_server_on_a_live_socket_is_refused(served) -> None:  # type: ignore[no-untyped-def]
    rd, sock = served
    with pytest.raises(HapticError, match="already serving"):
        ControlServer(rd, sock).start()


# --- real time on a pty ---------------------------------------------------------------------
def test_realtime_pty_session_with_device_process() -> None:
    """A second of real-time rendering against a device in another process.

    Nothing here is a wall-clock bound (a loaded machine starves either process): the checks
    are the loop's own schedule - no tick before its deadline, the ticks and the skipped ones
    filling the span between the first and the last wake - and the link's bookkeeping.
    """
    p = severe_shoulder()
    x0, y0 = rest_hand(p)
    with PtyRobot(SimRobotConfig(mode="realtime", motion="fastpull", x0_m=x0, y0_m=y0)) as robot:
        robot.start_process()
        link = RobotLink.open(robot.port)
        link.handshake(1000, 20, timeout_s=3.0)
        rd = Renderer(link, p, p, RendererConfig())
        trace = rd.run(1.0)
        link.close()
    assert len(trace) == 1000
    wake = np.array(rd.times.wake_ns)
    late = np.array(rd.times.late_ns)
    assert wake.size == 1000 and (late >= 0).all()  # real time: never ahead of the schedule
    # deadlines advance one period per tick and per skipped tick, so the first and the last
    # wake are at least that far apart (the first may itself have woken late)
    skipped = rd.times.skipped_ticks
    assert wake[-1] - wake[0] >= (999 + skipped) * rd.period_ns - late[0]
    s = trace.stats
    assert s["skipped_ticks"] == skipped
    assert s["period_us"]["p50"] == pytest.approx(
        float(np.percentile(np.diff(wake), 50)) / 1e3, rel=1e-6)
    assert "p99" in s["period_error_us"] and "overruns" in s
    assert s["link"]["states"] > 0
    f = np.hypot(trace.column("fx_n"), trace.column("fy_n"))
    if not trace.faults:  # a loaded machine may starve the device: then the fault is recorded
        assert f.max() > 3.0  # the fast pull was felt


def test_device_watchdog_over_a_pty_in_real_time() -> None:
    """The host stops commanding: the device zeroes the force, disarms and reports it."""
    from fieldbank.haptic import protocol as P

    with PtyRobot(SimRobotConfig(mode="realtime", watchdog_ms=20)) as robot:
        robot.start_thread()
        link = RobotLink.open(robot.port)
        link.handshake(1000, 20)
        link.arm()
        for _ in range(50):
            link.send_force(5.0, 0.0)
            link.wait_state(0.01)
        assert robot.device.fx_cmd == 5.0
        # a hang guard, not a bound: when the watchdog trips (20 ms after the last FORCE, on
        # the device's clock) is checked on a virtual clock in tests/test_haptic_faults.py
        deadline = time.monotonic() + 30.0
        while not link.state.flags & P.FLAG_WATCHDOG and time.monotonic() < deadline:
            link.wait_state(0.01)
        assert link.state.flags & P.FLAG_WATCHDOG and not link.state.flags & P.FLAG_ARMED
        assert robot.device.fx_cmd == 0.0 and robot.device.watchdog_tripped
        link.close()


def test_sim_url_handler_and_bad_options() -> None:
    port = serial.serial_for_url("sim://?motion=hold&x0_m=0.1&y0_m=0.4", timeout=0)
    assert port.device.config.x0_m == 0.1  # type: ignore[attr-defined]
    port.close()
    with pytest.raises(HapticError, match="unknown sim:// option"):
        RobotLink.open("sim://?speed=11")
    with pytest.raises(HapticError, match="motion"):
        RobotLink.open("sim://?motion=dance")


def test_handshake_refuses_a_rate_over_the_device_maximum() -> None:
    link = RobotLink.open("sim://?max_rate_hz=2000")
    with pytest.raises(HapticError, match="refused HELLO"):
        link.handshake(4000, 20)


def test_handshake_times_out_without_a_device() -> None:
    with PtyRobot(SimRobotConfig()) as robot:  # device never started
        link = RobotLink.open(robot.port)
        with pytest.raises(HapticError, match="no HELLO_ACK"):
            link.handshake(1000, 20, timeout_s=0.2)
        link.close()


# --- motions and models ---------------------------------------------------------------------
@pytest.mark.parametrize("kind", motions.MOTIONS)
def test_motions_start_at_rest_and_velocity_is_the_derivative(kind: str) -> None:
    # a path is its polyline (robot frame); here one starting at (0.1, 0.5)
    path = motions.format_path([(0.0, 0.1, 0.5), (0.4, 0.16, 0.47), (1.0, 0.12, 0.38)])
    m = motions.make_motion(kind, 0.1, 0.5, seed=2, path_text=path if kind == "path" else "")
    x, y, vx, vy = m(0.0)
    assert (x, y) == pytest.approx((0.1, 0.5), abs=1e-12) and (vx, vy) == (0.0, 0.0)
    h = 1e-6
    for t in (0.35, 0.7, 1.3):
        a, b = m(t - h), m(t + h)
        assert m(t)[2] == pytest.approx((b[0] - a[0]) / (2 * h), abs=1e-5)
        assert m(t)[3] == pytest.approx((b[1] - a[1]) / (2 * h), abs=1e-5)


def test_pull_goes_toward_the_body_by_its_distance() -> None:
    m = motions.make_motion("pull", 0.1, 0.5, distance_m=0.12, duration_s=2.0)
    end = m(motions.LEAD_IN_S + 2.0)
    assert end[:2] == pytest.approx((0.1, 0.38))
    assert end[2:] == pytest.approx((0.0, 0.0))


def test_severity_specs_for_the_renderer() -> None:
    assert parse_severity_options(["shoulder=severe, elbow=very_mild"]) == {"shoulder": "severe",
                                                                  "elbow": "very mild"}
    with pytest.raises(ParameterError, match="knee"):
        parse_severity_options(["knee=severe"])
    with pytest.raises(ParameterError, match="level"):
        parse_severity_options(["elbow=terrible"])
    base = unimpaired()
    sev = synthesize({"elbow": "severe"}, base)
    mod = synthesize({"elbow": "moderate"}, base)
    ef = 2
    assert sev.km_n_per_m[ef] > mod.km_n_per_m[ef] > base.km_n_per_m[ef]
    assert sev.km_n_per_m[0] == base.km_n_per_m[0]  # the shoulder untouched


# --- CLI ------------------------------------------------------------------------------------
def test_cli_probe_csv_and_json(tmp_path: Path) -> None:
    out = tmp_path / "p.csv"
    r = CliRunner().invoke(haptic, ["probe", "--motion", "fastpull", "--severity",
                                    "shoulder=severe", "--out", str(out), "--json"])
    assert r.exit_code == 0, r.output
    s = json.loads(r.stdout)
    assert s["peak_force_n"] > 5.0 and s["faults"] == []
    assert len(s["profile"]) == 100
    rows = [ln for ln in out.read_text().splitlines() if not ln.startswith("#")]
    assert rows[0] == "t_s,x_m,y_m,fx_n,fy_n,static_fx_n,static_fy_n"
    assert len(rows) == 1001


def test_cli_replay_and_export(probe_result, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    ref = Hdf5TraceSink(tmp_path).write_trace(probe_result.trace, "t")
    csv_path = tmp_path / "t.csv"
    r = CliRunner().invoke(haptic, ["replay", ref, "--rerun", "--csv", str(csv_path), "--json"])
    assert r.exit_code == 0, r.output
    s = json.loads(r.stdout)
    assert s["ticks"] == len(probe_result.trace)
    assert s["rerun"]["max_deviation_n"] < 1e-4
    assert csv_path.exists()


def test_cli_errors_are_clean() -> None:
    r = CliRunner().invoke(haptic, ["probe", "--severity", "knee=severe"])
    assert r.exit_code != 0 and isinstance(r.exception, ParameterError)
    r = CliRunner().invoke(haptic, ["switch", "C"])
    assert r.exit_code == 2
    r = CliRunner().invoke(haptic, ["status", "--socket", "/nonexistent/x.sock"])
    assert isinstance(r.exception, HapticError) and "no renderer" in str(r.exception)


def test_fault_codes_match_the_protocol_document() -> None:
    import re

    from fieldbank.haptic.protocol import FaultCode

    doc = (Path(__file__).parent.parent / "docs" / "robot-protocol.md").read_text()
    para = " ".join(doc[doc.index("Fault codes"):].split("\n\n")[0].split())
    listed = {int(n): name for n, name in re.findall(r"(\d+) ([a-zA-Z ]+?)[,.]", para)}
    assert sorted(listed) == [c.value for c in FaultCode]
    for code in FaultCode:  # the document's words for each code start like the enum's name
        assert listed[code.value].split()[0][:3].lower() in code.name.lower() or \
            code.name.lower()[:3] in listed[code.value].lower(), (code, listed[code.value])


def test_cli_talks_to_a_running_renderer(served) -> None:  # type: ignore[no-untyped-def]
    rd, sock = served
    run = CliRunner()
    s = ["--socket", str(sock)]
    r = run.invoke(haptic, ["status", *s, "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["mode"] == "ARMED"
    r = run.invoke(haptic, ["switch", "after", *s])
    assert r.exit_code == 0 and "switching to after; renderer armed, felt now: " in r.output
    r = run.invoke(haptic, ["abx", "start", "--trials", "2", "--seed", "9", *s, "--json"])
    assert r.exit_code == 0 and json.loads(r.stdout)["n_trials"] == 2
    assert json.loads(run.invoke(haptic, ["status", *s, "--json"]).stdout)["blend"] == "hidden"
    assert run.invoke(haptic, ["abx", "present", "x", *s]).exit_code == 0
    assert run.invoke(haptic, ["abx", "answer", "A", *s]).exit_code == 0
    r = run.invoke(haptic, ["abx", "answer", "B", *s, "--json"])
    res = json.loads(r.stdout)
    assert res["done"] and res["result"]["answered"] == 2
    r = run.invoke(haptic, ["abx", "answer", "B", *s])
    assert isinstance(r.exception, HapticError)
    # a block stopped early keeps its answers and scores them; then none runs
    assert run.invoke(haptic, ["abx", "start", "--trials", "4", *s]).exit_code == 0
    assert run.invoke(haptic, ["abx", "answer", "A", *s]).exit_code == 0
    r = run.invoke(haptic, ["abx", "stop", *s])
    assert r.exit_code == 0 and "block stopped after 1 of 4 trials" in r.output
    assert json.loads(run.invoke(haptic, ["status", *s, "--json"]).stdout)["abx_trial"] is None
    r = run.invoke(haptic, ["abx", "stop", *s])
    assert isinstance(r.exception, HapticError) and "no A/B/X block running" in str(r.exception)
    assert [b["answered"] for b in rd.activities.results["abx"]] == [2, 1]
    assert run.invoke(haptic, ["disarm", *s]).exit_code == 0
    assert rd.safety.mode == Mode.DISARMED
    r = run.invoke(haptic, ["switch", "A", *s])
    assert "renderer disarmed: no force until it is armed" in r.output
    assert run.invoke(haptic, ["arm", *s]).exit_code == 0
    assert rd.safety.mode == Mode.ARMED


def test_loop_runs_with_gc_off_and_warns_without_realtime(monkeypatch, caplog) -> None:  # type: ignore[no-untyped-def]
    import gc

    seen: list[bool] = []

    class Probe(Renderer):
        def tick(self) -> None:
            seen.append(gc.isenabled())
            super().tick()

    def refuse(*a: object) -> None:
        raise PermissionError("not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    p = severe_shoulder()
    link = RobotLink.open(sim_url(p, "hold"))
    link.handshake(1000, 20)
    rd = Probe(link, p, p, RendererConfig())
    was = gc.isenabled()
    with caplog.at_level("WARNING", logger="fieldbank.haptic.renderer"):
        trace = rd.run(0.05)
    assert seen and not any(seen)            # the collector is off inside the loop
    assert gc.isenabled() == was             # and restored after
    assert trace.stats["realtime_scheduling"] is False
    assert any("SCHED_FIFO" in r.message for r in caplog.records)


def test_whatif_render_pushes_before_and_after(served, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from fieldbank.cli.main import cli

    rd, sock = served
    r = CliRunner().invoke(cli, ["whatif", "--severity", "elbow=severe", "--botox", "ef=200",
                                    "--render", "--socket", str(sock), "--json"])
    assert r.exit_code == 0, r.output
    rendered = json.loads(r.stdout)["rendered"]
    assert rendered["pushed"] is True and rendered["mode"] == "ARMED"
    before = synthesize({"elbow": "severe"})
    deadline = time.time() + 3
    while rd.pair.params[0] != before and time.time() < deadline:
        time.sleep(0.01)
    a, b = rd.pair.params
    assert a == before
    assert b != before and b.km_n_per_m == before.km_n_per_m  # botulinum acts on α, β only
    assert b.alpha_n[2] < before.alpha_n[2]
    told = rd.metadata["model_info"]  # built through haptic.modelinfo.ModelInfo
    assert told["A"]["plan"] is None and told["B"]["label"].startswith("what-if result on ")
    assert told["B"]["plan"] and "botulinum" in told["B"]["plan"].lower()
    # no renderer: a clean error, not a traceback
    r = CliRunner().invoke(cli, ["whatif", "--severity", "elbow=severe", "--botox", "ef=200",
                                    "--render", "--socket", str(tmp_path / "none.sock")])
    assert r.exit_code == 1 and "no renderer on" in r.output


def test_whatif_render_stores_only_with_save_and_only_once_the_renderer_accepted(
        served, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from fieldbank.cli.main import cli
    from fieldbank.storage import Database

    url = f"sqlite:///{tmp_path / 'fb.sqlite3'}"
    with Database.open(url) as db:
        db.add_patient("P-1", 70.0, 1.7, "right")
        db.add_model(synthesize({"elbow": "severe"}), "synthetic", "elbow severe", "P-1")

    def stored() -> tuple[int, int]:
        with Database.open(url) as db:
            return len(db.list_plans()), len(db.list_models())

    base = ["whatif", "P-1", "--botox", "ef=200U", "--db", url, "--render"]
    # no renderer: the command fails and stores nothing, with --save too
    for extra in ([], ["--save"]):
        r = CliRunner().invoke(cli, [*base, *extra, "--socket", str(tmp_path / "none.sock")])
        assert r.exit_code == 1 and "no renderer on" in r.stderr
        assert stored() == (0, 1)
    _rd, sock = served
    r = CliRunner().invoke(cli, [*base, "--socket", str(sock)])
    assert r.exit_code == 0, r.output
    assert "stored: nothing (--save stores the plan and its after model)" in r.stderr
    assert stored() == (0, 1)
    r = CliRunner().invoke(cli, [*base, "--save", "--socket", str(sock)])
    assert r.exit_code == 0, r.output
    assert "stored: after model 2 (parent 1), plan 1" in r.stderr
    assert stored() == (1, 2)


#: Modules a live command must not load (they take a large part of a second to import).
HEAVY = ("numpy", "sqlalchemy", "matplotlib", "h5py")
#: Runs ``python -m fieldbank.cli ARGS`` and, at exit, reports the heavy modules it loaded.
_LOADED_AT_EXIT = """
import atexit, json, runpy, sys
heavy = set(json.loads(sys.argv[2]))
atexit.register(lambda: print("LOADED " + json.dumps(sorted(
    m for m in sys.modules if m.split(".")[0] in heavy)), file=sys.stderr))
sys.argv = ["fieldbank", *json.loads(sys.argv[1])]
runpy.run_module("fieldbank.cli", run_name="__main__")
"""


@pytest.mark.parametrize("argv", [
    ["switch", "B"], ["status", "--json"], ["status"], ["arm"],
    ["abx", "start", "--trials", "2"], ["train", "start", "--short"], ["train", "next", "--help"],
    ["switch", "--help"], ["push", "--help"], ["train", "--help"], ["--help"],
])
def test_live_commands_load_nothing_heavy(served, argv: list[str]) -> None:  # type: ignore[no-untyped-def]
    _rd, sock = served
    args = ["haptic", *argv] + ([] if "--help" in argv else ["--socket", str(sock)])
    r = subprocess.run([sys.executable, "-c", _LOADED_AT_EXIT, json.dumps(args),
                        json.dumps(HEAVY)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stderr.rsplit("LOADED ", 1)[1]) == []


def test_train_start_draws_designed_probes_and_refuses_a_bad_file(served,  # type: ignore[no-untyped-def]
                                                                  tmp_path: Path) -> None:
    """``train start --probes FILE`` reads the file 'fieldbank probe design --out' writes,
    loads nothing heavy doing so, and the trials draw the designed probe (relative to the
    shoulder) after the seed's; a bad file is refused, naming the file and the field, before
    anything starts."""
    _rd, sock = served
    probe = ProbePath("designed", "a short stroke toward the body", (0.0, 0.3, 0.6),
                      ((0.12, 0.65), (0.12, 0.6), (0.12, 0.55)), (0.02, 0.1))
    good = tmp_path / "probes.json"
    good.write_text(json.dumps(probes_document([probe])), encoding="utf-8")
    args = ["haptic", "train", "start", "--short", "--probes", str(good), "--socket", str(sock),
            "--json"]
    r = subprocess.run([sys.executable, "-c", _LOADED_AT_EXIT, json.dumps(args),
                        json.dumps(HEAVY)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stderr.rsplit("LOADED ", 1)[1]) == []
    assert json.loads(r.stdout)["instruction"] == "instructed"
    run = CliRunner()
    st = json.loads(run.invoke(haptic, ["train", "next", "--socket", str(sock), "--json"])
                    .stdout)
    assert [p["name"] for p in st["paths"]] == ["pull", "semi-ellipse", "designed"]
    assert st["paths"][2]["points_m"][0] == pytest.approx([0.10, 0.55])
    assert run.invoke(haptic, ["train", "stop", "--socket", str(sock)]).exit_code == 0
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({**probes_document([probe]), "version": 7}), encoding="utf-8")
    r = run.invoke(cli, ["haptic", "train", "start", "--probes", str(bad), "--socket",
                         str(sock)])
    assert r.exit_code == 1
    assert f"{bad}: version: 7 is newer than this fieldbank reads (1)" in r.output
    st = json.loads(run.invoke(haptic, ["status", "--socket", str(sock), "--json"]).stdout)
    assert st["training"]["done"] and st["training"]["abandoned"]  # the stopped one, still


def test_registered_help_lines_are_the_commands_own() -> None:
    from fieldbank.cli.haptic import COMMANDS
    from fieldbank.cli.haptic_train import HEAVY

    for name, lazy in {**COMMANDS, **HEAVY}.items():
        cmd = lazy.load()
        assert cmd.name == name
        assert lazy.help == cmd.get_short_help_str(limit=10_000), name
