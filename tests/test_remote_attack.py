"""The remote link attacked on real UDP between processes, as someone on the network would:
a recording of one session replayed from another address into the next, a bounded flood,
and a peer that holds the key and sends absurd values or NaN. Lockstep sessions (virtual
clocks, so a run is repeatable): a session that was not disturbed is the same, tick for tick,
as one nobody touched."""

from __future__ import annotations

import json
import math
import os
import socket
import subprocess
import threading
import time
import urllib.parse
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np
import pytest

from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic.motions import format_path
from fieldbank.haptic.recording import read_trace_h5
from fieldbank.haptic.remote.channel import UdpTransport
from fieldbank.haptic.remote.handshake import Initiator, Responder
from fieldbank.haptic.remote.wire import (
    FLAG_ARMED,
    HEADER,
    MAGIC,
    Kind,
    SessionCipher,
    State,
    new_key,
    peek_kind,
    write_key,
)
from tests.haptic_util import rest_hand
from tests.test_remote_sites import _cli, _free_udp_port

pytestmark = pytest.mark.slow

TIMEOUT_S = 300
#: The patient's robot: a severe elbow, lockstep.
PATIENT_ROBOT = "sim://?mode=lockstep&patient=elbow%3Dsevere"
DURATION_S = 2.5


def _clinician_robot() -> str:
    """The simulated clinician holds still at the patient's resting hand for 0.8 s, stretches
    the elbow 4 cm in 0.8 s and holds: the patient's robot holds the arm stretched."""
    x, y = rest_hand(synthesize({"elbow": "severe"}))
    r = math.hypot(x, y)
    pts = [(0.0, x, y), (0.8, x, y), (1.6, x + 0.04 * x / r, y + 0.04 * y / r)]
    return "sim://?" + urllib.parse.urlencode(
        {"mode": "lockstep", "motion": "path", "motion_path": format_path(pts)})


def _log(path: str) -> dict[str, np.ndarray]:
    with h5py.File(path, "r") as f:
        return {k: np.asarray(f[k]) for k in f}


class Lines:
    """A process's stderr, read line by line in a thread (so a test can wait for one)."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.lines: list[str] = []
        self._cv = threading.Condition()
        assert proc.stderr is not None
        self._th = threading.Thread(target=self._read, args=(proc.stderr,), daemon=True)
        self._th.start()

    def _read(self, stream: object) -> None:
        for line in stream:  # type: ignore[attr-defined]
            with self._cv:
                self.lines.append(line)
                self._cv.notify_all()

    def wait_for(self, text: str, timeout_s: float = 120.0) -> None:
        deadline = time.monotonic() + timeout_s
        with self._cv:
            while not any(text in ln for ln in self.lines):
                left = deadline - time.monotonic()
                if left <= 0:
                    pytest.fail(f"never said {text!r}:\n{''.join(self.lines)}")
                self._cv.wait(left)

    def text(self) -> str:
        self._th.join(10)
        return "".join(self.lines)


@dataclass
class Session:
    """One lockstep session of the two sites' processes; what each printed."""

    patient: dict
    clinician: dict
    patient_err: str
    clinician_err: str
    patient_code: int
    clinician_code: int
    attacker_got: list[bytes] = field(default_factory=list)


class Proxy:
    """Forwards the clinician's datagrams to the patient's site and back, keeping a copy of
    every one the clinician sent: a recorder on the network."""

    def __init__(self, patient_port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.up = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.up.bind(("127.0.0.1", 0))
        self.target = ("127.0.0.1", patient_port)
        self.recorded: list[bytes] = []
        self.client: tuple[str, int] | None = None
        self._stop = False
        self._th = threading.Thread(target=self._run, daemon=True)
        self._th.start()

    def _run(self) -> None:
        import select

        while not self._stop:
            r, _, _ = select.select([self.sock, self.up], [], [], 0.05)
            for s in r:
                data, addr = s.recvfrom(8192)
                if s is self.sock:
                    self.client = addr
                    self.recorded.append(data)
                    self.up.sendto(data, self.target)
                elif self.client is not None:
                    self.sock.sendto(data, self.client)

    def close(self) -> None:
        self._stop = True
        self._th.join(2)
        self.sock.close()
        self.up.close()


def _session(tmp: Path, key: Path, name: str, *, via_proxy: bool = False,
             attack: object = None) -> tuple[Session, Proxy | None]:
    """Run one session; ``attack(port, patient_lines)`` runs once the patient's site has
    engaged its clinician, from this process, and returns what its socket received."""
    port = _free_udp_port()
    link = ["--key", str(key), "--lockstep"]
    # a data directory of its own (the module's fixture runs before the per-test one)
    env = {**os.environ, "FIELDBANK_HOME": str(tmp / name / "home")}
    patient = subprocess.Popen(
        _cli("patient", "--robot", PATIENT_ROBOT, "--bind", f"127.0.0.1:{port}", "--log-dir",
             str(tmp / name), "--wait-s", "120", "--json", *link),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    p_lines = Lines(patient)
    proxy = Proxy(port) if via_proxy else None
    try:
        target = proxy.port if proxy is not None else port
        clinician = subprocess.Popen(
            _cli("clinician", "--robot", _clinician_robot(), "--peer", f"127.0.0.1:{target}",
                 "--duration-s", str(DURATION_S), "--trace-dir", str(tmp / name), "--no-db",
                 "--json", *link), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            env=env)
        got: list[bytes] = []
        if attack is not None:
            p_lines.wait_for("clinician confirmed")
            got = attack(port)  # type: ignore[operator]
        c_out, c_err = clinician.communicate(timeout=TIMEOUT_S)
        p_out = patient.stdout.read() if patient.stdout else ""  # type: ignore[union-attr]
        patient.wait(timeout=60)
    finally:
        for proc in (patient,):
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        if proxy is not None:
            proxy.close()
    return Session(json.loads(p_out), json.loads(c_out), p_lines.text(), c_err,
                   patient.returncode, clinician.returncode, got), proxy


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Session, list[bytes]]:
    """A session nobody touched, recorded on its way to the patient's site."""
    tmp = tmp_path_factory.mktemp("remote-attack")
    key = write_key(tmp / "session.key", new_key())
    run, proxy = _session(tmp, key, "recorded", via_proxy=True)
    assert proxy is not None
    assert run.patient_code == 0 and run.clinician_code == 0, run.clinician_err
    assert run.patient["account"]["complete"] and run.clinician["account"]["complete"]
    kinds = [peek_kind(d) for d in proxy.recorded]
    assert kinds.count(Kind.HELLO) >= 1 and kinds.count(Kind.STATE) > 2000
    return key, run, proxy.recorded


def _same_session(a: Session, b: Session) -> None:
    """The two sessions rendered the same, tick for tick, at both sites."""
    pa, pb = _log(a.patient["log_file"]), _log(b.patient["log_file"])
    assert set(pa) == set(pb) and len(pa["tick"]) == len(pb["tick"]) > 2000
    for k in pa:
        assert np.array_equal(pa[k], pb[k], equal_nan=True), k
    ta, tb = read_trace_h5(a.clinician["trace"]), read_trace_h5(b.clinician["trace"])
    for col in ("fx_n", "fy_n", "x_m", "y_m"):
        assert np.array_equal(ta.column(col), tb.column(col)), col
    assert float(np.max(np.hypot(pa["servo_fx_n"], pa["servo_fy_n"]))) > 2.0  # arm stretched


def _listen(sock: socket.socket, until: float) -> list[bytes]:
    sock.settimeout(0.05)
    got = []
    while time.monotonic() < until:
        try:
            got.append(sock.recvfrom(8192)[0])
        except TimeoutError:
            pass
    return got


def test_a_recorded_session_replayed_from_elsewhere_gets_nothing_and_changes_nothing(
        recorded: tuple[Path, Session, list[bytes]], tmp_path: Path) -> None:
    """While the next session runs, every datagram the clinician sent in the recorded one is
    replayed to the patient's site from another address: the
    attacker gets no STATE (nothing at all), the site refuses each — the HELLO as a handshake
    — and counts it, and the session is the same, tick for tick, as the recorded one."""
    key, first, rec = recorded

    def replay(port: int) -> list[bytes]:
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", 0))
        for i, d in enumerate(rec):   # in bursts, early in the session: all of it is read
            s.sendto(d, ("127.0.0.1", port))
            if i % 100 == 99:
                time.sleep(0.001)
        got = _listen(s, time.monotonic() + 1.0)
        s.close()
        return got

    run, _ = _session(tmp_path, key, "replayed", attack=replay)
    assert run.attacker_got == []                   # no STATE; no answer of any kind
    assert run.patient_code == 0 and run.clinician_code == 0, run.patient_err
    refused = run.patient["link"]["refused"]
    hellos = sum(1 for d in rec if peek_kind(d) == Kind.HELLO)
    assert refused.get("handshake", 0) == hellos
    assert refused.get("address", 0) == len(rec) - hellos
    assert "refused" in run.patient_err            # said on its terminal, counted
    assert [e["event"] for e in run.patient["events"]].count("link_lost") == 0
    _same_session(first, run)


def test_a_bounded_flood_changes_nothing(recorded: tuple[Path, Session, list[bytes]],
                                         tmp_path: Path) -> None:
    """20,000 datagrams at the patient's site during a session — random bytes, forged headers
    of every kind, the recorded session's — from another address: each is refused and counted,
    and the session is the same, tick for tick, as the one nobody touched."""
    key, first, rec = recorded
    rng = np.random.default_rng(7)
    session = int.from_bytes(rec[-1][6:14], "little")
    flood: list[bytes] = []
    for i in range(20_000):
        kind = i % 4
        if kind == 0:
            flood.append(rng.bytes(int(rng.integers(1, 300))))
        elif kind == 1:   # a well-formed header of a STATE, a forged body
            flood.append(HEADER.pack(MAGIC, int(Kind.STATE), 1, session, 10**6 + i)
                         + rng.bytes(121))
        elif kind == 2:
            flood.append(rec[int(rng.integers(len(rec)))])
        else:
            flood.append(HEADER.pack(MAGIC, int(Kind.HELLO), 1, i, 0) + rng.bytes(100))

    def attack(port: int) -> list[bytes]:
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", 0))
        for i, d in enumerate(flood):  # in bursts the site's socket holds, early in the session
            s.sendto(d, ("127.0.0.1", port))
            if i % 250 == 249:
                time.sleep(0.002)
        got = _listen(s, time.monotonic() + 0.5)
        s.close()
        return got

    run, _ = _session(tmp_path, key, "flooded", attack=attack)
    assert run.attacker_got == []
    assert run.patient_code == 0 and run.clinician_code == 0, run.patient_err
    refused = run.patient["link"]["refused"]
    assert sum(refused.values()) == len(flood)
    _same_session(first, run)


# --- a peer that holds the key ----------------------------------------------------------------
class Rogue:
    """A site written here that holds the key: it shakes hands like one and then sends what it
    likes, in lockstep with the real site (its STATE of tick n after the real site's n − 1)."""

    def __init__(self, peer: tuple[str, int] | None = None) -> None:
        self.transport = UdpTransport(("127.0.0.1", 0), peer)
        self.cipher: SessionCipher | None = None
        self.peer_states: dict[int, State] = {}
        self.echo_us = -1

    def close(self) -> None:
        self.transport.close()

    def connect(self, key: bytes) -> dict:
        """As the clinician: HELLO, WELCOME, CONFIRM."""
        ini = Initiator(key, 4242, {"rate_hz": 1000, "lockstep": True,
                                    "wall_time_s": time.time()})
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            self.transport.send(ini.hello)
            if self.transport.wait_readable(0.5):
                for data, _ in self.transport.receive():
                    got = ini.answer(data)
                    if isinstance(got, tuple):
                        self.cipher = got[0]
                        self.transport.send(ini.confirm(got[0]))
                        return dict(got[1].message or {})
        pytest.fail("the patient's site never answered")

    def accept(self, key: bytes, welcome: dict) -> None:
        """As the patient: answer the HELLO, wait for the proof."""
        resp = Responder(key)
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            if not self.transport.wait_readable(0.5):
                continue
            for data, addr in self.transport.receive():
                if peek_kind(data) == Kind.HELLO:
                    hello = resp.open_hello(data)
                    assert hello is not None
                    self.transport.send_to(resp.welcome(hello, addr, welcome), addr)
                elif (got := resp.confirm(data, addr)) is not None:
                    self.cipher = got[0]
                    self.transport.set_peer(addr)
                    if got[1].state is not None:
                        self.peer_states[got[1].state.tick] = got[1].state
                    return
        pytest.fail("the clinician's site never confirmed")

    def send(self, st: State, flags: int = FLAG_ARMED) -> None:
        assert self.cipher is not None
        self.transport.send(self.cipher.seal_state(st, flags=flags, t_us=st.tick * 1000,
                                                   echo_us=self.echo_us, hold_us=0))

    def wait_tick(self, tick: int, timeout_s: float = 30.0) -> bool:
        """Until the real site's STATE of ``tick`` (or a later one) arrived; False: its BYE or
        silence."""
        assert self.cipher is not None
        deadline = time.monotonic() + timeout_s
        while max(self.peer_states, default=-1) < tick:
            if time.monotonic() > deadline or not self.transport.wait_readable(
                    deadline - time.monotonic()):
                return False
            for data, _ in self.transport.receive():
                d = self.cipher.open(data)
                if d is None:
                    continue
                if d.kind == Kind.BYE and (d.message or {}).get("final", True):
                    return False  # (a BYE that is not final: the real site ramps out first)
                if d.state is not None:
                    self.peer_states[d.state.tick] = d.state
                    self.echo_us = d.t_us
        return True


@pytest.fixture()
def key_file(tmp_path: Path) -> Path:
    return write_key(tmp_path / "session.key", new_key())


def _read_key(path: Path) -> bytes:
    return bytes.fromhex(path.read_text().strip())


def test_a_keyed_patient_site_sending_1e6_newtons_faults_the_clinician_s_ramp_not_a_step(
        key_file: Path, tmp_path: Path) -> None:
    """A patient's site holding the key sends the hand's force as 5 N, then fx = 1e6 N: the
    clinician's site refuses it as implausible (beyond its robot's 40 N), faults, and its
    commanded force ramps from 5 N to zero — it never rises — says so on its terminal and
    exits with status 1."""
    x, y = rest_hand(synthesize({"elbow": "severe"}))
    rogue = Rogue()
    port = rogue.transport.address[1]
    clinician = subprocess.Popen(
        _cli("clinician", "--robot", "sim://?mode=lockstep&motion=hold", "--peer",
             f"127.0.0.1:{port}", "--duration-s", "3", "--trace-dir", str(tmp_path),
             "--no-db", "--json", "--key", str(key_file), "--lockstep"),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        rogue.accept(_read_key(key_file), {"rate_hz": 1000, "lockstep": True,
                                           "drawing": synthesize({}).to_dict(),
                                           "rest_hand_m": [x, y], "device": "rogue"})
        attack_tick = 1500
        for n in range(3000):
            fx = 1e6 if n == attack_tick else 5.0
            # it hands over 10 mJ a tick, so the clinician's energy tank lets the force
            # through (a tank that gets nothing displays nothing)
            rogue.send(State(n, x, y, 0.0, 0.0, fx, 0.0, 0.0, 0.0, 0.01 * n))
            if not rogue.wait_tick(n):
                break
        out, err = clinician.communicate(timeout=TIMEOUT_S)
    finally:
        rogue.close()
        if clinician.poll() is None:
            clinician.kill()
            clinician.wait()
    assert clinician.returncode == 1, err
    assert "fault PEER" in err and "1e+06 N" in err
    assert "did not render what was asked" in err
    summary = json.loads(out)
    assert not summary["account"]["complete"]
    trace = read_trace_h5(summary["trace"])
    f = np.hypot(trace.column("fx_n"), trace.column("fy_n"))
    at = attack_tick + 1                              # used one tick after it was sent
    before = float(f[at - 1])
    assert before == pytest.approx(5.0, abs=0.3)      # the clinician felt the 5 N
    after = f[at:]
    assert after.max() <= before + 1e-9               # never stepped up
    assert after[250:].max() == 0.0                   # zero after the ramp, and stays there
    # a raised cosine over 0.2 s: the steepest step is π/2 · 5 N / 200 ticks ≈ 0.04 N
    assert np.max(np.abs(np.diff(f[at - 1:]))) < 0.05
    print("clinician's force around the absurd datagram (N):",
          np.round(f[at - 3:at + 220:20], 2).tolist())


def _rogue_clinician(key_file: Path, tmp_path: Path, script: object
                     ) -> tuple[subprocess.CompletedProcess[str], dict, Rogue]:
    """The real patient's site against a rogue clinician running ``script(rogue, rest)``."""
    port = _free_udp_port()
    patient = subprocess.Popen(
        _cli("patient", "--robot", PATIENT_ROBOT, "--bind", f"127.0.0.1:{port}", "--log-dir",
             str(tmp_path), "--wait-s", "120", "--json", "--key", str(key_file), "--lockstep"),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    rogue = Rogue(("127.0.0.1", port))
    try:
        welcome = rogue.connect(_read_key(key_file))
        script(rogue, tuple(welcome["rest_hand_m"]))  # type: ignore[operator]
        assert rogue.cipher is not None
        rogue.transport.send(rogue.cipher.seal_json(Kind.BYE, {"reason": "done"}))
        out, err = patient.communicate(timeout=TIMEOUT_S)
    finally:
        rogue.close()
        if patient.poll() is None:
            patient.kill()
            patient.wait()
    return subprocess.CompletedProcess(patient.args, patient.returncode, out, err), \
        json.loads(out), rogue


def _stretch(rest: tuple[float, float], n: int) -> tuple[float, float, float, float]:
    """The rogue clinician's hand: at rest, then 3 cm toward the hand's radius over 1 s from
    tick 600, held (position and velocity)."""
    x, y = rest
    r = math.hypot(x, y)
    s = min(1.0, max(0.0, (n - 600) / 1000))
    v = 0.03 / 1.0 if 0.0 < s < 1.0 else 0.0
    return x + 0.03 * s * x / r, y + 0.03 * s * y / r, v * x / r, v * y / r


def test_a_keyed_clinician_sending_an_absurd_position_faults_the_patient_s_ramp_not_a_step(
        key_file: Path, tmp_path: Path) -> None:
    """A clinician's site holding the key stretches the arm 3 cm, then sends its hand 5 m
    away: the patient's site refuses it (outside its robot's workspace), faults, and its servo
    force ramps from what held the arm to zero — it never steps toward 5 m — says so on its
    terminal, and exits with status 1."""
    attack_tick = 2000

    def script(rogue: Rogue, rest: tuple[float, float]) -> None:
        for n in range(2600):
            x, y, vx, vy = _stretch(rest, n)
            if n == attack_tick:
                x = 5.0
            rogue.send(State(n, x, y, vx, vy, 0.0, 0.0, 0.0, 0.0, 0.0))
            if not rogue.wait_tick(n):
                break

    res, summary, _ = _rogue_clinician(key_file, tmp_path, script)
    assert res.returncode == 1, res.stderr
    assert "fault PEER" in res.stderr and "outside this robot's workspace" in res.stderr
    log = _log(summary["log_file"])
    f = np.hypot(log["servo_fx_n"], log["servo_fy_n"])
    at = int(np.flatnonzero(log["tick"] == attack_tick + 1)[0])
    held = f[at - 200:at]
    assert held.min() > 1.0                            # the robot held the stretched arm
    after = f[at:]
    assert after.max() <= 1.1 * held.max()             # no step toward the absurd target
    assert after[250:].max() == 0.0                    # zero after the ramp, and it stays
    # no change per tick beyond the servo's own (sensor noise through its damper) while it held
    assert np.max(np.abs(np.diff(f[at - 1:]))) <= 1.1 * np.max(np.abs(np.diff(held))) + 0.05
    assert [e["name"] for e in summary["events"] if e["event"] == "fault"] == ["PEER"]


def test_nan_then_genuine_datagrams_the_genuine_ones_are_accepted(key_file: Path,
                                                                  tmp_path: Path) -> None:
    """A clinician's site holding the key sends 30 STATEs with NaN under the sequence numbers
    its next 30 genuine STATEs will carry, then those: the NaN ones are refused (counted), and
    every genuine one is accepted and used — none refused as a replay."""
    nan_tick = 800
    seqs: dict[str, list[int]] = {"nan": [], "genuine": []}

    def script(rogue: Rogue, rest: tuple[float, float]) -> None:
        assert rogue.cipher is not None
        for n in range(1500):
            if n == nan_tick:
                base = rogue.cipher.seq
                for k in range(30):
                    rogue.cipher.seq = base + k
                    rogue.send(State(n + k, math.nan, rest[1], 0, 0, 0, 0, 0, 0, 0))
                    seqs["nan"].append(rogue.cipher.seq)
                rogue.cipher.seq = base
            x, y, vx, vy = _stretch(rest, n)
            rogue.send(State(n, x, y, vx, vy, 0.0, 0.0, 0.0, 0.0, 0.0))
            if nan_tick <= n < nan_tick + 30:
                seqs["genuine"].append(rogue.cipher.seq)
            if not rogue.wait_tick(n):
                break

    res, summary, _ = _rogue_clinician(key_file, tmp_path, script)
    assert seqs["nan"] == seqs["genuine"]              # the same 30 sequence numbers
    link = summary["link"]
    assert link["refused"] == {"nan": 30}
    assert link["lost"] == 0 and link["stale"] == 0    # every genuine STATE was used
    log = _log(summary["log_file"])
    rows = (log["tick"] > nan_tick) & (log["tick"] <= nan_tick + 30)
    assert np.all(log["new_state"][rows] == 1.0)       # each tick had its STATE
    assert not np.isnan(log["target_x_m"][rows]).any()
    assert res.returncode == 0, res.stderr             # the session rendered as asked
