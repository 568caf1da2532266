"""``fieldbank haptic``: render arm models on a robot, control a running renderer, probe, replay.

``serve`` owns the robot and the loop; the other commands talk to it over the local control
socket (``--socket``, default ``haptic.sock`` in the fieldbank data directory). ``probe`` and
``replay`` work on their own.
"""

from __future__ import annotations

import datetime as _dt
import logging
import os
import sys
from pathlib import Path
from typing import Any

import click

from fieldbank import modelsource
from fieldbank.cli.options import db_option, emit, json_option, open_db
from fieldbank.files import write_atomic
from fieldbank.haptic.errors import HapticError
from fieldbank.params import ArmParams

socket_option = click.option(
    "--socket", "socket_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
    help="Control socket of the renderer (default: haptic.sock in the fieldbank data dir).")


def _model(path: Path | None, severity: str | None) -> ArmParams:
    return modelsource.resolve(params_file=path, severity=[severity] if severity else [],
                               default=modelsource.synthetic()).params


def _models(db_url: str | None, files: tuple[Path | None, Path | None],
            severities: tuple[str | None, str | None],
            ids: tuple[int | None, int | None]) -> tuple[ArmParams, ArmParams,
                                                       tuple[int | None, int | None]]:
    """Models A and B from files, severities or database ids (B defaults to A)."""
    out: list[modelsource.ModelSource | None] = []
    for f, sev, mid, label in zip(files, severities, ids, ("before", "after"), strict=True):
        if sum(x is not None for x in (f, sev, mid)) > 1:
            raise click.UsageError(f"give the {label} model once: a file, a severity or an id")
        if f is None and not sev and mid is None:
            out.append(None)
            continue
        out.append(modelsource.resolve(
            params_file=f, severity=[sev] if sev else [], model_id=mid,
            open_db=lambda: open_db(db_url), what=f"{label} model"))
    a = out[0].params if out[0] is not None else ArmParams.from_anthropometry()
    b = out[1].params if out[1] is not None else a
    return a, b, (ids[0], ids[1] if out[1] is not None else ids[0])


def _pair(x: str | None, name: str) -> tuple[float, float]:
    if x is None:
        return (0.0, 0.0)
    try:
        a, b = (float(v) for v in x.split(","))
    except ValueError:
        raise click.BadParameter(f"{name} must read X,Y in metres; got {x!r}") from None
    return (a, b)


@click.group("haptic")
def haptic() -> None:
    """Feel arm models on a 2-DOF robot: serve, push, switch, abx, probe, status, replay."""


@haptic.command("serve")
@click.option("--robot", required=True, help="Robot port URL: /dev/ttyUSB0, a pty path, "
              "socket://host:port, or sim://?mode=realtime&motion=explore for the simulation.")
@click.option("--rate-hz", type=click.IntRange(500, 4000), default=1000, show_default=True)
@click.option("--duration-s", type=click.FloatRange(min=0.001), default=None,
              help="Stop after this long (default: until 'fieldbank haptic stop' or Ctrl-C).")
@click.option("--before", "before_file", type=click.Path(exists=True, path_type=Path),
              help="ArmParams JSON of the model before (A).")
@click.option("--after", "after_file", type=click.Path(exists=True, path_type=Path),
              help="ArmParams JSON of the model after (B).")
@click.option("--before-severity", help="Model A from a severity, e.g. elbow=severe.")
@click.option("--after-severity", help="Model B from a severity, e.g. elbow=mild.")
@click.option("--before-id", type=int, help="Model A by its id in the field database.")
@click.option("--after-id", type=int, help="Model B by its id in the field database.")
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
@click.option("--patient", help="Patient code the session belongs to (in the database).")
@click.option("--no-db", is_flag=True, help="Write the trace file only, not the database.")
@json_option
def serve(robot: str, rate_hz: int, duration_s: float | None, before_file: Path | None,
          after_file: Path | None, before_severity: str | None, after_severity: str | None,
          before_id: int | None, after_id: int | None, force_limit_n: float,
          shoulder_offset: str | None, crossfade_s: float, arm_on_start: bool,
          trace_dir: Path | None, socket_path: Path | None, db_url: str | None,
          patient: str | None, no_db: bool, as_json: bool) -> None:
    """Run the real-time renderer on ROBOT with models A (before) and B (after).

    The session's trace is written to an HDF5 file in --trace-dir and recorded in the field
    database (unless --no-db).
    """
    from fieldbank.haptic.control import ControlServer, data_home
    from fieldbank.haptic.link import RobotLink
    from fieldbank.haptic.recording import Hdf5TraceSink
    from fieldbank.haptic.renderer import Renderer, RendererConfig
    from fieldbank.haptic.safety import SafetyConfig

    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(levelname)s %(message)s")
    before, after, ids = _models(db_url, (before_file, after_file),
                                 (before_severity, after_severity), (before_id, after_id))
    offset = _pair(shoulder_offset, "--shoulder-offset")
    if robot.startswith("sim://"):
        from fieldbank.haptic.probe import sim_url

        # the simulated operator starts at the model's rest hand position unless told otherwise
        robot = sim_url(before, "explore", offset, robot)
    link = RobotLink.open(robot)
    try:
        info = link.handshake(rate_hz, 20)
        click.echo(f"robot {info.device_id!r}: protocol {info.protocol_version}, up to "
                   f"{info.max_rate_hz} Hz, device force limit {info.force_limit_n:g} N, "
                   f"watchdog {info.watchdog_ms} ms", err=True)
        cfg = RendererConfig(rate_hz=rate_hz, crossfade_s=crossfade_s,
                             shoulder_offset_m=offset,
                             arm_on_start=arm_on_start)
        rd = Renderer(link, before, after, cfg, safety=SafetyConfig(force_limit_n=force_limit_n))
        rd.metadata["robot"] = robot
        if any(i is not None for i in ids):
            rd.metadata["model_ids"] = {"A": ids[0], "B": ids[1]}
        with ControlServer(rd, socket_path) as server:
            click.echo(f"rendering at {rate_hz} Hz; control socket {server.path}", err=True)
            trace = rd.run(duration_s)
    finally:
        link.close()
    base = trace_dir or data_home() / "traces"
    name = "haptic-" + _dt.datetime.now(_dt.UTC).strftime("%Y%m%dT%H%M%S.%fZ")
    sink = Hdf5TraceSink(base)
    ref = sink.write_trace(trace, name)  # the file first: it survives a database failure
    click.echo(f"trace file: {ref}", err=True)
    summary = {**trace.summary(), "trace": ref, "sha256": sink.sha256[ref]}
    if not no_db:
        from fieldbank.haptic.dbsink import DatabaseTraceSink

        db = open_db(db_url)
        try:
            summary["database"] = DatabaseTraceSink(db, patient).write_trace(trace, name)
        finally:
            db.close()
    st = trace.stats.get("period_error_us", {})
    emit(summary, as_json,
          f"session: {len(trace)} ticks, max force {summary['max_force_n']:.2f} N, "
          f"{len(trace.faults)} fault(s), period error p50 {st.get('p50', 0):.1f} µs p99 "
          f"{st.get('p99', 0):.1f} µs max {st.get('max', 0):.1f} µs, "
          f"overruns >{trace.stats.get('overrun_threshold_ms', 1)} ms: "
          f"{trace.stats.get('overruns', 0)}\ntrace: {ref}"
          + (f"\ndatabase: {summary['database']}" if "database" in summary else ""))


@haptic.command("push")
@click.argument("before_file", required=False, type=click.Path(exists=True, path_type=Path))
@click.argument("after_file", required=False, type=click.Path(exists=True, path_type=Path))
@click.option("--before-severity")
@click.option("--after-severity")
@click.option("--before-id", type=int, help="Model A by its id in the field database.")
@click.option("--after-id", type=int, help="Model B by its id in the field database.")
@socket_option
@db_option
@json_option
def push(before_file: Path | None, after_file: Path | None, before_severity: str | None,
         after_severity: str | None, before_id: int | None, after_id: int | None,
         socket_path: Path | None, db_url: str | None, as_json: bool) -> None:
    """Send models BEFORE (A) and AFTER (B) to the running renderer (faded swap)."""
    from fieldbank.haptic.control import push_models

    if before_file is None and not before_severity and before_id is None:
        raise click.UsageError("give BEFORE_FILE, --before-severity or --before-id")
    before, after, ids = _models(db_url, (before_file, after_file),
                                 (before_severity, after_severity), (before_id, after_id))
    res = push_models(before, after, socket_path,
                      ids if any(i is not None for i in ids) else None)
    emit(res, as_json, "models pushed")


def _request(socket_path: Path | None, cmd: str, **args: Any) -> Any:
    from fieldbank.haptic.control import ControlClient

    return ControlClient(socket_path).request(cmd, **args)


@haptic.command("switch")
@click.argument("to", type=click.Choice(["A", "B", "before", "after"], case_sensitive=False))
@socket_option
@json_option
def switch(to: str, socket_path: Path | None, as_json: bool) -> None:
    """Crossfade the rendered model to A (before) or B (after)."""
    to = to.upper() if len(to) == 1 else to.lower()
    emit(_request(socket_path, "switch", to=to), as_json, f"switching to {to}")


@haptic.command("status")
@socket_option
@json_option
def status(socket_path: Path | None, as_json: bool) -> None:
    """Show the running renderer's mode, model blend, force and faults."""
    s = _request(socket_path, "status")
    emit(s, as_json, "\n".join(f"{k}: {v}" for k, v in s.items()))


for _name, _help in (("arm", "Arm (or re-arm after a fault) the running renderer."),
                     ("disarm", "Zero the force and disarm."),
                     ("stop", "End the session (the trace is written).")):
    def _make(name: str) -> Any:
        @socket_option
        @click.option("--json", "as_json", is_flag=True)
        def cmd(socket_path: Path | None, as_json: bool) -> None:
            emit(_request(socket_path, name), as_json, f"{name}: done")
        return cmd
    haptic.command(_name, help=_help)(_make(_name))


@haptic.group("abx")
def abx() -> None:
    """Blinded A/B/X trials on the running renderer."""


@abx.command("start")
@click.option("--trials", type=click.IntRange(1, 1000), default=10, show_default=True)
@click.option("--seed", type=int, default=None, help="Randomization seed (default: random).")
@click.option("--show-labels", is_flag=True, help="A = before and B = after (not hidden).")
@socket_option
@json_option
def abx_start(trials: int, seed: int | None, show_labels: bool, socket_path: Path | None,
              as_json: bool) -> None:
    """Start a block of TRIALS A/B/X trials."""
    seed = seed if seed is not None else int.from_bytes(os.urandom(4), "little")
    r = _request(socket_path, "abx", action="start", n_trials=trials, seed=seed,
                 hide_labels=not show_labels)
    emit(r, as_json, f"A/B/X block of {trials} trials started (seed {seed})")


@abx.command("present")
@click.argument("label", type=click.Choice(["A", "B", "X"], case_sensitive=False))
@socket_option
@json_option
def abx_present(label: str, socket_path: Path | None, as_json: bool) -> None:
    """Render A, B or this trial's X."""
    r = _request(socket_path, "abx", action="present", label=label.upper())
    emit(r, as_json, f"presenting {label.upper()} (trial {r['trial'] + 1})")


@abx.command("answer")
@click.argument("answer", type=click.Choice(["A", "B"], case_sensitive=False))
@socket_option
@json_option
def abx_answer(answer: str, socket_path: Path | None, as_json: bool) -> None:
    """Record that X felt like A or B; go to the next trial."""
    r = _request(socket_path, "abx", action="answer", answer=answer.upper())
    msg = f"answer recorded; next trial {r['trial'] + 1}"
    if r.get("done"):
        res = r["result"]
        msg = f"block done: {res['correct']} of {res['answered']} correct"
    emit(r, as_json, msg)


@haptic.command("probe")
@click.option("--motion", type=click.Choice(["pull", "fastpull", "ellipse", "circle", "explore",
                                             "hold"]), default="pull", show_default=True)
@click.option("--robot", default="sim://", show_default=True,
              help="sim:// (simulated, faster than real time) or a real robot's port.")
@click.option("--model", "model_file", type=click.Path(exists=True, path_type=Path))
@click.option("--severity", help="e.g. shoulder=severe,elbow=mild")
@click.option("--rate-hz", type=click.IntRange(500, 4000), default=1000, show_default=True)
@click.option("--duration-s", type=click.FloatRange(min=0.01), default=None)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path),
              help="Write the full profile as CSV.")
@json_option
def probe_cmd(motion: str, robot: str, model_file: Path | None, severity: str | None,
              rate_hz: int, duration_s: float | None, seed: int, out: Path | None,
              as_json: bool) -> None:
    """Run a scripted probing motion and report the force profile felt at the handle."""
    from fieldbank.haptic.probe import probe

    params = _model(model_file, severity)
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


@haptic.command("replay")
@click.argument("trace_ref", metavar="TRACE")
@click.option("--csv", "csv_out", type=click.Path(dir_okay=False, path_type=Path),
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
        try:
            sid = int(trace_ref[len(SESSION_PREFIX):])
        except ValueError:
            raise click.BadParameter(f"expected {SESSION_PREFIX}ID; got {trace_ref!r}") from None
        db = open_db(db_url)
        try:
            trace = read_trace_db(db, sid)
        finally:
            db.close()
    else:
        if not Path(trace_ref).is_file():
            raise click.BadParameter(f"no trace file {trace_ref!r} (nor {SESSION_PREFIX}ID)")
        trace = read_trace_h5(trace_ref)
    trace_file = trace_ref
    s = trace.summary()
    if csv_out is not None:
        write_atomic(csv_out, trace.to_csv())
    if rerun:
        s["rerun"] = do_rerun(trace)
    lines = [f"{trace_file}: {s['ticks']} ticks at {s['rate_hz']:g} Hz "
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


@haptic.command("sim-robot")
@click.option("--motion", type=click.Choice(["hold", "pull", "fastpull", "ellipse", "circle",
                                             "explore"]), default="explore", show_default=True)
@click.option("--mode", type=click.Choice(["realtime", "lockstep"]), default="realtime",
              show_default=True)
@click.option("--start", help="Start of the motion X,Y in m (robot frame).")
def sim_robot(motion: str, mode: str, start: str | None) -> None:
    """Run the simulated robot on a pty and print the port to give to 'serve --robot'."""
    from fieldbank.haptic.simrobot import PtyRobot, SimRobotConfig, serve_fd

    if start:
        x0, y0 = _pair(start, "--start")
    else:  # the rest hand position of the default (unimpaired) arm
        from fieldbank.model import Arm

        x0, y0 = (float(v) for v in Arm.from_params(ArmParams.from_anthropometry())
                  .rest_position())
    robot = PtyRobot(SimRobotConfig(mode=mode, motion=motion, x0_m=x0, y0_m=y0))
    click.echo(robot.port)
    try:
        serve_fd(robot.device, robot.master_fd)
    except KeyboardInterrupt:
        pass
    except OSError as exc:
        raise HapticError(f"simulated robot stopped: {exc}") from None
    finally:
        robot.close()
