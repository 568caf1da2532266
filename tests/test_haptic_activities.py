"""Activities on the loop (haptic/activities/): one at a time, addressed by the commands, fed by
the loop's tick hook, their results kept by kind; and the renderer as the activities and the
commands see it, nothing more."""

from __future__ import annotations

import pytest

from fieldbank.haptic.activities.abx import AbxBlock
from fieldbank.haptic.activities.base import ActivityHost
from fieldbank.haptic.activities.training import Training
from fieldbank.haptic.clock import VirtualClock
from fieldbank.haptic.commandbase import CommandTarget
from fieldbank.haptic.errors import CommandError
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.probe import sim_url
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.training import TrainingProtocol
from tests.haptic_util import severe_shoulder, unimpaired

PROTOCOL = TrainingProtocol(familiarisation_rounds=0, assessment_repetitions=1,
                            groups=("elbow",), severities=("severe", "mild"))


@pytest.fixture()
def rd() -> Renderer:
    link = RobotLink.open(sim_url(severe_shoulder(), "circle"))
    link.handshake(1000, 20)
    r = Renderer(link, severe_shoulder(), unimpaired(), RendererConfig(state_wait_s=0.05),
                 clock=VirtualClock())
    r.start(expected_ticks=20_000)
    for _ in range(400):  # the arming ramp
        r.tick()
    return r


def _do(rd: Renderer, name: str, ticks: int = 1, **args: object) -> dict[str, object]:
    req = rd.submit(name, **args)
    for _ in range(ticks):
        rd.tick()
    return req.wait()


def test_one_activity_at_a_time_and_every_result_kept(rd: Renderer) -> None:
    acts = rd.activities
    _do(rd, "abx_start", n_trials=4, seed=1)
    first = acts.running
    assert isinstance(first, AbxBlock) and acts.blinded
    _do(rd, "abx_answer", 200, answer="A")
    with pytest.raises(CommandError, match="a training protocol cannot start while an A/B/X "
                                           "block runs"):
        _do(rd, "train_start", protocol=PROTOCOL)
    # a new block closes the running one; its answer is kept, not lost
    _do(rd, "abx_start", n_trials=2, seed=2)
    assert acts.running is not first and [r["answered"] for r in acts.results["abx"]] == [1]
    for ans in ("A", "B"):
        _do(rd, "abx_answer", 200, answer=ans)
    assert acts.running is None and not acts.blinded
    assert [r["answered"] for r in acts.results["abx"]] == [1, 2]
    # the training protocol runs next; a finished one stays addressed (its final state)
    _do(rd, "train_start", protocol=PROTOCOL)
    assert isinstance(acts.running, Training) and not acts.blinded  # no trial presented yet
    _do(rd, "train_next", 1200)
    assert acts.blinded  # an assessment trial
    with pytest.raises(CommandError, match="a training protocol is already running"):
        _do(rd, "train_start", protocol=PROTOCOL)
    _do(rd, "train_stop")
    assert acts.running is None and acts.results["training"][0]["abandoned"] is True
    assert _do(rd, "train_next")["done"] is True
    trace = rd.finish()
    assert [r["answered"] for r in trace.metadata["abx"]] == [1, 2]
    assert len(trace.metadata["training"]) == 1


def test_the_tick_hook_feeds_the_trial_window(rd: Renderer) -> None:
    """The window of an answer counts the ticks the loop was not armed and the largest force,
    from the activity's tick hook: a trial disarmed for a while is flagged 'no force'."""
    _do(rd, "abx_start", n_trials=2, seed=5)
    act = rd.activities.running
    assert isinstance(act, AbxBlock)
    _do(rd, "abx_present", 300, label="X")
    assert act.window.ticks == 301 and act.window.unarmed_ticks == 0
    assert act.window.peak_force_n2 > 0.05 ** 2
    _do(rd, "disarm", 250)
    assert act.window.unarmed_ticks == 250
    _do(rd, "arm", 400)
    rec = _do(rd, "abx_answer", answer="A")
    assert rec["flagged"] is True and rec["flags"] == ["no force for 0.25 s (robot not armed)"]
    # the next trial's window starts clean
    assert act.window.ticks == 1 and act.window.unarmed_ticks == 0


def test_the_hosts_are_small() -> None:
    """What an activity may touch of the loop, and what a command may: the seams' surfaces."""
    def members(proto: type) -> set[str]:
        return {n for n in (*proto.__annotations__, *vars(proto))
                if not n.startswith("_") and n not in ("Protocol",)}

    host = members(ActivityHost)
    assert host == {"t_s", "dt_s", "safety", "pair", "queue_models", "log_event"}
    assert members(CommandTarget) == {"running", "activities", "felt", "arm", "disarm",
                                      "request_stop", "status", "info"}
