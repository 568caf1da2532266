"""The schema revisions this program knows, read from the packaged migration files.

Each revision file of ``fieldbank.migrations.versions`` names itself and its parent in its
``revision = "0003"`` and ``down_revision = "0002"`` (or ``None``) lines; read here as text, so
that opening a database at head needs neither alembic nor SQLAlchemy (tests/test_migrations.py
checks the reading against alembic's own). The directory is found through the package's import
spec (``importlib.resources`` would load zipfile, tempfile and shutil for it: the list
commands' start-up). :mod:`fieldbank.storage.migrate` drives alembic and uses these; the light
listing (:mod:`fieldbank.stored.listing`) compares a database's revision with
:func:`head_revision` before it reads.
"""

from __future__ import annotations

import functools
import importlib.util
import re
from pathlib import Path

from fieldbank.errors import StorageError

#: ``revision = "0003"`` and ``down_revision = "0002"`` (or ``None``) lines of a revision file.
_REVISION_LINE = re.compile(
    r"^(revision|down_revision)\s*(?::[^=]*)?=\s*(?:[\"']([^\"']+)[\"']|None)\s*$", re.M)


def versions_dir() -> Path:
    """The directory of the packaged revision files (``fieldbank.migrations.versions``)."""
    spec = importlib.util.find_spec("fieldbank.migrations")
    if spec is None or not spec.submodule_search_locations:
        raise StorageError("The migrations of this fieldbank are not installed "
                           "(fieldbank.migrations is missing).")
    return Path(next(iter(spec.submodule_search_locations))) / "versions"


@functools.cache
def _revision_files() -> tuple[tuple[str, str | None, Path], ...]:
    """(revision, down_revision, file) of every packaged revision file."""
    out = []
    for f in sorted(versions_dir().iterdir()):
        if not f.name.endswith(".py") or f.name.startswith("__"):
            continue
        found = {m.group(1): m.group(2)
                 for m in _REVISION_LINE.finditer(f.read_text(encoding="utf-8"))}
        if "revision" not in found or not found["revision"]:
            raise StorageError(f"Migration file {f.name} names no revision.")
        out.append((found["revision"], found.get("down_revision"), f))
    return tuple(out)


def known_revisions() -> list[str]:
    """Every revision this program's migrations know, oldest first."""
    files = _revision_files()
    down = {rev: parent for rev, parent, _ in files}
    heads = sorted(set(down) - {p for p in down.values() if p is not None})
    if len(heads) != 1:
        raise StorageError(f"Migrations must have one head; found {heads}.")
    chain: list[str] = []
    rev: str | None = heads[0]
    while rev is not None:
        if rev in chain or rev not in down:
            raise StorageError(f"Migrations do not form one chain at revision {rev!r}.")
        chain.append(rev)
        rev = down[rev]
    if len(chain) != len(down):
        raise StorageError("Migrations do not form one chain: "
                           f"{', '.join(sorted(set(down) - set(chain)))} left out.")
    return list(reversed(chain))


def head_revision() -> str:
    return known_revisions()[-1]


def revision_title(revision: str) -> str:
    """The first line of a revision's docstring (what it changes)."""
    import ast  # only to name a revision in a message: opening a database needs no parser

    for rev, _, f in _revision_files():
        if rev == revision:
            doc = (ast.get_docstring(ast.parse(f.read_text(encoding="utf-8"))) or "").strip()
            return doc.splitlines()[0].rstrip(".") if doc else rev
    return revision


def schema_state(current: str | None) -> str:
    """'empty', 'behind', 'current' or 'newer' (made by a newer fieldbank) for a revision."""
    if current is None:
        return "empty"
    if current == head_revision():
        return "current"
    return "behind" if current in known_revisions() else "newer"
