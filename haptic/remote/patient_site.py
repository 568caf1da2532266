"""The patient's site: the robot holding the patient's hand, following a distant clinician.

``fieldbank haptic remote patient --robot URL --key FILE --bind HOST:PORT`` runs
:func:`serve_patient`:

1. opens the robot (:func:`haptic.robots.open_robot`: the project's link or an installed
   adapter's robot), shakes hands at the loop's rate and asks for its force sensor (a robot
   without one cannot tell the clinician what the arm does: refused);
2. listens on UDP for the clinician's HELLO (:mod:`haptic.remote.handshake`: one that does not
   open under the key is not answered), checks the rate, the clock mode and the time, answers
   WELCOME — encrypted under the new session's keys — with what the clinician's station needs
   to draw the arm (its segment lengths, side and range of motion, never its muscles) and where
   the hand rests, and waits for the clinician to prove the key over this site's fresh nonce;
   then the clinician's address is pinned for the session;
3. arms the robot — inside the real-time context, right before the first tick, so nothing
   stands between the ARM frame and the first FORCE (the device's watchdog is 20 ms; preparing
   the process, a full garbage collection, took 0.2–1.6 s) — and runs the loop: each tick reads
   the robot and judges it (the renderer's safety monitor, :mod:`haptic.monitor`: every fault
   check of a loop on a robot), hands the patient's handle and the force the hand puts on it
   to the :class:`~haptic.remote.ports.PatientPort`, which answers the servo force, and sends
   that through the robot's limits (:mod:`haptic.safety`, the passivity controller of the
   handle port off: the link's is in the port);
4. ends after ``duration_s``, on Ctrl-C, or once the force has ramped out after the
   clinician's BYE or (lockstep) silence; commands zero and disarms; says what happened (the
   account of :mod:`haptic.remote.account`); writes its log (every tick: the patient's handle
   and force, the reference, the servo force, the energies at its port) as an HDF5 file.

A fault of the patient's robot latches (zero force, disarmed, its port stops following); the
clinician's station shows it. The link being lost ramps the servo force to zero; the robot
stays armed and follows again, ramping in, once the link has been back for ``resume_s``.
"""

from __future__ import annotations

import time
import urllib.parse
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fieldbank.errors import ParameterError
from fieldbank.files import write_new
from fieldbank.haptic.clock import Clock, RealClock, VirtualClock, cpu_plan, realtime
from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.monitor import SafetyMonitor
from fieldbank.haptic.patient import resolve_patient
from fieldbank.haptic.port import SensingPort
from fieldbank.haptic.remote.account import Account, account
from fieldbank.haptic.remote.channel import Address, Endpoint, UdpTransport
from fieldbank.haptic.remote.config import SiteConfig
from fieldbank.haptic.remote.handshake import Responder
from fieldbank.haptic.remote.ports import PatientPort
from fieldbank.haptic.remote.wire import Datagram, Kind, SessionCipher, key_fingerprint, peek_kind
from fieldbank.haptic.robots import open_robot, with_force_sensor
from fieldbank.haptic.safety import Mode
from fieldbank.haptic.simrobot import SimRobotConfig
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.redact import mask_url

#: HELLOs whose wall-clock time differs from this machine's by more than this are refused,
#: s (an old HELLO replayed to an idle site is refused before any key is drawn for it).
HELLO_MAX_SKEW_S = 120.0
#: Device watchdog asked of the patient's robot, ms.
WATCHDOG_MS = 20
Say = Callable[[str], None]


def _quiet(msg: str) -> None:
    del msg


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
    """What the patient's site leaves behind: its log file, its figures, its account."""

    ticks: int
    summary: dict[str, Any]
    log_file: str | None
    faults: list[dict[str, Any]]
    account: Account


class PatientSite:
    """The loop of the patient's site (robot and endpoint open, handshakes done).

    The robot is read, judged and commanded through one
    :class:`~haptic.monitor.SafetyMonitor` (every fault check of the renderer: the port's CRC
    bucket and sequence gaps, no state within the timeout, the robot's fault reports and flags,
    NaN, the workspace and the speed limit; the force through the robot's limits, the
    passivity controller of the handle port off: the link's is in the port).

    Parameters
    ----------
    robot : SensingPort
        The patient's robot (force sensor on).
    endpoint : Endpoint
    config : SiteConfig
    shoulder_m : (x, y), m
        The patient's shoulder in the robot frame.
    """

    def __init__(self, robot: SensingPort, endpoint: Endpoint, config: SiteConfig,
                 shoulder_m: tuple[float, float]) -> None:
        self.robot = robot
        self.config = config
        self.dt = 1.0 / config.rate_hz
        self.shoulder = shoulder_m
        self.monitor = SafetyMonitor(robot, config.safety, self.dt, force_from="the servo")
        #: the latched state machine and the force path (the monitor's)
        self.safety = self.monitor.safety
        #: how late the present tick woke, s (the loop keeping time, for engaging)
        self.late_s = 0.0
        self.port = PatientPort.for_site(endpoint, config, shoulder_m)
        self.port.robot_ok = lambda: self.safety.mode == Mode.ARMED
        self.port.latched = lambda: self.safety.latched
        self.port.late_s = lambda: self.late_s
        self.armed = False
        self._awaiting = False
        self.stop = False
        self.reason = ""
        #: the session ended as asked (its duration, the clinician's BYE, this site's Ctrl-C)
        self.asked = False

    def arm(self) -> None:
        """Arm the robot, refused (:class:`~haptic.errors.CommandError`) with every reason
        the monitor finds: the first FORCE must follow at once (the device's watchdog is a few
        ticks), so a real-time loop arms inside :func:`haptic.clock.realtime`, right before
        its first tick (:meth:`run`)."""
        self.monitor.arm(running=False)
        self.armed = True

    def tick(self) -> None:
        m = self.monitor
        wait = self.config.state_wait_s if self.config.lockstep and self._awaiting else 0.0
        new = m.read(wait, self.port.now())
        m.check(new)
        st = m.state
        sx, sy = self.shoulder
        fx, fy = self.port.tick(st.x - sx, st.y - sy, st.vx, st.vy, st.sensor_fx,
                                st.sensor_fy)
        fx, fy = m.output(fx, fy, st.vx, st.vy)
        if m.send(fx, fy):
            self._awaiting = True
        if self.port.closed and not self.stop:
            self.stop = True
            if self.port.ended:
                self.reason = f"the clinician's site ended the session ({self.port.ended})"
                self.asked = self.port.bye
            else:
                self.reason, self.asked = self.port.end_reason, True

    def run(self, duration_s: float | None, clock: Clock) -> None:
        """Arm (when not yet) and tick until the port closes — its planned end after
        ``duration_s``, or the clinician's end, the force ramped out either way — or
        :attr:`stop`; a tick woken a whole period late skips the ticks it missed instead of
        bursting through them. A robot that cannot be armed ends the session before its
        first tick, with the reason."""
        if not self.armed:
            try:
                self.arm()
            except HapticError as exc:
                self.reason = f"the patient's robot could not be armed: {exc}"
                return
        period = round(1e9 / self.config.rate_hz)
        if duration_s is not None:
            self.port.plan_end(max(1, round(duration_s * self.config.rate_hz)),
                               f"{duration_s:g} s passed")
        deadline = clock.now_ns()
        while not self.stop:
            clock.sleep_until(deadline)
            now = clock.now_ns()
            self.late_s = (now - deadline) * 1e-9
            self.tick()
            deadline += period
            if now >= deadline:
                deadline += ((now - deadline) // period + 1) * period

    def finish(self) -> None:
        """Zero force and disarm the robot (a failing robot is left)."""
        self.monitor.release()

    def account(self) -> Account:
        """The session in words (:mod:`haptic.remote.account`)."""
        cols = self.port.log.arrays()
        return account(cols["t_s"], cols["gain"], self.port.events,
                       ended=self.reason or "the loop stopped", asked=self.asked,
                       peer_name=self.port.peer_name)


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


def _handshake(transport: UdpTransport, key: bytes, cfg: SiteConfig, welcome: dict[str, Any],
               wait_s: float, say: Say
               ) -> tuple[SessionCipher, Datagram, Address, list[tuple[bytes, Address]]]:
    """Answer HELLOs until a clinician proves the key over this site's fresh nonce: the
    session's cipher, the datagram that proved it, the clinician's address, and what was read
    after it (:mod:`haptic.remote.handshake`)."""
    resp = Responder(key)
    told: set[tuple[Any, str]] = set()
    deadline = time.monotonic() + wait_s
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            raise HapticError(f"no clinician's site completed the handshake within {wait_s:g} s")
        if not transport.wait_readable(min(left, 0.5)):
            continue
        batch = transport.receive()
        answered: set[tuple[Any, bytes]] = set()  # a HELLO repeated while this site was busy
        for i, (data, addr) in enumerate(batch):
            if peek_kind(data) != Kind.HELLO:
                got = resp.confirm(data, addr)
                if got is not None:
                    return got[0], got[1], addr, batch[i + 1:]
                continue
            hello = resp.open_hello(data)
            if hello is None or (addr, hello.nonce) in answered:
                continue
            answered.add((addr, hello.nonce))
            why = _check_hello(dict(hello.message), cfg)
            if why:
                transport.send_to(resp.refusal(hello, f"refused: {why}"), addr)
                if (addr, why) not in told:
                    told.add((addr, why))
                    say(f"refused a HELLO from {addr[0]}:{addr[1]}: {why}")
                continue
            reply = resp.welcome(hello, addr, welcome)
            if reply:
                transport.send_to(reply, addr)


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
        How long to wait for a clinician to complete the handshake.
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
    opened = open_robot(robot, cfg.rate_hz, WATCHDOG_MS)
    transport: UdpTransport | None = None
    try:
        dev = opened.device
        assert dev is not None  # open_robot refuses a robot that does not say what it is
        sensing = with_force_sensor(opened, robot, "the patient's site")
        say(f"patient's robot {dev.device_id!r}: force sensor on, device limit "
            f"{dev.force_limit_n:g} N")
        transport = UdpTransport(bind)
        host, port = transport.address
        say(f"listening for the clinician on {host}:{port} (UDP; key {key_fingerprint(key)})")
        if ready is not None:
            ready((host, port))
        sx, sy = shoulder_m
        rest = (sensing.state.x - sx, sensing.state.y - sy)
        geo = Arm.from_params(drawing)
        welcome = {"rate_hz": cfg.rate_hz, "lockstep": cfg.lockstep,
                   "drawing": drawing.with_unimpaired_muscles().to_dict(),
                   "rest_hand_m": [rest[0], rest[1]], "device": dev.device_id,
                   "force_limit_n": cfg.safety.force_limit_n,
                   "reach_m": float(geo.l1 + geo.l2)}
        clock: Clock = VirtualClock() if cfg.lockstep else RealClock()
        # the process is prepared for the loop (a full collection, SCHED_FIFO) while it waits
        # for the clinician, so the loop starts the moment the clinician's does; pinned to
        # the core the clinician's loop would not take were both sites on one machine
        with realtime(not cfg.lockstep, cpu=cpu_plan()[1]) as grant:
            cipher, first, peer, after = _handshake(transport, key, cfg, welcome, wait_s, say)
            transport.set_peer(peer)  # pinned for the session: nothing from elsewhere is read
            endpoint = Endpoint(transport, cipher, cfg.impairment, cfg.lockstep, dt, peer=peer)
            site = PatientSite(sensing, endpoint, cfg, shoulder_m)
            endpoint.deliver(first, 0.0)
            endpoint.backlog = after
            say(f"clinician confirmed from {peer[0]}:{peer[1]}; session "
                f"{cipher.session:016x}")
            started = time.time()
            try:
                site.run(duration_s, clock)  # it arms the robot right before its first tick
            except KeyboardInterrupt:
                site.reason, site.asked = "interrupted at this site", True
            finally:
                site.finish()
        site.port.say_bye(site.reason or "the patient's site ended")
        acc = site.account()
        for line in acc.lines():
            say(line)
        summary = site.port.summary() | {
            "reason": site.reason, "realtime": grant.to_dict(), "robot": mask_url(robot),
            "device": dev.device_id,
            "started_at_unix_s": started, "shoulder_m": list(shoulder_m),
            "key_fingerprint": key_fingerprint(key), "description": description,
            "account": acc.to_dict(),
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
                             faults, acc)
    finally:
        if transport is not None:
            transport.close()
        opened.close()


__all__ = ["PatientResult", "PatientSite", "serve_patient", "sim_patient"]
