"""What a site accepts of its peer (plausibility), how an end of the link ramps out (a peer's
implausible data, its silence, its end), when it engages, and the session's account in words;
in one process (two processes over UDP: tests/test_remote_attack.py, test_remote_realtime.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic import protocol as P
from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.motions import pull
from fieldbank.haptic.port import HandleState, RobotPort, SensingPort
from fieldbank.haptic.remote.account import account
from fieldbank.haptic.remote.config import LinkConfig, SiteConfig
from fieldbank.haptic.remote.plausible import Plausibility, PlausibilityCheck
from fieldbank.haptic.remote.simulate import Pair, clinician_robot
from fieldbank.haptic.remote.wire import FLAG_ARMED, State
from fieldbank.haptic.robots import with_force_sensor
from fieldbank.haptic.safety import SafetyConfig
from tests.haptic_util import rest_hand

DT = 1e-3


def _limits(force_slew: float | None = 10_000.0) -> Plausibility:
    return Plausibility.of(SafetyConfig(force_limit_n=40.0, speed_limit_m_per_s=2.5,
                                        workspace_m=(-0.5, 0.6, 0.05, 0.8), passivity=False),
                           (0.0, 0.0), DT, force_slew_n_per_s=force_slew,
                           step_margin_m=0.001, watchdog_s=0.1, peer="the patient's site")


def _st(tick: int, x: float = 0.1, y: float = 0.4, fx: float = 1.0, vx: float = 0.0) -> State:
    return State(tick, x, y, vx, 0.0, fx, 0.0, 0.0, 0.0, 0.0)


# --- plausibility -------------------------------------------------------------------------------
def test_a_force_beyond_this_robot_s_clamp_or_stepping_faster_than_the_slew_is_refused() -> None:
    c = PlausibilityCheck(_limits())
    assert c.check(_st(1, fx=5.0), FLAG_ARMED) == ""
    assert "1e+06 N, beyond this robot's 40 N limit" in c.check(_st(2, fx=1e6), FLAG_ARMED)
    assert "changed by 12 N in 1 tick" in c.check(_st(2, fx=17.0), FLAG_ARMED)
    assert c.check(_st(2, fx=14.9), FLAG_ARMED) == ""          # 9.9 N in one tick: within
    assert c.check(_st(5, fx=39.0), FLAG_ARMED) == ""          # 24.1 N over 3 ticks: within
    assert c.last is not None and c.last.fx == 39.0            # the reference: the last accepted


def test_a_site_that_does_not_display_the_peer_s_force_checks_only_its_size() -> None:
    c = PlausibilityCheck(_limits(force_slew=None))
    assert c.check(_st(1, fx=0.0), FLAG_ARMED) == ""
    assert c.check(_st(2, fx=30.0), FLAG_ARMED) == ""           # the passivity controller steps it
    assert "limit" in c.check(_st(3, fx=41.0), FLAG_ARMED)


def test_positions_outside_the_workspace_or_jumping_faster_than_the_speed_limit_are_refused(
        ) -> None:
    c = PlausibilityCheck(_limits())
    assert c.check(_st(1, x=0.1), FLAG_ARMED) == ""
    assert "outside this robot's workspace" in c.check(_st(2, x=5.0), FLAG_ARMED)
    assert "moved 4 mm in 1 tick" in c.check(_st(2, x=0.104), FLAG_ARMED)
    assert c.check(_st(2, x=0.1034), FLAG_ARMED) == ""          # 2.5 mm + 1 mm margin per tick
    assert "speed of 3 m/s" in c.check(_st(3, vx=3.0), FLAG_ARMED)
    assert "tick 2 after tick 2" in c.check(_st(2), FLAG_ARMED)
    # across a disengagement the clutch may seat the clinician's position anew
    assert c.check(_st(10, x=0.3), 0) == ""
    assert c.check(_st(11, x=0.1), FLAG_ARMED) == ""
    # a silence longer than the watchdog does not widen what one datagram may move
    assert "moved" in c.check(_st(100_000, x=0.5), FLAG_ARMED)


# --- the ends of the link, in one process -------------------------------------------------------
@pytest.fixture(scope="module")
def elbow() -> tuple:
    p = synthesize({"elbow": "severe"})
    return p, rest_hand(p)


def _held_pair(p: object, hand: tuple[float, float], cfg: SiteConfig) -> Pair:
    """Both sites engaged, the clinician holding the severe elbow stretched 5 cm."""
    clink = clinician_robot(hand, cfg.rate_hz)
    pair = Pair(p, cfg, clink)  # type: ignore[arg-type]
    for _ in range(600):
        pair.tick()
    clink.port.device.perform(pull(hand[0], hand[1], 0.05, 1.0, (0.0, 1.0)))
    for _ in range(1500):
        pair.tick()
    return pair


def test_an_absurd_force_from_a_keyed_peer_is_a_fault_that_ramps_the_felt_force_out(
        elbow: tuple) -> None:
    """The patient's side, holding the key, sends fx = 1e6 N: the clinician's port refuses it,
    holds the link's fault and ramps the force from its last plausible value to zero (raised
    cosine over ramp_s), never toward the absurd one; the fault says what arrived."""
    p, hand = elbow
    pair = _held_pair(p, hand, SiteConfig(lockstep=True))
    held = math.hypot(pair.renderer.fx, pair.renderer.fy)
    assert held > 2.0
    pe = pair.patient.port.endpoint
    real = pe.send_state

    def absurd(st: State, now_s: float, flags: int = 0) -> None:
        real(State(st.tick, st.x, st.y, st.vx, st.vy, 1e6, st.fy, st.e_in, st.e_out,
                   st.e_sent), now_s, flags)

    pe.send_state = absurd  # type: ignore[method-assign]
    forces = []
    for _ in range(400):
        pair.tick()
        forces.append(math.hypot(pair.renderer.fx, pair.renderer.fy))
    run = pair.finish()
    f = np.array(forces)
    assert f.max() <= held * 1.05                       # never stepped up
    assert f[-150:].max() == 0.0                       # zero, and it stays zero
    assert np.max(np.abs(np.diff(f))) < 0.02 * held     # a ramp, not a step (π/2 · F / 200)
    faults = [e for e in run.clinician_summary["events"] if e["event"] == "fault"]
    assert faults[0]["name"] == "PEER" and "1e+06 N" in faults[0]["text"]
    assert run.clinician_summary["link_fault"].startswith("the patient's site sent a force")
    # the patient's side sees the clinician's fault flag and stops following too
    assert "peer_fault" in [e["event"] for e in run.patient_summary["events"]]


def test_a_silent_peer_in_lockstep_ends_the_session_with_a_ramp_not_a_step(elbow: tuple) -> None:
    """The patient's site stops answering while the clinician holds a stretched arm: after the
    lockstep wait the clinician's port ramps the felt force to zero (raised cosine over
    ramp_s), and only then ends the session (on_end)."""
    p, hand = elbow
    cfg = SiteConfig(lockstep=True, link=LinkConfig(lockstep_wait_s=0.05))
    pair = _held_pair(p, hand, cfg)
    held = math.hypot(pair.renderer.fx, pair.renderer.fy)
    ended = []
    pair.port.on_end = lambda: ended.append(pair.port.tick_n)
    forces = []
    for _ in range(400):
        pair.renderer.tick()                            # the patient's site no longer ticks
        forces.append(math.hypot(pair.renderer.fx, pair.renderer.fy))
    run = pair.finish()
    f = np.array(forces)
    assert f[0] > 0.9 * held and f[-100:].max() == 0.0
    assert np.max(np.abs(np.diff(f))) < 0.02 * held     # the old end: 5.9 → 3.8 N, then nothing
    ramp_ticks = round(cfg.link.ramp_s * cfg.rate_hz)
    assert len(ended) == 1 and np.count_nonzero(f > 0) <= ramp_ticks + 2
    ev = [e for e in run.clinician_summary["events"] if e["event"] == "peer_ended"]
    assert "silent" in ev[0]["reason"]


def test_the_clinician_s_stop_ramps_both_forces_out_before_the_session_ends(elbow: tuple) -> None:
    """The clinician stops the session (``fieldbank haptic stop``: the renderer's stop command)
    while holding the severe elbow stretched: the felt force and the patient's servo force
    ramp to zero together (raised cosine over ramp_s: no step at either handle), the patient's
    site hears why, and only then does the clinician's loop end."""
    p, hand = elbow
    cfg = SiteConfig(lockstep=True)
    pair = _held_pair(p, hand, cfg)
    before = []                                         # the servo's own tick-to-tick noise
    for _ in range(200):
        pair.tick()
        before.append(math.hypot(pair.patient.port.fx, pair.patient.port.fy))
    noise = float(np.max(np.abs(np.diff(before))))
    held = math.hypot(pair.renderer.fx, pair.renderer.fy)
    servo = before[-1]
    assert held > 2.0 and servo > 2.0 and noise < 0.2 * servo
    ended: list[int] = []
    stop_now = pair.port.on_end
    assert stop_now is not None

    def end() -> None:
        ended.append(pair.port.tick_n)
        stop_now()

    pair.port.on_end = end
    req = pair.renderer.submit("stop")                  # applied at the next tick
    felt, servos = [], []
    for _ in range(400):
        if ended:
            break
        pair.tick()
        felt.append(math.hypot(pair.renderer.fx, pair.renderer.fy))
        servos.append(math.hypot(pair.patient.port.fx, pair.patient.port.fy))
    assert req.wait(1.0) == {"stopping": True}
    run = pair.finish()
    f, s = np.array(felt), np.array(servos)
    ramp_ticks = round(cfg.link.ramp_s * cfg.rate_hz)
    assert len(ended) == 1 and ramp_ticks <= len(f) <= ramp_ticks + 3
    assert f[-1] == 0.0 and np.max(np.abs(np.diff(f))) < 0.03 * held      # a ramp, not a step
    assert np.max(np.abs(np.diff(s))) <= 1.2 * noise and s[-1] < 0.05 * servo
    closing = [e for e in run.clinician_summary["events"] if e["event"] == "closing"]
    assert closing and closing[0]["reason"] == "stopped by the clinician"
    heard = [e for e in run.patient_summary["events"] if e["event"] == "peer_ended"]
    assert heard and heard[0]["reason"] == "stopped by the clinician"


def test_a_site_engages_only_after_its_robot_has_been_ready_and_on_time_for_ready_s(
        elbow: tuple) -> None:
    p, hand = elbow
    cfg = SiteConfig(lockstep=True, link=LinkConfig(ready_s=0.5))
    pair = Pair(p, cfg, clinician_robot(hand, cfg.rate_hz))
    late = [0.0]
    pair.port.late_s = lambda: late[0]
    for k in range(1200):
        late[0] = 0.002 if k == 300 else 0.0            # one tick a whole period late at 0.3 s
        pair.tick()
    run = pair.finish()
    engaged = [e["t_s"] for e in run.clinician_summary["events"] if e["event"] == "engaged"]
    assert engaged and 0.8 <= engaged[0] <= 0.81        # 0.5 s on time after the late tick


# --- the patient's robot: a robot port with a force sensor -------------------------------------
class _Handle:
    """A scripted robot port: a state on every poll; ``sensor`` how it answers SENSOR_ON
    (``"reading"``: readings follow; ``"fault"``: a fault report)."""

    def __init__(self, sensor: str) -> None:
        self.state = HandleState(x=0.1, y=0.4)
        self.device = P.DeviceInfo(P.PROTOCOL_VERSION, "scripted", 1000, 40.0, 20)
        self.sensor = sensor
        self.asked = False

    def poll(self) -> int:
        st = self.state
        st.states += 1
        if self.asked and self.sensor == "reading":
            st.sensors += 1
        return 1

    def wait_state(self, timeout_s: float, spin_s: float = 0.0) -> int:
        return self.poll()

    def heartbeat(self) -> None:
        pass

    def send_force(self, fx_n: float, fy_n: float) -> None:
        pass

    def arm(self) -> None:
        pass

    def disarm(self) -> None:
        pass

    def counters(self) -> dict[str, int]:
        return {}

    def close(self) -> None:
        pass


class _Sensing(_Handle):
    def sensor_on(self) -> None:
        self.asked = True
        if self.sensor == "fault":
            self.state.device_faults += 1
            self.state.last_device_fault = 9


def test_the_patient_s_site_takes_only_a_robot_that_reports_the_hand_s_force() -> None:
    """A robot port without a force sensor, or whose robot refuses SENSOR_ON, is refused in
    words naming the robot; one whose readings arrive is the patient's robot."""
    bare = _Handle("reading")
    assert isinstance(bare, RobotPort) and not isinstance(bare, SensingPort)
    with pytest.raises(HapticError, match="desk://arm cannot report the force of the hand"):
        with_force_sensor(bare, "desk://arm", "the patient's site")
    with pytest.raises(HapticError, match="answered SENSOR_ON with fault 9"):
        with_force_sensor(_Sensing("fault"), "desk://arm", "the patient's site")
    good = _Sensing("reading")
    assert with_force_sensor(good, "desk://arm", "the patient's site") is good
    assert good.state.sensors > 0


# --- the account ----------------------------------------------------------------------------------
def test_the_account_names_each_span_of_zero_force_and_its_cause() -> None:
    t = np.arange(0, 15.0, 0.001)
    g = np.ones_like(t)
    g[t < 0.3] = 0.0
    g[(t >= 3.64) & (t < 4.66)] = 0.0                    # link lost at 3.44, ramped out by 3.64
    g[t >= 6.0] = 0.0                                    # a fault of this robot at 5.8
    events = [{"t_s": 3.44, "event": "link_lost"}, {"t_s": 4.6, "event": "link_up"},
              {"t_s": 5.8, "event": "fault", "name": "DEVICE"}]
    acc = account(t, g, events, ended="15 s passed", asked=True, peer_name="the patient's site")
    lines = acc.lines()
    assert lines[0] == ("link lost at t = 3.44 s: force ramped to zero by t = 3.64 s, zero for "
                        "1.02 s, back at t = 4.66 s")
    assert lines[1] == "fault DEVICE at t = 5.80 s: force zero for the remaining 9.2 s"
    assert not acc.complete and acc.engaged_at_s == pytest.approx(0.3)
    clean = account(t, np.where(t < 0.3, 0.0, 1.0), [], ended="15 s passed", asked=True,
                    peer_name="x")
    assert clean.complete and clean.lines() == ["ended at t = 15.00 s: 15 s passed"]
    never = account(t, np.zeros_like(t), [], ended="15 s passed", asked=True, peer_name="x")
    assert not never.complete and never.lines()[0] == "never engaged: no force was rendered"
    silent = account(t, np.where(t < 0.3, 0.0, 1.0), [], ended="the patient's site fell silent",
                     asked=False, peer_name="x")
    assert not silent.complete
