"""The clinician's site: the clinician's robot and station, the patient far away.

``fieldbank haptic remote clinician --robot URL --peer HOST:PORT --key FILE`` runs
:func:`serve_clinician`:

1. shakes hands with the patient's site (:mod:`haptic.remote.handshake`: the same HELLO,
   sealed under the key, repeated until a WELCOME or a refusal arrives; rate, clock mode, this
   machine's time). The WELCOME, sealed under the session's keys, brings the patient's arm
   geometry (to draw it, never its muscles) and where the patient's hand rests; a WELCOME at
   another rate or clock mode is refused (BYE) before either site engages;
2. runs an ordinary rendering session (:func:`haptic.session.serve`: the clinician's robot, its
   safety layer, the control channel, the station, the trace file and the database record)
   whose virtual arms are the link (:mod:`haptic.remote.environment`): the handle goes to the
   patient's site, the patient's force comes back through the passivity controller. The
   CONFIRM that proves this site holds the key goes with the loop's first tick, so the
   patient's site arms its robot and starts its loop when this one starts;
3. with a station, serves it with the remote panels (:mod:`haptic.remote.deskstation`): the
   link's figures and the supervised assessment, which reads the patient's side from the
   link's tap (:mod:`haptic.remote.tap`) and logs the posterior after each probe and the
   clinician's answers to a file beside the trace;
4. at its planned end, or when the clinician stops it (``fieldbank haptic stop``, Ctrl-C),
   ramps the force out and says BYE; then says what happened (the account of
   :mod:`haptic.remote.account`), writes the link's log (every tick: both ports' energies, the
   passivity controller, the round trip, the patient's side as received) as
   ``<trace>.link.h5``, and with a database records the link
   (:meth:`Database.add_remote_link`), its per-tick columns as traces of the session
   (``link.<column>``) and every posterior with the answer beside it
   (:meth:`Database.add_assessments`).

A lost link ramps the clinician's force to zero (the port's watchdog); the patient's BYE, or
its silence in lockstep, ramps it out and ends the session.
"""

from __future__ import annotations

import ipaddress
import json
import secrets
import tempfile
import time
import urllib.parse
from collections.abc import Callable, Mapping, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Protocol

from fieldbank.errors import ParameterError
from fieldbank.evaluate.design.config import NOISE_BOUNDS
from fieldbank.evaluate.severity import LEVELS as SEVERITY_LEVELS
from fieldbank.files import write_new
from fieldbank.haptic.clock import VirtualClock
from fieldbank.haptic.dbsink import SESSION_PREFIX, HapticStore
from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.modelinfo import ModelInfo
from fieldbank.haptic.remote.account import Account, account
from fieldbank.haptic.remote.channel import Endpoint, UdpTransport, same_address
from fieldbank.haptic.remote.config import SiteConfig
from fieldbank.haptic.remote.environment import remote_environment
from fieldbank.haptic.remote.handshake import Initiator
from fieldbank.haptic.remote.linklog import CLINICIAN_COLUMNS
from fieldbank.haptic.remote.ports import ClinicianPort
from fieldbank.haptic.remote.tap import TapWriter
from fieldbank.haptic.remote.wire import Kind, SessionCipher, key_fingerprint
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.safety import Mode
from fieldbank.haptic.session import SessionResult, serve
from fieldbank.haptic.station.launch import StationOptions
from fieldbank.params import JOINT_GROUPS, ArmParams
from fieldbank.probechoices import PREDICTORS
from fieldbank.validation import Interval, check_fields

Say = Callable[[str], None]
#: How often HELLO is repeated until the patient's site answers, s.
HELLO_EVERY_S = 0.5
#: The station's program of a remote session: the station with the desk's panel.
DESK_STATION = "fieldbank.haptic.remote.deskstation"
#: The classifier's candidates by default: every group at every severity, and the unimpaired arm.
GROUPS = ("shoulder", "elbow", "biarticular")
LEVELS = ("very mild", "mild", "moderate", "severe")
#: Ranges of the assessment's numbers: the force noise is the probe design's.
ASSESS_BOUNDS: dict[str, Interval] = {"force_sd_n": NOISE_BOUNDS["force_sd_n"]}


def _quiet(msg: str) -> None:
    del msg


@dataclass(frozen=True)
class AssessOptions:
    """The station's supervised assessment (:mod:`haptic.remote.desk`).

    Attributes
    ----------
    groups, levels : tuple of str
        The candidates: every group at every level of the severity scale, on the patient's body.
    unimpaired : bool
        Also the unimpaired arm.
    predictor : str
        How a candidate predicts the patient's force (:mod:`fieldbank.evaluate.classify`;
        'rigid': a hand holding the arm, for forces measured on a patient).
    force_sd_n : float, N
        The likelihood's force noise (model error and sensor noise); range in
        :data:`ASSESS_BOUNDS`.
    """

    groups: tuple[str, ...] = GROUPS
    levels: tuple[str, ...] = LEVELS
    unimpaired: bool = True
    predictor: str = "rigid"
    force_sd_n: float = 2.0

    def __post_init__(self) -> None:
        check_fields(self, ASSESS_BOUNDS, what="assessment setting")
        for what, names, known in (("muscle group", self.groups, tuple(JOINT_GROUPS)),
                                   ("severity", self.levels, SEVERITY_LEVELS[1:])):
            unknown = [n for n in names if n not in known]
            if unknown:
                raise ParameterError(f"the assessment's {what} is one of {', '.join(known)}; "
                                     f"got {', '.join(map(repr, unknown))}")
        if not self.unimpaired and not (self.groups and self.levels):
            raise ParameterError("the assessment needs a candidate: at least one muscle group "
                                 "and severity, or the unimpaired arm")
        if self.predictor not in PREDICTORS:
            raise ParameterError(f"the assessment's predictor is one of {', '.join(PREDICTORS)}"
                                 f"; got {self.predictor!r}")

    def to_dict(self) -> dict[str, Any]:
        return {"groups": list(self.groups), "levels": list(self.levels),
                "unimpaired": self.unimpaired, "predictor": self.predictor,
                "force_sd_n": self.force_sd_n}


class RemoteStore(HapticStore, Protocol):
    """The database methods a remote session adds to a haptic session's."""

    def add_remote_link(self, haptic_session_id: int, role: str, peer: str,
                        key_fingerprint: str, settings: Mapping[str, Any],
                        summary: Mapping[str, Any]) -> int: ...

    def add_assessments(self, haptic_session_id: int,
                        rows: Sequence[Mapping[str, Any]]) -> int: ...


StoreOpener = Callable[[], AbstractContextManager[RemoteStore]]


@dataclass(frozen=True)
class ClinicianResult:
    """What the clinician's site leaves behind."""

    session: SessionResult
    link_file: str | None
    link_summary: dict[str, Any]
    account: Account
    assessments: list[dict[str, Any]] = field(default_factory=list)


def default_bind(peer: tuple[str, int]) -> tuple[str, int]:
    """Any free port on the address family (and loopback-ness) of ``peer``."""
    try:
        ip = ipaddress.ip_address(peer[0])
    except ValueError:
        return ("0.0.0.0", 0)
    if ip.version == 6:
        return ("::1" if ip.is_loopback else "::", 0)
    return ("127.0.0.1" if ip.is_loopback else "0.0.0.0", 0)


def _hello(transport: UdpTransport, key: bytes, session: int, cfg: SiteConfig, wait_s: float,
           say: Say) -> tuple[SessionCipher, dict[str, Any]]:
    """HELLO (the same bytes, every HELLO_EVERY_S) until the patient's site answers: the
    session's cipher and the WELCOME (:mod:`haptic.remote.handshake`), or its refusal
    (raised). The CONFIRM that proves this site holds the key goes with the first tick
    (:attr:`ClinicianPort.greeting`): the patient's site arms its robot only then."""
    ini = Initiator(key, session, {**cfg.hello(), "wall_time_s": time.time(),
                                   "site": "clinician"})
    deadline = time.monotonic() + wait_s
    while True:
        transport.send(ini.hello)
        until = time.monotonic() + HELLO_EVERY_S
        while (left := until - time.monotonic()) > 0 and transport.wait_readable(left):
            for data, addr in transport.receive():
                if not same_address(addr, transport.peer):
                    ini.refused["address"] = ini.refused.get("address", 0) + 1
                    continue
                got = ini.answer(data)
                if isinstance(got, str):
                    raise HapticError(f"the patient's site refused the session: {got}")
                if got is not None:
                    cipher, d = got
                    welcome = dict(d.message or {})
                    if (welcome.get("rate_hz") != cfg.rate_hz
                            or bool(welcome.get("lockstep")) != cfg.lockstep):
                        why = (f"the patient's site runs at {welcome.get('rate_hz')} Hz, "
                               f"lockstep {welcome.get('lockstep')}; this site at "
                               f"{cfg.rate_hz} Hz, lockstep {cfg.lockstep}")
                        transport.send(cipher.seal_json(Kind.BYE, {"reason": why}))
                        raise HapticError(why)
                    for reason, n in ini.refused.items():
                        cipher.refused[reason] = cipher.refused.get(reason, 0) + n
                    return cipher, welcome
        if time.monotonic() > deadline:
            raise HapticError(f"no answer from the patient's site within {wait_s:g} s (is it "
                              "listening, on that address, with the same session key?)")
        say("  waiting for the patient's site…")


def read_assessment_log(path: Path) -> list[dict[str, Any]]:
    """The records the station appended (one JSON object a line); a torn last line (the
    station stopped mid-write) is left out."""
    if not path.exists():
        return []
    out = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            rec = json.loads(line)
        except ValueError:
            continue
        if isinstance(rec, dict):
            out.append(rec)
    return out


def assessment_rows(records: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """One row per probe: the posterior computed when the probe ended, the clinician's latest
    answer given after it (and before the next probe) beside it; posteriors recomputed later for
    the same probe (the clinician changed the prior) are kept in its ``revisions``."""
    keys = ("probe", "started_s", "ended_s", "prior", "posterior", "group",
            "group_probability", "level", "level_probability", "explains", "next_probe",
            "verdict", "link", "group_posterior", "level_posterior", "predictor")
    rows: list[dict[str, Any]] = []
    for rec in records:
        if rec.get("kind") == "posterior":
            if rows and rows[-1]["probe"] == rec.get("probe"):
                rows[-1].setdefault("revisions", []).append(
                    {k: rec.get(k) for k in ("prior", "posterior", "group",
                                             "group_probability", "level",
                                             "level_probability", "verdict")})
                continue
            rows.append({k: rec.get(k) for k in keys}
                        | {"answer_group": None, "answer_level": None, "answer_note": None,
                           "answered_s": None})
        elif rec.get("kind") == "answer" and rows:
            rows[-1].update({"answer_group": rec.get("group"), "answer_level": rec.get("level"),
                             "answer_note": rec.get("note"), "answered_s": rec.get("t_s")})
    return rows


def serve_clinician(robot: str, key: bytes, peer: tuple[str, int], *,
                    config: SiteConfig | None = None, bind: tuple[str, int] | None = None,
                    shoulder_offset_m: tuple[float, float] = (0.0, 0.0),
                    duration_s: float | None = None, station: StationOptions | None = None,
                    assess: AssessOptions | None = None, socket_path: str | Path | None = None,
                    trace_dir: str | Path | None = None, trace_name: str | None = None,
                    db: RemoteStore | StoreOpener | None = None, patient_code: str | None = None,
                    patient_note: str | None = None, wait_s: float = 30.0,
                    say: Say = _quiet) -> ClinicianResult:
    """Run the clinician's site for one session (module docstring).

    Parameters
    ----------
    robot : str
        The clinician's robot (``sim://…`` for the simulated one; in lockstep it must be
        ``mode=lockstep``).
    key : bytes
        The shared session key.
    peer : (host, port)
        The patient's site.
    config : SiteConfig, optional
        Rate, clock mode, link settings, injected impairment, the robot's limits.
    bind : (host, port), optional
        Local UDP address (default: any free port of the peer's family).
    shoulder_offset_m : (x, y), m
        Where the patient's shoulder is drawn in this robot's frame.
    duration_s : float, s, optional
    station : StationOptions, optional
        Serve the clinician's station with the remote panels.
    assess : AssessOptions, optional
        The station's supervised assessment (default candidates without it).
    trace_dir, trace_name, db, patient_code, patient_note, socket_path
        As :func:`haptic.session.serve`.
    wait_s : float, s
        How long to wait for the patient's site.
    say : callable(str)
    """
    cfg = config or SiteConfig()
    dt = 1.0 / cfg.rate_hz
    if cfg.lockstep and not (robot.startswith("sim://") and "mode=lockstep" in robot):
        raise HapticError("lockstep (simulated clocks) needs the simulated clinician's robot in "
                          "lockstep too: sim://?mode=lockstep&…")
    transport = UdpTransport(bind or default_bind(peer), peer)
    session_id = secrets.randbits(63)
    tap: TapWriter | None = None
    tmp: tempfile.TemporaryDirectory[str] | None = None
    try:
        say(f"saying HELLO to the patient's site at {peer[0]}:{peer[1]} (key "
            f"{key_fingerprint(key)})")
        cipher, welcome = _hello(transport, key, session_id, cfg, wait_s, say)
        endpoint = Endpoint(transport, cipher, cfg.impairment, cfg.lockstep, dt)
        drawing = ArmParams.from_dict(welcome.get("drawing") or {},
                                      where="the patient's site's WELCOME")
        rest = welcome.get("rest_hand_m") or [0.0, 0.3]
        say(f"patient's site answered: device {welcome.get('device')!r}, hand resting at "
            f"({rest[0]:.3f}, {rest[1]:.3f}) m from the shoulder")
        if robot.startswith("sim://"):
            parts = urllib.parse.urlsplit(robot)
            q = dict(urllib.parse.parse_qsl(parts.query))
            q.setdefault("x0_m", f"{rest[0] + shoulder_offset_m[0]:.6f}")
            q.setdefault("y0_m", f"{rest[1] + shoulder_offset_m[1]:.6f}")
            robot = "sim://?" + urllib.parse.urlencode(q)
        port = ClinicianPort.for_site(endpoint, cfg, shoulder_offset_m)
        port.greeting = Initiator.confirm(cipher)
        name = trace_name or ("remote-" + time.strftime("%Y%m%dT%H%M%SZ", time.gmtime()))
        log_dir = Path(trace_dir) if trace_dir is not None else None
        if log_dir is None:
            tmp = tempfile.TemporaryDirectory(prefix="fieldbank-remote-")
        assess_path = (log_dir or Path(tmp.name if tmp else ".")) / f"{name}.assessment.jsonl"
        station_opts = station
        if station is not None:
            tap = TapWriter(tuple(c for c, _ in CLINICIAN_COLUMNS))
            port.tap = tap
            station_opts = replace(station, program=DESK_STATION, panel={
                "tap_path": str(tap.path), "assessment_path": str(assess_path),
                "columns": [c for c, _ in CLINICIAN_COLUMNS], "rate_hz": cfg.rate_hz,
                "drawing": drawing.with_unimpaired_muscles().to_dict(),
                "assess": (assess or AssessOptions()).to_dict(),
                "impairment": cfg.impairment.to_dict(), "peer": f"{peer[0]}:{peer[1]}"})
        remote_meta = {"role": "clinician", "peer": f"{peer[0]}:{peer[1]}",
                       "session": f"{session_id:016x}", "key_fingerprint": key_fingerprint(key),
                       "rate_hz": cfg.rate_hz, "lockstep": cfg.lockstep,
                       "link": cfg.link.to_dict(), "impairment": cfg.impairment.to_dict(),
                       "patient_device": welcome.get("device")}

        def prepare(rd: Renderer) -> None:
            if cfg.lockstep:
                rd.clock = VirtualClock()
            port.robot_ok = lambda: rd.safety.mode == Mode.ARMED
            port.latched = lambda: rd.safety.latched
            late = rd.times
            port.late_s = lambda: late.late_ns[-1] * 1e-9 if late.late_ns else 0.0
            port.commanded = lambda: (rd.fx, rd.fy)
            port.on_end = rd.stop_now
            # the clinician's stop (haptic stop, Ctrl-C) ramps the force out, the patient's
            # site with it, before the loop ends
            rd.wind_down = lambda: port.end_now("stopped by the clinician")
            rd.metadata["remote"] = remote_meta

        if duration_s is not None:  # the port ends it, the force ramped out by then
            port.plan_end(max(1, round(duration_s * cfg.rate_hz)), f"{duration_s:g} s passed")
        label = f"the patient at {peer[0]}:{peer[1]} (remote; drawn with its geometry only)"
        info = {"A": ModelInfo.describe(label), "B": ModelInfo.describe(label)}
        result = serve(robot, drawing, drawing, model_info=info, duration_s=None,
                       config=RendererConfig(rate_hz=cfg.rate_hz,
                                             shoulder_offset_m=shoulder_offset_m,
                                             state_wait_s=cfg.state_wait_s if cfg.lockstep
                                             else 0.0,
                                             realtime_priority=not cfg.lockstep),
                       safety=cfg.safety, control=True, socket_path=socket_path,
                       station=station_opts, trace_dir=trace_dir, trace_name=name, db=db,
                       patient_code=patient_code, patient_note=patient_note, say=say,
                       environment=remote_environment(port, drawing), on_renderer=prepare)
        port.finish()
        if port.ended:
            ended, asked = f"the patient's site ended the session ({port.ended})", False
        elif port.closed:
            ended, asked = port.end_reason, True
        else:
            ended, asked = "stopped by the clinician", True
        port.say_bye(f"the clinician's session ended: {ended}")
        cols = port.log.arrays()
        acc = account(cols["t_s"], cols["gain"], port.events, ended=ended, asked=asked,
                      peer_name=port.peer_name)
        for line in acc.lines():
            say(line)
        summary = port.summary() | {"remote": remote_meta, "account": acc.to_dict()}
        say(f"link: round trip {summary['link']['rtt_ms']} ms, "
            f"{summary['link']['loss_fraction']:.1%} lost, passivity controller on "
            f"{port.pc.active_ticks} of {port.tick_n} ticks "
            f"({port.pc.dissipated_j:.3g} J dissipated)")
        link_file = None
        if log_dir is not None:
            path = log_dir / f"{name}.link.h5"
            write_new(path, port.log.to_hdf5({"summary": summary, "role": "clinician",
                                              "dt_s": dt}))
            link_file = str(path)
            say(f"link log: {path}")
        records = read_assessment_log(assess_path)
        rows = assessment_rows(records)
        if db is not None and result.database is not None:
            sid = int(result.database.removeprefix(SESSION_PREFIX))
            _record(db, sid, port, summary, remote_meta, rows)
        return ClinicianResult(result, link_file, summary, acc, rows)
    finally:
        transport.close()
        if tap is not None:
            tap.close()
        if tmp is not None:
            tmp.cleanup()


def _record(db: RemoteStore | StoreOpener, sid: int, port: ClinicianPort,
            summary: Mapping[str, Any], meta: Mapping[str, Any],
            rows: Sequence[Mapping[str, Any]]) -> None:
    def write(store: RemoteStore) -> None:
        prov = {"rate_hz": meta["rate_hz"], "frame": "shoulder of the patient",
                "what": "remote link log, clinician's port"}
        for (col, unit), arr in zip(CLINICIAN_COLUMNS, port.log.arrays().values(),
                                    strict=True):
            store.add_trace(sid, f"link.{col}", arr, unit, prov)
        store.add_remote_link(sid, "clinician", str(meta["peer"]), str(meta["key_fingerprint"]),
                              {k: meta[k] for k in ("rate_hz", "lockstep", "link",
                                                    "impairment", "session")},
                              {k: v for k, v in summary.items() if k != "remote"})
        if rows:
            store.add_assessments(sid, rows)

    if callable(db):
        with db() as store:
            write(store)
    else:
        write(db)
