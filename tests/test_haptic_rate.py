"""4 kHz on the simulated robot: ``fieldbank haptic serve --rate 4000`` renders at 4 kHz (the
loop's period is 250 µs; KINARM's loop runs at 4 kHz, haptic devices at 4 kHz and more), and
the session records its rate. No wall-clock bound is asserted: the tick count and the rate are
the loop's own."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from fieldbank.cli.main import cli
from fieldbank.storage import Database


def test_serve_renders_at_4_khz_and_records_it(tmp_path: Path) -> None:
    db_url = f"sqlite:///{tmp_path / 'fb.sqlite'}"
    Database.open(db_url).close()  # serve records into a database, never creates one
    run = CliRunner()
    r = run.invoke(cli, ["haptic", "serve", "--robot", "sim://?mode=lockstep&motion=circle",
                         "--rate", "4000", "--duration-s", "0.5", "--before-severity",
                         "elbow=severe", "--socket", str(tmp_path / "run" / "h.sock"),
                         "--db", db_url, "--trace-dir", str(tmp_path / "traces"), "--json"])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["rate_hz"] == 4000.0 and doc["ticks"] == 2000
    assert doc["max_force_n"] > 0.1  # the circle was felt
    with Database.open(db_url) as db:
        (sess,) = db.list_haptic_sessions()
        assert sess.stats["rate_hz"] == 4000.0
        assert sess.stats["metadata"]["renderer"]["rate_hz"] == 4000
        t = db.get_trace_array(next(x.id for x in db.list_traces(sess.id) if x.name == "t_s"))
    assert np.allclose(np.diff(t), 2.5e-4)
    shown = run.invoke(cli, ["haptic", "sessions", "show", str(sess.id), "--db", db_url])
    assert shown.exit_code == 0 and "at 4000 Hz" in shown.output
    too_fast = run.invoke(cli, ["haptic", "serve", "--robot", "sim://", "--rate", "4001"])
    assert too_fast.exit_code == 2 and "4001" in too_fast.output
