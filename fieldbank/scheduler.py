"""Which Dask scheduler a batch command uses, and the rule that keeps strangers off the cluster.

A Dask scheduler runs whatever code its clients send, on every worker, as the worker's user -
the user that holds the database's credentials and reaches the patients' data. So who may
talk to it matters more than anything else about a cluster. The rule, applied by
:func:`resolve_scheduler` before any connection is tried (nothing is sent, not even a name
looked up):

* ``tls://HOST:PORT`` (and ``wss://``): mutual TLS. This client shows its certificate and
  checks the scheduler's, both issued by the cluster's own authority
  (``fieldbank cluster certs``, :mod:`fieldbank.clustercerts`); the scheduler admits only
  holders of such a certificate. The three files - ``tls_ca``, ``tls_cert``, ``tls_key`` -
  come from the flags ``--tls-ca``/``--tls-cert``/``--tls-key``, the variables
  ``FIELDBANK_SCHEDULER_TLS_*`` or the ``[scheduler]`` table of ``fieldbank.toml``
  (:mod:`fieldbank.config`); they are checked here (readable, the key private to its owner,
  the certificate issued by that authority and valid today, the key its own) and turned into
  Dask's ``Security`` (:meth:`Scheduler.security`).
* ``tcp://`` (and ``ws://``, ``ucx://``): no encryption, no authentication. Allowed to this
  machine's loopback only (127.0.0.0/8, ::1, ``localhost``: a cluster on this machine);
  another host is refused unless ``--insecure-scheduler`` (``FIELDBANK_INSECURE_SCHEDULER``,
  ``[scheduler] insecure = true``) accepts the risk, which is then said on every run.

An address never carries a user or a password (:func:`fieldbank.config` refuses one without
echoing it). This module imports only the standard library until a connection is made (and
asyncio not before then: the batch commands' options import it); the certificate checks load
``cryptography``, the connection ``distributed``.
"""

from __future__ import annotations

import ipaddress
import os
import stat
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fieldbank.config import SCHEDULER_RE, Setting, setting
from fieldbank.errors import ClusterError

if TYPE_CHECKING:  # typing only: Dask loads when a batch connects
    from distributed import Client, Security

#: Schemes whose connections are TLS: they need the cluster's certificates.
TLS_SCHEMES = ("tls", "wss")
#: The certificate settings, in the order messages name them.
TLS_SETTINGS = ("scheduler.tls_ca", "scheduler.tls_cert", "scheduler.tls_key")
#: How to make the certificates, for messages.
MAKE_CERTS = "'fieldbank cluster certs --out DIR' makes them (docs/scale-out.md)"


@dataclass(frozen=True)
class SchedulerFlags:
    """What the command line said about the scheduler (None: the option was not given)."""

    address: str | None = None
    tls_ca: str | None = None
    tls_cert: str | None = None
    tls_key: str | None = None
    insecure: bool | None = None


@dataclass(frozen=True)
class TlsFiles:
    """The cluster's CA certificate and this client's certificate and key (PEM files)."""

    ca: Path
    cert: Path
    key: Path


@dataclass(frozen=True)
class Scheduler:
    """A scheduler a batch may connect to, as :func:`resolve_scheduler` accepted it.

    Attributes
    ----------
    address : str
        ``SCHEME://HOST:PORT`` (never a user or a password).
    source : str
        Where the address came from ('flag --scheduler', 'variable FIELDBANK_SCHEDULER', ...).
    tls : TlsFiles or None
        The certificates of a ``tls://``/``wss://`` address; None for a plain one.
    insecure : bool
        A plain address beyond the loopback, accepted by the insecure setting:
        :attr:`warning` says the risk.
    """

    address: str
    source: str
    tls: TlsFiles | None = None
    insecure: bool = False

    @property
    def warning(self) -> str | None:
        """The risk of an insecure scheduler, in words; None for a safe one."""
        if not self.insecure:
            return None
        return (f"WARNING: {self.address} is neither encrypted nor authenticated (accepted by "
                "--insecure-scheduler): anyone who can reach it can run any code on its "
                "workers as their user, with their database access, and read the tasks on "
                "the way. Use tls:// with the cluster's certificates (docs/scale-out.md).")

    def security(self) -> Security | None:
        """Dask's ``Security`` for this client: the certificates of a TLS address, with
        encryption required on every connection (to the scheduler and to each worker);
        None for a plain address on the loopback (or an insecure one)."""
        if self.tls is None:
            return None
        from distributed import Security

        return Security(tls_ca_file=str(self.tls.ca), tls_client_cert=str(self.tls.cert),
                        tls_client_key=str(self.tls.key), require_encryption=True)

    def connect(self, timeout_s: float) -> Client:
        """A Dask client of this scheduler, once the scheduler has answered Dask's handshake
        within ``timeout_s`` (Dask bounds the connection but not the handshake after it: a
        port that accepts and never answers would hold the command for ever).

        Raises
        ------
        ClusterError
            No scheduler answered within ``timeout_s`` (not running, unreachable, not a Dask
            scheduler, or it refused this client's certificate - a TLS refusal looks the same
            from here).
        """
        # asyncio with the connection: a command that only names a scheduler (every batch
        # command's options) starts without the event loop's modules
        import asyncio

        from distributed import Client
        from distributed.comm import connect

        security = self.security()
        args = security.get_connection_args("client") if security is not None else {}

        async def handshake() -> None:
            comm = await connect(self.address, timeout=timeout_s, **args)
            await comm.close()

        try:
            asyncio.run(asyncio.wait_for(handshake(), timeout_s))
            return Client(self.address, timeout=timeout_s, set_as_default=False,
                          security=security)
        except Exception as exc:  # OSError, TimeoutError, or a peer that is not Dask
            why = str(exc) or f"no answer within {timeout_s:g} s"
            how, take = "", ""
            if self.tls is not None:
                how = f" with the certificate {self.tls.cert}"
                take = (", and does it take this certificate (issued by the same 'fieldbank "
                        "cluster certs' run as its own)")
            raise ClusterError(
                f"cannot reach the Dask scheduler at {self.address}{how}: {why}. Is it "
                f"running (docs/scale-out.md: 'dask scheduler' and 'dask worker'){take}? "
                "Nothing was recorded.") from None


def is_loopback(host: str) -> bool:
    """Whether ``host`` (an address's host part, IPv6 in brackets) is this machine's loopback,
    judged from its text alone: an IP address in 127.0.0.0/8 or ::1 (also IPv4-mapped), or
    the name ``localhost``. Any other name is not, whatever it resolves to (resolving would
    send a query before the decision)."""
    h = host.strip().lower()
    if h.startswith("[") and h.endswith("]"):
        h = h[1:-1]
    if h == "localhost":
        return True
    try:
        ip = ipaddress.ip_address(h)
    except ValueError:
        return False
    mapped = getattr(ip, "ipv4_mapped", None)
    return ip.is_loopback or (mapped is not None and mapped.is_loopback)


def resolve_scheduler(option: str | SchedulerFlags | None = None) -> Scheduler | None:
    """The scheduler a batch command uses, checked against the rule of the module docstring;
    None: local worker processes.

    ``option``: the command line's scheduler options (:class:`SchedulerFlags`), or just an
    address (``--scheduler``). Each setting comes from its flag, else its variable, else
    ``fieldbank.toml``, else its default (:func:`fieldbank.config.setting`). An empty address
    means none.

    Raises
    ------
    ConfigError
        The address is not ``SCHEME://HOST:PORT`` with a scheme Dask speaks.
    ClusterError
        A plain address beyond the loopback without the insecure setting; a TLS address
        without its three certificate files, or with files that do not fit.
    """
    flags = option if isinstance(option, SchedulerFlags) else SchedulerFlags(address=option)
    if flags.address is not None and not flags.address.strip():
        return None
    where = setting("scheduler", flags.address)
    if where.value is None:
        return None
    address = str(where.value)
    m = SCHEDULER_RE.fullmatch(address)
    assert m is not None  # the setting's check matched it
    scheme, host = m.group(1), m.group(2)
    said = f"{address} (from {where.source})"
    if scheme in TLS_SCHEMES:
        files = [setting(name, getattr(flags, name.split(".")[1])) for name in TLS_SETTINGS]
        return Scheduler(address, where.source, check_tls_files(said, files))
    if is_loopback(host):
        return Scheduler(address, where.source)
    insecure = setting("scheduler.insecure", flags.insecure or None)
    if not insecure.value:
        port = m.group(3)
        raise ClusterError(
            f"the scheduler {said} is refused: a {scheme}:// connection is neither encrypted "
            f"nor authenticated, so anyone who can reach port {port} of {host} can run any code "
            "on the cluster's workers as their user - with their access to the database and "
            "the patients' data - and read or change the tasks on the way. Use "
            f"tls://{host}:{port} with the cluster's certificates ({MAKE_CERTS}), or a "
            "scheduler on this machine's loopback (tcp://127.0.0.1:PORT); to take the risk on a "
            "network you trust, give --insecure-scheduler (FIELDBANK_INSECURE_SCHEDULER=1, "
            "[scheduler] insecure = true). Nothing was sent.")
    return Scheduler(address, where.source, insecure=True)


def check_tls_files(said: str, files: list[Setting]) -> TlsFiles:
    """The certificate settings of a TLS address, each file checked: present and readable, the
    key readable by its owner only, the certificate issued by the CA, valid today, and the
    key its own.

    Raises
    ------
    ClusterError
        Naming the setting, the file and where its value came from.
    """
    missing = [s.name.split(".")[1] for s in files if s.value is None]
    if missing:
        raise ClusterError(
            f"the scheduler {said} speaks TLS and needs the cluster's certificates: "
            "tls_ca, tls_cert and tls_key under [scheduler] in fieldbank.toml, the variables "
            "FIELDBANK_SCHEDULER_TLS_CA/_CERT/_KEY or the flags --tls-ca/--tls-cert/--tls-key; "
            f"missing: {', '.join(missing)}. {MAKE_CERTS}.")
    ca_s, cert_s, key_s = files
    pems: dict[str, bytes] = {}
    for s in files:
        try:
            pems[s.name] = Path(s.value).read_bytes()
        except OSError as exc:
            raise ClusterError(f"{s.name} {s.value} (from {s.source}): cannot read it "
                               f"({exc.strerror}).") from None
    mode = os.stat(key_s.value).st_mode
    if os.name == "posix" and mode & 0o077:
        raise ClusterError(
            f"scheduler.tls_key {key_s.value} (from {key_s.source}) can be read by other users "
            f"(mode {stat.filemode(mode)}); whoever reads it can run code on the cluster. "
            f"Make it private: chmod 600 {key_s.value}.")
    _check_chain(pems[ca_s.name], pems[cert_s.name], ca_s, cert_s)
    import ssl

    try:
        ctx = ssl.create_default_context(ssl.Purpose.SERVER_AUTH, cafile=str(ca_s.value))
        ctx.load_cert_chain(str(cert_s.value), str(key_s.value))
    except (ssl.SSLError, ValueError) as exc:
        raise ClusterError(
            f"scheduler.tls_key {key_s.value} (from {key_s.source}) is not the key of "
            f"scheduler.tls_cert {cert_s.value}, or not a PEM private key without a "
            f"passphrase ({exc}).") from None
    return TlsFiles(Path(ca_s.value), Path(cert_s.value), Path(key_s.value))


def _check_chain(ca_pem: bytes, cert_pem: bytes, ca_s: Setting, cert_s: Setting) -> None:
    """The certificate is a PEM certificate issued by the CA and valid now."""
    from cryptography import x509
    from cryptography.exceptions import InvalidSignature

    def load(pem: bytes, s: Setting) -> Any:
        try:
            return x509.load_pem_x509_certificate(pem)
        except ValueError:
            raise ClusterError(f"{s.name} {s.value} (from {s.source}): not a PEM "
                               "certificate.") from None

    ca, cert = load(ca_pem, ca_s), load(cert_pem, cert_s)
    try:
        cert.verify_directly_issued_by(ca)
    except (ValueError, TypeError, InvalidSignature):
        raise ClusterError(
            f"scheduler.tls_cert {cert_s.value} was not issued by scheduler.tls_ca "
            f"{ca_s.value} (they come from different 'fieldbank cluster certs' runs?); the "
            "scheduler would refuse it.") from None
    now = datetime.now(UTC)
    for c, s in ((ca, ca_s), (cert, cert_s)):
        if now > c.not_valid_after_utc:
            raise ClusterError(f"{s.name} {s.value} expired on "
                               f"{c.not_valid_after_utc:%Y-%m-%d}: {MAKE_CERTS}.")
        if now < c.not_valid_before_utc:
            raise ClusterError(f"{s.name} {s.value} is not valid before "
                               f"{c.not_valid_before_utc:%Y-%m-%d %H:%M} UTC (is this "
                               "machine's clock right?).")
