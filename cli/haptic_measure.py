"""``fieldbank haptic measure``: measure a patient's maps on the robot and store them."""

from __future__ import annotations

from datetime import date
from pathlib import Path

import click

from fieldbank import measurechoices as mc
from fieldbank.cli.options import (
    DATE,
    SESSION_LABEL,
    db_option,
    emit_json,
    from_top,
    json_option,
    open_db,
    say,
    xy_metres,
)
from fieldbank.cli.progress import robot_time
from fieldbank.cli.table import wrap
from fieldbank.haptic.safety import SafetyConfig
from fieldbank.sanitize import printable


def _grid(text: str) -> tuple[int, int]:
    cols, sep, rows = text.lower().partition("x")
    try:
        return int(cols), int(rows if sep else cols)
    except ValueError:
        raise click.BadParameter(f"{text!r}: expected COLUMNSxROWS, e.g. 5x5") from None


@click.command("measure")
@db_option
@click.option("--robot", "url", required=True, default=from_top("--robot"),
              help="Robot port: /dev/ttyUSB0, a pty, socket://…, or sim://?patient=SPEC "
                   "(a virtual patient: model id, file:PATH or a severity).")
@click.option("--patient", "patient_code", required=True, help="Patient code (stored).")
@click.option("--session", "session_label", type=SESSION_LABEL, required=True,
              help="Session label.")
@click.option("--date", "session_date", type=DATE,
              help="Date of the session.")
@click.option("--protocol", "parts", multiple=True, type=click.Choice(mc.PARTS),
              help="Part(s) to measure (repeatable; default all three).")
@click.option("--grid", default="5x5", show_default=True, help="Postures, COLUMNSxROWS.")
@click.option("--spacing-mm", type=float, default=None,
              help="Distance between postures (default: 7% of the patient's arm length).")
@click.option("--centre", default=None,
              help="Grid centre X,Y in m, shoulder frame (default: the patient's hand at "
                   "shoulder 40°, elbow 80°).")
@click.option("--directions", type=int, default=mc.DIRECTIONS, show_default=True,
              help="Displacement directions per posture (stiffness).")
@click.option("--displacement-mm", type=float, default=mc.DISPLACEMENT_M * 1000,
              show_default=True, help="Size of each displacement (stiffness).")
@click.option("--hold-s", type=float, default=mc.HOLD_S, show_default=True,
              help="Hold after each displacement (stiffness).")
@click.option("--stretch-speed", type=float, default=mc.STRETCH_SPEED_M_PER_S,
              show_default=True,
              help="Hand speed of the stretch passes, m/s.")
@click.option("--shoulder", default="0,0", show_default=True,
              help="The shoulder's position in robot coordinates X,Y, m.")
@click.option("--force-limit-n", type=float, default=SafetyConfig.force_limit_n, show_default=True)
@click.option("--raw", "raw_out", type=click.Path(dir_okay=False, path_type=Path),
              help="Where to write the raw recording (NWB); default: the data directory.")
@click.option("--force", is_flag=True, help="Replace an existing --raw file.")
@click.option("--must-see", "must_see", default=None, metavar="GROUPS",
              help="Refuse, before the robot moves, a protocol that would not see these muscle "
                   "groups' passive force and stretch reflex (e.g. ef,bf; 'all').")
@json_option
def measure(db_url: str | None, url: str, patient_code: str, session_label: str,
            session_date: date | None, parts: tuple[str, ...], grid: str,
            spacing_mm: float | None, centre: str | None, directions: int,
            displacement_mm: float, hold_s: float, stretch_speed: float, shoulder: str,
            force_limit_n: float, raw_out: Path | None, force: bool, must_see: str | None,
            as_json: bool) -> None:
    """Measure PATIENT's postural and stiffness maps on the robot and store them.

    The robot holds the relaxed hand at each posture of the grid (postural), displaces it a
    few millimetres in several directions and holds (stiffness), and moves it through the
    postures at speed (stretch); every raw sample is kept in an NWB file, and the maps are
    estimated from it with their standard deviations (docs/measuring.md).
    """
    # the robot link and the estimator: when the command runs (--help stays light)
    from fieldbank.haptic.measure import MeasureConfig, measure_session
    from fieldbank.haptic.safety import SafetyConfig
    from fieldbank.measure.protocol import ProtocolConfig
    from fieldbank.measure.visibility import parse_groups

    protocol = ProtocolConfig(parts=parts or mc.PARTS, grid=_grid(grid),
                              spacing_m=None if spacing_mm is None else spacing_mm / 1000,
                              centre_m=None if centre is None else xy_metres(centre, "--centre"),
                              displacement_m=displacement_mm / 1000, directions=directions,
                              hold_s=hold_s, stretch_speed_m_per_s=stretch_speed)
    cfg = MeasureConfig(shoulder_offset_m=xy_metres(shoulder, "--shoulder"),
                        safety=SafetyConfig(force_limit_n=force_limit_n, passivity=False))
    seen = parse_groups(must_see) if must_see else ()  # before the database opens
    with open_db(db_url) as db, robot_time("measuring") as progress:
        res = measure_session(db, url, patient_code, session_label, protocol, cfg, raw_out,
                              session_date, force, seen, say, progress)
    if as_json:
        emit_json({"robot_time_s": res.robot_time_s, "raw_file": res.raw_file,
                   "visibility": res.sight.to_dict() if res.sight else None,
                   "raw_sha256": res.raw_sha256, "trials": res.trials,
                   "trials_dropped": list(res.trials_dropped), **res.report.to_json_dict()})
    maps = sum(o.n_maps for o in res.report.outcomes)
    for note in res.notes:
        say(wrap(f"note: {note}"))
    say(wrap(f"measured {patient_code} / {printable(session_label)}: {res.trials} trials in "
             f"{res.robot_time_s / 60:.1f} min of robot time; {maps} map(s) stored; raw "
             f"recording {printable(res.raw_file)}"))
