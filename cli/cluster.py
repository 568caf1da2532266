"""``fieldbank cluster certs``: the certificates a Dask cluster admits its members by."""

from __future__ import annotations

import json
import shlex

import click

from fieldbank.cli.options import emit_json, json_option, say


@click.group("cluster")
def cluster() -> None:
    """The Dask cluster of the batch commands: its certificates (docs/scale-out.md)."""


@cluster.command("certs")
@click.option("--out", "out_dir", required=True, type=click.Path(file_okay=False),
              help="Directory for the certificates and keys (made, readable by you only, when "
                   "it does not exist; its parent must).")
@click.option("--host", "hosts", multiple=True, metavar="NAME|IP",
              help="A name or address of the scheduler's machine, written into its "
                   "certificate (repeatable; localhost, 127.0.0.1 and ::1 are always there).")
@click.option("--days", type=int, default=365, show_default=True,
              help="How long the certificates are valid.")
@click.option("--force", is_flag=True,
              help="Replace a set already in --out (every machine then needs the new files).")
@json_option
def certs(out_dir: str, hosts: tuple[str, ...], days: int, force: bool, as_json: bool) -> None:
    """Make a certificate authority for one cluster and the scheduler's, the workers' and the
    clients' certificates and keys (keys 0600), with fieldbank's Dask settings (dask.yaml),
    and say where each goes.

    The authority's own key is never written: no file can issue another certificate the
    cluster trusts. Every holder of one of these certificates can run code on the workers.
    """
    from fieldbank.clustercerts import CertOptions, write_certs

    done = write_certs(out_dir, CertOptions(days=days, hosts=tuple(hosts)), force=force)
    if as_json:
        emit_json(done.to_dict())
    d = done.out_dir.resolve()

    def f(name: str) -> str:  # a path in a shell command
        return shlex.quote(str(d / name))

    def toml(name: str) -> str:  # a path as a TOML string (JSON's escapes are TOML's)
        return json.dumps(str(d / name))

    host = next((h for h in done.hosts), "HOST")
    addr = f"tls://{f'[{host}]' if ':' in host else host}:8786"
    say(f"wrote {len(done.files)} files to {d} (keys readable by you only); the authority's "
        f"SHA-256 fingerprint {done.ca_fingerprint}; valid until "
        f"{done.not_after:%Y-%m-%d}.\n"
        f"\nThe scheduler's machine (ca.pem, scheduler.pem, scheduler-key.pem, dask.yaml):\n"
        f"  DASK_CONFIG={f('dask.yaml')} \\\n"
        f"  dask scheduler --protocol tls --host {host} --port 8786 "
        f"--dashboard-address 127.0.0.1:8787 \\\n    --tls-ca-file {f('ca.pem')} "
        f"--tls-cert {f('scheduler.pem')} --tls-key {f('scheduler-key.pem')}\n"
        f"\nEach worker machine (ca.pem, worker.pem, worker-key.pem, dask.yaml):\n"
        f"  DASK_CONFIG={f('dask.yaml')} \\\n"
        f"  dask worker {addr} --nworkers auto --nthreads 1 \\\n"
        f"    --tls-ca-file {f('ca.pem')} --tls-cert {f('worker.pem')} "
        f"--tls-key {f('worker-key.pem')}\n"
        f"\nWhere fieldbank's batch commands run (ca.pem, client.pem, client-key.pem), in "
        f"fieldbank.toml:\n"
        f"  [scheduler]\n  address = \"{addr}\"\n  tls_ca = {toml('ca.pem')}\n"
        f"  tls_cert = {toml('client.pem')}\n  tls_key = {toml('client-key.pem')}\n"
        "\nCopy each key only to the machines that need it, readable by the user that runs "
        "Dask there (chmod 600): whoever holds any of these keys can run code on the "
        "workers. dask.yaml makes the cluster's idle timers less frequent and stops the "
        "workers' profiler (docs/scale-out.md, \"Quieter workers\"); leave DASK_CONFIG out "
        "to keep Dask's defaults.")
