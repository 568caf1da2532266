"""``fieldbank ingest``: read lab files into the database, all or nothing."""

from __future__ import annotations

import stat
from datetime import date
from pathlib import Path
from typing import TYPE_CHECKING

import click

from fieldbank.cli.options import (
    DATE,
    SESSION_LABEL,
    db_option,
    emit_json,
    json_option,
    open_db,
    xy_metres,
)
from fieldbank.sanitize import printable

if TYPE_CHECKING:  # typing only; tqdm loads when a batch is large enough to show a bar
    from tqdm import tqdm

#: Show a progress bar from this many files on (on a terminal).
PROGRESS_MIN_FILES = 20
#: A file this small is read to see whether it holds only blank lines.
_BLANK_CHECK_BYTES = 4096


def _is_empty(path: Path) -> bool:
    """A regular file of no bytes, or only white space (anything else - missing, a device,
    a link's target - is the reader's to refuse)."""
    try:
        st = path.stat()
        if not stat.S_ISREG(st.st_mode):
            return False
        return st.st_size == 0 or (st.st_size <= _BLANK_CHECK_BYTES
                                   and not path.read_bytes().strip())
    except OSError:
        return False


@click.command("ingest")
@db_option
@click.argument("files", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option("--patient", "patient_code", required=True, help="Patient code.")
@click.option("--session", "session_label", type=SESSION_LABEL, required=True,
              help="Session label, e.g. pre-BoNT (created if new).")
@click.option("--date", "session_date", type=DATE,
              help="Date of the session.")
@click.option("--dry-run", is_flag=True, help="Validate and report; store nothing.")
@click.option("--limit", "limit_items", multiple=True, metavar="NAME=VALUE",
              help="Override an ingest limit (repeatable): max_file_bytes, "
                   "max_decompressed_bytes, max_compression_ratio, max_rows, max_maps, "
                   "max_problems, max_force_n, max_stiffness_n_per_m (docs/formats.md).")
@click.option("--kind", type=click.Choice(["postural", "stiffness"]),
              help="Kind of map, for files that do not say (a file saying otherwise is refused).")
@click.option("--frame", type=click.Choice(["shoulder"]), help="Frame, for files that do not say.")
@click.option("--sign", type=click.Choice(["arm-on-handle", "handle-on-arm"]),
              help="Whose force, for files that do not say.")
@click.option("--velocity", metavar="SPEED|VX,VY",
              help="Endpoint velocity of a stiffness map in m/s (0 = static), for files that "
                   "do not say.")
@click.option("--column", "columns", multiple=True, metavar="NAME=HEADER",
              help="Read the file's column (or raw channel) HEADER as NAME, e.g. x_mm=HandX, "
                   "fx_n=ForceX; for C3D recordings NAME is x, y, vx, vy, fx, fy and HEADER an "
                   "analog label or MARKER:x; for NWB position, velocity, force and HEADER a "
                   "series' name or path; for MAT files a variable (repeatable).")
@click.option("--shoulder", metavar="X,Y",
              help="Raw recordings: the shoulder's position in the file's coordinates, m "
                   "(required for KINARM exams).")
@click.option("--trial-events", "trial_events", multiple=True, metavar="LABEL",
              help="Raw recordings: the events (by label) that start a trial; other events "
                   "are ignored (repeatable).")
@click.option("--unit", "units", multiple=True, metavar="ROLE=UNIT",
              help="Raw recordings: the unit of a channel the file states none for, e.g. "
                   "fx=N, position=mm (repeatable; never overrides a unit the file states).")
@json_option
def ingest(db_url: str | None, files: tuple[str, ...], patient_code: str, session_label: str,
           session_date: date | None, dry_run: bool, limit_items: tuple[str, ...],
           kind: str | None, frame: str | None, sign: str | None, velocity: str | None,
           columns: tuple[str, ...], shoulder: str | None, trial_events: tuple[str, ...],
           units: tuple[str, ...], as_json: bool) -> None:
    """Ingest postural and stiffness maps from FILES (CSV, HDF5, MATLAB .mat v5/v7.3), or
    raw NWB, C3D and KINARM recordings whose maps are estimated (docs/measuring.md).

    Every file is validated first; any problem anywhere stores nothing. A file already
    stored (same SHA-256) is reported and not stored again.
    """
    from fieldbank.ingest import IngestLimits, ReadOptions, ingest_paths  # readers: when it runs

    empty = [f for f in files if _is_empty(Path(f))]
    if empty:  # before the database opens; a file of nothing is empty, not of unknown format
        raise click.ClickException(
            "Nothing was stored: " + ", ".join(printable(f) for f in empty)
            + (" is" if len(empty) == 1 else " are") + " empty (no bytes, or only blank "
            "lines): nothing to read. Was it exported completely?")
    limits = IngestLimits.from_environment(limit_items)
    options = ReadOptions.from_flags(kind, frame, sign, velocity, columns,
                                     xy_metres(shoulder, "--shoulder") if shoulder else None,
                                     trial_events, units)
    bar: tqdm | None = None
    if len(files) >= PROGRESS_MIN_FILES:
        from tqdm import tqdm

        bar = tqdm(total=2 * len(files), unit="step", disable=None, leave=False,
                   desc="validate+store")

    def progress(done: int, total: int, name: str) -> None:
        if bar is not None:
            bar.n = done
            bar.refresh()

    try:
        with open_db(db_url) as db:
            report = ingest_paths(db, [Path(f) for f in files], patient_code, session_label,
                                  session_date, dry_run, progress, limits, options)
    finally:
        if bar is not None:
            bar.close()
    if as_json:
        emit_json(report.to_json_dict())
    for o in report.outcomes:
        if o.status == "duplicate":
            click.echo(f"{printable(o.file_name)}: already stored (SHA-256 "
                       f"{o.sha256[:12]}…), skipped", err=True)
    verb = "would store" if dry_run else "stored"
    n = report.n_stored if not dry_run else sum(o.status == "would-store"
                                                for o in report.outcomes)
    click.echo(f"{verb} {n} file(s) for {report.patient_code} / "
               f"{printable(report.session_label)}; "
               f"{report.n_duplicates} duplicate(s)", err=True)
