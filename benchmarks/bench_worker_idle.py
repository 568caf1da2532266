"""Benchmark: what an idle Dask cluster burns, with Dask's defaults and with fieldbank's
``dask.yaml`` (:mod:`fieldbank.clusterconfig`), judged on CPU time.

Each variant starts, as processes of their own and as docs/scale-out.md tells a clinic to,
a TLS scheduler and one ``dask worker --nworkers 1 --nthreads 1`` (a worker process under its
nanny), with the certificates and ``dask.yaml`` that ``fieldbank cluster certs`` writes.
Once the worker has joined and ``--settle`` seconds have passed, it reads (psutil) the CPU
time of the worker process, the nanny and the scheduler over ``--seconds`` of wall time with
nothing to do: heartbeats, the event-loop tick, the system monitor, the memory monitor, the
profiler, TLS. Variants:

* Dask's defaults (the baseline: a cluster started without ``DASK_CONFIG``);
* fieldbank's ``dask.yaml`` (``DASK_CONFIG=…/dask.yaml`` for the scheduler and the worker);
* each of its settings alone (its ``DASK_…`` environment variable), so that each is seen to
  pay for what it costs (``--each``).

The variants are run in turn, ``--rounds`` times, so that a change of the machine's load
falls on all of them; the table gives each variant's median over the rounds, and beside it
the ratio to the baseline of the same round (median of the rounds' ratios). The worker is
asked for its configuration, so a variant that did not take is seen.

Run: python benchmarks/bench_worker_idle.py [--seconds 20] [--rounds 2] [--each]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.bench_refit_cluster import _client, _cpu, cluster
from benchmarks.timing import load_line
from fieldbank.clusterconfig import CONFIG_FILE, SETTINGS


class Idle(NamedTuple):
    worker: float  # CPU-s per wall-s
    nanny: float
    scheduler: float
    config: dict[str, object]  # the worker's view of the keys


def _worker_config(addr: str, certs: Path) -> dict[str, object]:
    client = _client(addr, certs)
    keys = [s.key for s in SETTINGS]

    def read() -> dict[str, object]:
        import dask

        return {k: dask.config.get(k) for k in keys}

    try:
        got = client.run(read)  # type: ignore[attr-defined]
    finally:
        client.close()  # type: ignore[attr-defined]
    return dict(next(iter(got.values())))


def idle(certs: Path, env: dict[str, str], seconds: float, settle: float, log: Path) -> Idle:
    with cluster(certs, 1, log, env) as (addr, sched, worker_ps, nanny_ps):
        config = _worker_config(addr, certs)
        time.sleep(settle)
        w0, n0, s0 = _cpu(worker_ps), _cpu(nanny_ps), _cpu([sched])
        t = time.perf_counter()
        time.sleep(seconds)
        wall = time.perf_counter() - t
        w1, n1, s1 = _cpu(worker_ps), _cpu(nanny_ps), _cpu([sched])
    return Idle((w1 - w0) / wall, (n1 - n0) / wall, (s1 - s0) / wall, config)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="idle wall time measured")
    ap.add_argument("--settle", type=float, default=5.0,
                    help="wait after the worker joined, before measuring")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--each", action="store_true", help="also each setting alone")
    ap.add_argument("--log", default=None, help="file for the cluster's own output")
    args = ap.parse_args()
    from fieldbank.clustercerts import CertOptions, write_certs

    print(f"at start: {load_line()}", flush=True)
    with tempfile.TemporaryDirectory(prefix="fieldbank-idle-") as d:
        certs = write_certs(Path(d) / "certs", CertOptions(days=2, hosts=("127.0.0.1",))).out_dir
        log = Path(args.log) if args.log else Path(d) / "cluster.log"
        variants: list[tuple[str, dict[str, str]]] = [
            ("Dask's defaults (baseline)", {}),
            (f"fieldbank's {CONFIG_FILE}", {"DASK_CONFIG": str(certs / CONFIG_FILE)})]
        if args.each:
            variants += [(f"only {s.key}: {s.env_value}", {s.env_name: s.env_value})
                         for s in SETTINGS]
        runs: dict[str, list[Idle]] = {name: [] for name, _ in variants}
        for r in range(args.rounds):
            for name, env in variants:
                runs[name].append(idle(certs, env, args.seconds, args.settle, log))
                got = runs[name][-1]
                print(f"round {r + 1}: {name}: worker {1e3 * got.worker:.1f}, nanny "
                      f"{1e3 * got.nanny:.1f}, scheduler {1e3 * got.scheduler:.1f} ms CPU per "
                      f"s; {load_line()}", flush=True)
    base = runs[variants[0][0]]
    print(f"\n{args.rounds} rounds of {args.seconds:g} s idle each; medians, ms of CPU per "
          "second of wall time; ratio: to the baseline of the same round (median)\n")
    print("| variant | worker | nanny | worker + nanny | × baseline | scheduler | × baseline "
          "| the worker's configuration |")
    print("|---|---|---|---|---|---|---|---|")
    for name, got in runs.items():
        wn = [g.worker + g.nanny for g in got]
        ratio_wn = statistics.median(x / (b.worker + b.nanny) for x, b in zip(wn, base,
                                                                             strict=True))
        ratio_s = statistics.median(g.scheduler / b.scheduler for g, b in zip(got, base,
                                                                            strict=True))
        conf = ", ".join(f"{k.rsplit('.', 2)[-2]}.{k.rsplit('.', 1)[-1]}={v}"
                         for k, v in got[-1].config.items())
        print(f"| {name} | {1e3 * statistics.median(g.worker for g in got):.1f} | "
              f"{1e3 * statistics.median(g.nanny for g in got):.1f} | "
              f"{1e3 * statistics.median(wn):.1f} | {ratio_wn:.2f} | "
              f"{1e3 * statistics.median(g.scheduler for g in got):.1f} | {ratio_s:.2f} | "
              f"{conf} |")
    print(f"\nat end: {load_line()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
