"""The cluster for real: a ``LocalCluster`` whose scheduler and worker require TLS, with the
certificates ``fieldbank cluster certs`` makes. The project's client runs a batch from the
settings in ``fieldbank.toml``; a client without the cluster's certificate - none at all, one of
another authority, plain tcp:// - is refused, and its ``Client.run(lambda: os.getuid())`` runs
nothing. Then a scheduler (``dask scheduler``, ``dask worker`` as processes) killed mid-task:
what the command reports is what the database holds, after the worker has finished the task."""

from __future__ import annotations

import json
import logging
import os
import socket
import ssl
import subprocess
import sys
import threading
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from fieldbank.cli.main import cli
from fieldbank.clustercerts import CertOptions, write_certs
from fieldbank.engine import Done, Task, run_batch
from fieldbank.errors import ClusterError
from fieldbank.scheduler import Scheduler, SchedulerFlags, resolve_scheduler
from fieldbank.storage import Database
from tests.cohort_helpers import store_sessions

pytestmark = [pytest.mark.slow]
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def certs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_certs(tmp_path_factory.mktemp("c") / "certs", CertOptions()).out_dir


@pytest.fixture(scope="module")
def stranger(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A set of another authority: what a stranger can make for himself."""
    return write_certs(tmp_path_factory.mktemp("s") / "certs", CertOptions()).out_dir


@pytest.fixture(scope="module")
def tls_cluster(certs: Path) -> Iterator[Any]:
    """One worker process; scheduler and worker speak only TLS, each with its own
    certificate; the cluster's own client uses the client certificate."""
    from distributed import LocalCluster, Security

    def c(n: str) -> str:
        return str(certs / n)

    security = Security(tls_ca_file=c("ca.pem"),
                        tls_scheduler_cert=c("scheduler.pem"),
                        tls_scheduler_key=c("scheduler-key.pem"),
                        tls_worker_cert=c("worker.pem"), tls_worker_key=c("worker-key.pem"),
                        tls_client_cert=c("client.pem"), tls_client_key=c("client-key.pem"),
                        require_encryption=True)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, protocol="tls://",
                      host="127.0.0.1", security=security, dashboard_address="127.0.0.1:0",
                      silence_logs=logging.ERROR, env={"FIELDBANK_DB": ""}) as cluster:
        yield cluster


def test_the_projects_certificates_run_a_batch_on_a_cluster_that_requires_tls(
        tls_cluster: Any, certs: Path, clean_work: Path) -> None:
    address = tls_cluster.scheduler_address
    assert address.startswith("tls://127.0.0.1:")
    url = f"sqlite:///{clean_work / 'fb.sqlite'}"
    with Database.open(url, create=True, upgrade="always") as db:
        store_sessions(db, 1, sessions=("pre",))
    Path("fieldbank.toml").write_text(
        f'[scheduler]\naddress = "{address}"\ntls_ca = "{certs / "ca.pem"}"\n'
        f'tls_cert = "{certs / "client.pem"}"\ntls_key = "{certs / "client-key.pem"}"\n')
    r = CliRunner().invoke(cli, ["fit", "--all", "--db", url, "--max-evals", "60",
                                 "--replicates", "4"], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    assert f"1 task(s) on {address} (1 worker(s))" in r.output
    with Database.open(url) as db:
        (run,) = db.list_runs()
        assert run.engine == f"dask {address}" and run.counts["done"] == 1 and run.left == 0
        (job,) = db.list_jobs(run.id)
        assert job.worker is not None and job.worker.startswith("tls://127.0.0.1:")
        assert len(db.list_fits()) == 1
    # the same certificates run code on the workers: the certificate is what admits
    sched = resolve_scheduler(None)
    assert sched is not None and sched.tls is not None
    client = sched.connect(30)
    try:
        assert set(client.run(os.getuid).values()) == {os.getuid()}
    finally:
        client.close()


def _stranger_runs(address: str, security: Any, marker: Path) -> BaseException | None:
    """A stranger's ``Client(...).run``: touches ``marker`` and returns the worker's uid, if
    the cluster lets it run; the exception that stopped it, else None."""
    from distributed import Client

    def probe() -> int:
        marker.touch()
        return os.getuid()

    try:
        with Client(address, security=security, timeout=10, set_as_default=False) as c:
            c.run(probe)
    except Exception as exc:
        return exc
    return None


def test_a_client_without_the_clusters_certificate_is_refused_and_runs_nothing(
        tls_cluster: Any, certs: Path, stranger: Path, clean_work: Path, tmp_path: Path) -> None:
    from distributed import Security

    address = tls_cluster.scheduler_address
    host, port = address.removeprefix("tls://").rsplit(":", 1)
    clients_before = set(tls_cluster.scheduler.clients)
    marker = tmp_path / "ran"
    # no certificate at all: the server's handshake asks for one and refuses the connection
    ctx = ssl.create_default_context(cafile=str(certs / "ca.pem"))
    ctx.check_hostname = False
    with socket.create_connection((host, int(port)), timeout=30) as raw:
        why = "closed without a word"
        try:
            with ctx.wrap_socket(raw) as tls:  # TLS 1.3: the refusal comes after the hello
                tls.sendall(b"\x00" * 16)
                got = tls.recv(1)
        except (ssl.SSLError, ConnectionError) as exc:
            got, why = b"", str(exc)
        assert got == b"", "the scheduler answered a client without a certificate"
        # the refusal as the client's TLS stack reports it: the alert itself, or the
        # connection the server ended after it (reset, closed, or an EOF inside the record)
        words = ("CERTIFICATE_REQUIRED", "reset", "closed", "EOF occurred")
        assert any(w in why for w in words), why
    # a certificate of another authority (trusting the cluster's own): refused, nothing run
    exc = _stranger_runs(address, Security(
        tls_ca_file=str(certs / "ca.pem"), tls_client_cert=str(stranger / "client.pem"),
        tls_client_key=str(stranger / "client-key.pem"), require_encryption=True), marker)
    assert isinstance(exc, OSError), exc
    # the stranger's own authority all through: refused too
    exc = _stranger_runs(address, Security(
        tls_ca_file=str(stranger / "ca.pem"), tls_client_cert=str(stranger / "client.pem"),
        tls_client_key=str(stranger / "client-key.pem"), require_encryption=True), marker)
    assert exc is not None
    assert not marker.exists()
    # plain tcp:// to the TLS port: no Dask handshake ever comes back; refused in bounded time
    with pytest.raises(ClusterError, match="cannot reach the Dask scheduler"):
        Scheduler(f"tcp://{host}:{port}", "test").connect(5)
    # fieldbank with the stranger's files: refused, and no run recorded
    url = f"sqlite:///{clean_work / 'fb.sqlite'}"
    with Database.open(url, create=True, upgrade="always") as db:
        store_sessions(db, 1, sessions=("pre",))
    r = CliRunner().invoke(cli, [
        "fit", "--all", "--db", url, "--scheduler", address,
        "--tls-ca", str(stranger / "ca.pem"), "--tls-cert", str(stranger / "client.pem"),
        "--tls-key", str(stranger / "client-key.pem")], catch_exceptions=False)
    assert r.exit_code == 1 and "cannot reach the Dask scheduler" in r.output
    with Database.open(url) as db:
        assert db.list_runs() == []
    assert set(tls_cluster.scheduler.clients) == clients_before
    # the flags alone, without the files in the settings, are refused before connecting
    with pytest.raises(ClusterError, match="missing: tls_cert, tls_key"):
        resolve_scheduler(SchedulerFlags(address, tls_ca=str(certs / "ca.pem")))


# --- the scheduler killed mid-task ----------------------------------------------------------
def gated(db: Database, task: Task, options: Mapping[str, Any]) -> Done:
    """A task that runs until the test opens its gate, saying when it started and returned."""
    Path(options["started"]).touch()
    while not Path(options["gate"]).exists():
        time.sleep(0.05)
    Path(options["returned"]).touch()
    return Done("done", "the gate opened")


def test_after_the_scheduler_is_killed_the_command_reports_what_the_database_holds(
        tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'fb.sqlite'}"
    Database.open(url, create=True, upgrade="always").close()
    dask = str(Path(sys.executable).with_name("dask"))
    env = {**os.environ, "PYTHONPATH": str(ROOT), "FIELDBANK_DB": ""}
    info = tmp_path / "scheduler.json"
    sched = subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", "0",
                              "--no-dashboard", "--scheduler-file", str(info)],
                             env=env, stderr=subprocess.DEVNULL)
    worker: subprocess.Popen[bytes] | None = None
    try:
        deadline = time.monotonic() + 120
        while not info.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        time.sleep(0.2)  # written whole
        address = json.loads(info.read_text())["address"]
        worker = subprocess.Popen([dask, "worker", address, "--nthreads", "1", "--no-nanny"],
                                  env=env, stderr=subprocess.DEVNULL)
        opts = {k: str(tmp_path / k) for k in ("started", "gate", "returned")}
        out: dict[str, Any] = {}

        def batch() -> None:
            with Database.open(url) as db:
                out["res"] = run_batch(db, "fit", [Task("k", "P-1", "pre")], gated, opts,
                                       scheduler=address)

        t = threading.Thread(target=batch)
        t.start()
        while not Path(opts["started"]).exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert Path(opts["started"]).exists(), "the task never started"
        sched.kill()  # SIGKILL: no goodbye to the client or the worker
        t.join(timeout=120)
        assert not t.is_alive()
        (said,) = out["res"].outcomes
        assert said.state == "failed" and "scheduler" in said.detail
        # the worker still runs the task; once it has finished (its process ends after the
        # task's thread), the database still holds what the command reported
        Path(opts["gate"]).touch()
        assert worker.wait(timeout=120) is not None
        assert Path(opts["returned"]).exists(), "the worker never finished the task"
        with Database.open(url) as db:
            (job,) = db.list_jobs(out["res"].run.id)
            assert (job.state, job.error) == (said.state, said.detail)
    finally:
        for p in (sched, worker):
            if p is not None and p.poll() is None:
                p.kill()
                p.wait()
