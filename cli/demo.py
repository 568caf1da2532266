"""``fieldbank demo``: ingest, fit, what-if, report and a simulated haptic session on a fresh
embedded database and the shipped synthetic sample data (see :mod:`fieldbank.demo`)."""

from __future__ import annotations

import time

import click

from fieldbank.demo import run_demo


@click.command("demo")
@click.option("--out", "out_dir", default="demo-out", show_default=True,
              type=click.Path(file_okay=False), help="Directory for everything the demo writes.")
@click.option("--home", default=None, type=click.Path(file_okay=False),
              help="Data directory of the fresh database (default: OUT/home).")
@click.option("--force", is_flag=True,
              help="Start over in a data directory a previous demo left behind.")
@click.option("--jobs", type=click.IntRange(min=1), default=None,
              help="Worker processes for the report (default: the cores available).")
@click.option("--haptic-seconds", type=click.FloatRange(min=0.5, max=30.0), default=3.0,
              show_default=True, help="Length of the simulated haptic session.")
def demo(out_dir: str, home: str | None, force: bool, jobs: int | None,
         haptic_seconds: float) -> None:
    """Run the whole product once on synthetic sample data, saying what it does."""
    t0 = time.perf_counter()

    def say(msg: str) -> None:
        click.echo(f"[{time.perf_counter() - t0:5.1f} s] {msg}", err=True)

    res = run_demo(out_dir, home, force, jobs, haptic_seconds, say)
    say(f"done: report {res.report_dir / 'report.html'}; database {res.home}; "
        f"total {time.perf_counter() - t0:.1f} s")
    click.echo(f"next: FIELDBANK_HOME={res.home} fieldbank report --kind botulinum "
               f"--out {res.report_dir}-botulinum", err=True)
