"""Secrets in URLs are never printed, stored or embedded.

One function masks them (:func:`fieldbank.redact.mask_url`); these tests run a table of
passwords a careless user might type - with ``/``, ``@``, ``:``, ``%``, ``?``, ``#``, ``&``,
spaces, non-ASCII letters, and one given as ``?password=`` - through it and through every
place a URL is shown or kept: errors, ``db current`` / ``db check``, the haptic session record
and statistics, the HDF5 trace, ``haptic replay --csv``, and reports (which carry no database
URL at all).
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
from pathlib import Path
from urllib.parse import quote

import h5py
import numpy as np
import pytest
from click.testing import CliRunner
from sqlalchemy.engine import make_url

from fieldbank.errors import FieldbankError
from fieldbank.redact import mask_url, quote_password, redact, url_secrets
from fieldbank.storage import Database, resolve_url

ROOT = Path(__file__).resolve().parents[1]

#: Passwords that broke the old stripping, or could break a parser.
NASTY = [
    "p/ss", "p@ss", "p:ss", "50%off", "%41%42", "a?b", "a#b", "a&b=c", "sp ace",
    "pässwörd", "密码-p", "?password=x", "@@/:?#", "x@host/db", "-=+@cmd",
]


def _variants(pw: str) -> list[str]:
    """URL texts carrying ``pw``: typed raw, percent-encoded, as a query parameter."""
    enc = quote(pw, safe="")
    return [f"postgresql+psycopg://ana:{pw}@db.example:5432/fb",
            f"postgresql+psycopg://ana:{enc}@db.example/fb?sslmode=require",
            f"postgresql+psycopg://ana@db.example/fb?password={enc}",
            f"postgresql+psycopg://ana@db.example/fb?sslmode=require&password={pw}",
            f"postgresql+psycopg://ana@db.example/fb?application_name=x&PassWord={enc}",
            f"socket://operator:{pw}@robot.lab:4000"]


def _leaks(pw: str, text: str, url: str) -> bool:
    """Whether ``text`` shows ``pw`` (raw or encoded) where ``url`` did not show it anyway
    outside the secret (a password such as '?password=x' also names the parameter)."""
    masked_url = mask_url(url)
    return any(form in text and form not in masked_url.replace("***", "")
               for form in {pw, quote(pw, safe="")})


@pytest.mark.parametrize("pw", NASTY)
def test_mask_url_hides_every_form_of_the_password(pw: str) -> None:
    for url in _variants(pw):
        masked = mask_url(url)
        assert "***" in masked and not _leaks(pw, masked, url), (url, masked)
        assert "ana" in masked or "operator" in masked  # the rest stays readable
        parsed = make_url(quote_password(url)) if url.startswith("postgresql") else None
        if parsed is not None:
            assert not _leaks(pw, mask_url(parsed), url), mask_url(parsed)
            # an error text quoting the URL's parts is scrubbed too
            msg = f"could not connect to {parsed.host} as {parsed.username} with {pw}"
            assert not _leaks(pw, redact(msg, url), url)


def test_mask_url_leaves_urls_without_secrets_alone() -> None:
    for url in ("sqlite:////tmp/a:b@c/fieldbank.sqlite3", "/dev/ttyUSB0",
                "sim://?mode=realtime&motion=hold", "postgresql+psycopg://ana@db/fb"):
        assert mask_url(url) == url and url_secrets(url) == []


@pytest.mark.parametrize("pw", ["p@ss", "x@host/db", "@@/:?#"])
def test_a_password_with_at_signs_is_the_password_the_user_meant(pw: str) -> None:
    u = resolve_url(f"postgresql+psycopg://ana:{pw}@db.example:5432/fb")
    assert (u.username, u.password, u.host, u.port, u.database) == (
        "ana", pw, "db.example", 5432, "fb")


@pytest.mark.parametrize("pw", ["p@ss/w:rd?#", "pässwörd&x"])
def test_unreachable_server_error_names_no_password(pw: str) -> None:
    for url in (f"postgresql+psycopg://ana:{pw}@127.0.0.1:1/fb",
                f"postgresql+psycopg://ana@127.0.0.1:1/fb?password={quote(pw, safe='')}"):
        r = CliRunner().invoke(_cli(), ["patient", "list", "--db", url])
        assert r.exit_code == 1 and "***@127.0.0.1:1/fb" in r.output.replace(
            "ana@127.0.0.1:1/fb?password=***", "***@127.0.0.1:1/fb")
        assert "Connection refused" in r.output and not _leaks(pw, r.output, url), r.output


def _cli():  # type: ignore[no-untyped-def]
    from fieldbank.cli.main import cli

    return cli


@pytest.mark.postgres
@pytest.mark.parametrize("pw", ["p/ss@w:rd%?#x", "pässwörd&x=1"])
def test_db_commands_never_print_the_password(pg_url: str, pw: str) -> None:
    # the test server trusts local connections, so any password reaches it
    base = make_url(pg_url)
    raw = (f"postgresql+psycopg://{base.username}:{pw}@{base.host}:{base.port}/"
           f"{base.database}")
    query = (f"postgresql+psycopg://{base.username}@{base.host}:{base.port}/{base.database}"
             f"?password={quote(pw, safe='')}")
    for url in (raw, query):
        for args in (("db", "upgrade"), ("db", "current", "--json"), ("db", "current"),
                     ("db", "check", "--json"), ("db", "gc"), ("patient", "list")):
            r = CliRunner().invoke(_cli(), [*args, "--db", url])
            assert r.exit_code == 0, (args, r.output)
            assert not _leaks(pw, r.output, url), (args, r.output)
        shown = json.loads(CliRunner().invoke(_cli(), ["db", "current", "--json", "--db",
                                                       url]).stdout)["url"]
        assert "***" in shown and base.host in shown


# --- robot URLs: session record, statistics, trace file, replay CSV ------------------------
class _TcpRobot:
    """The simulated robot (realtime) behind a TCP port, so a ``socket://`` URL - which may
    carry a user and password - reaches it."""

    def __init__(self) -> None:
        from fieldbank.haptic.simrobot import SimDevice, SimRobotConfig
        from tests.haptic_util import rest_hand, severe_shoulder

        x0, y0 = rest_hand(severe_shoulder())
        self.device = SimDevice(SimRobotConfig(mode="realtime", motion="hold", x0_m=x0,
                                               y0_m=y0))
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        from fieldbank.haptic.simrobot import serve_fd

        conn, _ = self.server.accept()
        try:
            serve_fd(self.device, conn.fileno(), self.stop.is_set, spin=False)
        except OSError:
            pass
        finally:
            conn.close()

    def close(self) -> None:
        self.stop.set()
        self.server.close()
        self.thread.join(2)


@pytest.mark.slow
def test_robot_password_is_kept_nowhere(tmp_path: Path) -> None:
    from fieldbank.haptic.session import serve
    from tests.haptic_util import severe_shoulder, unimpaired

    pw = "Op3r:at%40r"  # as pyserial's socket:// accepts it (userinfo percent-encoded)
    robot = _TcpRobot()
    url = f"socket://operator:{pw}@127.0.0.1:{robot.port}"
    dburl = f"sqlite:///{tmp_path / 'h.sqlite3'}"
    try:
        with Database.open(dburl) as db:
            res = serve(url, severe_shoulder(), unimpaired(), duration_s=0.3, control=False,
                        trace_dir=tmp_path / "traces", trace_name="s1", db=db)
    finally:
        robot.close()
    secrets = {pw, "Op3r:at@r"}
    assert not any(s in res.robot for s in secrets) and "***" in res.robot
    # the trace file (attributes are stored uncompressed: a byte search finds any copy)
    raw = Path(str(res.trace_file)).read_bytes()
    assert not any(s.encode() in raw for s in secrets)
    with h5py.File(str(res.trace_file)) as h:
        assert "***" in json.loads(h.attrs["metadata"])["robot"]
    # the database: session row, statistics, audit log
    with Database.open(dburl) as db:
        sess = db.list_haptic_sessions()[0]
        stored = json.dumps([sess.robot_url, sess.stats,
                             [e.detail for e in db.audit_entries()]])
    assert not any(s in stored for s in secrets) and "***" in sess.robot_url
    # replay --csv of the database session and of the file
    for ref in (str(res.database), str(res.trace_file)):
        out = tmp_path / f"replay-{ref.rsplit(':', 1)[-1].replace('/', '_')}.csv"
        r = CliRunner().invoke(_cli(), ["haptic", "replay", ref, "--csv", str(out), "--db",
                                        dburl])
        assert r.exit_code == 0, r.output
        assert not any(s in out.read_text() + r.output for s in secrets)


def test_replay_csv_masks_a_trace_recorded_before_masking(tmp_path: Path) -> None:
    from fieldbank.haptic.recording import COLUMNS, Trace, read_trace_h5, write_trace_h5

    t = Trace(t_s=np.zeros(2), data=np.zeros((2, len(COLUMNS)), np.float32), rate_hz=1000.0,
              metadata={"robot": "socket://op:OldS3cret@robot:4000"})
    path = tmp_path / "old.h5"
    write_trace_h5(t, path)
    with h5py.File(path, "r+") as h:  # as an older fieldbank wrote it: the URL in clear
        h.attrs["metadata"] = json.dumps({"robot": "socket://op:OldS3cret@robot:4000"})
    assert "OldS3cret" not in read_trace_h5(path).to_csv()
    out = tmp_path / "old.csv"
    r = CliRunner().invoke(_cli(), ["haptic", "replay", str(path), "--csv", str(out)])
    assert r.exit_code == 0 and "OldS3cret" not in out.read_text() + r.output


@pytest.mark.parametrize("pw", ["p/ss", "a@b", "c?d#e"])
def test_robot_port_error_names_no_password(pw: str) -> None:
    from fieldbank.haptic.link import RobotLink

    url = f"socket://op:{pw}@127.0.0.1:1"
    with pytest.raises(FieldbankError) as info:
        RobotLink.open(url)
    assert not _leaks(pw, str(info.value), url), str(info.value)


# --- reports carry no database URL ----------------------------------------------------------
@pytest.mark.slow
def test_report_embeds_no_database_url(tmp_path: Path) -> None:
    from tests.report_helpers import build_batch

    batch = build_batch(tmp_path, patients=("SYN-001",))
    secret = "R3port-S3cret"
    url = batch["url"] + f"?password={secret}"  # SQLite ignores it; it must go nowhere
    out = tmp_path / "rep"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run([sys.executable, "-m", "fieldbank.cli", "report", "--db", url, "--out",
                        str(out), "--jobs", "1"], cwd=ROOT, env=env, text=True,
                       capture_output=True, timeout=300)
    assert r.returncode == 0, r.stderr
    db_file = batch["url"].removeprefix("sqlite:///")
    for name in ("report.html", "metrics.csv", "metrics.json"):
        text = (out / name).read_text(encoding="utf-8")
        assert secret not in text and db_file not in text and "sqlite:" not in text, name
    assert secret not in r.stdout + r.stderr
    assert "database" not in json.loads((out / "metrics.json").read_text())["inputs"]
