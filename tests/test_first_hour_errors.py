"""The mistakes of a first hour, each answered in the user's words before anything is opened,
loaded or stored: typed ids, dates that cannot be, a given plan in the future, empty labels and
files, units fieldbank does not read, misspelt commands at every level, the settings' flags
before the command, one "patient not found", the robot's port and faults as the user knows
them, and a station that did not start saying why."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from datetime import date, timedelta
from pathlib import Path

import pytest
from click.testing import CliRunner, Result

from fieldbank.cli.main import cli

NOPE_DB = "sqlite:////nonexistent-dir/never.sqlite3"


def run(*args: str) -> Result:
    return CliRunner().invoke(cli, list(args))


def refused(r: Result, code: int = 2) -> str:
    """The message of a command refused with ``code``, never a traceback."""
    assert r.exit_code == code, r.output
    assert r.exception is None or isinstance(r.exception, SystemExit), repr(r.exception)
    assert "Traceback" not in r.output
    return r.stderr


@pytest.fixture
def db_url(tmp_path: Path) -> str:
    """Three patients, a synthetic model of SYN-001 and one plan on it (no fit: fast)."""
    from fieldbank.evaluate.severity import synthesize
    from fieldbank.interventions import Botulinum, Plan
    from fieldbank.interventions.whatif import save_plan
    from fieldbank.modelsource import stored
    from fieldbank.storage import Database

    url = f"sqlite:///{tmp_path / 'fb.sqlite3'}"
    with Database.open(url) as db:
        for code in ("SYN-001", "SYN-002", "SYN-003"):
            db.add_patient(code, 72.0, 1.74, "right")
        db.ensure_session("SYN-001", "pre-BoNT", date(2024, 1, 10))
        m = db.add_model(synthesize({"elbow": "severe"}), "synthetic", "elbow severe",
                         "SYN-001")
        save_plan(db, stored(db, m.id), Plan((Botulinum({"ef": 150.0}),), "botulinum"))
    return url


# --- typed ids, checked before the database opens ------------------------------------------------
@pytest.mark.parametrize("args", [
    ("models", "show", "abc"), ("models", "show", "99999999999999999999999"),
    ("plans", "show", "99999999999999999999999"), ("plans", "show", "0"),
    ("plans", "give", "x1", "--on", "2024-01-01"), ("haptic", "sessions", "show", "one"),
    ("export", "--model", "abc", "-o", "m.osim"), ("export", "--trace", "1e3", "-o", "t.mot"),
    ("jobs", "9999999999999"), ("validate", "--plan", "two"),
    ("haptic", "replay", "haptic_session:abc"),
])
def test_an_id_that_cannot_be_one_is_refused_in_words_before_the_database(args) -> None:  # type: ignore[no-untyped-def]
    err = refused(run(*args, "--db", NOPE_DB))
    assert " id" in err and ("whole numbers" in err or "ids run from 1 to" in err), err
    assert "No database" not in err  # the id was checked first


def test_a_plan_is_never_recorded_as_given_in_the_future(db_url: str) -> None:
    tomorrow = (date.today() + timedelta(days=1)).isoformat()
    err = refused(run("plans", "give", "1", "--on", tomorrow, "--db", db_url))
    assert f"{tomorrow} is in the future" in err
    err = refused(run("whatif", "SYN-001", "--botox", "ef=100U", "--save", "--given-on",
                      tomorrow, "--db", db_url))
    assert "is in the future" in err
    assert json.loads(run("plans", "list", "--given", "--json", "--db", db_url).stdout) == []
    assert run("plans", "give", "1", "--on", date.today().isoformat(),
               "--db", db_url).exit_code == 0


def test_a_date_before_year_one_and_a_centre_at_infinity_are_refused_in_words() -> None:
    base = ("haptic", "measure", "--robot", "sim://", "--patient", "P", "--session", "s",
            "--db", NOPE_DB)
    assert "there is no year 0" in refused(run(*base, "--date", "0000-01-01"))
    err = refused(run(*base, "--centre", "inf,0"))
    assert "--centre must read X,Y in metres, two finite numbers" in err
    err = refused(run(*base, "--must-see", "ef,zz"), code=1)  # before the database opens
    assert "--must-see: unknown muscle group(s) zz" in " ".join(err.split())
    assert "No database" not in err
    from fieldbank.errors import ParameterError
    from fieldbank.measure.protocol import ProtocolConfig

    with pytest.raises(ParameterError, match="centre x"):
        ProtocolConfig(centre_m=(float("inf"), 0.0))


def test_an_empty_session_label_is_refused_before_the_robot_moves(db_url: str,
                                                                  tmp_path: Path) -> None:
    from fieldbank.errors import ParameterError, StorageError
    from fieldbank.haptic.measure import measure_session
    from fieldbank.measure.protocol import ProtocolConfig
    from fieldbank.storage import Database

    assert "a session label must not be empty" in refused(run(
        "haptic", "measure", "--robot", "sim://", "--patient", "SYN-001", "--session", "",
        "--db", db_url))
    # the library checks it first too: a port that cannot be opened is never reached
    raw = tmp_path / "raw.nwb"
    with Database.open(db_url) as db:
        with pytest.raises(ParameterError, match="must not be empty"):
            measure_session(db, str(tmp_path / "no-port"), "SYN-001", "  ", ProtocolConfig(),
                            raw_out=raw)
        with pytest.raises(StorageError, match="is dated 2024-01-10; got 2024-03-01"):
            measure_session(db, str(tmp_path / "no-port"), "SYN-001", "pre-BoNT",
                            ProtocolConfig(), raw_out=raw, session_date=date(2024, 3, 1))
    assert not raw.exists()


# --- the user's words ---------------------------------------------------------------------------
@pytest.mark.parametrize(("args", "words"), [
    (("--botox", "ef=5000U"), "--botox 'ef=5000U': the dose into one group must be from 0 to "
                              "600 U; got 5000 U"),
    (("--botox", "ef=-5U"), "the dose into one group must be from 0 to 600 U; got -5 U"),
    (("--lengthen", "bf=50cm"), "--lengthen 'bf=50cm': a lengthening must be more than 0 and "
                                "at most 4 cm; got 50 cm"),
    (("--cast", "ef=9cm"), "a cast's lengthening must be more than 0 and at most 2 cm"),
    (("--botox", "ef=100U", "--weeks", "-3"), "the weeks since the injection must be from 0 "
                                              "to 52 weeks; got -3 weeks"),
    (("--rhizotomy", "ef:5"), "the factor the reflex gain β is multiplied by must be from 0 "
                              "to 1; got 5"),
    (("--baclofen", "ef:1"), "a factor of 1 would change nothing"),
    (("--tenotomy", "xx"), "--tenotomy 'xx': 'xx' is not a muscle group"),
    (("--botox", "ef=200mg"), "'mg' is not a unit of toxin); a dose is written 200, 200U or "
                              "200 units"),
])
def test_whatif_errors_speak_the_command_line_and_come_before_the_database(args, words) -> None:  # type: ignore[no-untyped-def]
    # a patient in a database that does not exist: the argument is refused first
    err = refused(run("whatif", "SYN-001", *args, "--db", NOPE_DB), code=1)
    flat = " ".join(err.split())
    assert words in flat, flat
    for internal in ("units[", "delta_m", "weeks_since", "'factor'", "'group'"):
        assert internal not in flat


# --- did you mean, at every level ----------------------------------------------------------------
@pytest.mark.parametrize(("args", "meant"), [
    (("modles",), "models"), (("haptic", "sesions"), "sessions"),
    (("haptic", "train", "simulte"), "simulate"), (("models", "lst"), "list"),
    (("plans", "shw"), "show"), (("haptic", "remote", "patinet"), "patient"),
])
def test_a_misspelt_command_gets_a_did_you_mean_at_every_level(args, meant) -> None:  # type: ignore[no-untyped-def]
    # a fresh process: no command module loaded yet, as a user starts it
    r = subprocess.run([sys.executable, "-m", "fieldbank.cli", *args], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "Did you mean" in r.stderr and f"'{meant}'" in r.stderr, r.stderr


# --- the settings' flags before the command ------------------------------------------------------
def test_a_settings_flag_may_come_before_the_command(db_url: str) -> None:
    r = run("--db", db_url, "patient", "list")
    assert r.exit_code == 0, r.output
    assert "SYN-002" in r.stdout and "3 patient(s) in sqlite:///" in r.stderr
    doc = json.loads(run("--db", db_url, "config", "show", "--json").stdout)
    db = next(s for s in doc["settings"] if s["name"] == "db")
    assert db["source"] == "flag --db"
    # the command's own flag wins
    r = run("--db", NOPE_DB, "patient", "list", "--db", db_url)
    assert r.exit_code == 0 and "SYN-001" in r.stdout


# --- one "patient not found" --------------------------------------------------------------------
@pytest.mark.parametrize("args", [
    ("export", "--patient", "NOPE", "-o", "{tmp}/x.h5"), ("maps", "list", "--patient", "NOPE"),
    ("models", "list", "--patient", "NOPE"), ("plans", "list", "--patient", "NOPE"),
    ("haptic", "sessions", "list", "--patient", "NOPE"),
    ("haptic", "train", "results", "--patient", "NOPE"), ("validate", "--loo", "NOPE"),
    ("whatif", "NOPE", "--botox", "ef=100U"), ("fit", "NOPE"), ("patient", "show", "NOPE"),
])
def test_an_unknown_patient_is_the_same_message_everywhere(db_url: str, tmp_path: Path,
                                                           args) -> None:  # type: ignore[no-untyped-def]
    err = refused(run(*(a.format(tmp=tmp_path) for a in args), "--db", db_url), code=1)
    assert "No patient with code 'NOPE' in sqlite:///" in err
    assert "nearest: SYN-001" in err


# --- files --------------------------------------------------------------------------------------
def test_an_empty_file_is_called_empty_and_nothing_is_stored(db_url: str,
                                                             tmp_path: Path) -> None:
    empty = tmp_path / "empty.csv"
    empty.write_bytes(b"")
    blank = tmp_path / "blank.csv"
    blank.write_text("\n \n")
    err = refused(run("ingest", str(empty), str(blank), "--patient", "SYN-001", "--session",
                      "x", "--db", db_url), code=1)
    assert "empty.csv" in err and "blank.csv" in err and "are empty" in err
    assert "unknown format" not in err
    assert json.loads(run("maps", "list", "--json", "--db", db_url).stdout) == []


# --- the robot, as the user knows it ------------------------------------------------------------
def test_a_simulated_robot_url_is_quoted_as_typed() -> None:
    err = refused(run("haptic", "serve", "--robot", "sim://?mode=warp", "--before-severity",
                      "elbow=severe", "--no-db", "--duration-s", "0.05"), code=1)
    assert "cannot open robot port 'sim://?mode=warp'" in err
    assert "x0_m" not in err and "motion=" not in err and "seed=" not in err
    err = refused(run("haptic", "probe", "--robot", "sim://?mode=warp", "--severity",
                      "elbow=severe"), code=1)
    assert "'sim://?mode=warp'" in err and "x0_m" not in err


def test_a_fault_the_robot_reports_is_said_in_words() -> None:
    from fieldbank.haptic.link import RobotLink
    from fieldbank.haptic.monitor import SafetyMonitor
    from fieldbank.haptic.protocol import FLAG_FAULT, FLAG_WATCHDOG, FaultCode, device_report
    from fieldbank.haptic.safety import Mode, SafetyConfig
    from tests.haptic_util import MemoryPort

    assert device_report(0, FLAG_WATCHDOG) == ("the robot stopped itself: its watchdog tripped "
                                               "(no force command reached it in time)")
    text = device_report(2, FLAG_FAULT)
    assert "a fault of its own" in text and "a timeout (no frame in time) (code 2)" in text
    link = RobotLink(MemoryPort())
    for counter, words in (("watchdog_flag_frames", "watchdog tripped"),
                           ("fault_flag_frames", "a fault of its own")):
        monitor = SafetyMonitor(link, SafetyConfig(), 0.001)
        monitor.safety.mode = Mode.ARMED  # armed, as a running loop is
        setattr(link.state, counter, getattr(link.state, counter) + 1)  # a flagged STATE came
        monitor.check(1)
        (rec,) = [r for r in monitor.safety.latched_records() if r.code == FaultCode.DEVICE]
        assert rec.code == FaultCode.DEVICE and words in rec.message, rec.message
        assert "flags" not in rec.message and "code 0" not in rec.message
        assert rec.message.startswith("the robot stopped itself: ")


def test_a_station_that_does_not_start_says_what_happened(tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    from fieldbank.haptic.errors import HapticError
    from fieldbank.haptic.station.launch import START_TIMEOUT_S, StationProcess

    assert START_TIMEOUT_S >= 60  # a busy machine takes twenty seconds and more to start it
    st = StationProcess(str(tmp_path / "snap"), str(tmp_path / "sock"))
    with pytest.raises(HapticError, match=r"did not start listening within 0\.001 s \(it was "
                                          r"still starting"):
        st.start(timeout_s=0.001)
    monkeypatch.setattr(sys, "executable", "/bin/false")
    with pytest.raises(HapticError, match="ended with exit status 1 before it listened") as exc:
        StationProcess(str(tmp_path / "snap"), str(tmp_path / "sock")).start()
    assert "messages are above" not in str(exc.value)


# --- output: no glued text, progress in robot time ------------------------------------------------
def test_the_severity_table_keeps_its_columns_apart_with_scores() -> None:
    r = run("whatif", "--severity", "elbow=severe", "--botox", "ef=200U", "--timecourse",
            "--interval-samples", "0")
    assert r.exit_code == 0, r.output
    lines = r.stdout.splitlines()
    start = next(k for k, ln in enumerate(lines) if ln.startswith("Severity per muscle group"))
    rows = lines[start + 1:start + 7]
    assert [row.split()[0] for row in rows] == ["sf", "se", "ef", "ee", "bf", "be"]
    for row in rows:
        cells = [c for c in row.split("  ") if c.strip()]
        assert len(cells) == 3, row  # name, contracture, spasticity: two spaces apart at least
        assert re.search(r"[)*][A-Za-z]", row) is None, row  # no cell run into the next
    assert max(len(ln) for ln in lines) <= 100


def test_the_stretch_tables_keep_their_columns_apart_for_a_severe_arm() -> None:
    # torques past 10 N·m, changes of -100 %, catch angles of three digits: the widest cells
    r = run("whatif", "--severity", "shoulder=severe,elbow=severe", "--tenotomy", "ef",
            "--interval-samples", "0")
    assert r.exit_code == 0, r.output
    lines = r.stdout.splitlines()
    for head, ncells in (("Joint stretch", 4), ("Catch angle", 4)):
        start = next(k for k, ln in enumerate(lines) if ln.startswith(head))
        rows = lines[start + 2:start + 6]
        assert {" ".join(row.split()[:2]) for row in rows} == {
            "elbow extension", "elbow flexion", "shoulder extension", "shoulder flexion"}
        for row in rows:  # a change in % follows its pair; every pair two spaces from the next
            cells = [c for c in re.split(r" {2,}", re.sub(r" [+-]\d+%", "", row)) if c.strip()]
            assert len(cells) == ncells, row
            assert all(re.fullmatch(r"−?[\d.]+ → (−?[\d.]+|—)|— → —", c) for c in cells[1:]), row
    torque = next(ln for ln in lines if ln.startswith("elbow extension"))
    assert "-100%" in torque and "11.12 → 11.12" in " ".join(lines)
    assert max(len(ln) for ln in lines) <= 100


def test_a_measurement_reports_its_robot_time_as_it_goes(tmp_path: Path) -> None:
    from fieldbank.cli.progress import robot_time_text
    from fieldbank.evaluate.severity import synthesize
    from fieldbank.haptic.measure import run_protocol
    from fieldbank.measure.protocol import ProtocolConfig, plan
    from fieldbank.model import Arm

    the_plan = plan(ProtocolConfig(parts=("postural",), grid=(2, 1)),
                    Arm.from_params(synthesize({"elbow": "severe"})))
    heard: list[tuple[float, float]] = []
    run_protocol("sim://?patient=elbow=severe", the_plan,
                 progress=lambda done, total: heard.append((done, total)))
    done = [d for d, _ in heard]
    total = heard[0][1]
    assert len(heard) > 2 and done == sorted(done) and done[0] == 0.0
    assert all(t == total for _, t in heard) and total >= the_plan.duration_s
    assert total - done[-1] <= 0.5 + 1e-9  # heard twice a robot second, to the end
    assert robot_time_text(126.0, 450.0) == "2.1 of 7.5 min of robot time, 5.4 min left"
    assert robot_time_text(3.0, 10.0) == "3.0 of 10.0 s of robot time, 7.0 s left"
