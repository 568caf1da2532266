"""The ``fieldbank haptic`` commands that run the loop or read traces: ``serve``, ``probe``,
``replay``, ``sim-robot`` (numpy, the renderer and the database layer load inside the commands,
so their ``--help`` starts at once)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import click

from fieldbank.cli.haptic import resolve_sources, socket_option
from fieldbank.cli.options import (
    MODEL_ID,
    SESSION_ID,
    db_option,
    emit,
    from_top,
    json_option,
    log_info_to_stderr,
    open_db,
    output_file,
    say,
    xy_metres,
)
from fieldbank.config import setting
from fieldbank.files import read_json_document, write_atomic
from fieldbank.haptic.errors import HapticError
from fieldbank.params import ArmParams
from fieldbank.probepath import MAX_DRAWN_PROBES, read_probes

if TYPE_CHECKING:  # typing only: the library loads when a command runs
    from fieldbank.haptic.training import TrainingProtocol


def protocol_named(text: str) -> TrainingProtocol:
    """'seed' (the paper's protocol), 'short', or a JSON file of a TrainingProtocol."""
    from fieldbank.haptic.training import TrainingProtocol

    if text == "seed":
        return TrainingProtocol.seed_protocol()
    if text == "short":
        return TrainingProtocol.short()
    path = Path(text)
    if not path.is_file():
        raise click.BadParameter(f"a training protocol is seed, short or a JSON file; got "
                                 f"{text!r}", param_hint="--training-protocol")
    try:
        doc = read_json_document(path)
        if isinstance(doc, dict) and not doc.get("name"):
            doc = {**doc, "name": path.stem}  # the page names the protocol by its file
        return TrainingProtocol.from_dict(doc)
    except ValueError as exc:
        raise click.BadParameter(f"{path}: {exc}", param_hint="--training-protocol") from None


def station_protocol(text: str, probes_file: Path | None) -> TrainingProtocol:
    """The protocol the station's 'Start training' begins: :func:`protocol_named`, with the
    designed probes of ``probes_file`` (``fieldbank probe design --out``) as its further
    probes when given."""
    protocol = protocol_named(text)
    if probes_file is None:
        return protocol
    return replace(protocol, extra_probes=read_probes(probes_file, MAX_DRAWN_PROBES))


@click.command("serve")
@click.option("--robot", default=from_top("--robot"),
              help="Robot port URL: /dev/ttyUSB0, a pty path, socket://host:port, "
              "sim://?mode=realtime&motion=explore for the simulation, or a URL an installed "
              "robot adapter serves (docs/robot-adapters.md) (default: FIELDBANK_ROBOT, else "
              "robot in fieldbank.toml).")
@click.option("--rate-hz", "--rate", "rate_hz", type=click.IntRange(500, 4000), default=1000,
              show_default=True, help="Tick rate, Hz (4000 for stiffer rendering and lower "
              "latency; the session records it).")
@click.option("--duration-s", type=click.FloatRange(min=0.001), default=None,
              help="Stop after this long (default: until 'fieldbank haptic stop' or Ctrl-C).")
@click.option("--before", "before_file", type=click.Path(exists=True, path_type=Path),
              help="ArmParams JSON of the model before (A).")
@click.option("--after", "after_file", type=click.Path(exists=True, path_type=Path),
              help="ArmParams JSON of the model after (B).")
@click.option("--before-severity", help="Model A from a severity, e.g. elbow=severe.")
@click.option("--after-severity", help="Model B from a severity, e.g. elbow=mild.")
@click.option("--before-id", type=MODEL_ID, help="Model A by its id in the field database.")
@click.option("--after-id", type=MODEL_ID, help="Model B by its id in the field database.")
@click.option("--force-limit-n", type=click.FloatRange(min=0.1, max=200.0), default=40.0,
              show_default=True)
@click.option("--shoulder-offset", help="Shoulder position in robot coordinates, X,Y in m.")
@click.option("--crossfade-s", type=click.FloatRange(min=0.0, max=5.0), default=0.5,
              show_default=True)
@click.option("--arm/--no-arm", "arm_on_start", default=True, show_default=True,
              help="Arm at once (else wait for 'fieldbank haptic arm').")
@click.option("--trace-dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Where the session trace goes (default: traces/ in the data dir).")
@socket_option
@db_option
@click.option("--patient", help="Patient code the session belongs to (default: its models' "
              "patient).")
@click.option("--patient-note", help="Why the session's patient is not its models' patient "
              "(required then).")
@click.option("--no-db", is_flag=True, help="Write the trace file only, not the database.")
@click.option("--station", is_flag=True, help="Serve the clinician's station page (prints its "
              "address with the session's token).")
@click.option("--station-host", default="127.0.0.1", show_default=True,
              help="Address the station binds to.")
@click.option("--station-port", type=click.IntRange(0, 65535), default=0,
              help="Port of the station (default: any free port).")
@click.option("--station-allow-remote", is_flag=True,
              help="Allow a --station-host other machines can reach (unencrypted).")
@click.option("--station-view", type=click.Choice(["opposite", "behind"]), default="opposite",
              show_default=True, help="The patient faces the clinician (seed), or seen from "
              "behind the patient.")
@click.option("--training-protocol", default="seed", show_default=True,
              help="What the station's 'Start training' runs: seed, short, or a JSON file.")
@click.option("--training-probes", type=click.Path(dir_okay=False, path_type=Path),
              help="Designed probes the station's instructed training draws besides the "
                   "seed's (the file 'fieldbank probe design --out' writes), in place of any "
                   "the protocol names.")
@json_option
def serve(robot: str | None, rate_hz: int, duration_s: float | None, before_file: Path | None,
          after_file: Path | None, before_severity: str | None, after_severity: str | None,
          before_id: int | None, after_id: int | None, force_limit_n: float,
          shoulder_offset: str | None, crossfade_s: float, arm_on_start: bool,
          trace_dir: Path | None, socket_path: Path | None, db_url: str | None,
          patient: str | None, patient_note: str | None, no_db: bool, station: bool,
          station_host: str, station_port: int, station_allow_remote: bool,
          station_view: str, training_protocol: str, training_probes: Path | None,
          as_json: bool) -> None:
    """Run the real-time renderer on ROBOT with models A (before) and B (after).

    The session's trace is written to an HDF5 file in --trace-dir and recorded in the field
    database (unless --no-db). With --station, the clinician's station page is served.
    """
    from fieldbank.haptic import session
    from fieldbank.haptic.rendererconfig import RendererConfig
    from fieldbank.haptic.safety import SafetyConfig
    from fieldbank.haptic.station.launch import StationOptions

    robot = setting("robot", robot).value
    if robot is None:
        raise click.UsageError("no robot: give --robot PORT (e.g. /dev/ttyUSB0, or sim:// for "
                               "the simulation), or set FIELDBANK_ROBOT or robot in "
                               "fieldbank.toml.")
    log_info_to_stderr()
    before, after, ids, info = resolve_sources(db_url, (before_file, after_file),
                                               (before_severity, after_severity),
                                               (before_id, after_id))
    cfg = RendererConfig(rate_hz=rate_hz, crossfade_s=crossfade_s,
                         shoulder_offset_m=xy_metres(shoulder_offset, "--shoulder-offset"),
                         arm_on_start=arm_on_start)
    opts = None
    if station:
        opts = StationOptions(station_host, station_port, station_allow_remote, station_view,
                              station_protocol(training_protocol, training_probes).to_dict())
    elif training_probes is not None:
        raise click.UsageError("--training-probes is for the station's training; add --station")
    res = session.serve(
        robot, before, after, model_ids=ids, patient_code=patient, patient_note=patient_note,
        model_info=info, duration_s=duration_s, config=cfg,
        safety=SafetyConfig(force_limit_n=force_limit_n), socket_path=socket_path,
        station=opts, trace_dir=trace_dir or session.default_trace_dir(),
        db=None if no_db else (lambda: open_db(db_url)), say=say)
    summary, trace = res.summary(), res.trace
    st = trace.stats.get("period_error_us", {})
    emit(summary, as_json,
         f"session: {len(trace)} ticks, max force {summary['max_force_n']:.2f} N, "
         f"{len(trace.faults)} fault(s), period error p50 {st.get('p50', 0):.1f} µs p99 "
         f"{st.get('p99', 0):.1f} µs max {st.get('max', 0):.1f} µs, "
         f"overruns >{trace.stats.get('overrun_threshold_ms', 1)} ms: "
         f"{trace.stats.get('overruns', 0)}\ntrace: {res.trace_file}"
         + (f"\ndatabase: {res.database}" if res.database else "")
         + "".join(f"\n{line}" for res_ in trace.metadata.get("training", [])
                   for line in training_lines(res_)))


@click.command("probe")
@click.option("--motion", type=click.Choice(["pull", "fastpull", "ellipse", "circle", "explore",
                                             "hold"]), default="pull", show_default=True)
@click.option("--robot", default=from_top("--robot", "sim://"), show_default="sim://",
              help="sim:// (simulated, faster than real time) or a real robot's port.")
@click.option("--model", "model_file", type=click.Path(exists=True, path_type=Path))
@click.option("--severity", help="e.g. shoulder=severe,elbow=mild")
@click.option("--rate-hz", type=click.IntRange(500, 4000), default=1000, show_default=True)
@click.option("--duration-s", type=click.FloatRange(min=0.01), default=None)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path),
              callback=output_file,
              help="Write the full profile as CSV.")
@json_option
def probe_cmd(motion: str, robot: str, model_file: Path | None, severity: str | None,
              rate_hz: int, duration_s: float | None, seed: int, out: Path | None,
              as_json: bool) -> None:
    """Run a scripted probing motion and report the force profile felt at the handle."""
    from fieldbank import modelsource
    from fieldbank.haptic.probe import probe

    params = modelsource.resolve(params_file=model_file, severity=[severity] if severity else [],
                                 default=modelsource.synthetic()).params
    res = probe(params, motion, robot, rate_hz, duration_s, seed)
    if out is not None:
        write_atomic(out, res.to_csv())
    s = res.summary()
    if as_json:
        s["profile"] = res.table(every=max(1, rate_hz // 100))
    emit(s, as_json,
         f"{motion}: peak {s['peak_force_n']:.2f} N at {s['peak_at_s']:.3f} s, direction "
         f"{s['peak_direction_deg']:.0f}°, path {s['path_length_m'] * 100:.1f} cm, RMS "
         f"difference to the static field {s['rms_error_vs_static_n']:.2f} N"
         + (f"\nprofile: {out}" if out else ""))


@click.command("replay")
@click.argument("trace_ref", metavar="TRACE")
@click.option("--csv", "csv_out", type=click.Path(dir_okay=False, path_type=Path),
              callback=output_file,
              help="Export the trace as CSV.")
@click.option("--rerun", is_flag=True, help="Recompute the model forces from the recorded "
              "handle motion and compare.")
@db_option
@json_option
def replay(trace_ref: str, csv_out: Path | None, rerun: bool, db_url: str | None,
           as_json: bool) -> None:
    """Summarise a recorded session; export it; re-run it offline.

    TRACE is a trace file (.h5) or a database session, haptic_session:ID.
    """
    from fieldbank.haptic.dbsink import SESSION_PREFIX, read_trace_db
    from fieldbank.haptic.recording import read_trace_h5
    from fieldbank.haptic.replay import rerun as do_rerun

    if trace_ref.startswith(SESSION_PREFIX):
        sid = SESSION_ID.convert(trace_ref[len(SESSION_PREFIX):], None, None)
        with open_db(db_url) as db:
            trace = read_trace_db(db, sid)
    else:
        if not Path(trace_ref).is_file():
            raise click.BadParameter(f"no trace file {trace_ref!r} (nor {SESSION_PREFIX}ID)")
        trace = read_trace_h5(trace_ref)
    s = trace.summary()
    if csv_out is not None:
        write_atomic(csv_out, trace.to_csv())
    if rerun:
        s["rerun"] = do_rerun(trace)
    lines = [f"{trace_ref}: {s['ticks']} ticks at {s['rate_hz']:g} Hz "
             f"({s['duration_s']:.3f} s), max force {s['max_force_n']:.2f} N, "
             f"{len(s['faults'])} fault(s), {s['events']} event(s)"]
    for f in s["faults"]:
        lines.append(f"  fault {f['name']} at {f['t_s']:.4f} s: {f['message']}")
    if rerun:
        lines.append(f"rerun: {s['rerun']['ticks']} ticks, max deviation "
                     f"{s['rerun']['max_deviation_n']:.3g} N")
    if csv_out:
        lines.append(f"csv: {csv_out}")
    emit(s, as_json, "\n".join(lines))


@click.command("sim-robot")
@click.option("--motion", type=click.Choice(["hold", "pull", "fastpull", "ellipse", "circle",
                                             "explore"]), default="explore", show_default=True)
@click.option("--mode", type=click.Choice(["realtime", "lockstep"]), default="realtime",
              show_default=True)
@click.option("--start", help="Start of the motion X,Y in m (robot frame).")
def sim_robot(motion: str, mode: str, start: str | None) -> None:
    """Run the simulated robot on a pty and print the port to give to 'serve --robot'."""
    from fieldbank.haptic.clock import collector_off, cpu_plan, enter_device_realtime
    from fieldbank.haptic.simrobot import PtyRobot, SimRobotConfig, serve_fd
    from fieldbank.model import Arm

    if start:
        x0, y0 = xy_metres(start, "--start")
    else:  # the rest hand position of the default (unimpaired) arm
        x0, y0 = (float(v) for v in Arm.from_params(ArmParams.from_anthropometry())
                  .rest_position())
    robot = PtyRobot(SimRobotConfig(mode=mode, motion=motion, x0_m=x0, y0_m=y0))
    click.echo(robot.port)
    grant = enter_device_realtime(cpu_plan()[1])
    click.echo(f"device: {grant.text()}", err=True)
    try:
        with collector_off():
            serve_fd(robot.device, robot.master_fd)
    except KeyboardInterrupt:
        pass
    except OSError as exc:
        raise HapticError(f"simulated robot stopped: {exc}") from None
    finally:
        robot.close()


def training_lines(result: dict[str, object]) -> list[str]:
    """A training session's result as terminal lines."""
    from fieldbank.haptic.trainingresults import accuracy_text

    summary = result.get("summary")
    if not isinstance(summary, dict):
        return []
    head = "training (stopped early)" if result.get("abandoned") else "training"
    return [f"{head}:", *accuracy_text(summary)]
