"""The two sites as two processes over real UDP on the loopback (lockstep virtual clocks, so a
30 s session takes less than that): passive, the felt peak as the patient's, recorded."""

from __future__ import annotations

import json
import math
import socket
import subprocess
import sys
import urllib.parse
from pathlib import Path

import h5py
import numpy as np
import pytest

from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic.motions import format_path
from fieldbank.haptic.recording import read_trace_h5
from fieldbank.haptic.remote.simulate import (
    CLINICIAN_HAND_KG,
    PEAK_ERROR_100MS_5PCT,
    stretch_script,
)
from fieldbank.haptic.remote.wire import new_key, write_key
from fieldbank.storage import Database
from tests.haptic_util import rest_hand

TIMEOUT_S = 600


def _free_udp_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = int(s.getsockname()[1])
    s.close()
    return port


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "fieldbank.cli", "haptic", "remote", *args]


def _logs(path: Path) -> dict[str, np.ndarray]:
    with h5py.File(path, "r") as f:
        return {k: np.asarray(f[k]) for k in f}


@pytest.mark.slow
@pytest.mark.postgres
def test_two_processes_100ms_5pct_loss_severe_elbow_passive_and_peak_as_the_patients(
        tmp_path: Path, pg_url: str) -> None:
    """Two processes on the loopback, 100 ms one-way delay and 5 % loss injected at each site,
    a severe-elbow virtual patient, 30 s of scripted probing (slow and fast elbow stretches,
    three times): the link stays passive at every tick, the clinician's felt peak force is
    within the error docs/remote.md documents of the patient's, and the session is recorded
    with its link in PostgreSQL."""
    key = write_key(tmp_path / "session.key", new_key())
    Database.open(pg_url, upgrade="always").close()   # a clinic's database, at the head
    p = synthesize({"elbow": "severe"})
    hand = rest_hand(p)
    r = math.hypot(*hand)
    script = stretch_script(hand, (hand[0] / r, hand[1] / r), repeat=3)
    path = format_path([(t, x, y) for t, (x, y) in zip(script.path.times_s,
                                                        script.path.points_m, strict=True)])
    clinician_robot = "sim://?" + urllib.parse.urlencode(
        {"mode": "lockstep", "motion": "path", "motion_path": path,
         "handle_mass_kg": f"{1.0 + CLINICIAN_HAND_KG:g}"})
    port = _free_udp_port()
    link = ["--key", str(key), "--lockstep", "--delay-ms", "100", "--loss", "0.05"]
    patient = subprocess.Popen(
        _cli("patient", "--robot", "sim://?mode=lockstep&patient=elbow%3Dsevere",
             "--bind", f"127.0.0.1:{port}", "--log-dir", str(tmp_path / "patient"),
             "--wait-s", "120", "--json", *link),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        clinician = subprocess.run(
            _cli("clinician", "--robot", clinician_robot, "--peer", f"127.0.0.1:{port}",
                 "--duration-s", f"{script.path.duration_s + 0.7:.3f}", "--trace-dir",
                 str(tmp_path / "clinician"), "--db", pg_url, "--json", *link),
            capture_output=True, text=True, timeout=TIMEOUT_S)
        p_out, p_err = patient.communicate(timeout=60)
    finally:
        if patient.poll() is None:
            patient.kill()
            patient.wait()
    assert clinician.returncode == 0, clinician.stderr
    assert patient.returncode == 0, p_err
    c_sum = json.loads(clinician.stdout)
    p_sum = json.loads(p_out)
    assert "the clinician's site ended the session" in p_sum["reason"]
    assert c_sum["account"]["complete"] and p_sum["account"]["complete"]
    lk = c_sum["link"]
    assert lk["refused"] == {} and p_sum["link"]["refused"] == {}
    assert 195 <= lk["rtt_ms"] <= 210                    # 100 ms each way + a tick each way
    assert 0.03 < lk["loss_fraction"] < 0.07 and 0.03 < p_sum["link"]["loss_fraction"] < 0.07

    cl = _logs(Path(c_sum["link_file"]))
    pl = _logs(Path(p_sum["log_file"]))
    n = min(len(cl["tick"]), len(pl["tick"]))
    assert n >= 30_000 and np.array_equal(cl["tick"][:n], pl["tick"][:n])   # 30 s at 1 kHz
    created = (cl["e_out_j"][:n] + pl["e_out_j"][:n]) - (cl["e_in_j"][:n] + pl["e_in_j"][:n])
    assert float(created.max()) <= 1e-9                 # passive at every tick
    assert float(pl["e_out_j"][n - 1]) > 0.3            # energy did flow (J): the arm was moved
    assert c_sum["passivity_active_ticks"] > 0          # and the controller had work to do

    # the peak the clinician felt (commanded to its robot) against the patient's hand's
    trace = read_trace_h5(c_sum["trace"])
    felt = float(np.max(np.hypot(trace.column("fx_n"), trace.column("fy_n"))))
    patient_peak = float(np.max(np.hypot(pl["hand_fx_n"], pl["hand_fy_n"])))
    lo, hi = PEAK_ERROR_100MS_5PCT
    assert lo <= felt / patient_peak - 1.0 <= hi, (felt, patient_peak)

    with Database.open(pg_url) as db:
        sid = int(c_sum["database"].split(":")[1])
        rec = db.get_remote_link(sid)
        assert rec is not None and rec.role == "clinician"
        assert rec.settings["impairment"]["delay_s"] == pytest.approx(0.1)
        assert rec.summary["link"]["loss_fraction"] == pytest.approx(lk["loss_fraction"])
        names = {t.name for t in db.list_traces(sid)}
        assert {"link.e_in_j", "link.e_out_j", "link.peer_fx_n", "link.rtt_s"} <= names
