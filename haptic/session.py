"""A rendering session on a robot, start to finish: what ``fieldbank haptic serve`` and the
product tour run.

:func:`serve`

1. with a database, checks the session's patient against its models' (a session rendering
   another patient's models needs a stated reason) before anything moves;
2. opens the robot (:func:`haptic.robots.open_robot`: the project's link, or an installed
   adapter's; a ``sim://`` URL gets a simulated operator who starts at model A's rest hand
   position) and handshakes at the loop's rate;
3. renders model A (before) and B (after) — with the control channel open (``fieldbank
   haptic switch``, ``push``, ``abx``, ``train`` …; pushed model ids are checked against the
   database and the session's patient), optionally the clinician's station
   (:mod:`haptic.station`, a page in its own process reading the loop's snapshot) and, for
   scripted demonstrations, a schedule of switches — until the duration passes, a ``stop``
   arrives, or Ctrl-C;
4. closes the port, then writes the trace: first the HDF5 file (so it survives a database
   failure), then the database record with the session's own start and end times and its
   A/B/X and training trials.

Progress goes to a ``say`` callback, one line per step; the caller decides where lines go.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import threading
import time
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fieldbank.haptic.commandbase import RendererCommand
from fieldbank.haptic.commands import Push, Switch
from fieldbank.haptic.control import ControlServer
from fieldbank.haptic.dbsink import DatabaseTraceSink, HapticStore
from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.modelinfo import ModelInfoPair, model_info_pair, to_wire
from fieldbank.haptic.pair import Environment
from fieldbank.haptic.probe import sim_url
from fieldbank.haptic.protocol import DeviceInfo
from fieldbank.haptic.recording import Hdf5TraceSink, Trace
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.robots import open_robot
from fieldbank.haptic.safety import SafetyConfig
from fieldbank.haptic.snapshot import SnapshotWriter
from fieldbank.haptic.station.launch import StationOptions, StationProcess
from fieldbank.home import data_home
from fieldbank.params import ArmParams
from fieldbank.redact import mask_url
from fieldbank.validation import Interval, check_fields

#: One line of progress for the user.
Say = Callable[[str], None]
#: Opens the field database when the session is over (used as a context manager).
StoreOpener = Callable[[], AbstractContextManager[HapticStore]]

#: Device watchdog asked for in the handshake, ms: no FORCE for this long → zero and disarm.
WATCHDOG_MS = 20
#: The simulated operator's motion for ``sim://`` robots.
SIM_MOTION = "explore"


def _quiet(msg: str) -> None:
    del msg


def default_trace_dir() -> Path:
    """``traces/`` in the fieldbank data directory."""
    return data_home() / "traces"


def trace_name_now() -> str:
    """``haptic-<UTC time to the µs>``: a name no other session of this machine has."""
    return "haptic-" + _dt.datetime.now(_dt.UTC).strftime("%Y%m%dT%H%M%S.%fZ")


#: Allowed range of a scheduled switch's time.
SWITCH_BOUNDS: dict[str, Interval] = {"at_s": Interval(0.0, None, "s")}


@dataclass(frozen=True)
class ScheduledSwitch:
    """Crossfade to ``to`` ('A'/'before' or 'B'/'after') ``at_s`` seconds after rendering
    starts; checked when made, so a bad schedule fails before the robot is opened."""

    at_s: float
    to: str

    def __post_init__(self) -> None:
        check_fields(self, SWITCH_BOUNDS, what="switch time")
        Switch(self.to)


@dataclass(frozen=True)
class SessionResult:
    """What a session left behind.

    Attributes
    ----------
    trace : Trace
    robot : str
        The port URL rendered on (for ``sim://``, with the operator's start filled in), its
        password masked (:func:`fieldbank.redact.mask_url`).
    device : DeviceInfo
        What the robot said about itself in the handshake.
    name : str
        The trace's name (file stem and database label).
    trace_file : str or None
        Path of the HDF5 trace file, if one was written.
    sha256 : str or None
        SHA-256 of the trace file.
    database : str or None
        ``haptic_session:ID`` of the database record, if one was written.
    station_url : str or None
        The station page's address (with its token), if one was served.
    """

    trace: Trace
    robot: str
    device: DeviceInfo
    name: str
    trace_file: str | None = None
    sha256: str | None = None
    database: str | None = None
    station_url: str | None = None

    def summary(self) -> dict[str, Any]:
        """The trace's summary with the robot (as given, without secrets) and where it was
        stored (``trace``, ``sha256``, ``database``)."""
        out = self.trace.summary()
        out["robot"] = self.robot
        if self.trace_file is not None:
            out["trace"] = self.trace_file
            out["sha256"] = self.sha256
        if self.database is not None:
            out["database"] = self.database
        return out


def _run_schedule(rd: Renderer, switches: Sequence[ScheduledSwitch], over: threading.Event,
                  crossfade_s: float, say: Say) -> None:
    while not rd.running and not over.is_set():
        time.sleep(1e-3)
    t0 = time.monotonic()
    for sw in sorted(switches, key=lambda s: s.at_s):
        if over.wait(max(0.0, t0 + sw.at_s - time.monotonic())) or not rd.running:
            return
        cmd = Switch(sw.to)
        rd.submit(cmd)
        to = "after (B)" if cmd.weight else "before (A)"
        say(f"  switch to {to}, {crossfade_s:g} s crossfade")


def _with_store(db: HapticStore | StoreOpener, fn: Callable[[HapticStore], Any]) -> Any:
    if callable(db):
        with db() as store:
            return fn(store)
    return fn(db)


def _push_vet(db: HapticStore | StoreOpener, patient_code: str | None,
              patient_note: str | None) -> Callable[[RendererCommand], None]:
    """Refuses a push whose model ids the database does not know, or that belong to another
    patient than the session's (without a stated reason)."""

    def vet(cmd: RendererCommand) -> None:
        if isinstance(cmd, Push) and cmd.model_ids and any(
                v is not None for v in cmd.model_ids.values()):
            ids = [cmd.model_ids.get("A"), cmd.model_ids.get("B")]
            _with_store(db, lambda s: s.session_patient(ids, patient_code, patient_note))

    return vet


def serve(robot: str, before: ArmParams, after: ArmParams, *,
          model_ids: tuple[int | None, int | None] = (None, None),
          patient_code: str | None = None, patient_note: str | None = None,
          model_info: ModelInfoPair | None = None, duration_s: float | None = None,
          config: RendererConfig | None = None, safety: SafetyConfig | None = None,
          control: bool = True, socket_path: str | Path | None = None,
          station: StationOptions | None = None,
          switches: Sequence[ScheduledSwitch] = (),
          trace_dir: str | Path | None = None, trace_name: str | None = None,
          db: HapticStore | StoreOpener | None = None, say: Say = _quiet,
          watchdog_ms: int = WATCHDOG_MS, environment: Environment | None = None,
          on_renderer: Callable[[Renderer], None] | None = None,
          snapshot_dir: str | Path | None = None) -> SessionResult:
    """Render ``before`` (A) and ``after`` (B) on ``robot``; store the trace.

    Parameters
    ----------
    robot : str
        Port URL: ``/dev/ttyUSB0``, a pty path, ``socket://host:port``, ``sim://?…`` for the
        simulated robot (``mode=realtime`` for a live session), or a URL of a scheme an
        installed robot adapter serves (:mod:`haptic.robots`).
    before, after : ArmParams
        Models A and B.
    model_ids : (int or None, int or None)
        Their ids in the field database, if stored (the record refers to them; models without
        an id are stored with the session).
    patient_code : str, optional
        The patient the session belongs to in the database (default: its models' patient).
    patient_note : str, optional
        Why the session's patient is not its models' patient (required then).
    model_info : mapping of ModelInfo, optional
        What the station says about each model: ``{"A": ModelInfo, "B": ModelInfo}``
        (:mod:`haptic.modelinfo`; their wire dictionaries are accepted too).
    duration_s : float, s, optional
        How long to render; None: until a ``stop`` command or Ctrl-C.
    config : RendererConfig, optional
        Loop settings (rate, crossfade, shoulder offset, arming).
    safety : SafetyConfig, optional
        Limits and thresholds.
    control : bool
        Open the control channel while rendering.
    socket_path : str or Path, optional
        Its socket (default: ``haptic.sock`` in the data directory).
    station : StationOptions, optional
        Serve the clinician's station page (needs the control channel); its address, with
        the session's token, goes to ``say`` and into the result.
    switches : sequence of ScheduledSwitch
        Scripted switches, timed from the start of rendering.
    trace_dir : str or Path, optional
        Directory of the HDF5 trace file (:func:`default_trace_dir` is the usual choice);
        None: no file.
    trace_name : str, optional
        The trace's name (default :func:`trace_name_now`).
    db : HapticStore or StoreOpener, optional
        Where the session is recorded: an open database, or a function that opens one, called
        only once the file is written (a long session then holds no connection) and closed
        again here. None: no record.
    say : callable(str), optional
        Receives one line of progress per step.
    watchdog_ms : int, ms
        The device watchdog asked for in the handshake (the device may keep a shorter one).
    environment : callable, optional
        What the loop ticks in place of the compiled arms (:data:`haptic.pair.Environment`:
        the remote link puts a distant patient there).
    on_renderer : callable(Renderer), optional
        Called with the renderer once it is built, before the robot is armed.
    snapshot_dir : str or Path, optional
        Publish the loop's snapshot (:mod:`haptic.snapshot`) in this directory, for a display
        in another process (the workspace's robot view); a station makes its own.

    Returns
    -------
    SessionResult
    """
    cfg = config or RendererConfig()
    name = trace_name or trace_name_now()
    info = to_wire(model_info_pair(model_info, "serve"))
    if station is not None and not control:
        raise HapticError("the station needs the control channel (control=True)")
    vet = None
    if db is not None:
        # the patient rule first: nothing moves for a session that could not be recorded
        patient_code = _with_store(db, lambda s: s.session_patient(model_ids, patient_code,
                                                                    patient_note))
        vet = _push_vet(db, patient_code, patient_note)
    # what the user gave is what is shown and recorded; the simulated robot's start position
    # and motion filled in here are details of the simulation, not of the robot asked for
    given = robot
    if robot.startswith("sim://"):
        robot = sim_url(before, SIM_MOTION, cfg.shoulder_offset_m, robot)
    port = open_robot(robot, cfg.rate_hz, watchdog_ms, shown=given)
    try:
        device = port.device
        assert device is not None  # open_robot refuses a robot that does not say what it is
        say(f"robot {device.device_id!r}: protocol {device.protocol_version}, up to "
            f"{device.max_rate_hz} Hz, device force limit {device.force_limit_n:g} N, "
            f"watchdog {device.watchdog_ms} ms")
        rd = Renderer(port, before, after, cfg, safety=safety, environment=environment)
        if on_renderer is not None:
            on_renderer(rd)
        # the trace, its file, the database record and every printout keep the URL masked
        rd.metadata["robot"] = mask_url(given)
        if any(i is not None for i in model_ids):
            rd.metadata["model_ids"] = {"A": model_ids[0], "B": model_ids[1]}
        if info:
            rd.metadata["model_info"] = info
        if patient_code is not None:
            rd.metadata["patient"] = patient_code
        station_url = None
        with contextlib.ExitStack() as stack:
            where = ""
            if control:
                server = stack.enter_context(ControlServer(rd, socket_path, vet=vet))
                where = f"; control socket {server.path}"
            if snapshot_dir is not None:
                rd.snapshot = stack.enter_context(SnapshotWriter(snapshot_dir))
            if station is not None:
                # started before the loop takes real-time priority, which a child would inherit
                snap = stack.enter_context(SnapshotWriter())
                rd.snapshot = snap
                proc = stack.enter_context(StationProcess.for_session(
                    str(snap.path), str(server.path), station))
                station_url = proc.url
                say(f"station: {station_url}")
            say(f"rendering at {cfg.rate_hz} Hz{where}")
            over = threading.Event()
            if switches:
                th = threading.Thread(target=_run_schedule, name="haptic-schedule", daemon=True,
                                      args=(rd, switches, over, cfg.crossfade_s, say))
                th.start()
                stack.callback(th.join, 1.0)
            stack.callback(over.set)
            trace = rd.run(duration_s)
    finally:
        port.close()
    trace_file = sha = ref = None
    if trace_dir is not None:
        sink = Hdf5TraceSink(trace_dir)
        trace_file = sink.write_trace(trace, name)  # the file first: it survives the database
        sha = sink.sha256[trace_file]
        say(f"trace file: {trace_file}")
    if db is not None:
        ref = _with_store(db, lambda s: DatabaseTraceSink(s, patient_code, patient_note)
                          .write_trace(trace, name))
    return SessionResult(trace, mask_url(given), device, name, trace_file, sha, ref,
                         station_url)
