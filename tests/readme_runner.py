"""Run the README's commands as written: every ```sh block, in order, on a fresh home.

The README is a test (tests/test_readme.py). Each command of every ``sh`` code block runs as a
new user would type it - through ``bash``, in one fresh working directory (``demo-out/``
relative to it, ``.venv`` the environment the tests run in), with no fieldbank setting in the
environment and an empty home directory - one after the other, each handing the next what it
made (the database, the ids it printed). A command passes when it exits 0 and prints no
traceback.

Where a command cannot run as written here, an HTML comment right before its block says what
the test does instead; readers of the rendered README do not see it. One line per command::

    <!-- readme-test:
    KEY :: ACTION
    -->

``KEY`` is the command's text (its comment left out), or a piece of it that no other command
of the block contains; a directive whose key matches no command, or several, fails the test, so the
directives cannot rot as the README changes. ``ACTION`` is one of

``exit N``
    the command exits with status N (``fieldbank validate`` exits 1 when a prediction failed);
``expect TEXT``
    its output (stdout and stderr) contains TEXT: how the tours hand each other the ids they
    create (``--save :: expect plan 7`` before a later ``plans show 7``);
``add OPTIONS``
    appended to the command: a documented option that shortens a long run (``--grid 3x3``);
``instead COMMAND``
    run COMMAND in its place, for a command that would change the test's own environment
    (``scripts/demo`` installs the environment first; the test has one);
``skip REASON``
    not run; the reason is reported as a warning (a command for another machine, the test
    suite itself);
``background TEXT``
    started and left running once its output shows TEXT (a renderer the next commands talk
    to); at the end of the block it is ended by its ``stop`` command, else waited for;
``stop COMMAND``
    how a ``background`` command is ended at the end of its block (``fieldbank haptic stop``);
``offline REASON``
    the command names another machine but sends it nothing (``cluster certs --host``: a
    certificate for that address): it runs, and the reason says why that is safe.

Several directives may name the same command. No command may name a machine other than this
one: an address that is not the loopback (in ``tcp://``, ``tls://``, ``socket://``, a database
URL, ``--bind``/``--peer``/``--host``) fails the test unless the command is skipped or marked
``offline`` - the test never sends a packet beyond the loopback.
"""

from __future__ import annotations

import ipaddress
import os
import re
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import IO

ROOT = Path(__file__).resolve().parents[1]
ACTIONS = ("exit", "expect", "add", "instead", "skip", "background", "stop", "offline")
#: A hang guard for one command, never a timing target: a busy machine is slow.
COMMAND_TIMEOUT_S = 1800.0
_FENCE = re.compile(r"^```sh\s*\n(.*?)^```", re.S | re.M)
_DIRECTIVES = re.compile(r"<!--\s*readme-test:?\s*\n(.*?)-->", re.S)
_ADDRESS = re.compile(
    r"(?:[a-z][a-z0-9+.\-]*://(?:[^/@\s\"']*@)?(?P<url>\[[^\]]+\]|[^/:?\s\"']+))"
    r"|(?:--(?:bind|peer|host|station-host)[ =]+(?P<opt>\[[^\]]+\]|[^:\s\"']+))")


@dataclass
class Command:
    """One command of a block as the README shows it, and what the test does with it."""

    text: str                       # as written (continuation lines joined), comment kept
    line: int                       # line of the README it starts on
    exit: int = 0
    expect: list[str] = field(default_factory=list)
    add: str = ""
    instead: str = ""
    skip: str = ""
    background: str = ""
    stop: str = ""
    offline: str = ""

    @property
    def bare(self) -> str:
        """The command without its trailing comment (what directives' keys match)."""
        return strip_comment(self.text)

    @property
    def to_run(self) -> str:
        return self.instead or (self.text if not self.add else f"{self.bare} {self.add}")


@dataclass
class Block:
    line: int
    commands: list[Command]


def strip_comment(cmd: str) -> str:
    """``cmd`` without a trailing shell comment (a ``#`` outside quotes after a blank)."""
    quote = ""
    for i, c in enumerate(cmd):
        if quote:
            if c == quote:
                quote = ""
        elif c in "'\"":
            quote = c
        elif c == "#" and (i == 0 or cmd[i - 1].isspace()):
            return cmd[:i].rstrip()
    return cmd.rstrip()


def parse(text: str) -> list[Block]:
    """The README's sh blocks with their directives applied (module docstring); a directive
    that matches no command or several raises ValueError naming it."""
    blocks = []
    for m in _FENCE.finditer(text):
        start = text.count("\n", 0, m.start()) + 2  # first line inside the fence
        commands: list[Command] = []
        pending = ""
        for k, raw in enumerate(m.group(1).splitlines()):
            if pending:
                pending += " " + raw.strip()
            elif raw.strip():
                pending, first = raw.strip(), start + k
            else:
                continue
            if pending.endswith("\\"):
                pending = pending[:-1].rstrip()
                continue
            commands.append(Command(pending, first))
            pending = ""
        before = text[:m.start()].rstrip()
        d = _DIRECTIVES.fullmatch(before[before.rfind("<!--"):]) if before.endswith("-->") \
            else None
        if d is not None:
            _apply(d.group(1), commands, start)
        blocks.append(Block(start, commands))
    return blocks


def _apply(spec: str, commands: list[Command], line: int) -> None:
    for raw in spec.splitlines():
        if not raw.strip():
            continue
        key, sep, action = raw.partition("::")
        key, action = key.strip(), action.strip()
        verb, _, arg = action.partition(" ")
        if not sep or not key or verb not in ACTIONS:
            raise ValueError(f"README block at line {line}: directive {raw.strip()!r} is not "
                             f"'KEY :: ACTION' with an action among {', '.join(ACTIONS)}")
        hits = [c for c in commands if key == c.bare] or [c for c in commands
                                                           if key in c.bare]
        if len(hits) != 1:
            raise ValueError(f"README block at line {line}: directive key {key!r} matches "
                             f"{len(hits)} commands; it must match exactly one")
        cmd = hits[0]
        if verb == "exit":
            cmd.exit = int(arg)
        elif verb == "expect":
            cmd.expect.append(arg)
        else:
            setattr(cmd, verb, arg)


def foreign_addresses(cmd: str) -> list[str]:
    """Every host ``cmd`` names that is not this machine's loopback."""
    out = []
    for m in _ADDRESS.finditer(cmd):
        host = (m.group("url") or m.group("opt") or "").strip("[]")
        if not host or host in ("localhost",) or m.group(0).startswith(("sim://", "file://")):
            continue
        if m.group(0).startswith("sqlite:"):
            continue
        try:
            if ipaddress.ip_address(host).is_loopback:
                continue
        except ValueError:
            pass
        out.append(host)
    return out


@dataclass
class Outcome:
    command: Command
    status: int | None
    output: str
    seconds: float
    cpu_seconds: float


class Runner:
    """Runs parsed blocks in ``work`` with the environment of a fresh user (module
    docstring); ``log`` gets a transcript."""

    def __init__(self, work: Path, log: IO[str]) -> None:
        self.work = work
        self.log = log
        home = work.parent / "home"
        tmp = work.parent / "tmp"
        for d in (work, home, tmp):
            d.mkdir(parents=True, exist_ok=True)
        venv = Path(sys.prefix)
        for name, target in ((".venv", venv), ("benchmarks", ROOT / "benchmarks"),
                             ("scripts", ROOT / "scripts")):
            if not (work / name).exists():
                (work / name).symlink_to(target)
        env = {k: v for k, v in os.environ.items()
               if not k.startswith(("FIELDBANK_", "XDG_", "PYTEST_"))}
        env.update(HOME=str(home), TMPDIR=str(tmp), XDG_CONFIG_HOME=str(home / ".config"),
                   XDG_DATA_HOME=str(home / ".local" / "share"),
                   PATH=f"{venv / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}",
                   PYTHONUNBUFFERED="1", COLUMNS="100")
        self.env = env
        self.skipped: list[tuple[Command, str]] = []
        self.outcomes: list[Outcome] = []

    # --- one command ----------------------------------------------------------------------
    def _export(self, cmd: str) -> bool:
        m = re.fullmatch(r"export\s+([A-Za-z_][A-Za-z0-9_]*)=(.*)", cmd)
        if m is None:
            return False
        r = subprocess.run(["bash", "-c", f"printf %s {m.group(2)}"], cwd=self.work,
                           env=self.env, capture_output=True, text=True, timeout=60)
        assert r.returncode == 0, r.stderr
        self.env[m.group(1)] = r.stdout
        self.log.write(f"$ {cmd}\n  -> {m.group(1)}={r.stdout}\n")
        return True

    def run(self, cmd: Command) -> Outcome:
        script = cmd.to_run
        t0, c0 = time.monotonic(), _children_cpu()
        r = subprocess.run(["bash", "-c", script], cwd=self.work, env=self.env,
                           capture_output=True, text=True, timeout=COMMAND_TIMEOUT_S)
        out = Outcome(cmd, r.returncode, r.stdout + r.stderr, time.monotonic() - t0,
                      _children_cpu() - c0)
        self._record(out, script)
        return out

    def start(self, cmd: Command) -> tuple[subprocess.Popen[str], list[str]]:
        """Start a background command; returns once its output shows ``cmd.background``."""
        script = cmd.to_run
        proc = subprocess.Popen(["bash", "-c", f"exec {script}"], cwd=self.work, env=self.env,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                start_new_session=True)
        lines: list[str] = []

        def read() -> None:
            assert proc.stdout is not None
            for line in proc.stdout:
                lines.append(line)

        threading.Thread(target=read, daemon=True).start()
        deadline = time.monotonic() + COMMAND_TIMEOUT_S
        while time.monotonic() < deadline:
            if any(cmd.background in ln for ln in lines):
                break
            if proc.poll() is not None:
                time.sleep(0.2)  # the reader's last lines
                raise AssertionError(f"README line {cmd.line}: {script!r} ended (status "
                                     f"{proc.returncode}) before printing "
                                     f"{cmd.background!r}:\n{''.join(lines)[-4000:]}")
            time.sleep(0.1)
        else:
            _end(proc)
            raise AssertionError(f"README line {cmd.line}: {script!r} never printed "
                                 f"{cmd.background!r}")
        self.log.write(f"$ {script} &   (running)\n{''.join(lines)}")
        return proc, lines

    def _record(self, out: Outcome, script: str) -> None:
        self.outcomes.append(out)
        self.log.write(f"$ {script}\n{out.output}[status {out.status}; {out.seconds:.1f} s "
                       f"wall, {out.cpu_seconds:.1f} s CPU]\n")
        self.log.flush()

    # --- a block --------------------------------------------------------------------------
    def block(self, block: Block) -> list[str]:
        """Run ``block``; returns what went wrong (empty: it passed)."""
        problems: list[str] = []
        background: list[tuple[Command, subprocess.Popen[str], list[str]]] = []
        try:
            for cmd in block.commands:
                where = f"README line {cmd.line}: {cmd.text!r}"
                if cmd.skip:
                    self.skipped.append((cmd, cmd.skip))
                    self.log.write(f"# skipped: {cmd.text}\n#   {cmd.skip}\n")
                    continue
                hosts = [] if cmd.offline else foreign_addresses(cmd.to_run)
                if hosts:
                    problems.append(f"{where} names another machine ({', '.join(hosts)}): "
                                    "use the loopback or skip it with the reason")
                    continue
                if self._export(cmd.bare):
                    continue
                if cmd.background:
                    proc, lines = self.start(cmd)
                    background.append((cmd, proc, lines))
                    continue
                out = self.run(cmd)
                problems += _judge(where, cmd.exit, cmd.expect, out.status, out.output)
                if problems:
                    break
        finally:
            for cmd, proc, lines in background:
                if cmd.stop and proc.poll() is None:
                    self.run(replace(cmd, instead=cmd.stop, add="", expect=[], exit=0))
                try:
                    status = proc.wait(timeout=120)
                except subprocess.TimeoutExpired:
                    _end(proc)
                    status = None
                text = "".join(lines)
                self.log.write(f"# background {cmd.to_run!r} ended: status {status}\n{text}")
                problems += _judge(f"README line {cmd.line}: {cmd.text!r} (background)",
                                   cmd.exit, cmd.expect, status, text)
        return problems


def _judge(where: str, want: int, expect: list[str], status: int | None,
           output: str) -> list[str]:
    tail = output[-3000:]
    if "Traceback (most recent call last)" in output:
        return [f"{where} printed a traceback:\n{tail}"]
    if status != want:
        return [f"{where} exited {status}, not {want}:\n{tail}"]
    return [f"{where}: its output lacks {e!r}:\n{tail}" for e in expect if e not in output]


def _end(proc: subprocess.Popen[str]) -> None:
    try:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(timeout=30)
    except (ProcessLookupError, subprocess.TimeoutExpired):
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait()


def _children_cpu() -> float:
    t = os.times()
    return t.children_user + t.children_system

