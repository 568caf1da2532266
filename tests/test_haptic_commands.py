"""The command table (parsing, errors, how the renderer answers) and the session use case."""

from __future__ import annotations

from pathlib import Path

import pytest

from fieldbank.errors import ParameterError
from fieldbank.haptic import commands as C
from fieldbank.haptic.commandbase import RendererCommand
from fieldbank.haptic.errors import CommandError, HapticError
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.probe import sim_url
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from tests.haptic_util import severe_shoulder, unimpaired


@pytest.mark.parametrize("req,expected", [
    ({"cmd": "switch", "to": "B"}, C.Switch("B")),
    ({"cmd": "switch", "to": "before"}, C.Switch("before")),
    ({"cmd": "arm"}, C.Arm()),
    ({"cmd": "disarm"}, C.Disarm()),
    ({"cmd": "stop"}, C.Stop()),
    ({"cmd": "status"}, C.Status()),
    ({"cmd": "abx", "action": "start", "n_trials": "4", "seed": 7, "hide_labels": 0},
     C.AbxStart(n_trials=4, seed=7)),
    ({"cmd": "abx", "action": "start"}, C.AbxStart()),
    ({"cmd": "abx", "action": "present", "label": "X"}, C.AbxPresent("X")),
    ({"cmd": "abx", "action": "answer", "answer": "a"}, C.AbxAnswer("a")),
])
def test_requests_parse_into_the_command_table(req: dict[str, object],
                                               expected: RendererCommand) -> None:
    assert C.parse_request(req) == expected


def test_push_request_parses_models_and_ids() -> None:
    before, after = severe_shoulder(), unimpaired()
    cmd = C.parse_request({"cmd": "push", "before": before.to_dict(), "after": after.to_dict(),
                           "model_ids": {"A": 3, "B": None}})
    assert cmd == C.Push(before, after, {"A": 3, "B": None})
    with pytest.raises(ParameterError, match="push: before"):
        C.parse_request({"cmd": "push", "before": {"km_n_per_m": [1.0]}, "after": after.to_dict()})
    with pytest.raises(CommandError, match="model_ids"):
        C.parse_request({"cmd": "push", "before": before.to_dict(), "after": after.to_dict(),
                         "model_ids": {"C": 1}})


@pytest.mark.parametrize("req,message", [
    ({"to": "A"}, '"cmd" string'),
    ({"cmd": "explode"}, "unknown control command 'explode'"),
    ({"cmd": "abx", "action": "skip"}, "abx action must be start, present, answer or stop"),
    ({"cmd": "switch", "to": "C"}, "switch to 'before'/'A' or 'after'/'B'; got 'C'"),
    ({"cmd": "switch", "to": ["A"]}, "switch to"),
])
def test_malformed_requests_say_what_is_wrong(req: dict[str, object], message: str) -> None:
    with pytest.raises(CommandError, match=message):
        C.parse_request(req)


def test_every_command_is_in_the_table_once() -> None:
    assert set(C.COMMANDS) == {"switch", "push", "arm", "disarm", "stop", "status", "info",
                               "abx_start", "abx_present", "abx_answer", "abx_stop", "train_start",
                               "train_next", "train_answer", "train_stop"}
    assert all(cls.name == name for name, cls in C.COMMANDS.items())
    assert (set(C.WIRE.values()) | set(C.ABX_ACTIONS.values()) | set(C.TRAIN_ACTIONS.values())
            == set(C.COMMANDS.values()))


def test_the_renderer_answers_every_submission() -> None:
    p = severe_shoulder()
    link = RobotLink.open(sim_url(p, "hold"))
    link.handshake(1000, 20)
    rd = Renderer(link, p, p, RendererConfig(state_wait_s=0.05, realtime_priority=False))
    try:
        # not running: what needs the loop is refused, the rest is applied at once
        with pytest.raises(CommandError, match="not running"):
            rd.submit(C.Arm()).wait()
        sw = rd.submit("switch", target="B").wait()
        assert sw["blend_target"] == 1.0 and sw["mode"] == "DISARMED"
        assert rd.submit(C.Status()).wait()["running"] is False
        # a command that cannot be built is answered with its error, never raised by submit
        with pytest.raises(CommandError, match="switch to"):
            rd.submit("switch", target="C").wait()
        with pytest.raises(CommandError, match="unknown renderer command 'explode'"):
            rd.submit("explode").wait()
        req = rd.submit(C.Push(unimpaired(), p, {"A": 1, "B": 2}))
        assert req.wait()["pushed"] is True
        assert rd.pair.params == (unimpaired(), p) and rd.metadata["model_ids"] == {"A": 1, "B": 2}
        with pytest.raises(HapticError, match="did not answer"):
            C.Request("status").wait(timeout_s=0.01)
    finally:
        link.close()


# --- the session use case -------------------------------------------------------------------
def test_session_with_a_schedule_a_trace_file_and_a_database_opened_after(tmp_path: Path) -> None:
    from fieldbank.haptic.session import ScheduledSwitch, serve
    from fieldbank.storage import Database

    url = f"sqlite:///{tmp_path / 'fb.sqlite'}"

    def open_db() -> Database:
        return Database.open(url, upgrade="always", store_root=tmp_path / "arrays")

    lines: list[str] = []
    res = serve("sim://?mode=realtime&motion=hold", severe_shoulder(), unimpaired(),
                duration_s=1.2, config=RendererConfig(realtime_priority=False), control=False,
                switches=[ScheduledSwitch(0.6, "A"), ScheduledSwitch(0.3, "after")],
                trace_dir=tmp_path / "traces", trace_name="s1", db=open_db, say=lines.append)
    assert len(res.trace) == 1200
    assert [e["to"] for e in res.trace.events if e["event"] == "switch"] == [1.0, 0.0]
    # the robot as given: the simulated operator's start and motion are not the user's URL
    assert res.robot == "sim://?mode=realtime&motion=hold"
    assert res.trace.metadata["robot"] == res.robot
    assert res.trace_file == str(tmp_path / "traces" / "s1.h5") and len(res.sha256 or "") == 64
    s = res.summary()
    assert s["trace"] == res.trace_file and s["database"] == res.database
    assert res.database is not None
    with open_db() as db:
        sess = db.get_haptic_session(int(res.database.split(":")[1]))
        assert sess.stats["name"] == "s1" and sess.robot_url == res.robot
    assert lines[0].startswith("robot 'fieldbank-sim': protocol 1")
    assert lines[1] == "rendering at 1000 Hz"
    assert lines[2:4] == ["  switch to after (B), 0.5 s crossfade",
                          "  switch to before (A), 0.5 s crossfade"]
    assert lines[4] == f"trace file: {res.trace_file}"


def test_session_into_an_open_database_with_the_control_channel(tmp_path: Path) -> None:
    from fieldbank.haptic.session import serve
    from fieldbank.storage import Database

    sock = tmp_path / "run" / "h.sock"
    with Database.open(f"sqlite:///{tmp_path / 'fb.sqlite'}", upgrade="always",
                       store_root=tmp_path / "arrays") as db:
        m = db.add_model(severe_shoulder(), "synthetic", "severe shoulder")
        res = serve("sim://?mode=realtime&motion=hold", severe_shoulder(), severe_shoulder(),
                    model_ids=(m.id, m.id), duration_s=0.3, socket_path=sock,
                    config=RendererConfig(realtime_priority=False), db=db)
        assert res.trace_file is None and "trace" not in res.summary()
        assert res.database is not None
        sess = db.get_haptic_session(int(res.database.split(":")[1]))
        assert sess.model_a_id == m.id and sess.model_b_id == m.id
    assert res.trace.metadata["model_ids"] == {"A": m.id, "B": m.id}
    assert not sock.exists()


def test_a_bad_schedule_fails_before_the_robot_is_opened() -> None:
    from fieldbank.haptic.session import ScheduledSwitch

    with pytest.raises(ParameterError, match="'at_s' switch time"):
        ScheduledSwitch(-0.1, "A")
    with pytest.raises(CommandError, match="switch to"):
        ScheduledSwitch(0.5, "C")
