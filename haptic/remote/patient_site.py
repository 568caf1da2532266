"""The patient's site: the robot holding the patient's hand, following a distant clinician.

``fieldbank haptic remote patient --robot URL --key FILE --bind HOST:PORT`` runs
:func:`serve_patient`:

1. opens the robot, shakes hands at the loop's rate and asks for its force sensor (a robot
   without one cannot tell the clinician what the arm does: refused);
2. listens on UDP for the clinician's HELLO (authenticated with the session key; nothing else
   is answered), checks the rate and clock mode, answers WELCOME with what the clinician's
   station needs to draw the arm — its segment lengths, side and range of motion, never its
   muscles — and where the hand rests;
3. arms the robot and runs the loop: each tick reads the robot (every safety check of
   :mod:`haptic.remote.guard`), hands the patient's handle and the force the hand puts on it
   to the :class:`~haptic.remote.ports.PatientPort`, which answers the servo force, and sends
   that through the site's own limits (:mod:`haptic.safety`, the passivity controller of the
   handle port off: the link's is in the port);
4. ends on the clinician's BYE, after ``duration_s``, when the peer falls silent in lockstep, or
   on Ctrl-C; commands zero and disarms; writes its log (every tick: the patient's handle and
   force, the reference, the servo force, the energies at its port) as an HDF5 file.

A fault of the patient's robot latches (zero force, disarmed, its port stops following); the
clinician's station shows it. The link being lost ramps the servo force to zero; the robot
stays armed and follows again, ramping in, once the link has been back for ``resume_s``.
"""

from __future__ import annotations

import time
import urllib.parse
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fieldbank.errors import ParameterError
from fieldbank.files import write_new
from fieldbank.haptic.clock import Clock, RealClock, VirtualClock, realtime
from fieldbank.haptic.errors import HapticError, LinkDown
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.patient import resolve_patient
from fieldbank.haptic.protocol import FaultCode
from fieldbank.haptic.remote.channel import Endpoint, Impairment, UdpTransport
from fieldbank.haptic.remote.guard import RobotGuard
from fieldbank.haptic.remote.ports import LinkConfig, PatientPort
from fieldbank.haptic.remote.wire import Authenticator, Kind, Role, key_fingerprint
from fieldbank.haptic.safety import Mode, Safety, SafetyConfig
from fieldbank.haptic.simrobot import SimRobotConfig
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.redact import mask_url

#: HELLOs whose wall-clock time differs from this machine's by more than this are refused
#: (an old HELLO replayed to an idle site), s.
HELLO_MAX_SKEW_S = 120.0
#: Device watchdog asked of the patient's robot, ms.
WATCHDOG_MS = 20
Say = Callable[[str], None]


def _quiet(msg: str) -> None:
    del msg


@dataclass(frozen=True)
class SiteConfig:
    """Settings of either site's loop.

    Attributes
    ----------
    rate_hz : int, Hz
        The loop's rate (both sites must agree).
    lockstep : bool
        Virtual clocks advancing together (both sites simulated; faster than real time).
    link : LinkConfig
    impairment : Impairment
        What this site does to the STATE datagrams it receives (tests and benchmarks).
    safety : SafetyConfig
        The limits of this site's robot (the handle port's passivity controller is off: the
        link's controller is in the port).
    state_wait_s : float, s
        Lockstep robots: how long to wait for each STATE.
    """

    rate_hz: int = 1000
    lockstep: bool = False
    link: LinkConfig = field(default_factory=LinkConfig)
    impairment: Impairment = field(default_factory=Impairment)
    safety: SafetyConfig = field(default_factory=lambda: SafetyConfig(passivity=False))
    state_wait_s: float = 0.05

    def __post_init__(self) -> None:
        if not (isinstance(self.rate_hz, int) and 250 <= self.rate_hz <= 4000):
            raise ParameterError(f"The 'rate_hz' remote site setting must be an integer from "
                                 f"250 to 4000 Hz; got {self.rate_hz!r} instead.")
        if self.safety.passivity:
            raise ParameterError("a remote site's robot runs without the handle port's "
                                 "passivity controller (the link's controller replaces it): "
                                 "give SafetyConfig(passivity=False)")

    def hello(self) -> dict[str, Any]:
        return {"rate_hz": self.rate_hz, "lockstep": self.lockstep}


def sim_patient(robot: str) -> tuple[str, ArmParams, tuple[float, float], str]:
    """For a ``sim://`` robot with a virtual patient: the URL with the handle where the relaxed
    hand rests (unless the URL says where), the arm, its shoulder in the robot frame and its
    description."""
    parts = urllib.parse.urlsplit(robot)
    cfg = SimRobotConfig.from_query(parts.query)
    if not cfg.patient:
        raise ParameterError(f"{mask_url(robot)}: a simulated patient's site needs "
                             "patient=… in the sim:// URL (a stored model id, file:PATH or a "
                             "severity such as elbow=severe)")
    src = resolve_patient(cfg.patient)
    q = dict(urllib.parse.parse_qsl(parts.query, keep_blank_values=True))
    hx, hy = Arm.from_params(src.params).rest_position()
    q.setdefault("x0_m", f"{float(hx) + cfg.patient_x_m:.6f}")
    q.setdefault("y0_m", f"{float(hy) + cfg.patient_y_m:.6f}")
    return ("sim://?" + urllib.parse.urlencode(q), src.params,
            (cfg.patient_x_m, cfg.patient_y_m), src.description)


@dataclass(frozen=True)
class PatientResult:
    """What the patient's site leaves behind: its log file and its figures."""

    ticks: int
    summary: dict[str, Any]
    log_file: str | None
    faults: list[dict[str, Any]]


class PatientSite:
    """The loop of the patient's site (robot link and endpoint open, handshakes done).

    Parameters
    ----------
    link : RobotLink
        The patient's robot (force sensor on).
    endpoint : Endpoint
    config : SiteConfig
    shoulder_m : (x, y), m
        The patient's shoulder in the robot frame.
    """

    def __init__(self, link: RobotLink, endpoint: Endpoint, config: SiteConfig,
                 shoulder_m: tuple[float, float]) -> None:
        self.link = link
        self.config = config
        self.dt = 1.0 / config.rate_hz
        self.shoulder = shoulder_m
        self.safety = Safety(config.safety, self.dt)
        self.guard = RobotGuard(link, self.safety, self.dt)
        self.port = PatientPort(endpoint, config.link, self.dt)
        self.port.robot_ok = lambda: self.safety.mode == Mode.ARMED
        self._awaiting = False
        self._down = False
        self.stop = False
        self.reason = ""

    def arm(self) -> None:
        link = self.link
        self.safety.rearm((link.x, link.y, link.vx, link.vy))
        self.guard.forgive()
        link.arm()

    def _trip(self, code: int, message: str) -> None:
        self.safety.trip(code, self.port.now(), message)
        self.port.fault = True
        if not self._down:
            try:
                self.link.disarm()
            except LinkDown:
                self._down = True

    def tick(self) -> None:
        link = self.link
        new = 0
        if not self._down:
            try:
                wait = self.config.state_wait_s if self.config.lockstep else 0.0
                new = link.wait_state(wait) if wait > 0 and self._awaiting else link.poll()
            except LinkDown as exc:
                self._down = True
                self._trip(FaultCode.DISCONNECT, str(exc))
        if self.safety.mode == Mode.ARMED:
            code, msg = self.guard.check(new)
            if code:
                self._trip(code, msg)
        sx, sy = self.shoulder
        fx, fy = self.port.tick(link.x - sx, link.y - sy, link.vx, link.vy, link.sensor_fx,
                                link.sensor_fy)
        fx, fy = self.safety.output(fx, fy, link.vx, link.vy)
        if self.safety.limiter.nan_seen:
            self.safety.limiter.nan_seen = False
            self._trip(FaultCode.NAN, "non-finite servo force")
            fx = fy = 0.0
        if not self._down:
            try:
                link.send_force(fx, fy)
                self._awaiting = True
            except LinkDown as exc:
                self._down = True
                self._trip(FaultCode.DISCONNECT, str(exc))
        if self.port.ended:
            self.stop = True
            self.reason = f"the clinician's site: {self.port.ended}"

    def run(self, duration_s: float | None, clock: Clock) -> None:
        period = round(1e9 / self.config.rate_hz)
        end = None if duration_s is None else round(duration_s * self.config.rate_hz)
        deadline = clock.now_ns()
        n = 0
        while not self.stop and (end is None or n < end):
            clock.sleep_until(deadline)
            self.tick()
            n += 1
            deadline += period
            now = clock.now_ns()
            if now > deadline + period:
                deadline = now  # far behind (suspended): never burst through missed ticks
        if end is not None and n >= end and not self.reason:
            self.reason = f"{duration_s:g} s passed"

    def finish(self) -> None:
        try:
            if not self._down:
                self.link.send_force(0.0, 0.0)
                self.link.disarm()
        except LinkDown:
            self._down = True


def _await_sensor(link: RobotLink, robot: str) -> None:
    link.sensor_on()
    deadline = time.monotonic() + 1.0
    while link.sensors == 0:
        link.send_force(0.0, 0.0)
        link.wait_state(0.01)
        if link.device_faults:
            raise HapticError(f"the robot at {mask_url(robot)} has no force sensor (it answered "
                              f"SENSOR_ON with fault {link.last_device_fault}); the patient's "
                              "site needs one")
        if time.monotonic() > deadline:
            raise HapticError(f"the robot at {mask_url(robot)} sent no force-sensor reading "
                              "within 1 s of SENSOR_ON; the patient's site needs one")


def _check_hello(msg: dict[str, Any], cfg: SiteConfig) -> str:
    """Why a HELLO cannot be served ('' when it can)."""
    if msg.get("rate_hz") != cfg.rate_hz:
        return f"rate {msg.get('rate_hz')!r} Hz; this site runs at {cfg.rate_hz} Hz"
    if bool(msg.get("lockstep")) != cfg.lockstep:
        return ("clock mode differs: both sites must run in lockstep (simulated) or both in "
                "real time")
    t = msg.get("wall_time_s")
    if not isinstance(t, (int, float)) or abs(time.time() - float(t)) > HELLO_MAX_SKEW_S:
        return f"its clock is more than {HELLO_MAX_SKEW_S:g} s from this machine's (or absent)"
    return ""


def serve_patient(robot: str, key: bytes, bind: tuple[str, int], drawing: ArmParams,
                  shoulder_m: tuple[float, float], *, config: SiteConfig | None = None,
                  duration_s: float | None = None, wait_s: float = 600.0,
                  log_dir: str | Path | None = None, name: str | None = None,
                  description: str = "", ready: Callable[[tuple[str, int]], None] | None = None,
                  say: Say = _quiet) -> PatientResult:
    """Run the patient's site for one session (module docstring).

    Parameters
    ----------
    robot : str
        The patient's robot (``sim://?patient=…`` for a simulated patient).
    key : bytes
        The shared session key.
    bind : (host, port)
        Where to listen for the clinician.
    drawing : ArmParams
        What the clinician's station draws (only its geometry is sent).
    shoulder_m : (x, y), m
        The patient's shoulder in the robot frame.
    config : SiteConfig, optional
    duration_s : float, s, optional
        End after this long (None: at the clinician's BYE or Ctrl-C).
    wait_s : float, s
        How long to wait for the clinician's HELLO.
    log_dir : str or Path, optional
        Where the site's log goes (None: not written).
    name : str, optional
        The log's name (default ``remote-patient-<UTC time>``).
    description : str
        What the patient is, kept in this site's log only (never sent).
    ready : callable((host, port)), optional
        Told the bound address once the site listens.
    say : callable(str)
    """
    cfg = config or SiteConfig()
    dt = 1.0 / cfg.rate_hz
    link = RobotLink.open(robot)
    transport: UdpTransport | None = None
    try:
        dev = link.handshake(cfg.rate_hz, WATCHDOG_MS)
        _await_sensor(link, robot)
        say(f"patient's robot {dev.device_id!r}: force sensor on, device limit "
            f"{dev.force_limit_n:g} N")
        transport = UdpTransport(bind)
        endpoint = Endpoint(transport, Authenticator(key, Role.PATIENT), cfg.impairment,
                            cfg.lockstep, dt)
        endpoint.learn_peer = True
        host, port = transport.address
        say(f"listening for the clinician on {host}:{port} (UDP; key {key_fingerprint(key)})")
        if ready is not None:
            ready((host, port))
        hello = None
        deadline = time.monotonic() + wait_s
        while hello is None:
            left = deadline - time.monotonic()
            if left <= 0:
                raise HapticError(f"no clinician's HELLO within {wait_s:g} s")
            d = endpoint.wait_message((Kind.HELLO,), min(left, 1.0))
            if d is None:
                continue
            why = _check_hello(dict(d.message or {}), cfg)
            if why:
                endpoint.send_message(Kind.BYE, {"reason": f"refused: {why}"}, 0.0)
                say(f"refused a HELLO: {why}")
                endpoint.auth.session = None
                continue
            hello = d
        sx, sy = shoulder_m
        rest = (link.x - sx, link.y - sy)
        geo = Arm.from_params(drawing)
        welcome = {"rate_hz": cfg.rate_hz, "lockstep": cfg.lockstep,
                   "drawing": drawing.with_unimpaired_muscles().to_dict(),
                   "rest_hand_m": [rest[0], rest[1]], "device": dev.device_id,
                   "force_limit_n": cfg.safety.force_limit_n,
                   "reach_m": float(geo.l1 + geo.l2)}
        endpoint.send_message(Kind.WELCOME, welcome, 0.0)
        say(f"clinician connected from {transport.peer}; session "
            f"{endpoint.auth.session:016x}")
        site = PatientSite(link, endpoint, cfg, shoulder_m)
        site.arm()
        clock: Clock = VirtualClock() if cfg.lockstep else RealClock()
        started = time.time()
        try:
            with realtime(not cfg.lockstep):
                site.run(duration_s, clock)
        except KeyboardInterrupt:
            site.reason = "interrupted"
        finally:
            site.finish()
        try:
            endpoint.send_message(Kind.BYE, {"reason": site.reason or "the patient's site "
                                             "ended"}, site.port.now())
        except HapticError:
            pass
        say(f"session over: {site.reason}")
        summary = site.port.summary() | {
            "reason": site.reason, "robot": mask_url(robot), "device": dev.device_id,
            "started_at_unix_s": started, "shoulder_m": list(shoulder_m),
            "key_fingerprint": key_fingerprint(key), "description": description,
            "config": {"rate_hz": cfg.rate_hz, "lockstep": cfg.lockstep,
                       "link": cfg.link.to_dict(), "impairment": cfg.impairment.to_dict()}}
        faults = [r.to_dict() for r in site.safety.log_records]
        summary["faults"] = faults
        path = None
        if log_dir is not None:
            stem = name or ("remote-patient-" + time.strftime("%Y%m%dT%H%M%SZ", time.gmtime()))
            path = Path(log_dir) / f"{stem}.h5"
            path.parent.mkdir(parents=True, exist_ok=True)
            write_new(path, site.port.log.to_hdf5({"summary": summary, "role": "patient",
                                                   "dt_s": dt}))
            say(f"log: {path}")
        return PatientResult(site.port.tick_n, summary, None if path is None else str(path),
                             faults)
    finally:
        if transport is not None:
            transport.close()
        link.close()


__all__ = ["PatientResult", "PatientSite", "SiteConfig", "serve_patient", "sim_patient"]
