"""Start-up: which modules a command loads (never how long it takes - loaded machines vary).

* every command's and subcommand's ``--help`` loads none of the numerics, the database layer,
  the plotting or the event loop (numpy, scipy, nlopt, SQLAlchemy, alembic, h5py, matplotlib,
  pyserial, asyncio);
* a command that lists what the database holds (``patient list``, ``models list``, ``maps
  list``, ``plans list``, ``jobs``, with their filters and ``--json``) reads a database at head
  through its driver alone: none of the above, nor the storage layer (``fieldbank.storage``:
  its ORM, the array store ``fieldbank.arraystore``, the integrity check), nor psycopg for a
  SQLite file; on PostgreSQL psycopg and still no SQLAlchemy or numpy. A database behind head
  is opened through the storage layer (which migrates it) - the light path is not taken
  blindly;
* the choices and defaults the options show are the library's own, kept in leaf modules that
  import nothing (``fieldbank.fitchoices``, ``.probechoices``, ``.measurechoices``,
  ``fieldbank.interventions.whatifchoices``), which the library's configurations and the
  commands both read: no copy to keep equal.

``benchmarks/bench_cli_startup.py`` measures the times, as ratios to ``import click``.
"""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Nothing of these may load for --help.
HEAVY_FOR_HELP = ("numpy", "scipy", "nlopt", "sqlalchemy", "alembic", "h5py", "matplotlib",
                  "serial", "asyncio")
#: Nothing of these may load for a command that lists a database at head (a SQLite file).
HEAVY_FOR_READS = (*HEAVY_FOR_HELP, "fieldbank.storage", "fieldbank.storage.check",
                   "fieldbank.arraystore", "psycopg")
#: Nothing of these may load for a command that lists a server database (psycopg itself loads
#: asyncio).
SERVER_READ_HEAVY = (*(h for h in HEAVY_FOR_HELP if h != "asyncio"), "fieldbank.storage",
                     "fieldbank.arraystore")
#: The list commands, with filters and --json.
READS = ["patient list", "patient list --json", "models list", "models list --patient P-1",
         "maps list", "maps list --patient P-1 --kind postural --json", "plans list",
         "plans list --kind botulinum --json", "jobs", "jobs 1 --json", "jobs --kind fit"]
#: Commands whose module this check does not cover yet (their --help still loads numerics).
NOT_COVERED: set[tuple[str, ...]] = set()

_WALK = """
import json, sys
import click
from fieldbank.cli.main import cli

heavy = json.loads(sys.argv[1])
found = {}
walked = []

def run(path):
    walked.append(" ".join(path))
    try:
        cli.main([*path, "--help"], prog_name="fieldbank", standalone_mode=False)
    except SystemExit:
        pass
    loaded = sorted(h for h in heavy if h in sys.modules)
    if loaded:
        found[" ".join(path)] = loaded

def walk(group, path):
    ctx = click.Context(group, info_name="fieldbank")
    for name in group.list_commands(ctx):
        sub = path + [name]
        if tuple(sub) in {tuple(x) for x in json.loads(sys.argv[2])}:
            continue
        run(sub)
        if found:
            return
        cmd = group.get_command(ctx, name)
        if isinstance(cmd, click.Group):
            walk(cmd, sub)

run([])
walk(cli, [])
print(json.dumps({"found": found, "walked": walked}))
"""


def _python(code: str, *args: str, env: dict[str, str] | None = None) -> dict[str, object]:
    r = subprocess.run([sys.executable, "-c", code, *args], cwd=ROOT, capture_output=True,
                       text=True, timeout=300, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads(r.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def test_no_help_loads_anything_heavy() -> None:
    doc = _python(_WALK, json.dumps(HEAVY_FOR_HELP), json.dumps(sorted(NOT_COVERED)))
    walked = doc["walked"]
    assert isinstance(walked, list) and len(walked) > 40  # every command and subcommand
    assert {"whatif", "plans show", "haptic train simulate", "db upgrade"} <= set(walked)
    assert doc["found"] == {}, f"--help loaded heavy modules: {doc['found']}"


_READ = """
import json, sys
from fieldbank.cli.main import cli
try:
    cli.main(sys.argv[2].split(), prog_name="fieldbank", standalone_mode=False)
except SystemExit as exc:
    if exc.code:
        raise
print(json.dumps(sorted(h for h in json.loads(sys.argv[1]) if h in sys.modules)))
"""


@pytest.fixture(scope="module")
def stored_home(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A data directory with a database at head holding a patient, two models, a plan and a
    batch run."""
    from fieldbank.interventions import Botulinum, Plan
    from fieldbank.interventions.whatif import save_plan
    from fieldbank.modelsource import synthetic
    from fieldbank.storage import Database

    home = tmp_path_factory.mktemp("home")
    with Database.open(f"sqlite:///{home / 'fieldbank.sqlite3'}") as db:
        db.add_patient("P-1", 70.0, 1.7, "right")
        source = synthetic(["elbow=severe"])
        saved = save_plan(db, source, Plan((Botulinum({"ef": 100.0}),)))
        assert saved.plan_id == 1
        run = db.start_run("fit", "local processes (1)", {}, [("P-1/pre", "P-1", "pre")])
        db.give_up_job(run.id, "P-1/pre", "no maps")
    return home


def _reads(command: str, heavy: tuple[str, ...], **env: str) -> list[str]:
    environ = {**os.environ, **env}
    environ.pop("FIELDBANK_DB", None)
    loaded = _python(_READ, json.dumps([*heavy, "sqlite3", "fieldbank.stored.listing"]),
                     command, env=environ)
    assert isinstance(loaded, list)
    return loaded


@pytest.mark.parametrize("command", READS)
def test_listing_a_database_loads_its_driver_only(stored_home: Path, command: str) -> None:
    loaded = _reads(command, HEAVY_FOR_READS, FIELDBANK_HOME=str(stored_home))
    assert {"sqlite3", "fieldbank.stored.listing"} <= set(loaded)  # it did read the database
    assert sorted(set(loaded) - {"sqlite3", "fieldbank.stored.listing"}) == [], loaded


@pytest.mark.postgres
def test_listing_a_server_database_loads_psycopg_and_no_sqlalchemy(pg_url: str) -> None:
    from fieldbank.storage import Database

    with Database.open(pg_url, upgrade="always") as db:
        db.add_patient("P-1", 70.0, 1.7, "right")
    for command in ("patient list --json", "jobs", "plans list"):
        loaded = _reads(f"{command} --db {pg_url}", (*SERVER_READ_HEAVY, "psycopg"))
        assert "psycopg" in loaded and "fieldbank.stored.listing" in loaded
        assert sorted(set(loaded) - {"psycopg", "fieldbank.stored.listing", "sqlite3"}) == [], \
            loaded


def test_a_database_behind_head_is_opened_through_the_storage_layer(tmp_path: Path) -> None:
    from sqlalchemy import create_engine

    from fieldbank.storage import migrate

    home = tmp_path / "home"
    home.mkdir()
    engine = create_engine(f"sqlite:///{home / 'fieldbank.sqlite3'}")
    migrate.upgrade(engine, migrate.known_revisions()[-2])
    engine.dispose()
    loaded = _reads("patient list", ("sqlalchemy", "alembic"), FIELDBANK_HOME=str(home))
    assert {"sqlalchemy", "alembic"} <= set(loaded)  # migrated to head, then listed


#: The library's leaf modules that own the choices and defaults the options show.
CHOICE_LEAVES = ("fieldbank/fitchoices.py", "fieldbank/probechoices.py",
                 "fieldbank/measurechoices.py", "interventions/whatifchoices.py")


@pytest.mark.parametrize("leaf", CHOICE_LEAVES)
def test_the_choices_leaves_import_nothing(leaf: str) -> None:
    tree = ast.parse((ROOT / leaf).read_text(encoding="utf-8"))
    imports = [n for n in ast.walk(tree) if isinstance(n, ast.Import | ast.ImportFrom)]
    assert [ast.unparse(n) for n in imports] == ["from __future__ import annotations"]


def test_no_command_keeps_a_copy_of_the_library_s_choices() -> None:
    assert not (ROOT / "cli" / "choices.py").exists()
    for path in sorted((ROOT / "cli").glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        modules = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
        assert "fieldbank.cli.choices" not in modules, path.name


def test_every_path_family_offered_is_one_the_search_knows() -> None:
    from fieldbank.evaluate.design.paths import FAMILIES
    from fieldbank.probechoices import PATH_FAMILIES

    assert tuple(FAMILIES) == PATH_FAMILIES
