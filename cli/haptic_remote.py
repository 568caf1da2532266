"""``fieldbank haptic remote``: feel a distant patient through a delayed, authenticated link.

``key`` writes a session key; ``patient`` runs the patient's site (its robot holds the
patient's hand); ``clinician`` runs the clinician's site (robot and station). Both sites read
the same key file; nothing from anyone without it is answered. Each site prints what happens
as it happens (engaged, link lost and back, faults, the other site's end) and, at the end, the
spans in which its force was held at zero and why; the exit status is 1 when the session did
not render what was asked (never engaged, a fault, the link lost, the other site's end).
"""

from __future__ import annotations

import logging
import sys
import urllib.parse
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from fieldbank.cli.options import (
    db_option,
    emit,
    from_top,
    json_option,
    open_db,
    option_group,
    say,
    xy_metres,
)
from fieldbank.haptic.remote.passivity import PASSIVITY_MODES
from fieldbank.haptic.rendererconfig import RENDERER_BOUNDS

# The link, the sites and the robot load inside the commands: '--help' starts at once.
if TYPE_CHECKING:
    from fieldbank.haptic.remote.config import SiteConfig

#: Port the patient's site listens on by default.
DEFAULT_PORT = 47400


def _address(text: str, name: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    host = host.strip("[]")
    try:
        n = int(port)
    except ValueError:
        n = -1
    if not sep or not host or not 0 <= n <= 65535:
        raise click.BadParameter(f"{name} must read HOST:PORT; got {text!r}")
    return host, n


def _whole(bound: float | None) -> int | None:
    return None if bound is None else int(bound)


#: The loop's rate: the renderer's range (the clinician's site is a rendering session).
_RATE = RENDERER_BOUNDS["rate_hz"]

link_options = option_group(
    click.option("--key", "key_file", required=True,
                 type=click.Path(dir_okay=False, path_type=Path),
                 help="The key both sites share ('fieldbank haptic remote key'); each "
                      "session's own keys are drawn from it and both sites' fresh values."),
    click.option("--rate-hz", type=click.IntRange(_whole(_RATE.low), _whole(_RATE.high)),
                 default=1000,
                 show_default=True, help="Loop and link rate (both sites the same: the "
                                         "handshake refuses a difference)."),
    click.option("--lockstep", is_flag=True,
                 help="Simulated clocks advancing together, faster than real time (both "
                      "robots simulated, mode=lockstep)."),
    click.option("--duration-s", type=click.FloatRange(min=0.001), default=None,
                 help="End after this long (default: the other site's BYE or Ctrl-C)."),
    click.option("--delay-ms", type=click.FloatRange(0, 2000), default=0.0, show_default=True,
                 help="Injected one-way delay of what this site receives (tests, benchmarks)."),
    click.option("--jitter-ms", type=click.FloatRange(0, 500), default=0.0, show_default=True,
                 help="Injected jitter (± uniform) of what this site receives."),
    click.option("--loss", type=click.FloatRange(0, 0.5), default=0.0, show_default=True,
                 help="Injected loss probability of what this site receives."),
    click.option("--impair-seed", type=int, default=0, show_default=True),
    click.option("--watchdog-ms", type=click.FloatRange(5, 2000), default=100.0,
                 show_default=True, help="No datagram for this long: the link is lost and "
                                         "the force ramps to zero."),
    click.option("--passivity", type=click.Choice(PASSIVITY_MODES), default="tdpa",
                 show_default=True, help="The link's passivity controller (off: observe only)."),
    click.option("--force-limit-n", type=click.FloatRange(min=0.1, max=200.0), default=40.0,
                 show_default=True, help="This site's robot force limit."),
)


def _site(o: dict[str, Any]) -> SiteConfig:
    """The site's settings from :data:`link_options`."""
    from fieldbank.haptic.remote.channel import Impairment
    from fieldbank.haptic.remote.config import LinkConfig, SiteConfig
    from fieldbank.haptic.safety import SafetyConfig

    return SiteConfig(rate_hz=o["rate_hz"], lockstep=o["lockstep"],
                      link=LinkConfig(watchdog_s=o["watchdog_ms"] / 1000,
                                      passivity=o["passivity"]),
                      impairment=Impairment(o["delay_ms"] / 1000, o["jitter_ms"] / 1000,
                                            o["loss"], o["impair_seed"]),
                      safety=SafetyConfig(force_limit_n=o["force_limit_n"], passivity=False))


@click.group("remote")
def remote() -> None:
    """Remote assessment: the clinician's robot and the patient's, joined by a delayed link.

    Run 'patient' where the patient is (its robot holds the patient's hand), 'clinician'
    where the clinician is; both with the same --key file (docs/remote.md).
    """


@remote.command("key")
@click.option("--out", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="The key file to write (readable by you only; never over a file).")
def key_cmd(out: Path) -> None:
    """Write a new session key for both sites (copy it to the other site securely)."""
    from fieldbank.haptic.remote.wire import key_fingerprint, new_key, write_key

    key = new_key()
    write_key(out, key)
    say(f"session key written to {out} (fingerprint {key_fingerprint(key)}); give both sites "
        "the same file")


@remote.command("patient")
@click.option("--robot", required=True, default=from_top("--robot"),
              help="The patient's robot, with a force sensor at its handle: a port, an "
                   "installed adapter's URL, or sim://?patient=SPEC (a simulated patient: a "
                   "stored model id, file:PATH or a severity such as elbow=severe).")
@click.option("--bind", default=f"127.0.0.1:{DEFAULT_PORT}", show_default=True,
              help="HOST:PORT to listen on (0.0.0.0:PORT for other machines).")
@click.option("--shoulder", help="The patient's shoulder in robot coordinates X,Y, m (a "
                                 "simulated patient's comes from its URL).")
@click.option("--drawing", "drawing_file", type=click.Path(exists=True, path_type=Path),
              help="Arm parameters whose geometry the clinician's station draws (default: "
                   "the simulated patient's, else the default body).")
@click.option("--log-dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Where this site's link log goes (default: traces/ in the data directory).")
@click.option("--wait-s", type=click.FloatRange(min=0.1), default=600.0, show_default=True,
              help="How long to wait for the clinician.")
@link_options
@json_option
def patient(robot: str, bind: str, shoulder: str | None, drawing_file: Path | None,
            log_dir: Path | None, wait_s: float, key_file: Path, as_json: bool,
            **link: Any) -> None:
    """Run the patient's site: its robot follows the distant clinician's hand."""
    from fieldbank.haptic import session
    from fieldbank.haptic.remote.patient_site import serve_patient, sim_patient
    from fieldbank.haptic.remote.wire import read_key
    from fieldbank.modelsource import from_file, synthetic

    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(levelname)s %(message)s")
    description = ""
    if robot.startswith("sim://") and "patient=" in urllib.parse.urlsplit(robot).query:
        robot, params, shoulder_m, description = sim_patient(robot)
    else:
        if shoulder is None:
            raise click.UsageError("--shoulder X,Y is needed for a robot other than a "
                                   "simulated patient's")
        params, shoulder_m = synthetic(()).params, xy_metres(shoulder, "--shoulder")
    if shoulder is not None:
        shoulder_m = xy_metres(shoulder, "--shoulder")
    if drawing_file is not None:
        params = from_file(drawing_file).params
    res = serve_patient(robot, read_key(key_file), _address(bind, "--bind"), params, shoulder_m,
                        config=_site(link), duration_s=link["duration_s"], wait_s=wait_s,
                        log_dir=log_dir or session.default_trace_dir(),
                        description=description, say=say)
    emit(res.summary | {"log_file": res.log_file}, as_json,
         f"patient's site: {res.ticks} ticks; {res.summary['reason']}"
         + (f"\nlog: {res.log_file}" if res.log_file else ""))
    _exit_unless_complete(res.account.complete)


@remote.command("clinician")
@click.option("--robot", required=True, default=from_top("--robot"),
              help="The clinician's robot: a port, or sim://?… (simulated).")
@click.option("--peer", required=True, help="The patient's site, HOST:PORT.")
@click.option("--bind", help="Local HOST:PORT (default: any free port).")
@click.option("--shoulder-offset", help="Where the patient's shoulder is drawn in this "
                                        "robot's frame, X,Y in m.")
@click.option("--trace-dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Directory of the trace and link files (default: traces/ in the data "
                   "directory).")
@db_option
@click.option("--patient", "patient_code", help="Patient code the session belongs to.")
@click.option("--patient-note", help="Why the session is filed under that patient.")
@click.option("--no-db", is_flag=True, help="Write the files only, not the database.")
@click.option("--station", is_flag=True, help="Serve the clinician's station (prints its "
                                              "address).")
@click.option("--station-host", default="127.0.0.1", show_default=True)
@click.option("--station-port", type=click.IntRange(0, 65535), default=0)
@click.option("--station-allow-remote", is_flag=True,
              help="Allow a --station-host other machines can reach (unencrypted).")
@click.option("--candidate-levels", default="very mild,mild,moderate,severe",
              show_default=True, help="Severities the station's classifier considers.")
@click.option("--wait-s", type=click.FloatRange(min=0.1), default=30.0, show_default=True,
              help="How long to wait for the patient's site.")
@link_options
@json_option
def clinician(robot: str, peer: str, bind: str | None, shoulder_offset: str | None,
              trace_dir: Path | None, db_url: str | None, patient_code: str | None,
              patient_note: str | None, no_db: bool, station: bool, station_host: str,
              station_port: int, station_allow_remote: bool, candidate_levels: str,
              wait_s: float, key_file: Path, as_json: bool, **link: Any) -> None:
    """Run the clinician's site: feel the distant patient through the link."""
    from fieldbank.haptic import session
    from fieldbank.haptic.remote.clinician_site import AssessOptions, serve_clinician
    from fieldbank.haptic.remote.wire import read_key
    from fieldbank.haptic.station.launch import StationOptions

    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(levelname)s %(message)s")
    opts = StationOptions(station_host, station_port, station_allow_remote) if station else None
    levels = tuple(v.strip() for v in candidate_levels.split(",") if v.strip())
    res = serve_clinician(
        robot, read_key(key_file), _address(peer, "--peer"), config=_site(link),
        bind=_address(bind, "--bind") if bind else None,
        shoulder_offset_m=xy_metres(shoulder_offset, "--shoulder-offset"),
        duration_s=link["duration_s"], station=opts, assess=AssessOptions(levels=levels),
        trace_dir=trace_dir or session.default_trace_dir(), patient_code=patient_code,
        patient_note=patient_note, db=None if no_db else (lambda: open_db(db_url)),
        wait_s=wait_s, say=say)
    out = res.session.summary() | {"link": res.link_summary["link"],
                                   "account": res.link_summary["account"],
                                   "link_events": res.link_summary["events"],
                                   "link_file": res.link_file,
                                   "passivity_active_ticks":
                                       res.link_summary["passivity_active_ticks"],
                                   "passivity_dissipated_j":
                                       res.link_summary["passivity_dissipated_j"],
                                   "assessments": res.assessments}
    lk = res.link_summary["link"]
    emit(out, as_json,
         f"clinician's site: {len(res.session.trace)} ticks, max force "
         f"{out['max_force_n']:.2f} N; link round trip {lk['rtt_ms']} ms, "
         f"{lk['loss_fraction']:.1%} lost; passivity controller on "
         f"{res.link_summary['passivity_active_ticks']} ticks\ntrace: "
         f"{res.session.trace_file}\nlink: {res.link_file}"
         + (f"\ndatabase: {res.session.database}" if res.session.database else ""))
    _exit_unless_complete(res.account.complete)


def _exit_unless_complete(complete: bool) -> None:
    """Exit status 1 after a session that did not render what was asked (its account, printed
    on stderr, says why)."""
    if not complete:
        say("the session did not render what was asked (see above)")
        click.get_current_context().exit(1)

