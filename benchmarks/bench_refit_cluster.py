"""Benchmark: a cohort refit on a real Dask cluster with TLS, judged on CPU time.

Target (BRIEF §17, docs/scale-out.md): a refit of 10,000 sessions in ≤ 1 hour on 16 cores; the
engine's bookkeeping ≤ 2 % of a task; scaling efficiency ≥ 0.85 at 2 workers.

Unlike ``bench_cluster.py`` (a ``LocalCluster`` inside the benchmark's process), every part
here is its own process, started as docs/scale-out.md tells a clinic to start them:

* the cluster's certificates from :func:`fieldbank.clustercerts.write_certs` (what
  ``fieldbank cluster certs`` writes);
* ``dask scheduler --protocol tls`` with the scheduler's certificate, and W ``dask worker``
  processes (one thread each, each under its nanny) with the workers' certificate, all with
  ``DASK_CONFIG`` naming the ``dask.yaml`` written beside the certificates
  (``--dask-defaults``: without it, Dask's defaults);
* the refit itself: ``fieldbank fit --all --scheduler tls://… --tls-ca … --tls-cert …
  --tls-key … --seed S --db URL``, the command a user types, as a process.

The database is a PostgreSQL database of its own (``--database`` on the server of ``--db``;
made when missing) holding ``--sessions`` sessions of synthetic patients (two sessions each,
``tests/cohort_helpers.py``: noisy postural and stiffness maps through the real ingest). It is
built once and kept; each configuration refits every session with its own seed, so none finds
another's fits. Before the clock starts, each cluster fits one patient with another seed: the
workers import fieldbank and open their database handle, as they do once in their life.

Measured, for each number of workers: the CPU time of every process of the cluster (psutil,
before and after the command: the worker processes, their nannies, the scheduler, the
command), the wall time, and from the job rows of the run (``jobs``) each task's time and the
fit's own (``fit_s``, ``fit_cpu_s`` in the job's result: the CPU of the thread that fitted),
and from the scheduler Dask's own count of the CPU of the threads that ran the tasks. Then:

* sessions per CPU-second of the workers (worker processes and nannies), and of the whole
  cluster (scheduler and command included);
* scaling efficiency on CPU time: the 2-worker figure over the 1-worker one (1.0: a second
  worker costs nothing beyond its fits); beside it, the same on wall time, which on a shared
  machine says more about the neighbours than about the cluster;
* the overhead per task: a worker's CPU per session less the fit's own CPU (the engine's
  bookkeeping, Dask's protocol and TLS, the nanny's and the worker's heartbeats), and the
  task's own work around its fit: the task thread's CPU less the fit's (the session's maps
  read, the fit key looked up, the fit and its model stored, the job marked; the marks alone,
  the engine's bookkeeping, are ``bench_bookkeeping.py``'s: target ≤ 2 % of a task);
* a 10,000-session refit on 16 and 64 cores, a worker per core: 10,000 × one worker's CPU
  per session (whole cluster) / (cores × efficiency), and what the single scheduler's CPU per
  task allows.

Run: python benchmarks/bench_refit_cluster.py [--sessions 50] [--workers 1 2]
                                              [--database fbrefit] [--db SERVER_URL]
                                              [--dask-defaults] [--stop-at HH:MM]
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import NamedTuple

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.timing import load_line

TARGET_EFFICIENCY = 0.85
TARGET_BOOKKEEPING = 0.02
TARGET_HOURS_16 = 1.0
SESSIONS = 10_000
IDLE_S = 20.0
BIN = Path(sys.executable).parent


class Run(NamedTuple):
    workers: int
    sessions: int
    wall_s: float
    worker_cpu_s: float  # the worker processes
    nanny_cpu_s: float
    scheduler_cpu_s: float
    command_cpu_s: float
    task_cpu_s: float  # Dask's count: the threads that ran the tasks
    fit_cpu_s: list[float]
    fit_wall_s: list[float]
    job_wall_s: list[float]  # started_at .. finished_at of each job row
    idle_workers_cps: float  # CPU-s per second of the idle cluster: workers and nannies
    idle_scheduler_cps: float
    command: str
    load_start: str
    load_end: str

    @property
    def cluster_cpu_s(self) -> float:
        return self.worker_cpu_s + self.nanny_cpu_s + self.scheduler_cpu_s + self.command_cpu_s

    def per_cpu_s(self, cpu: float) -> float:
        return self.sessions / cpu


def ensure_database(server_url: str, name: str) -> str:
    """The URL of database ``name`` on the server, made when it is not there."""
    from sqlalchemy import create_engine, text
    from sqlalchemy.engine import make_url

    admin = create_engine(server_url, isolation_level="AUTOCOMMIT")
    with admin.connect() as c:
        if c.scalar(text("SELECT 1 FROM pg_database WHERE datname = :n"), {"n": name}) is None:
            c.execute(text(f'CREATE DATABASE "{name}"'))
    admin.dispose()
    return make_url(server_url).set(database=name).render_as_string(hide_password=False)


def ensure_cohort(url: str, sessions: int) -> int:
    """At least ``sessions`` sessions with maps in the database (two per patient); returns how
    many it holds."""
    from fieldbank.storage import Database
    from tests.cohort_helpers import store_sessions

    with Database.open(url, create=True, upgrade="always") as db:
        have = len(db.list_patients())
        want = (sessions + 1) // 2
        if have < want:
            t = time.perf_counter()
            # patients numbered on from those stored: same seed stream, new codes
            store_sessions(db, want - have, seed=have, prefix=f"R{have:05d}")
            print(f"stored {2 * (want - have)} sessions in {time.perf_counter() - t:.0f} s",
                  flush=True)
        return 2 * len(db.list_patients())


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _cpu(procs: Sequence[object]) -> float:
    """User + system CPU seconds of the processes, each counted alone."""
    import psutil

    total = 0.0
    for p in procs:
        assert isinstance(p, psutil.Process)
        t = p.cpu_times()
        total += t.user + t.system
    return total


@contextmanager
def cluster(certs: Path, workers: int, log: Path, dask_env: Mapping[str, str] | None = None,
            ) -> Iterator[tuple[str, object, list[object], list[object]]]:
    """A TLS scheduler and ``workers`` worker processes (one thread each, under a nanny), as
    processes of their own, with the ``DASK_*`` variables of ``dask_env`` (none: Dask's
    defaults). Yields the address, the scheduler's process, the workers' and the nannies'."""
    import psutil

    env = {k: v for k, v in os.environ.items() if not k.startswith("DASK_")}
    env.update(dask_env or {})

    port = _free_port()
    addr = f"tls://127.0.0.1:{port}"
    out = log.open("ab")
    sched = subprocess.Popen(
        [str(BIN / "dask"), "scheduler", "--protocol", "tls", "--host", "127.0.0.1",
         "--port", str(port), "--no-dashboard", "--tls-ca-file", str(certs / "ca.pem"),
         "--tls-cert", str(certs / "scheduler.pem"), "--tls-key",
         str(certs / "scheduler-key.pem")], stdout=out, stderr=out, env=env)
    nannies = [subprocess.Popen(
        [str(BIN / "dask"), "worker", addr, "--nworkers", "1", "--nthreads", "1",
         "--no-dashboard", "--name", f"w{i}", "--tls-ca-file", str(certs / "ca.pem"),
         "--tls-cert", str(certs / "worker.pem"), "--tls-key", str(certs / "worker-key.pem")],
        stdout=out, stderr=out, env=env) for i in range(workers)]
    try:
        client = _client(addr, certs)
        client.wait_for_workers(workers, timeout=300)
        client.close()
        nanny_ps = [psutil.Process(p.pid) for p in nannies]
        worker_ps = [c for n in nanny_ps for c in n.children(recursive=True)]
        yield addr, psutil.Process(sched.pid), worker_ps, nanny_ps
    finally:
        for p in (*nannies, sched):
            p.terminate()
        for p in (*nannies, sched):
            try:
                p.wait(30)
            except subprocess.TimeoutExpired:
                p.kill()
        out.close()


def _client(addr: str, certs: Path) -> object:
    from distributed import Client
    from distributed.security import Security

    sec = Security(tls_ca_file=str(certs / "ca.pem"), tls_client_cert=str(certs / "client.pem"),
                   tls_client_key=str(certs / "client-key.pem"), require_encryption=True)
    return Client(addr, security=sec, timeout=300, set_as_default=False)  # a loaded machine


def _task_cpu(addr: str, certs: Path) -> float:
    """Dask's count of the CPU the task threads spent executing tasks, all workers together."""
    client = _client(addr, certs)
    try:
        metrics = client.run_on_scheduler(  # type: ignore[attr-defined]
            lambda dask_scheduler: dict(dask_scheduler.cumulative_worker_metrics))
    finally:
        client.close()  # type: ignore[attr-defined]
    return float(sum(v for k, v in metrics.items() if isinstance(k, tuple) and len(k) == 4
                     and k[0] == "execute" and k[2] == "thread-cpu"))


def _fit_command(url: str, addr: str, certs: Path, seed: int,
                 patient: str | None = None) -> list[str]:
    cmd = [str(BIN / "fieldbank"), "fit", "--all", "--scheduler", addr,
           "--tls-ca", str(certs / "ca.pem"), "--tls-cert", str(certs / "client.pem"),
           "--tls-key", str(certs / "client-key.pem"), "--seed", str(seed), "--db", url]
    return cmd + (["--patient", patient] if patient else [])


def _follow(proc: subprocess.Popen[str], url: str, t0: float,
            cpu: Callable[[], tuple[float, float, float]], stop_after: float | None,
            every: float = 60.0) -> bool:
    """Wait for the command, printing every ``every`` seconds how far the run is (jobs done,
    the CPU so far). True when it is still running after ``stop_after`` seconds."""
    while True:
        left = every if stop_after is None else min(every, t0 + stop_after - time.perf_counter())
        try:
            proc.wait(max(0.0, left))
            return False
        except subprocess.TimeoutExpired:
            if stop_after is not None and time.perf_counter() - t0 >= stop_after:
                return True
            done = _done_jobs(url)
            w, n, s = cpu()
            print(f"  {time.perf_counter() - t0:6.0f} s: {done} done; CPU workers {w:.0f} s, "
                  f"nannies {n:.1f} s, scheduler {s:.1f} s"
                  + (f" = {done / (w + n):.3f} sessions per worker CPU-second" if done else "")
                  + f"; {load_line()}", flush=True)


def _done_jobs(url: str) -> int:
    from sqlalchemy import create_engine, text

    eng = create_engine(url)
    with eng.connect() as c:
        run = c.scalar(text("SELECT max(id) FROM job_runs WHERE kind = 'fit'"))
        n = c.scalar(text("SELECT count(*) FROM jobs WHERE run_id = :r AND state = 'done'"),
                     {"r": run})
    eng.dispose()
    return int(n or 0)


def _jobs(url: str, first: int | None = None) -> tuple[list[float], list[float], list[float],
                                                       int]:
    """The latest fit run's job rows (the ``first`` to finish, when given): each job's wall
    time, the fit's own wall and CPU time; and how many jobs were not done."""
    from sqlalchemy import create_engine, text

    eng = create_engine(url)
    with eng.connect() as c:
        run = c.scalar(text("SELECT max(id) FROM job_runs WHERE kind = 'fit'"))
        rows = c.execute(text("SELECT state, started_at, finished_at, result_json FROM jobs "
                              "WHERE run_id = :r ORDER BY finished_at NULLS LAST"),
                         {"r": run}).all()
    if first is not None:
        rows = [r for r in rows if r[0] == "done"][:first]
    eng.dispose()
    walls, fits, cpus, bad = [], [], [], 0
    for state, start, end, result in rows:
        if state != "done":
            bad += 1
            continue
        r = json.loads(result)
        walls.append((end - start).total_seconds())
        fits.append(float(r["fit_s"]))
        cpus.append(float(r["fit_cpu_s"]))
    return walls, fits, cpus, bad


def measure(url: str, certs: Path, workers: int, log: Path,
            stop_after: float | None = None, stop_at: float | None = None,
            dask_env: Mapping[str, str] | None = None) -> Run:
    """One refit on a fresh cluster of ``workers`` workers, stopped after ``stop_after``
    seconds or at the epoch time ``stop_at``, whichever comes first."""
    with cluster(certs, workers, log, dask_env) as (addr, sched, worker_ps, nanny_ps):
        warm = subprocess.run(_fit_command(url, addr, certs, 1000 + workers, "R00000-0000"),
                              capture_output=True, text=True)
        if warm.returncode != 0:
            raise SystemExit(f"warm-up failed: {warm.stderr[-2000:]}")
        i0, j0, t = _cpu(worker_ps) + _cpu(nanny_ps), _cpu([sched]), time.perf_counter()
        time.sleep(IDLE_S)  # the cluster's own cost with nothing to do: heartbeats
        idle = time.perf_counter() - t
        idle_w = (_cpu(worker_ps) + _cpu(nanny_ps) - i0) / idle
        idle_s = (_cpu([sched]) - j0) / idle
        cmd = _fit_command(url, addr, certs, workers)
        shown = shlex.join(["fieldbank", *cmd[1:]]).replace(str(certs), "certs")
        shown = shown.replace(url, "$URL")
        load_start = load_line()
        _children_cpu_delta()  # the warm-up's
        task0 = _task_cpu(addr, certs)
        w0, n0, s0 = _cpu(worker_ps), _cpu(nanny_ps), _cpu([sched])
        if stop_at is not None:
            left = max(0.0, stop_at - time.time())
            stop_after = left if stop_after is None else min(stop_after, left)
        t = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                text=True)
        err: list[str] = []
        reader = threading.Thread(target=lambda: err.append(proc.stderr.read() if proc.stderr
                                                            else ""), daemon=True)
        reader.start()
        stopped = _follow(proc, url, t, lambda: (_cpu(worker_ps) - w0, _cpu(nanny_ps) - n0,
                                                 _cpu([sched]) - s0), stop_after)
        wall = time.perf_counter() - t
        w1, n1, s1 = _cpu(worker_ps), _cpu(nanny_ps), _cpu([sched])
        task1 = _task_cpu(addr, certs)
        load_end = load_line()
        done = None
        if stopped:  # the sessions done by now count; the command is stopped as Ctrl-C does
            done = _done_jobs(url)
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(120)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            print(f"stopped after {wall:.0f} s with {done} sessions done", flush=True)
        reader.join()
        command_cpu = _children_cpu_delta()  # the command's, reaped
        if not stopped and proc.returncode != 0:
            raise SystemExit(f"the refit failed ({proc.returncode}): {''.join(err)[-2000:]}")
    walls, fits, cpus, bad = _jobs(url, done)
    if bad and not stopped:
        raise SystemExit(f"{bad} jobs not done")
    return Run(workers, len(cpus), wall, w1 - w0, n1 - n0, s1 - s0, command_cpu,
               task1 - task0, cpus, fits, walls, idle_w, idle_s, shown, load_start, load_end)


def _utc_today(hhmm: str) -> float:
    """The epoch time of ``HH:MM`` UTC next to come."""
    from datetime import UTC, datetime, timedelta

    now = datetime.now(UTC)
    h, m = (int(x) for x in hhmm.split(":"))
    at = now.replace(hour=h, minute=m, second=0, microsecond=0)
    return (at if at > now else at + timedelta(days=1)).timestamp()


_CHILDREN = [0.0]


def _children_cpu_delta() -> float:
    """CPU of the children reaped since the last call (the refit command)."""
    import resource

    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    now = r.ru_utime + r.ru_stime
    delta, _CHILDREN[0] = now - _CHILDREN[0], now
    return delta


def _median_gap(r: Run) -> float:
    return statistics.median(w - f for w, f in zip(r.job_wall_s, r.fit_wall_s, strict=True))


def report(runs: list[Run]) -> None:
    print()
    for r in runs:
        print(f"{r.workers} worker(s): `{r.command}`")
        print(f"  at start: {r.load_start}; at end: {r.load_end}")
    print()
    head = ("| | " + " | ".join(f"{r.workers} worker{'s' if r.workers > 1 else ''}"
                                for r in runs) + " |")
    print(head)
    print("|---" * (len(runs) + 1) + "|")

    def row(name: str, vals: Sequence[str]) -> None:
        print(f"| {name} | " + " | ".join(vals) + " |")

    row("sessions refitted", [f"{r.sessions}" for r in runs])
    row("wall time", [f"{r.wall_s:.0f} s" for r in runs])
    row("CPU: workers / nannies", [f"{r.worker_cpu_s:.0f} s / {r.nanny_cpu_s:.1f} s"
                                   for r in runs])
    row("CPU: scheduler / command", [f"{r.scheduler_cpu_s:.1f} s / {r.command_cpu_s:.1f} s"
                                     for r in runs])
    row("sessions per CPU-second (workers + nannies)",
        [f"{r.per_cpu_s(r.worker_cpu_s + r.nanny_cpu_s):.3f}" for r in runs])
    row("sessions per CPU-second (whole cluster)",
        [f"{r.per_cpu_s(r.cluster_cpu_s):.3f}" for r in runs])
    row("sessions per wall second", [f"{r.sessions / r.wall_s:.3f}" for r in runs])
    row("a fit's own CPU (mean; median)",
        [f"{statistics.fmean(r.fit_cpu_s):.3f} s; {statistics.median(r.fit_cpu_s):.3f} s"
         for r in runs])
    row("a fit's own wall (mean)", [f"{statistics.fmean(r.fit_wall_s):.2f} s" for r in runs])
    def share(extra: float, r: Run) -> str:
        return f"{1e3 * extra:.1f} ms = {100 * extra / statistics.fmean(r.fit_cpu_s):.2f} %"

    row("overhead per task, CPU: worker + nanny per session − fit",
        [share((r.worker_cpu_s + r.nanny_cpu_s) / r.sessions - statistics.fmean(r.fit_cpu_s),
               r) for r in runs])
    row("the idle cluster's CPU per second: workers + nannies / scheduler",
        [f"{1e3 * r.idle_workers_cps:.1f} ms / {1e3 * r.idle_scheduler_cps:.1f} ms"
         for r in runs])
    row("overhead per task less the idle cluster's over the wall time",
        [share((r.worker_cpu_s + r.nanny_cpu_s - r.idle_workers_cps * r.wall_s) / r.sessions
               - statistics.fmean(r.fit_cpu_s), r) for r in runs])
    row("the task's reads and writes around its fit, CPU: task thread − fit",
        [share(r.task_cpu_s / r.sessions - statistics.fmean(r.fit_cpu_s), r) for r in runs])
    row("job row wall − fit wall (median)",
        [f"{1e3 * _median_gap(r):.0f} ms" for r in runs])
    row("scheduler CPU per task", [f"{1e3 * r.scheduler_cpu_s / r.sessions:.1f} ms"
                                   for r in runs])
    by = {r.workers: r for r in runs}
    if 1 in by and 2 in by:
        one, two = by[1], by[2]
        eff_w = two.per_cpu_s(two.worker_cpu_s + two.nanny_cpu_s) / one.per_cpu_s(
            one.worker_cpu_s + one.nanny_cpu_s)
        eff_c = two.per_cpu_s(two.cluster_cpu_s) / one.per_cpu_s(one.cluster_cpu_s)
        eff_wall = (two.sessions / two.wall_s) / (2 * one.sessions / one.wall_s)
        print(f"\nscaling efficiency at 2 workers on CPU time (sessions per CPU-second, 2 "
              f"workers / 1): workers {eff_w:.2f}, whole cluster {eff_c:.2f} (target >= "
              f"{TARGET_EFFICIENCY:g}); on wall time {eff_wall:.2f} (the machine is shared)")
        eff = min(1.0, eff_c)
        per = one.cluster_cpu_s / one.sessions
    else:
        print("\n(one configuration: its CPU per session, efficiency taken as 1.0)")
        eff, per = 1.0, runs[-1].cluster_cpu_s / runs[-1].sessions
    base = by.get(2, runs[-1])
    for cores in (16, 64):
        hours = SESSIONS * per / (cores * eff) / 3600
        print(f"estimate: {SESSIONS} sessions on {cores} cores, a worker per core = {SESSIONS} x "
              f"{per:.2f} CPU-s / ({cores} x {eff:.2f}) = {hours:.2f} h"
              + (f" (target <= {TARGET_HOURS_16:g} h)" if cores == 16 else ""))
    sched = base.scheduler_cpu_s / base.sessions
    print(f"the one scheduler: {1e3 * sched:.1f} ms CPU per task -> at most {1 / sched:.0f} "
          f"tasks/s; 64 cores ask {64 * eff / per:.1f} tasks/s")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sessions", type=int, default=50)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--database", default="fbrefit",
                    help="database on the server (made and filled when missing; kept)")
    ap.add_argument("--db", default=os.environ.get("FIELDBANK_TEST_PG_URL"),
                    help="PostgreSQL server URL")
    ap.add_argument("--log", default=None, help="file for the cluster's own output")
    ap.add_argument("--stop-after", type=float, default=None, metavar="SECONDS",
                    help="stop each refit after this long and count the sessions done by then "
                         "(a run too long for the time at hand)")
    ap.add_argument("--dask-defaults", action="store_true",
                    help="start the scheduler and the workers with Dask's defaults, without "
                         "the dask.yaml of 'fieldbank cluster certs'")
    ap.add_argument("--stop-at", default=None, metavar="HH:MM",
                    help="stop any refit still running at this UTC time of day, as --stop-after "
                         "does (the configurations after it start and stop at once)")
    args = ap.parse_args()
    if not args.db:
        print("give --db or set FIELDBANK_TEST_PG_URL (scripts/pg-test-server starts a server)")
        return 2
    from fieldbank.clustercerts import CertOptions, write_certs
    from fieldbank.clusterconfig import CONFIG_FILE

    stop_at = _utc_today(args.stop_at) if args.stop_at else None

    print(f"at start: {load_line()}", flush=True)
    url = ensure_database(args.db, args.database)
    have = ensure_cohort(url, args.sessions)
    if have != args.sessions:
        print(f"note: the database holds {have} sessions; all are refitted")
    runs = []
    with tempfile.TemporaryDirectory(prefix="fieldbank-refit-") as d:
        certs = Path(d) / "certs"
        write_certs(certs, CertOptions(days=2, hosts=("127.0.0.1",)))
        log = Path(args.log) if args.log else Path(d) / "cluster.log"
        dask_env = {} if args.dask_defaults else {"DASK_CONFIG": str(certs / CONFIG_FILE)}
        print("the scheduler and the workers run with " + (
            "Dask's defaults" if args.dask_defaults else f"fieldbank's {CONFIG_FILE}"),
            flush=True)
        _children_cpu_delta()
        for w in args.workers:
            r = measure(url, certs, w, log, args.stop_after, stop_at, dask_env)
            print(f"{w} worker(s): {r.sessions} sessions in {r.wall_s:.0f} s, workers' CPU "
                  f"{r.worker_cpu_s:.0f} s, {load_line()}", flush=True)
            if r.sessions:
                runs.append(r)
                if len(runs) < len(args.workers):
                    report(runs)  # so far: a later configuration may not finish
    if not runs:
        print("no session was refitted")
        return 1
    report(runs)
    print(f"at end: {load_line()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
