"""The README is a test: every command of its ``sh`` blocks runs, in order, on a fresh home
(tests/readme_runner.py says how, and the HTML-comment directives a block may carry); then
every list and show command, on the database the tours leave, prints within 100 columns.

The run writes a transcript of every command with its output, status, wall and CPU time to
``readme-run.log`` in the test's temporary directory (kept by pytest for the last runs), and
``FIELDBANK_README_LOG`` names another place for it.
"""

from __future__ import annotations

import os
import subprocess
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.readme_runner import ROOT, Block, Runner, foreign_addresses, parse

README = ROOT / "README.md"
#: The widest line a table or a message may print (the README promises 100 columns).
WIDTH = 100


class ReadmeSkip(UserWarning):
    """A README command the test does not run, with the reason."""


def _blocks() -> list[Block]:
    return parse(README.read_text(encoding="utf-8"))


def test_every_directive_names_one_command_and_no_command_leaves_this_machine() -> None:
    blocks = _blocks()  # a directive matching no command, or several, raises here
    commands = [c for b in blocks for c in b.commands]
    assert len(commands) > 40
    for c in commands:
        if not c.skip and not c.offline:
            assert not foreign_addresses(c.to_run), (c.line, c.text)
        if c.background:
            assert c.stop or "--duration-s" in c.to_run or c.exit == 0, c.text
    # the tours start where a new user starts, and the skips say why
    assert commands[0].bare == "scripts/demo"
    assert all(len(c.skip) > 20 for c in commands if c.skip)
    assert all(len(c.offline) > 20 for c in commands if c.offline)


def test_the_address_check_catches_another_machine() -> None:
    assert foreign_addresses("fieldbank report --scheduler tcp://10.0.0.5:8786") == ["10.0.0.5"]
    assert foreign_addresses("x --db postgresql+psycopg://u:p@db.example/fb") == ["db.example"]
    assert foreign_addresses("x --peer 192.168.1.4:47400 --bind 0.0.0.0:1") == [
        "192.168.1.4", "0.0.0.0"]
    assert foreign_addresses("x --peer 127.0.0.1:47400 --robot sim://?mode=realtime "
                             "--db sqlite:///demo-out/a.sqlite3 tls://[::1]:8786") == []


@pytest.fixture(scope="module")
def toured(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Runner, list[str]]]:
    """The README run once, block by block: the runner and what went wrong (empty: all
    passed)."""
    base = tmp_path_factory.mktemp("readme")
    log_path = Path(os.environ.get("FIELDBANK_README_LOG") or base / "readme-run.log")
    with log_path.open("w", encoding="utf-8") as log:
        runner = Runner(base / "work", log)
        problems: list[str] = []
        for block in _blocks():
            problems = runner.block(block)
            if problems:
                break
        yield runner, problems


@pytest.mark.timeout(5400)  # a hang guard: on a busy machine the tours take many minutes
def test_every_readme_command_runs_as_written(toured: tuple[Runner, list[str]]) -> None:
    runner, problems = toured
    for cmd, why in runner.skipped:
        warnings.warn(ReadmeSkip(f"README line {cmd.line}: not run: {cmd.text!r}: {why}"),
                      stacklevel=1)
    assert not problems, "\n\n".join(problems)
    ran = {o.command.line for o in runner.outcomes}
    assert len(ran) >= 40
    wall = sum(o.seconds for o in runner.outcomes)
    cpu = sum(o.cpu_seconds for o in runner.outcomes)
    print(f"README: {len(ran)} commands, {wall:.0f} s wall, {cpu:.0f} s CPU; "
          f"{len(runner.skipped)} not run")


#: Every command that lists or shows what the database holds, as the tours leave it.
LIST_AND_SHOW = [
    "patient list", "patient show SYN-001", "maps list", "maps list --patient SYN-001",
    "models list", "models list --patient SYN-001", "models show 1", "models show 4",
    "plans list", "plans show 1", "plans show 7", "jobs", "jobs 1", "haptic sessions list",
    "haptic sessions show 1", "haptic sessions show 3", "haptic train results", "config show",
    "db check", "db current", "fit SYN-001 --session pre-BoNT", "validate",
    "validate --loo SYN-002", "whatif SYN-001 --botox ef=200U",
    "whatif SYN-001 --botox ef=200U,bf=100U --timecourse",
    "whatif SYN-001 --session pre-BoNT --botox ef=200U --detail",
]


@pytest.mark.timeout(5400)
def test_every_list_and_show_fits_in_100_columns(toured: tuple[Runner, list[str]]) -> None:
    runner, problems = toured
    assert not problems, "the README run failed first"
    env = {**runner.env, "FIELDBANK_HOME": "demo-out/home"}
    wide: list[str] = []
    for args in LIST_AND_SHOW:
        r = subprocess.run(["bash", "-c", f"fieldbank {args}"], cwd=runner.work, env=env,
                           capture_output=True, text=True, timeout=900)
        assert r.returncode in (0, 1) and "Traceback" not in r.stderr, (args, r.stderr)
        assert r.stdout.strip() or r.stderr.strip(), args
        for stream in (r.stdout, r.stderr):
            wide += [f"fieldbank {args}: {len(line)} columns: {line}"
                     for line in stream.splitlines() if len(line) > WIDTH]
    # what the tours printed, too (haptic measure's notes, fit's tables, ...): every
    # fieldbank command's (a benchmark's figures are a script's, not the product's)
    for o in runner.outcomes:
        if not o.command.bare.startswith(("fieldbank", ".venv/bin/fieldbank")):
            continue
        wide += [f"{o.command.text}: {len(line)} columns: {line}"
                 for line in o.output.splitlines()
                 if len(line) > WIDTH and not _exempt(line)]
    assert not wide, "\n".join(wide)


def _exempt(line: str) -> bool:
    """Lines a person does not read as a table: a JSON document's, a path or URL alone."""
    s = line.strip()
    return s.startswith(('"', "{", "[")) or " " not in s
