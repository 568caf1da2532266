"""Start-up cost of the command line, as ratios to ``python -c "import click"`` in the same run.

Each command runs as a fresh process, as a user starts it. Its CPU time (user + system of the
child) and wall time are compared with the baseline ``python -c "import click"`` measured in
the same run, interleaved round by round so that a busy machine slows every command alike.
Targets are judged on CPU time (a shared machine's wall time says as much about the neighbours
as about the command); both are printed, with the load average before and after.

* commands that open no database: ``--version``, ``--help``, ``haptic switch B`` (the live
  command a clinician sends to a running renderer; no renderer runs here, so it exits with
  "no renderer" after the same imports and argument parsing) and every command's and
  subcommand's ``--help``;
* the commands that list what a database holds - ``patient list``, ``models list``,
  ``maps list``, ``plans list``, ``jobs`` - on a database of ``--patients`` patients (default
  100) that this script builds first: per patient a session of measured maps (the synthetic
  patients' postural and stiffness maps, ingested as CSV files), the model they were made from,
  a botulinum plan applied to it, and a task in a batch run (every tenth one failed);
* for information, ``import click`` + a SQLAlchemy round trip (open the same database, read one
  row): what any command that goes through SQLAlchemy pays before it does anything.

Target: each command ≤ 3× the CPU time of ``import click`` on the embedded (SQLite) database.
On PostgreSQL the reads are printed for information beside ``import click, psycopg``: the
driver's own import is part of any command that talks to the server.

Run: python benchmarks/bench_cli_startup.py [--rounds N] [--patients N] [--quick]
     [--pg-server URL]   # also on PostgreSQL: a fresh database on that server, dropped after
"""

from __future__ import annotations

import argparse
import hashlib
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

TARGET_RATIO = 3.0
CLICK = 'python -c "import click" (baseline)'
ROUND_TRIP = "import click + SQLAlchemy round trip (information)"
DRIVER = "import click + psycopg (information)"
#: The commands that list what the database holds.
READS = ("patient list", "models list", "maps list", "plans list", "jobs")

_ROUND_TRIP_CODE = """
import sys
import click
from sqlalchemy import create_engine, text
engine = create_engine(sys.argv[1])
with engine.connect() as conn:
    conn.execute(text("SELECT code FROM patients LIMIT 1")).all()
"""


def _fieldbank() -> list[str]:
    exe = Path(sys.executable).with_name("fieldbank")
    if exe.exists():
        return [str(exe)]
    found = shutil.which("fieldbank")
    if found is None:
        raise SystemExit("the fieldbank command is not installed (run scripts/setup)")
    return [found]


def _time(cmd: list[str], env: dict[str, str]) -> tuple[float, float, int]:
    """(wall s, CPU s of the child, exit status) of one run."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                          check=False)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, done.returncode


def _help_commands(quick: bool) -> list[list[str]]:
    """Every command and subcommand, as argument lists (``[]`` is the top level)."""
    import click

    from fieldbank.cli.main import cli

    out: list[list[str]] = []

    def walk(group: click.Group, path: list[str]) -> None:
        ctx = click.Context(group, info_name="fieldbank")
        for name in group.list_commands(ctx):
            out.append([*path, name])
            cmd = group.get_command(ctx, name)
            if isinstance(cmd, click.Group) and not quick:
                walk(cmd, [*path, name])

    walk(cli, [])
    return out


def build_cohort(url: str, n: int) -> None:
    """``n`` synthetic patients with maps, a model, a plan and a batch-run task each."""
    from fieldbank.fitting.synthetic import impaired_params, synthetic_patient
    from fieldbank.interventions import Botulinum, Plan
    from fieldbank.interventions.whatif import save_plan
    from fieldbank.modelsource import stored
    from fieldbank.params import ArmParams
    from fieldbank.storage import Database, IncomingFile

    codes = [f"SYN-{i + 1:03d}" for i in range(n)]
    plan = Plan((Botulinum({"ef": 100.0}),))
    with Database.open(url, upgrade="always") as db:
        run = db.start_run("fit", "local processes (2)", {"all": True},
                           [(f"{c}/pre", c, "pre") for c in codes])
        base = ArmParams.from_anthropometry()
        for i, code in enumerate(codes):
            db.add_patient(code, 55.0 + i % 40, 1.55 + (i % 9) * 0.04,
                           "right" if i % 3 else "left")
            truth = impaired_params(("elbow", "shoulder")[i % 2],
                                    ("mild", "moderate", "severe")[i % 3], base)
            files = []
            for k, m in enumerate(synthetic_patient(truth, seed=i, patient=code).maps):
                data = m.to_csv().encode()
                files.append(IncomingFile(f"{code}-{k}.csv", hashlib.sha256(data).hexdigest(),
                                          "csv", data, (m,)))
            db.ingest_files(code, "pre", files)
            model = db.add_model(truth, "synthetic", f"truth of {code}", patient_code=code)
            save_plan(db, stored(db, model.id), plan)
            job = db.start_job(run.id, f"{code}/pre", "worker-1")
            db.finish_job(run.id, f"{code}/pre", "failed" if i % 10 == 9 else "done",
                          {"model_id": model.id}, "stopped" if i % 10 == 9 else None,
                          attempt=job.attempts)
        db.finish_run(run.id)


@contextmanager
def _pg_database(server: str) -> Iterator[str]:
    """A fresh database on the PostgreSQL server at ``server``, dropped afterwards."""
    from sqlalchemy import create_engine, text
    from sqlalchemy.engine import make_url

    name = f"fbbench_{uuid.uuid4().hex[:12]}"
    admin = create_engine(server, isolation_level="AUTOCOMMIT")
    with admin.connect() as c:
        c.execute(text(f'CREATE DATABASE "{name}"'))
    try:
        yield make_url(server).set(database=name).render_as_string(hide_password=False)
    finally:
        with admin.connect() as c:
            c.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        admin.dispose()


def _measure(cases: dict[str, list[str]], env: dict[str, str],
             rounds: int) -> tuple[dict[str, float], dict[str, float]]:
    """Median wall and CPU seconds per case, the cases interleaved round by round."""
    for name, cmd in cases.items():  # warm the file cache once; a read must succeed
        _, _, status = _time(cmd, env)
        if status != 0 and name != "fieldbank haptic switch B":
            raise SystemExit(f"{name} failed (exit {status}): {' '.join(cmd)}")
    wall: dict[str, list[float]] = {k: [] for k in cases}
    cpu: dict[str, list[float]] = {k: [] for k in cases}
    for _ in range(rounds):
        for name, cmd in cases.items():
            w, c, _ = _time(cmd, env)
            wall[name].append(w)
            cpu[name].append(c)
    return ({k: statistics.median(v) for k, v in wall.items()},
            {k: statistics.median(v) for k, v in cpu.items()})


def _table(title: str, names: list[str], wall: dict[str, float], cpu: dict[str, float]) -> float:
    """Print the rows of ``names`` against the click baseline; the worst CPU ratio."""
    print(f"\n{title}")
    print(f"{'command':<56} {'CPU ms':>7} {'x click':>8} {'wall ms':>8} {'x click':>8}")
    worst = 0.0
    for name in names:
        rc = cpu[name] / cpu[CLICK]
        rw = wall[name] / wall[CLICK]
        print(f"{name[:56]:<56} {cpu[name] * 1000:7.1f} {rc:7.2f}x {wall[name] * 1000:8.1f} "
              f"{rw:7.2f}x")
        if name not in (CLICK, ROUND_TRIP, DRIVER):
            worst = max(worst, rc)
    return worst


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--patients", type=int, default=100)
    ap.add_argument("--quick", action="store_true",
                    help="Top-level commands' --help only (not every subcommand).")
    ap.add_argument("--pg-server", metavar="URL", default=None,
                    help="Also measure the reads on a fresh database on this PostgreSQL server.")
    args = ap.parse_args()
    fb = _fieldbank()
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        home = Path(tmp)
        sqlite_url = f"sqlite:///{home / 'fieldbank.sqlite3'}"
        t0 = time.perf_counter()
        build_cohort(sqlite_url, args.patients)
        print(f"built a database of {args.patients} patients in "
              f"{time.perf_counter() - t0:.0f} s", file=sys.stderr)
        env = {k: v for k, v in os.environ.items() if k != "FIELDBANK_DB"}
        env["FIELDBANK_HOME"] = str(home)
        sock = str(home / "no-renderer.sock")
        cases: dict[str, list[str]] = {
            CLICK: [sys.executable, "-c", "import click"],
            ROUND_TRIP: [sys.executable, "-c", _ROUND_TRIP_CODE, sqlite_url],
            **{f"fieldbank {c}": [*fb, *c.split()] for c in READS},
            "fieldbank --version": [*fb, "--version"],
            "fieldbank --help": [*fb, "--help"],
            "fieldbank haptic switch B": [*fb, "haptic", "switch", "B", "--socket", sock],
        }
        for path in _help_commands(args.quick):
            cases[f"fieldbank {' '.join(path)} --help"] = [*fb, *path, "--help"]
        wall, cpu = _measure(cases, env, args.rounds)
        load1 = os.getloadavg()
        print(f"load average (1, 5, 15 min): before {load0[0]:.2f} {load0[1]:.2f} "
              f"{load0[2]:.2f}, after {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}; "
              f"{os.cpu_count()} cores; {args.rounds} rounds, medians; {args.patients} patients")
        reads = [CLICK, ROUND_TRIP, *(f"fieldbank {c}" for c in READS)]
        worst_reads = _table("commands that list the database (SQLite file)", reads, wall, cpu)
        light = [k for k in cases if k not in reads]
        worst_light = _table("commands that open no database", [CLICK, *light], wall, cpu)
        print()
        ok = True
        for what, worst in (("listing (SQLite)", worst_reads), ("no database", worst_light)):
            verdict = "meets" if worst <= TARGET_RATIO else "MISSES"
            ok &= worst <= TARGET_RATIO
            print(f"worst CPU ratio, {what}: {worst:.2f}x import click ({verdict} the "
                  f"{TARGET_RATIO:g}x target)")
        if args.pg_server:
            sys.stdout.flush()
            with _pg_database(args.pg_server) as pg_url:
                build_cohort(pg_url, args.patients)
                pg_cases = {
                    CLICK: cases[CLICK],
                    DRIVER: [sys.executable, "-c", "import click, psycopg"],
                    ROUND_TRIP: [sys.executable, "-c", _ROUND_TRIP_CODE, pg_url],
                    **{f"fieldbank {c} (PostgreSQL)": [*fb, *c.split(), "--db", pg_url]
                       for c in READS},
                }
                load2 = os.getloadavg()
                pg_wall, pg_cpu = _measure(pg_cases, env, args.rounds)
                load3 = os.getloadavg()
            print(f"\nload average (1, 5, 15 min): before {load2[0]:.2f} {load2[1]:.2f} "
                  f"{load2[2]:.2f}, after {load3[0]:.2f} {load3[1]:.2f} {load3[2]:.2f}")
            worst_pg = _table("commands that list the database (PostgreSQL)", list(pg_cases),
                              pg_wall, pg_cpu)
            driver = pg_cpu[DRIVER] / pg_cpu[CLICK]
            print(f"\nworst CPU ratio, listing (PostgreSQL): {worst_pg:.2f}x import click, of "
                  f"which importing the driver (psycopg) is {driver:.2f}x (information: the "
                  "target is set on the embedded database)")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
