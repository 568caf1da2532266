"""Shared set-up of the report tests: a small stored batch built by the real flow."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from click.testing import CliRunner, Result


def build_batch(root: Path, patients: tuple[str, ...] = ("SYN-001", "SYN-002")) -> dict[str, Any]:
    """Samples → ingest → fit → botulinum and lengthening plans, on a SQLite file under root."""
    from fieldbank.cli.demo import populate
    from fieldbank.storage import Database

    url = f"sqlite:///{root / 'db' / 'fieldbank.sqlite3'}"
    with Database.open(url) as db:
        info = populate(db, root / "samples", patients=patients)
    info["url"] = url
    return info


def run_cli(*args: str) -> Result:
    from fieldbank.cli.main import cli

    return CliRunner().invoke(cli, list(args), catch_exceptions=False)
