"""Measuring an arm on the robot: the protocol driven by a position servo, every sample kept.

:func:`run_protocol` opens the robot link, shakes hands, asks for the force sensor
(SENSOR_ON; a robot without one is refused), arms, and follows the plan of
:mod:`fieldbank.measure.protocol` — first a slow approach from wherever the handle is to the
first posture — with a position servo in the host loop::

    F = K_s (r − x) + B_s (ṙ − v) − F̃_hand     (r, ṙ the plan's reference, x, v the handle)

(default K_s = 5,000 N/m, B_s = 150 N·s/m: an order stiffer than a hypertonic arm at rest,
damped enough for ≈ 2–3 kg of handle and arm). F̃_hand is the force sensor's reading low-passed
at 30 Hz (``feedforward_cutoff_hz``; the grip's own resonance, hundreds of hertz, stays out of
the loop): cancelling it keeps the arm from dragging the handle off the reference's velocity
during a pass — measured on the virtual patient, a severe reflex slowed a 1 m/s pass by 5 % and
biased the moving stiffness by 16 % without it, ≤ 5 % with it. What offset remains costs nothing:
the estimator reads the measured positions and velocities.

Safety is the rendering's, through the same monitor (:mod:`haptic.monitor`,
:mod:`haptic.safety`): every command passes the force-rate limit and the saturation
(``force_limit_n``, 40 N), every STATE is checked (workspace, speed, NaN, CRC, sequence gaps,
the device's fault and watchdog flags, timeout) and any fault zeroes the force, disarms and
latches. The passivity controller is off here: it guards a *virtual environment* against energy
the sampled loop invents, whereas the servo moves the arm by design (the energy it puts in is
bounded by the force and speed limits). A fault ends the measurement: the trial it fell in and
every later one are marked with the fault, and :class:`MeasurementAborted` carries the
recording so far so nothing measured is lost.

The samples (time, handle position and velocity, force sensor, commanded force) are kept at the
loop rate, in the shoulder frame (robot frame − ``shoulder_offset_m``), with the force as the arm
exerts it on the handle (the sensor's reading).

Before the robot moves, :func:`measure_session` says per muscle group whether the planned
postures and passes reach its slack length and its reflex threshold
(:mod:`fieldbank.measure.visibility`), and refuses - with the change that would - when a group
the operator must see would not be seen.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from datetime import UTC, date, datetime
from pathlib import Path

import numpy as np

from fieldbank.errors import ParameterError, StorageError
from fieldbank.files import write_new
from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.monitor import SafetyMonitor
from fieldbank.haptic.port import RobotPort
from fieldbank.haptic.protocol import FaultCode
from fieldbank.haptic.robots import open_robot, with_force_sensor
from fieldbank.haptic.safety import Mode, SafetyConfig
from fieldbank.home import data_home
from fieldbank.ingest import IngestReport, ingest_data
from fieldbank.measure.nwbraw import RecordingInfo, write_recording
from fieldbank.measure.protocol import ProtocolConfig, ProtocolPlan, Segment, plan
from fieldbank.measure.recording import Recording, Trial
from fieldbank.measure.visibility import ProtocolSight, check_must_see, sight
from fieldbank.model import Arm
from fieldbank.redact import mask_url
from fieldbank.sanitize import file_component
from fieldbank.storage import Database
from fieldbank.validation import Interval, check_fields, check_tuple

#: Allowed range of every numeric setting of :class:`MeasureConfig`.
MEASURE_BOUNDS: dict[str, Interval] = {
    "rate_hz": Interval(250, 4000, "Hz"),
    "servo_k_n_per_m": Interval(100.0, 20000.0, "N/m"),
    "servo_b_n_s_per_m": Interval(0.0, 2000.0, "N·s/m"),
    "approach_speed_m_per_s": Interval(0.01, 0.5, "m/s"),
    "state_wait_s": Interval(0.0, 1.0, "s"),
    "force_feedforward": Interval(0.0, 1.0, ""),
    "feedforward_cutoff_hz": Interval(1.0, 200.0, "Hz"),
}


@dataclass(frozen=True)
class MeasureConfig:
    """Loop, servo and safety settings of a measurement (ranges in :data:`MEASURE_BOUNDS`)."""

    rate_hz: int = 1000
    servo_k_n_per_m: float = 5000.0
    servo_b_n_s_per_m: float = 150.0
    approach_speed_m_per_s: float = 0.1
    force_feedforward: float = 1.0
    feedforward_cutoff_hz: float = 30.0
    shoulder_offset_m: tuple[float, float] = (0.0, 0.0)
    state_wait_s: float = 0.005
    safety: SafetyConfig = field(default_factory=lambda: SafetyConfig(passivity=False))

    def __post_init__(self) -> None:
        check_fields(self, MEASURE_BOUNDS, what="measure setting")
        check_tuple("shoulder_offset_m", self.shoulder_offset_m, 2, Interval(None, None, "m"),
                    what="measure setting")


class MeasurementAborted(HapticError):
    """A safety fault ended the measurement; ``recording`` holds every sample taken."""

    def __init__(self, message: str, recording: Recording | None,
                 commanded: np.ndarray | None) -> None:
        super().__init__(message)
        self.recording = recording
        self.commanded = commanded


def _approach(start: tuple[float, float], to: tuple[float, float], speed: float) -> Segment:
    d = math.hypot(to[0] - start[0], to[1] - start[1])
    return Segment("move", 0.0, max(0.5, 1.875 * d / speed), start, to)


#: Robot time done, s, and the whole, s (the approach included): called twice a robot second.
Progress = Callable[[float, float], None]


def run_protocol(url: str, plan: ProtocolPlan, config: MeasureConfig | None = None,
                 clock: object = time.perf_counter,
                 progress: Progress | None = None) -> tuple[Recording, np.ndarray]:
    """Drive the robot at ``url`` through ``plan``; the recording and the commanded forces.
    ``progress`` hears how much robot time is done, twice a robot second.

    The robot is opened by :func:`fieldbank.haptic.robots.open_robot` (a built-in scheme or a
    robot adapter's) and driven through its port alone; measuring needs a force sensor
    (:class:`fieldbank.haptic.port.SensingPort`).

    Raises :class:`MeasurementAborted` (with the samples so far) on a safety fault,
    :class:`HapticError` when the robot cannot be used (no handshake, no force sensor).
    """
    cfg = config or MeasureConfig()
    robot = open_robot(url, cfg.rate_hz, round(cfg.safety.state_timeout_ms) or 20)
    try:
        return _run(robot, url, plan, cfg, clock, progress)
    finally:
        try:
            robot.send_force(0.0, 0.0)
            robot.disarm()
        except (HapticError, OSError):  # LinkDown among them: the robot is gone already
            pass
        robot.close()


def _run(robot: RobotPort, url: str, plan: ProtocolPlan, cfg: MeasureConfig,
         clock: object, progress: Progress | None = None) -> tuple[Recording, np.ndarray]:
    dt = 1.0 / cfg.rate_hz
    robot.heartbeat()
    sensing = with_force_sensor(robot, url, "measuring", clock)  # type: ignore[arg-type]
    st = sensing.state
    ox, oy = cfg.shoulder_offset_m
    monitor = SafetyMonitor(sensing, cfg.safety, dt)
    monitor.arm(running=False)
    approach = _approach((st.x - ox, st.y - oy), plan.start_m, cfg.approach_speed_m_per_s)
    t_off = approach.duration_s
    total = t_off + plan.duration_s
    n_ticks = math.ceil(total / dt) + 2
    rows = np.empty((n_ticks, 9))
    k_s, b_s = cfg.servo_k_n_per_m, cfg.servo_b_n_s_per_m
    ff = cfg.force_feedforward
    lp = 1.0 - math.exp(-2.0 * math.pi * cfg.feedforward_cutoff_hz * dt)
    hfx, hfy = st.sensor_fx, st.sensor_fy
    seg_i = 0
    segs = plan.segments
    fault = ""
    n = 0
    realtime = not url.startswith("sim://") or "realtime" in url
    t_wall0 = clock()  # type: ignore[operator]
    every = max(1, cfg.rate_hz // 2)
    for k in range(n_ticks):
        t = k * dt
        if progress is not None and k % every == 0:
            progress(t, total)
        if t < t_off:
            rx, ry, rvx, rvy = approach.reference(t)
        else:
            tp = t - t_off
            seg_i = plan.segment_at(tp, seg_i)
            rx, ry, rvx, rvy = segs[seg_i].reference(tp)
        x, y = st.x - ox, st.y - oy
        vx, vy = st.vx, st.vy
        # the hand's force, low-passed, is cancelled so the arm cannot drag the handle off the
        # reference's velocity (the reflex makes the force steep in the velocity)
        hfx += lp * (st.sensor_fx - hfx)
        hfy += lp * (st.sensor_fy - hfy)
        fx = k_s * (rx - x) + b_s * (rvx - vx) - ff * hfx
        fy = k_s * (ry - y) + b_s * (rvy - vy) - ff * hfy
        # every check is the monitor's (haptic.monitor): a fault zeroes the force and latches
        fx, fy = monitor.output(fx, fy, vx, vy)
        monitor.send(fx, fy)
        monitor.check(monitor.read(cfg.state_wait_s, t))
        rows[n] = (t - t_off, st.x - ox, st.y - oy, st.vx, st.vy, st.sensor_fx,
                   st.sensor_fy, fx, fy)
        n += 1
        if monitor.mode != Mode.ARMED:
            first = monitor.safety.log_records[:1]
            fault = (f"{FaultCode(first[0].code).name}: {first[0].message}" if first
                     else "the safety layer disarmed the servo")
            break
        if realtime:
            wait = t_wall0 + (k + 1) * dt - clock()  # type: ignore[operator]
            if wait > 0:
                time.sleep(wait)
    data = rows[:n]
    keep = data[:, 0] >= 0.0
    data = data[keep]
    rec = _recording(data, plan, url, fault)
    if fault:
        raise MeasurementAborted(
            f"measurement stopped at {data[-1, 0] if len(data) else 0.0:.2f} s of "
            f"{plan.duration_s:.1f} s: {fault}", rec, data[:, 7:9] if rec else None)
    return rec, data[:, 7:9]  # type: ignore[return-value]


def _recording(data: np.ndarray, plan: ProtocolPlan, url: str, fault: str) -> Recording | None:
    if len(data) < 2:
        return None
    end = float(data[-1, 0])
    trials = []
    for pt in plan.trials:
        status = ""
        if pt.stop_s > end + 1e-9:
            status = f"not completed: {fault}" if fault else "not completed"
        stop = min(pt.stop_s, end) if status else pt.stop_s
        start = min(pt.start_s, stop)
        w0 = min(pt.window_s[0], stop)
        w1 = min(pt.window_s[1], stop)
        trials.append(Trial(pt.index, pt.role, pt.posture, start, stop, (w0, w1),
                            pt.velocity_m_per_s, pt.label, status))
    chans = {"x": "STATE x (m)", "y": "STATE y (m)", "vx": "STATE vx (m/s)",
             "vy": "STATE vy (m/s)", "fx": "SENSOR fx (N)", "fy": "SENSOR fy (N)"}
    t = data[:, 0]
    ok = np.concatenate([[True], np.diff(t) > 0])
    return Recording(t[ok], data[ok, 1:3], data[ok, 3:5], data[ok, 5:7], tuple(trials), chans,
                     source=f"fieldbank haptic measure on {mask_url(url)}")


def check_plan_fits(plan: ProtocolPlan, cfg: MeasureConfig) -> None:
    """Refuse a plan whose reference leaves the safety workspace (robot frame) or whose pass
    speed is over the speed limit, before the robot moves."""
    x0, x1, y0, y1 = cfg.safety.workspace_m
    ox, oy = cfg.shoulder_offset_m
    for s in plan.segments:
        for px, py in (s.start_m, s.end_m):
            rx, ry = px + ox, py + oy
            if not (x0 <= rx <= x1 and y0 <= ry <= y1):
                raise ParameterError(f"the protocol reaches ({rx:.3f}, {ry:.3f}) m (robot "
                                     f"frame), outside the workspace {cfg.safety.workspace_m}")
        if s.speed_m_per_s > 0.9 * cfg.safety.speed_limit_m_per_s:
            raise ParameterError(f"pass speed {s.speed_m_per_s:g} m/s is too close to the "
                                 f"speed limit {cfg.safety.speed_limit_m_per_s:g} m/s")


@dataclass(frozen=True)
class MeasureResult:
    """What a measurement did: robot time, the raw file, the ingest report, the estimate."""

    robot_time_s: float
    raw_file: str
    raw_sha256: str
    report: IngestReport
    trials: int
    trials_dropped: tuple[str, ...]
    notes: tuple[str, ...] = ()
    #: What the protocol could see per muscle group (:mod:`fieldbank.measure.visibility`).
    sight: ProtocolSight | None = None


def measure_session(db: Database, url: str, patient_code: str, session_label: str,
                    protocol: ProtocolConfig, config: MeasureConfig | None = None,
                    raw_out: str | Path | None = None, session_date: date | None = None,
                    force: bool = False, must_see: Sequence[str] = (),
                    report: Callable[[str], None] | None = None,
                    progress: Progress | None = None) -> MeasureResult:
    """Measure a patient on the robot and store the maps (raw recording kept).

    The raw recording is written as NWB (:mod:`fieldbank.measure.nwbraw`) to ``raw_out``
    (default: ``measurements/<patient>_<session>_<UTC time>.nwb`` in the data directory;
    never over an existing file unless ``force``) and ingested like any lab file, so the maps
    are stored with the same provenance and the raw file is kept unchanged in the database.
    When a fault stops the measurement, the raw file is still written (every sample taken)
    and :class:`MeasurementAborted` is raised; no map is stored.

    Before the robot moves, what the protocol sees of each muscle group goes to ``report``
    line by line; a group of ``must_see`` it would not see refuses the measurement
    (:class:`fieldbank.measure.visibility.ProtocolBlind`, with a suggestion). While the robot
    moves, ``progress`` hears the robot time done and the whole (:func:`run_protocol`).
    """
    cfg = config or MeasureConfig()
    if not session_label.strip():  # before the robot moves, not after
        raise ParameterError("A session label must not be empty.")
    patient = db.get_patient(patient_code)
    known = {s.label: s for s in db.list_sessions(patient_code)}
    was = known.get(session_label)
    if was is not None and None not in (session_date, was.session_date) \
            and was.session_date != session_date:
        raise StorageError(f"Session {session_label!r} of patient {patient_code!r} is dated "
                          f"{was.session_date}; got {session_date}. Give its date or "
                          "another session label.")
    arm = Arm.from_params(patient.arm_params())
    the_plan = plan(protocol, arm)
    check_plan_fits(the_plan, cfg)
    seen = sight(the_plan, arm)
    if report is not None:
        for line in seen.table():
            report(line)
    check_must_see(the_plan, arm, must_see, lambda p: _fits(p, cfg), seen)
    started = datetime.now(UTC)
    stamp = started.strftime("%Y%m%dT%H%M%SZ")
    out = Path(raw_out) if raw_out is not None else (
        data_home() / "measurements"
        / f"{file_component(patient_code)}_{file_component(session_label)}_{stamp}.nwb")
    info = RecordingInfo(patient_code, session_label, f"robot {mask_url(url)}",
                         start_time=started, protocol_json=json.dumps(asdict(the_plan.config)))
    if out.exists() and not force:  # before the robot moves, not after
        raise HapticError(f"{out}: exists; give another --raw file or --force")
    try:
        rec, commanded = run_protocol(url, the_plan, cfg, progress=progress)
    except MeasurementAborted as exc:
        if exc.recording is not None:
            _write_raw(out, write_recording(exc.recording, info, exc.commanded,
                                            the_plan.postures_m), force)
            raise MeasurementAborted(f"{exc}; the samples so far are in {out}; no map was "
                                     "stored", exc.recording, exc.commanded) from None
        raise
    data = write_recording(rec, info, commanded, the_plan.postures_m)
    _write_raw(out, data, force)
    ingested = ingest_data(db, [(str(out), data)], patient_code, session_label, session_date)
    dropped = tuple(t.label + ": " + t.status for t in rec.trials if t.status)
    return MeasureResult(the_plan.duration_s, str(out), hashlib.sha256(data).hexdigest(),
                         ingested, len(rec.trials), dropped, the_plan.notes, seen)


def _fits(p: ProtocolPlan, cfg: MeasureConfig) -> bool:
    try:
        check_plan_fits(p, cfg)
    except ParameterError:
        return False
    return True


def _write_raw(path: Path, data: bytes, force: bool) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        write_new(path, data, force)
    except FileExistsError:
        raise HapticError(f"{path}: exists; give another --raw file or --force") from None
