"""Who may use the cluster, without a cluster: the scheduler rule (tls:// with the cluster's
certificates, tcp:// only on the loopback unless the risk is accepted in words) tried on a real
listening socket that must see no connection; certificates made by ``fieldbank cluster certs``
and every way they can fail to fit; passwords never echoed; an unreachable scheduler leaves no
run; a job the command gave up is not overwritten by a worker that finishes it later."""

from __future__ import annotations

import json
import socket
import stat
from collections.abc import Iterator
from pathlib import Path

import pytest
from click.testing import CliRunner, Result

from fieldbank import engine
from fieldbank.cli.main import cli
from fieldbank.clustercerts import FILES, KEY_FILES, WRITTEN, CertOptions, write_certs
from fieldbank.engine import Done, Task, Where, _execute_with, _lost
from fieldbank.errors import ClusterError, ConfigError, FileRefused, ParameterError
from fieldbank.scheduler import SchedulerFlags, is_loopback, resolve_scheduler
from fieldbank.storage import Database
from tests.cohort_helpers import store_sessions


def run(*args: str, env: dict[str, str] | None = None) -> Result:
    return CliRunner().invoke(cli, list(args), env=env, catch_exceptions=False)


@pytest.fixture(scope="module")
def certs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_certs(tmp_path_factory.mktemp("c") / "certs", CertOptions()).out_dir


@pytest.fixture(scope="module")
def other_certs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A set of another run: another authority."""
    return write_certs(tmp_path_factory.mktemp("o") / "certs", CertOptions()).out_dir


def _client(d: Path) -> SchedulerFlags:
    return SchedulerFlags("tls://sched.example:8786", str(d / "ca.pem"), str(d / "client.pem"),
                          str(d / "client-key.pem"))


# --- the rule --------------------------------------------------------------------------------
def test_loopback_is_judged_from_the_text_alone() -> None:
    for host in ("127.0.0.1", "127.8.9.10", "localhost", "LOCALHOST", "[::1]",
                 "[::ffff:127.0.0.1]"):
        assert is_loopback(host), host
    # names are not resolved, so a name is never the loopback; nor is 'any address'
    for host in ("10.0.0.5", "0.0.0.0", "[::]", "sched.example", "127.1", "2130706433",
                 "localhost.evil.example", "[fe80::1]"):
        assert not is_loopback(host), host


def test_plain_addresses_only_on_the_loopback_unless_the_risk_is_accepted(
        clean_work: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert resolve_scheduler(None) is None
    assert resolve_scheduler("  ") is None
    s = resolve_scheduler("tcp://127.0.0.1:8786")
    assert s is not None and s.security() is None and s.warning is None
    with pytest.raises(ClusterError, match=r"tcp://10\.1\.2\.3:8786 \(from flag --scheduler\) "
                                           r"is refused: .*anyone who can reach port 8786 of "
                                           r"10\.1\.2\.3 can run any code"):
        resolve_scheduler("tcp://10.1.2.3:8786")
    monkeypatch.setenv("FIELDBANK_SCHEDULER", "ws://sched.example:8786")
    with pytest.raises(ClusterError, match="from variable FIELDBANK_SCHEDULER"):
        resolve_scheduler(None)
    # accepted by the flag, the variable or the file, and then the risk is said in words
    s = resolve_scheduler(SchedulerFlags(insecure=True))
    assert s is not None and s.insecure and s.security() is None
    assert s.warning is not None and "anyone who can reach it can run any code" in s.warning
    monkeypatch.setenv("FIELDBANK_INSECURE_SCHEDULER", "yes")
    assert resolve_scheduler(None).insecure  # type: ignore[union-attr]
    monkeypatch.delenv("FIELDBANK_INSECURE_SCHEDULER")
    monkeypatch.delenv("FIELDBANK_SCHEDULER")
    Path("fieldbank.toml").write_text('[scheduler]\naddress = "tcp://10.0.0.5:8786"\n'
                                      "insecure = true\n")
    s = resolve_scheduler(None)
    assert s is not None and s.insecure and s.source.startswith("file ")
    # bad addresses stay configuration errors
    with pytest.raises(ConfigError, match=r"--scheduler must be .*; got 'http://x:1'"):
        resolve_scheduler("http://x:1")
    monkeypatch.setenv("FIELDBANK_SCHEDULER", "10.1.2.3:8786")
    with pytest.raises(ConfigError, match=r"FIELDBANK_SCHEDULER must be a Dask scheduler "
                                          r"address .*; got '10\.1\.2\.3:8786'"):
        resolve_scheduler(None)


def test_tls_needs_the_three_files_and_checks_that_they_fit(
        clean_work: Path, certs: Path, other_certs: Path, tmp_path: Path) -> None:
    with pytest.raises(ClusterError, match=r"needs the cluster's certificates.*missing: "
                                           r"tls_ca, tls_cert, tls_key\..*cluster certs"):
        resolve_scheduler("tls://sched.example:8786")
    s = resolve_scheduler(_client(certs))
    assert s is not None and s.tls is not None and s.tls.cert == certs / "client.pem"
    sec = s.security()
    assert sec is not None and sec.require_encryption
    assert sec.get_connection_args("client")["ssl_context"] is not None
    # a certificate of another authority, a key of another certificate
    f = _client(certs)
    with pytest.raises(ClusterError, match=r"was not issued by scheduler\.tls_ca"):
        resolve_scheduler(SchedulerFlags(f.address, f.tls_ca, str(other_certs / "client.pem"),
                                         str(other_certs / "client-key.pem")))
    with pytest.raises(ClusterError, match=r"is not the key of scheduler\.tls_cert"):
        resolve_scheduler(SchedulerFlags(f.address, f.tls_ca, f.tls_cert,
                                         str(certs / "worker-key.pem")))
    with pytest.raises(ClusterError, match=r"tls_ca .*nowhere\.pem \(from flag --tls-ca\): "
                                           r"cannot read it"):
        resolve_scheduler(SchedulerFlags(f.address, str(tmp_path / "nowhere.pem"), f.tls_cert,
                                         f.tls_key))
    with pytest.raises(ClusterError, match="not a PEM certificate"):
        resolve_scheduler(SchedulerFlags(f.address, f.tls_key, f.tls_cert, f.tls_key))
    # a key others can read is refused, naming the fix
    loose = tmp_path / "loose-key.pem"
    loose.write_bytes((certs / "client-key.pem").read_bytes())
    loose.chmod(0o644)
    with pytest.raises(ClusterError, match=r"can be read by other users \(mode -rw-r--r--\).*"
                                           r"chmod 600"):
        resolve_scheduler(SchedulerFlags(f.address, f.tls_ca, f.tls_cert, str(loose)))


def test_the_certificate_settings_come_from_flag_variable_or_file_and_config_show_says_which(
        clean_work: Path, certs: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    Path("fieldbank.toml").write_text(
        f'[scheduler]\naddress = "tls://10.0.0.5:8786"\ntls_ca = "{certs / "ca.pem"}"\n'
        f'tls_cert = "{certs / "client.pem"}"\ntls_key = "{certs / "client-key.pem"}"\n')
    s = resolve_scheduler(None)
    assert s is not None and s.address == "tls://10.0.0.5:8786" and s.tls is not None
    monkeypatch.setenv("FIELDBANK_SCHEDULER_TLS_KEY", str(certs / "worker-key.pem"))
    with pytest.raises(ClusterError, match=r"worker-key\.pem \(from variable "
                                           r"FIELDBANK_SCHEDULER_TLS_KEY\) is not the key"):
        resolve_scheduler(None)
    # the flag comes first
    assert resolve_scheduler(SchedulerFlags(tls_key=str(certs / "client-key.pem"))) is not None
    doc = json.loads(run("config", "show", "--json").stdout)
    rows = {r["name"]: r for r in doc["settings"]}
    assert rows["scheduler"]["value"] == "tls://10.0.0.5:8786"
    assert rows["scheduler.tls_ca"]["source"].startswith("file ")
    assert rows["scheduler.tls_key"]["source"] == "variable FIELDBANK_SCHEDULER_TLS_KEY"
    assert rows["scheduler.insecure"]["value"] == "False"
    # the old one-line form still reads
    Path("fieldbank.toml").write_text('scheduler = "tcp://127.0.0.1:8786"\n')
    assert resolve_scheduler(None).address == "tcp://127.0.0.1:8786"  # type: ignore[union-attr]


def test_a_password_in_a_scheduler_address_is_never_echoed(
        clean_work: Path, sqlite_url: str) -> None:
    bad = "tcp://u:s3cretpw@10.0.0.5:8786"
    r = run("fit", "--all", "--scheduler", bad, "--db", sqlite_url)
    assert r.exit_code == 1 and "without a user or a password" in r.output
    assert "s3cretpw" not in r.output and "u:***@10.0.0.5" in r.output
    r = run("validate", "--db", sqlite_url, env={"FIELDBANK_SCHEDULER": bad})
    assert r.exit_code == 1 and "FIELDBANK_SCHEDULER" in r.output and "s3cretpw" not in r.output
    Path("fieldbank.toml").write_text(f'scheduler = "{bad}"\n')
    r = run("config", "show")
    assert r.exit_code == 1 and "s3cretpw" not in r.output and "***" in r.output
    r = run("report", "--out", "r", "--db", sqlite_url)
    assert r.exit_code == 1 and "s3cretpw" not in r.output


# --- nothing is sent -------------------------------------------------------------------------
def _this_machines_address() -> str:
    """An IPv4 address of this machine that is not the loopback (a UDP 'connect' only picks
    the route: no datagram leaves)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.connect(("192.0.2.1", 9))
        except OSError:
            pytest.skip("this machine has no network interface besides the loopback")
        ip = str(s.getsockname()[0])
    if is_loopback(ip):
        pytest.skip("this machine has no network interface besides the loopback")
    return ip


@pytest.fixture
def listener() -> Iterator[socket.socket]:
    """A TCP socket listening on every interface, accepting nothing by itself."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("0.0.0.0", 0))
        s.listen(8)
        s.setblocking(False)
        yield s


def _connections(s: socket.socket) -> int:
    n = 0
    while True:
        try:
            conn, _ = s.accept()
        except BlockingIOError:
            return n
        conn.close()
        n += 1


def test_a_plain_scheduler_on_another_host_is_refused_before_anything_is_sent(
        clean_work: Path, listener: socket.socket, sqlite_url: str,
        monkeypatch: pytest.MonkeyPatch) -> None:
    ip = _this_machines_address()
    port = listener.getsockname()[1]
    with Database.open(sqlite_url, create=True, upgrade="always") as db:
        store_sessions(db, 1, sessions=("pre",))
    address = f"tcp://{ip}:{port}"
    for cmd in (["fit", "--all"], ["validate"], ["report", "--out", "r"]):
        r = run(*cmd, "--scheduler", address, "--db", sqlite_url)
        assert r.exit_code == 1, cmd
        assert f"{address} (from flag --scheduler) is refused" in r.output
        assert "neither encrypted nor authenticated" in r.output and "Traceback" not in r.output
    assert _connections(listener) == 0  # nothing reached the socket
    # the same socket is reached once the risk is accepted: the check above could fail. No
    # scheduler answers there, and the failed attempt leaves no run behind
    monkeypatch.setattr(engine, "CONNECT_TIMEOUT_S", 2.0)
    r = run("fit", "--all", "--scheduler", address, "--insecure-scheduler", "--db", sqlite_url)
    assert r.exit_code == 1 and "WARNING: " + address in r.output
    assert "anyone who can reach it can run any code" in r.output
    assert f"cannot reach the Dask scheduler at {address}" in r.output
    assert _connections(listener) >= 1
    with Database.open(sqlite_url) as db:
        assert db.list_runs() == []


def test_an_unreachable_scheduler_leaves_no_run_behind(
        clean_work: Path, sqlite_url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    with socket.socket() as s:  # a free port on the loopback, closed again: nothing listens
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with Database.open(sqlite_url, create=True, upgrade="always") as db:
        store_sessions(db, 1, sessions=("pre",))
    monkeypatch.setattr(engine, "CONNECT_TIMEOUT_S", 1.0)
    for _ in range(3):
        r = run("fit", "--all", "--scheduler", f"tcp://127.0.0.1:{port}", "--db", sqlite_url)
        assert r.exit_code == 1 and "cannot reach the Dask scheduler" in r.output
        assert "Nothing was recorded" in r.output
    with Database.open(sqlite_url) as db:
        assert db.list_runs() == []
    assert "no batch runs" in run("jobs", "--db", sqlite_url).output


# --- what the command reports is what the database holds ----------------------------------
def _finishes(db: Database, task: Task, options: dict[str, object]) -> Done:
    return Done("done", "stored", {"n": 1})


def test_a_job_given_up_is_not_overwritten_by_its_worker_finishing_later(
        any_db_url: str) -> None:
    with Database.open(any_db_url, create=True, upgrade="always") as db:
        tasks = [Task("a", None), Task("b", None)]
        run_rec = db.start_run("fit", "test", {}, [(t.key, None, None) for t in tasks])
        where = Where(any_db_url, None, run_rec.id, run_rec.token)
        # a: the worker has started it, then the command loses the scheduler and gives it up;
        # the worker finishes afterwards
        db.start_job(run_rec.id, "a", "w1")
        said = _lost(db, where, tasks[0], "scheduler-connection-lost")
        assert said.state == "failed"
        (job, written) = db.finish_job(run_rec.id, "a", "done", {"n": 1}, attempt=1)
        assert not written and job.state == "failed" and "connection-lost" in (job.error or "")
        # b: the worker finished first; giving it up afterwards reports what it stored
        late = _execute_with(db, where, _finishes, {}, tasks[1])
        assert late.state == "done"
        said_b = _lost(db, where, tasks[1], "scheduler-connection-lost")
        assert said_b.state == "done" and said_b.result == {"n": 1}
        stored = {j.key: j.state for j in db.list_jobs(run_rec.id)}
        assert stored == {"a": said.state, "b": said_b.state}
        # an attempt that is no longer the live one cannot end the job either
        db2 = db.start_run("fit", "test", {}, [("c", None, None)])
        db.start_job(db2.id, "c", "w1")
        db.start_job(db2.id, "c", "w2")  # the scheduler ran it again elsewhere
        assert not db.finish_job(db2.id, "c", "failed", error="old", attempt=1)[1]
        job, written = db.finish_job(db2.id, "c", "done", attempt=2)
        assert written and job.state == "done" and job.attempts == 2


# --- fieldbank cluster certs -----------------------------------------------------------------
def test_cluster_certs_writes_a_set_with_private_keys_and_never_overwrites_without_force(
        clean_work: Path) -> None:
    r = run("cluster", "certs", "--out", "certs", "--host", "10.0.0.5", "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    d = Path("certs")
    assert sorted(p.name for p in d.iterdir()) == sorted(WRITTEN)
    assert stat.S_IMODE(d.stat().st_mode) == 0o700
    for name in WRITTEN:
        mode = stat.S_IMODE((d / name).stat().st_mode)
        assert mode & 0o077 == 0 if name in KEY_FILES else mode & 0o022 == 0, name
    assert not any("ca-key" in p.name for p in d.iterdir())  # the authority's key: never
    assert "dask scheduler --protocol tls" in r.stderr and "tls_cert = " in r.stderr
    assert r.stderr.count(f"DASK_CONFIG={(d / 'dask.yaml').resolve()}") == 2  # both commands
    assert doc["files"][-1].endswith("dask.yaml")
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes

    sched = x509.load_pem_x509_certificate((d / "scheduler.pem").read_bytes())
    names = sched.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert "10.0.0.5" in {str(ip) for ip in names.get_values_for_type(x509.IPAddress)}
    ca = x509.load_pem_x509_certificate((d / "ca.pem").read_bytes())
    for role in ("scheduler", "worker", "client"):
        x509.load_pem_x509_certificate((d / f"{role}.pem").read_bytes()
                                       ).verify_directly_issued_by(ca)
    assert doc["ca_sha256"].replace(":", "").lower() == ca.fingerprint(hashes.SHA256()).hex()
    before = {n: (d / n).read_bytes() for n in FILES}
    r = run("cluster", "certs", "--out", "certs")
    assert r.exit_code == 1 and "already holds ca.pem" in r.output and "--force" in r.output
    assert {n: (d / n).read_bytes() for n in FILES} == before
    for name in FILES:  # a dask.yaml alone in the directory is not replaced either
        (d / name).unlink()
    (d / "dask.yaml").write_text("distributed: {}\n")
    r = run("cluster", "certs", "--out", "certs")
    assert r.exit_code == 1 and "already holds dask.yaml" in r.output
    assert (d / "dask.yaml").read_text() == "distributed: {}\n" and len(list(d.iterdir())) == 1
    assert run("cluster", "certs", "--out", "certs", "--force").exit_code == 0
    assert all((d / n).read_bytes() != before[n] for n in FILES)
    assert sorted(p.name for p in d.iterdir()) == sorted(WRITTEN)  # no temporary left


def test_cluster_certs_refuses_clearly(clean_work: Path) -> None:
    r = run("cluster", "certs", "--out", "no/such/dir")
    assert r.exit_code == 1 and "the directory no/such does not exist" in r.output
    Path("file").write_text("x")
    r = run("cluster", "certs", "--out", "file")
    assert r.exit_code != 0 and "Traceback" not in r.output
    r = run("cluster", "certs", "--out", "c", "--days", "0")
    assert r.exit_code == 1 and "'days' parameter must be a whole number" in r.output
    r = run("cluster", "certs", "--out", "c", "--host", "*.example")
    assert r.exit_code == 1 and "no wildcards" in r.output
    assert not Path("c").exists()
    with pytest.raises(ParameterError):
        CertOptions(days=4000)
    with pytest.raises(FileRefused, match="not a directory"):
        write_certs(Path("file"), CertOptions())
