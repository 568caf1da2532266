"""Start-up time of the command line, as ratios to baselines run in the same process.

Each command runs as a fresh process, as a user starts it; its wall time and CPU time (user +
system of the child) are compared with a baseline measured in the same run, interleaved round
by round so that a busy machine slows both alike:

* ``python -c "import click"`` for the commands that open no database: ``--version``,
  ``--help``, ``haptic switch B`` (the live command a clinician sends to a running renderer; no
  renderer runs here, so it exits with "no renderer" after the same imports and argument
  parsing) and every command's and subcommand's ``--help``;
* ``import click`` + a database round trip (SQLAlchemy opens the same SQLite file and reads
  one row) for the commands that read the database: ``patient list``, ``models list``,
  ``maps list``, ``plans list``.

Target: each ≤ 3× its baseline. Printed with the load average before and after.
Run: python benchmarks/bench_cli_startup.py [--rounds N] [--quick]
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_RATIO = 3.0
CLICK = 'python -c "import click" (baseline)'
ROUND_TRIP = "import click + database round trip (baseline)"

_ROUND_TRIP_CODE = """
import sys
import click
from sqlalchemy import create_engine, text
engine = create_engine("sqlite:///" + sys.argv[1])
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


def _time(cmd: list[str], env: dict[str, str]) -> tuple[float, float]:
    """(wall s, CPU s of the child) of one run."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   check=False)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


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


def _make_database(home: Path) -> Path:
    """A database at head with a patient, two models and a plan (what the reads list)."""
    from fieldbank.interventions import Botulinum, Plan
    from fieldbank.interventions.whatif import save_plan
    from fieldbank.modelsource import synthetic
    from fieldbank.storage import Database

    path = home / "fieldbank.sqlite3"
    with Database.open(f"sqlite:///{path}") as db:
        db.add_patient("P-1", 70.0, 1.7, "right")
        save_plan(db, synthetic(["elbow=severe"]), Plan((Botulinum({"ef": 100.0}),)))
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--quick", action="store_true",
                    help="Top-level commands' --help only (not every subcommand).")
    args = ap.parse_args()
    fb = _fieldbank()
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        home = Path(tmp)
        db_file = _make_database(home)
        env = {k: v for k, v in os.environ.items() if k != "FIELDBANK_DB"}
        env["FIELDBANK_HOME"] = str(home)
        sock = str(home / "no-renderer.sock")
        light: dict[str, list[str]] = {
            CLICK: [sys.executable, "-c", "import click"],
            "fieldbank --version": [*fb, "--version"],
            "fieldbank --help": [*fb, "--help"],
            "fieldbank haptic switch B": [*fb, "haptic", "switch", "B", "--socket", sock],
        }
        for path in _help_commands(args.quick):
            light[f"fieldbank {' '.join(path)} --help"] = [*fb, *path, "--help"]
        reads: dict[str, list[str]] = {
            ROUND_TRIP: [sys.executable, "-c", _ROUND_TRIP_CODE, str(db_file)],
            **{f"fieldbank {c}": [*fb, *c.split()] for c in
               ("patient list", "models list", "maps list", "plans list")},
        }
        cases = {**light, **reads}
        for cmd in cases.values():  # warm the file cache once
            _time(cmd, env)
        wall: dict[str, list[float]] = {k: [] for k in cases}
        cpu: dict[str, list[float]] = {k: [] for k in cases}
        for _ in range(args.rounds):
            for name, cmd in cases.items():
                w, c = _time(cmd, env)
                wall[name].append(w)
                cpu[name].append(c)
    load1 = os.getloadavg()
    med = {k: statistics.median(v) for k, v in wall.items()}
    cmed = {k: statistics.median(v) for k, v in cpu.items()}
    print(f"load average (1, 5, 15 min): before {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}, "
          f"after {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}; {os.cpu_count()} cores; "
          f"{args.rounds} rounds, medians")
    print(f"{'command':<58} {'wall ms':>8} {'x base':>7} {'CPU ms':>8} {'x base':>7}")
    worst: dict[str, tuple[float, str]] = {}
    for group, base in ((light, CLICK), (reads, ROUND_TRIP)):
        for name in group:
            r = med[name] / med[base]
            rc = cmed[name] / cmed[base] if cmed[base] > 0 else float("nan")
            print(f"{name[:58]:<58} {med[name] * 1000:8.1f} {r:6.2f}x {cmed[name] * 1000:8.1f} "
                  f"{rc:6.2f}x")
            if name != base and r > worst.get(base, (0.0, ""))[0]:
                worst[base] = (r, name)
    for base, (r, name) in worst.items():
        verdict = "meets" if r <= TARGET_RATIO else "MISSES"
        print(f"worst against {base}: {r:.2f}x ({name}; {verdict} the {TARGET_RATIO:g}x target)")


if __name__ == "__main__":
    main()
