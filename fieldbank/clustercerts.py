"""A Dask cluster's own certificate authority and its certificates (``fieldbank cluster certs``).

A cluster admits a machine by its certificate: the scheduler, every worker and every client
that runs fieldbank's batch commands shows one issued by the cluster's authority and checks
the other side's (mutual TLS; :mod:`fieldbank.scheduler`, docs/scale-out.md). This module makes
that authority and the three certificates, with the ``cryptography`` package (X.509, keys and
signatures come from it, never from code written here):

=====================================  =========================================================
``ca.pem``                             the authority's certificate: to every machine
``scheduler.pem``, ``scheduler-key.pem``  the scheduler's machine (TLS server and client)
``worker.pem``, ``worker-key.pem``      every worker machine (workers listen and connect)
``client.pem``, ``client-key.pem``      where fieldbank's batch commands run (client only)
``dask.yaml``                           the scheduler's and the workers' machines: fieldbank's
                                        Dask settings (:mod:`fieldbank.clusterconfig`)
=====================================  =========================================================

Keys are ECDSA P-256, written 0600 from their creation; certificates 0644. The authority's
own private key signs the three certificates in memory and is never written: no file
anywhere can issue another certificate this cluster trusts. Adding a machine uses the
existing files; replacing a lost or leaked key means a new set (``--force``) deployed to every
machine, which also shuts out every holder of the old one - there is no revocation list,
because there is nothing to revoke with.

Dask checks that a peer's certificate comes from the authority, not which host it names (it
expects addresses to be IPs): every holder of any of these certificates is a member of the
cluster and can run code on its workers. The scheduler's certificate names the hosts given
(``--host``) anyway, so that standard tools can check them.

``dask.yaml`` is no secret: it makes the cluster's idle timers less frequent and stops the
workers' profiler, and is read only by the processes started with ``DASK_CONFIG`` naming it
(the commands ``fieldbank cluster certs`` prints).

The files are written together (:func:`fieldbank.files.write_directory`): a failure leaves
none of them, and a set in place is replaced only with ``force``.
"""

from __future__ import annotations

import ipaddress
import os
import re
import secrets
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any, ClassVar

from fieldbank.clusterconfig import CONFIG_FILE, dask_yaml
from fieldbank.errors import FileRefused, ParameterError
from fieldbank.files import DISK_FULL_ERRNOS, disk_full_message, write_directory
from fieldbank.validation import Interval, check_fields

#: Certificate and key file of each role, in the order they are listed.
ROLES = ("scheduler", "worker", "client")
CA_FILE = "ca.pem"
#: Every file a set holds.
FILES = (CA_FILE, *(f for r in ROLES for f in (f"{r}.pem", f"{r}-key.pem")))
#: Every file written: the set and fieldbank's Dask settings.
WRITTEN = (*FILES, CONFIG_FILE)
#: The private keys among them (written 0600).
KEY_FILES = tuple(f"{r}-key.pem" for r in ROLES)
#: Slack for clocks that disagree: certificates are valid from this long before now.
CLOCK_SLACK = timedelta(minutes=5)
_DNS_NAME = re.compile(r"(?=.{1,253}$)([A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?\.?)+")


@dataclass(frozen=True)
class CertOptions:
    """What a set of certificates is made with.

    Attributes
    ----------
    days : int
        How long the certificates (and the authority) are valid, days.
    hosts : tuple of str
        Names and IP addresses of the scheduler's machine, written into its certificate
        (``localhost``, 127.0.0.1 and ::1 are always there).
    """

    days: int = 365
    hosts: tuple[str, ...] = field(default=())

    BOUNDS: ClassVar[dict[str, Interval]] = {"days": Interval.whole(1, 3650, "days")}

    def __post_init__(self) -> None:
        check_fields(self, self.BOUNDS)
        bad = [h for h in self.hosts if _host_name(h) is None]
        if bad:
            raise ParameterError(f"--host {bad[0]!r} is neither an IP address nor a host name "
                                 "(letters, digits, '-' and '.'; no wildcards).")


@dataclass(frozen=True)
class CertSet:
    """A set written: where, its files, the authority's fingerprint and the expiry."""

    out_dir: Path
    files: tuple[Path, ...]
    ca_fingerprint: str
    not_after: datetime
    hosts: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return {"out": str(self.out_dir), "files": [str(p) for p in self.files],
                "ca_sha256": self.ca_fingerprint, "not_after": self.not_after.isoformat(),
                "scheduler_hosts": list(self.hosts)}


def _host_name(text: str) -> Any:
    """The subject alternative name for a host given as text, or None if it is not one."""
    from cryptography import x509

    try:
        return x509.IPAddress(ipaddress.ip_address(text.strip("[]")))
    except ValueError:
        pass
    return x509.DNSName(text) if _DNS_NAME.fullmatch(text) else None


def _usage(**allowed: bool) -> Any:
    """An X.509 key usage extension allowing only the uses named."""
    from cryptography import x509

    uses = ("digital_signature", "content_commitment", "key_encipherment", "data_encipherment",
            "key_agreement", "key_cert_sign", "crl_sign", "encipher_only", "decipher_only")
    return x509.KeyUsage(**{u: allowed.get(u, False) for u in uses})


def make_certs(options: CertOptions) -> tuple[dict[str, bytes], str, datetime]:
    """A new authority and the three certificates: (file name -> PEM bytes, the authority's
    SHA-256 fingerprint, the expiry). Nothing is written."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    now = datetime.now(UTC)
    start, end = now - CLOCK_SLACK, now + timedelta(days=options.days)
    cluster = secrets.token_hex(4)  # tells the sets of different runs apart in messages

    def name(cn: str) -> x509.Name:
        return x509.Name([x509.NameAttribute(NameOID.ORGANIZATION_NAME, "fieldbank"),
                          x509.NameAttribute(NameOID.COMMON_NAME, cn)])

    def builder(subject: x509.Name, issuer: x509.Name, key: Any) -> x509.CertificateBuilder:
        return (x509.CertificateBuilder().subject_name(subject).issuer_name(issuer)
                .public_key(key.public_key()).serial_number(x509.random_serial_number())
                .not_valid_before(start).not_valid_after(end)
                .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()),
                               critical=False))

    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca_name = name(f"fieldbank cluster {cluster} authority")
    ca = (builder(ca_name, ca_name, ca_key)
          .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
          .add_extension(_usage(key_cert_sign=True, crl_sign=True), critical=True)
          .sign(ca_key, hashes.SHA256()))
    ca_ski = ca.extensions.get_extension_for_class(x509.SubjectKeyIdentifier).value
    out = {CA_FILE: ca.public_bytes(serialization.Encoding.PEM)}
    sans = ["localhost", "127.0.0.1", "::1", *options.hosts]
    for role in ROLES:
        key = ec.generate_private_key(ec.SECP256R1())
        usage = ([ExtendedKeyUsageOID.CLIENT_AUTH] if role == "client" else
                 [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH])
        b = (builder(name(f"fieldbank cluster {cluster} {role}"), ca_name, key)
             .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
             .add_extension(_usage(digital_signature=True, key_agreement=True), critical=True)
             .add_extension(x509.ExtendedKeyUsage(usage), critical=False)
             .add_extension(x509.AuthorityKeyIdentifier.from_issuer_subject_key_identifier(
                 ca_ski), critical=False))
        if role == "scheduler":
            b = b.add_extension(x509.SubjectAlternativeName(
                [_host_name(h) for h in dict.fromkeys(sans)]), critical=False)
        out[f"{role}.pem"] = b.sign(ca_key, hashes.SHA256()).public_bytes(
            serialization.Encoding.PEM)
        out[f"{role}-key.pem"] = key.private_bytes(
            serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption())
    fingerprint = ca.fingerprint(hashes.SHA256()).hex(":").upper()
    return {f: out[f] for f in FILES}, fingerprint, end


def write_certs(out_dir: str | Path, options: CertOptions, force: bool = False) -> CertSet:
    """Make a set (:func:`make_certs`) and write it, with ``dask.yaml``, into ``out_dir``
    (created 0700 when it does not exist; its parent must).

    Raises
    ------
    FileRefused
        ``out_dir`` is not a directory, its parent does not exist, it holds files of a set
        already (without ``force``), or the files could not be written (nothing was).
    """
    out = Path(out_dir).expanduser()
    if os.path.lexists(out) and not out.is_dir():
        raise FileRefused(f"{out} exists and is not a directory.")
    if not out.parent.is_dir():
        raise FileRefused(f"the directory {out.parent} does not exist; create it first (or "
                          "choose another --out).")
    there = [f for f in WRITTEN if os.path.lexists(out / f)]
    if there and not force:
        raise FileRefused(
            f"{out} already holds {', '.join(there)}; replacing them shuts out "
            "every machine that has the old files until it gets the new ones. Give --force to "
            "replace them, or choose another --out.")
    pems, fingerprint, end = make_certs(options)
    files: dict[str, bytes | str] = {**pems, CONFIG_FILE: dask_yaml()}
    modes: Mapping[str, int] = {f: 0o600 if f in KEY_FILES else 0o644 for f in WRITTEN}
    try:
        write_directory(out, files, modes=modes, private=True)
    except OSError as exc:
        if exc.errno in DISK_FULL_ERRNOS:
            raise FileRefused(disk_full_message(out, exc)) from None
        raise FileRefused(f"cannot write the certificates into {out}: "
                          f"{exc.strerror or exc}; nothing was written.") from None
    return CertSet(out, tuple(out / f for f in WRITTEN), fingerprint, end, options.hosts)
