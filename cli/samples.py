"""``fieldbank samples``: write the synthetic sample files (not patient data)."""

from __future__ import annotations

import click

from fieldbank.cli.options import emit_json, json_option


@click.command("samples")
@click.argument("directory", type=click.Path(file_okay=False))
@click.option("--seed", type=int, default=20240601, show_default=True)
@json_option
def samples(directory: str, seed: int, as_json: bool) -> None:
    """Write lab-style map files of synthetic patients into DIRECTORY (seeded)."""
    from fieldbank.interventions.samples import write_samples  # numerics: when it runs

    manifest = write_samples(directory, seed)
    if as_json:
        emit_json(manifest)
    n = sum(len(s["files"]) for p in manifest["patients"] for s in p["sessions"])
    click.echo(f"wrote {n} synthetic sample file(s) for {len(manifest['patients'])} patients "
               f"to {directory} (see manifest.json)", err=True)
