"""What the remote link's protection costs, against the link before it, in the same run.

The link before (the baseline, rebuilt here as :class:`HmacCodec`): a 48-byte header and the
body in clear, a 16-byte truncated HMAC-SHA256 tag, the replay window marked before the body
was decoded. The link now (:mod:`haptic.remote.wire`, :mod:`haptic.remote.handshake`): a
22-byte clear header, everything else sealed with AES-256-GCM under per-direction keys
from an X25519 + HKDF handshake.

1. **bytes per datagram** of each kind, both links;
2. **CPU per datagram**: seal + open of one STATE (this thread's CPU time, best of 5);
3. **CPU per tick** of both sites in one process (the benchmark's lockstep pair: ports,
   passivity, safety, the simulated robots; in-memory transport), both links interleaved;
   and one handshake's CPU;
4. **round trip on the loopback**: a STATE sealed here, opened, answered and sealed by an echo
   process, opened here — both links, interleaved in blocks of 500 (so a busy spell lands on
   both); p50 / p99 / max;
5. ``--sessions N``: N real-time sessions of the two sites' processes (``fieldbank haptic
   remote patient|clinician``, simulated robots), ``--busy`` with one ``while True: pass``
   process per core beside them: the faults each site latched and when, whether each rendered
   what was asked, the round trip p99 the clinician's port measured; and ``--prep``: how long
   preparing a process for the loop takes (a full garbage collection in a process that loaded
   the command line; :func:`haptic.clock.realtime`) — what stood between the patient's ARM and
   its first FORCE before the patient's site armed inside it (the device watchdog is 20 ms).

Every figure beside the load average.

    python benchmarks/bench_remote_link.py [--quick] [--sessions 10 --busy] [--prep] [--json]
"""

from __future__ import annotations

import argparse
import hashlib
import hmac
import json
import math
import os
import socket
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import numpy as np

from benchmarks.timing import load_line, per_call
from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic.remote.channel import UdpTransport
from fieldbank.haptic.remote.config import SiteConfig
from fieldbank.haptic.remote.handshake import Initiator, Responder
from fieldbank.haptic.remote.simulate import Pair, clinician_robot, handshake_in_memory
from fieldbank.haptic.remote.wire import (
    Datagram,
    Kind,
    Role,
    State,
    json_body,
    new_key,
    parse_json,
    write_key,
)
from fieldbank.model import Arm

ST = State(12345, 0.082, 0.547, 0.031, -0.012, 4.7, -1.2, 1.25, 0.75, 0.5)
WELCOME = {"rate_hz": 1000, "lockstep": False,
           "drawing": synthesize({"elbow": "severe"}).with_unimpaired_muscles().to_dict(),
           "rest_hand_m": [0.082, 0.547], "device": "fieldbank-sim", "force_limit_n": 40.0,
           "reach_m": 0.65}
HELLO = {"rate_hz": 1000, "lockstep": False, "wall_time_s": 1.8e9, "site": "clinician"}


class HmacCodec:
    """The link before, as the baseline: what :class:`SessionCipher` does, with its layout."""

    HEADER = struct.Struct("<4sBBBBQQqqq")
    STATE = struct.Struct("<Q9d")

    def __init__(self, key: bytes, role: Role, session: int) -> None:
        self._key, self.role, self.session = key, role, session
        self.seq, self.newest, self._seen, self.late, self.accepted = 0, -1, 0, 0, 0
        self.refused: dict[str, int] = {}

    def _mac(self, data: bytes) -> bytes:
        return hmac.new(self._key, b"fieldbank-remote-1" + data, hashlib.sha256).digest()[:16]

    def refuse(self, reason: str) -> None:
        self.refused[reason] = self.refused.get(reason, 0) + 1

    def seal(self, kind: Kind, body: bytes, *, flags: int = 0, t_us: int = 0,
             echo_us: int = -1, hold_us: int = 0) -> bytes:
        self.seq += 1
        data = self.HEADER.pack(b"FBR1", 1, int(kind), int(self.role), flags, self.session,
                                self.seq, t_us, echo_us, hold_us) + body
        return data + self._mac(data)

    def seal_state(self, st: State, **kw: int) -> bytes:
        return self.seal(Kind.STATE, self.STATE.pack(st.tick, st.x, st.y, st.vx, st.vy, st.fx,
                                                     st.fy, st.e_in, st.e_out, st.e_sent), **kw)

    def seal_json(self, kind: Kind, message: Mapping[str, Any], **kw: int) -> bytes:
        return self.seal(kind, json_body(kind, message), **kw)

    def open(self, data: bytes) -> Datagram | None:
        body, tag = data[:-16], data[-16:]
        if not hmac.compare_digest(self._mac(body), tag):
            self.refuse("mac")
            return None
        (_, _, kind, role, flags, session, seq, t_us, echo_us,
         hold_us) = self.HEADER.unpack_from(body)
        if role != self.role.peer or session != self.session:
            self.refuse("role")
            return None
        if seq <= self.newest and (self.newest - seq >= 64
                                   or self._seen & (1 << (self.newest - seq))):
            self.refuse("replay")
            return None
        if seq > self.newest:
            shift = seq - self.newest
            self._seen = ((self._seen << shift) | 1) & ((1 << 64) - 1) if shift < 64 else 1
            self.newest = seq
        else:
            self._seen |= 1 << (self.newest - seq)
        payload = body[self.HEADER.size:]
        k = Kind(kind)
        if k == Kind.STATE:
            tick, *vals = self.STATE.unpack(payload)
            if not all(math.isfinite(v) for v in vals):
                return None
            return Datagram(k, Role(role), flags, session, seq, t_us, echo_us, hold_us,
                            State(tick, *vals))
        return Datagram(k, Role(role), flags, session, seq, t_us, echo_us, hold_us,
                        None, parse_json(payload))


def legacy_pair(key: bytes) -> tuple[HmacCodec, HmacCodec]:
    return HmacCodec(key, Role.CLINICIAN, 7), HmacCodec(key, Role.PATIENT, 7)


# --- 1, 2: bytes and CPU per datagram ------------------------------------------------------------
def sizes() -> list[dict[str, Any]]:
    key = new_key()
    old_c, old_p = legacy_pair(key)
    ini = Initiator(key, 7, HELLO)
    resp = Responder(key)
    hello = resp.open_hello(ini.hello)
    assert hello is not None
    welcome = resp.welcome(hello, "here", WELCOME)
    got = ini.answer(welcome)
    assert isinstance(got, tuple)
    c = got[0]
    bye = {"reason": "the clinician's session ended: 60 s passed", "final": True}
    return [
        {"kind": "STATE", "old": len(old_c.seal_state(ST)), "new": len(c.seal_state(ST))},
        {"kind": "HELLO", "old": len(old_c.seal_json(Kind.HELLO, HELLO)), "new": len(ini.hello)},
        {"kind": "WELCOME", "old": len(old_p.seal_json(Kind.WELCOME, WELCOME)),
         "new": len(welcome)},
        {"kind": "CONFIRM", "old": 0, "new": len(ini.confirm(c))},
        {"kind": "BYE", "old": len(old_c.seal_json(Kind.BYE, bye)),
         "new": len(c.seal_json(Kind.BYE, bye))},
    ]


def per_datagram() -> dict[str, Any]:
    key = new_key()
    old_c, old_p = legacy_pair(key)
    new_c, new_p = handshake_in_memory(key, 1000)

    def old() -> None:
        old_p.open(old_c.seal_state(ST))

    def new() -> None:
        new_p.open(new_c.seal_state(ST))

    def handshake() -> None:
        handshake_in_memory(key, 1000)

    ow, oc = per_call(old, 20000)
    nw, nc = per_call(new, 20000)
    hw, hc = per_call(handshake, 200)
    return {"old_us": oc, "new_us": nc, "old_wall_us": ow, "new_wall_us": nw,
            "ratio": nc / oc, "handshake_us": hc, "handshake_wall_us": hw}


# --- 3: CPU per tick of both sites ---------------------------------------------------------------
def per_tick(ticks: int, blocks: int) -> dict[str, Any]:
    p = synthesize({"elbow": "severe"})
    hand = tuple(float(v) for v in Arm.from_params(p).rest_position())
    out: dict[str, list[float]] = {"old": [], "new": []}
    for b in range(blocks):
        for link in ("old", "new") if b % 2 == 0 else ("new", "old"):
            cfg = SiteConfig(lockstep=True)
            pair = Pair(p, cfg, clinician_robot((hand[0], hand[1]), cfg.rate_hz))
            if link == "old":
                c, pt = legacy_pair(new_key())
                pair.port.endpoint.cipher = c  # type: ignore[assignment]
                pair.patient.port.endpoint.cipher = pt  # type: ignore[assignment]
            for _ in range(300):
                pair.tick()
            c0 = time.thread_time_ns()
            for _ in range(ticks):
                pair.tick()
            out[link].append((time.thread_time_ns() - c0) / ticks / 1e3)
            pair.finish()
    old, new = float(np.median(out["old"])), float(np.median(out["new"]))
    return {"old_us": old, "new_us": new, "ratio": new / old, "blocks": blocks, "ticks": ticks}


# --- 4: round trip on the loopback ---------------------------------------------------------------
def echo(port_file: str, link: str, key_hex: str) -> None:
    """The echo process: opens each STATE and answers it sealed, until b"stop"."""
    key = bytes.fromhex(key_hex)
    tr = UdpTransport(("127.0.0.1", 0))
    Path(port_file).write_text(str(tr.address[1]))
    cipher: Any = HmacCodec(key, Role.PATIENT, 7) if link == "old" else None
    resp = Responder(key)
    while True:
        tr.wait_readable(1.0)
        for data, addr in tr.receive():
            if data == b"stop":
                tr.close()
                return
            if cipher is None:
                if data[4] == Kind.HELLO:
                    hello = resp.open_hello(data)
                    if hello is not None:
                        tr.send_to(resp.welcome(hello, addr, {"rate_hz": 1000}), addr)
                elif (got := resp.confirm(data, addr)) is not None:
                    cipher = got[0]
                continue
            d = cipher.open(data)
            if d is not None and d.state is not None:
                tr.send_to(cipher.seal_state(d.state, t_us=d.t_us), addr)


def round_trip(pings: int, block: int) -> dict[str, Any]:
    key = new_key()
    tmp = Path(tempfile.mkdtemp(prefix="bench-remote-"))
    procs, ends = {}, {}
    for link in ("old", "new"):
        pf = tmp / link
        procs[link] = subprocess.Popen([sys.executable, __file__, "--echo", str(pf), link,
                                        key.hex()])
        for _ in range(1200):  # a busy machine takes its time to start a process
            if pf.exists() and pf.read_text():
                break
            time.sleep(0.1)
        ends[link] = ("127.0.0.1", int(pf.read_text()))
    sock = {k: UdpTransport(("127.0.0.1", 0), v) for k, v in ends.items()}
    ciphers: dict[str, Any] = {"old": HmacCodec(key, Role.CLINICIAN, 7)}
    ini = Initiator(key, 7, {"rate_hz": 1000})
    while "new" not in ciphers:
        sock["new"].send(ini.hello)
        if sock["new"].wait_readable(0.5):
            for data, _ in sock["new"].receive():
                got = ini.answer(data)
                if isinstance(got, tuple):
                    ciphers["new"] = got[0]
                    sock["new"].send(ini.confirm(got[0]))
    rtt: dict[str, list[float]] = {"old": [], "new": []}
    try:
        for b in range(max(1, pings // block)):
            for link in ("old", "new") if b % 2 == 0 else ("new", "old"):
                tr, c = sock[link], ciphers[link]
                for i in range(block):
                    t0 = time.perf_counter()
                    tr.send(c.seal_state(State(i, ST.x, ST.y, ST.vx, ST.vy, ST.fx, ST.fy,
                                               ST.e_in, ST.e_out, ST.e_sent)))
                    while tr.wait_readable(1.0):
                        got = [c.open(d) for d, _ in tr.receive()]
                        if any(g is not None for g in got):
                            break
                    rtt[link].append(time.perf_counter() - t0)
    finally:
        for link, tr in sock.items():
            for _ in range(3):
                tr.send(b"stop")
            tr.close()
            try:
                procs[link].wait(10)
            except subprocess.TimeoutExpired:
                procs[link].kill()
                procs[link].wait()
    res: dict[str, Any] = {}
    for link, v in rtt.items():
        a = np.asarray(v) * 1e6
        res[link] = {"p50_us": float(np.percentile(a, 50)), "p99_us": float(np.percentile(a, 99)),
                     "max_us": float(a.max()), "n": len(a)}
    res["p99_ratio"] = res["new"]["p99_us"] / res["old"]["p99_us"]
    return res


# --- 5: real-time sessions -----------------------------------------------------------------------
def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "fieldbank.cli", "haptic", "remote", *args]


def session(tmp: Path, key: Path, seconds: float) -> dict[str, Any]:
    """One real-time session of the two sites' processes on the loopback."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    patient = subprocess.Popen(
        _cli("patient", "--robot", "sim://?mode=realtime&patient=elbow%3Dsevere", "--bind",
             f"127.0.0.1:{port}", "--key", str(key), "--log-dir", str(tmp), "--json"),
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    clinician = subprocess.run(
        _cli("clinician", "--robot", "sim://?mode=realtime&motion=hold", "--peer",
             f"127.0.0.1:{port}", "--key", str(key), "--duration-s", str(seconds), "--no-db",
             "--trace-dir", str(tmp), "--json"), capture_output=True, text=True, timeout=300)
    p_out = patient.communicate(timeout=60)[0]
    c, p = json.loads(clinician.stdout), json.loads(p_out)
    import h5py  # only here: the link log

    with h5py.File(c["link_file"]) as f:
        rtt = np.asarray(f["rtt_s"])
    rtt = rtt[np.isfinite(rtt)] * 1e3
    return {"patient_faults": [(f["name"], round(f["t_s"], 2)) for f in p["faults"]],
            "clinician_faults": [(f["name"], round(f["t_s"], 2)) for f in c["faults"]],
            "patient_complete": p["account"]["complete"],
            "clinician_complete": c["account"]["complete"],
            "engaged_at_s": c["account"]["engaged_at_s"],
            "rtt_p50_ms": float(np.percentile(rtt, 50)),
            "rtt_p99_ms": float(np.percentile(rtt, 99)),
            "skipped_ticks": c["stats"]["skipped_ticks"],
            "codes": (patient.returncode, clinician.returncode)}


def sessions(n: int, seconds: float, busy: bool) -> dict[str, Any]:
    tmp = Path(tempfile.mkdtemp(prefix="bench-remote-"))
    key = write_key(tmp / "session.key", new_key())
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
            for _ in range(len(os.sched_getaffinity(0)))] if busy else []
    try:
        time.sleep(1.0 if busy else 0.0)
        load = load_line()
        runs = [session(tmp / str(k), key, seconds) for k in range(n)]
    finally:
        for h in hogs:
            h.kill()
            h.wait()
    return {"busy": busy, "load": load, "runs": runs}


def prep(busy: bool) -> dict[str, Any]:
    """How long entering :func:`haptic.clock.realtime` takes in a process that loaded the
    command line (5 processes)."""
    code = ("import time, fieldbank.cli.main, fieldbank.haptic.remote.patient_site\n"
            "from fieldbank.haptic.clock import realtime\n"
            "t = time.perf_counter()\n"
            "with realtime(True):\n    print(time.perf_counter() - t)\n")
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
            for _ in range(len(os.sched_getaffinity(0)))] if busy else []
    try:
        out = [float(subprocess.run([sys.executable, "-c", code], capture_output=True,
                                    text=True, timeout=120).stdout) for _ in range(5)]
    finally:
        for h in hogs:
            h.kill()
            h.wait()
    return {"busy": busy, "seconds": out, "load": load_line()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--sessions", type=int, default=0)
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--busy", action="store_true")
    ap.add_argument("--prep", action="store_true")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--echo", nargs=3, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.echo:
        echo(*a.echo)
        return 0
    sys.stdout.reconfigure(line_buffering=True)  # type: ignore[attr-defined]
    out: dict[str, Any] = {"load_start": load_line()}
    print(out["load_start"])
    out["sizes"] = sizes()
    print("\n## Bytes per datagram (UDP payload)\n\n| kind | before | now |\n|---|---|---|")
    for r in out["sizes"]:
        print(f"| {r['kind']} | {r['old'] or '–'} | {r['new']} |")
    d = out["per_datagram"] = per_datagram()
    print(f"\n## CPU per STATE sealed and opened\n\nbefore {d['old_us']:.2f} µs, now "
          f"{d['new_us']:.2f} µs ({d['ratio']:.2f}×); one handshake (both sides, in memory) "
          f"{d['handshake_us']:.0f} µs")
    t = out["per_tick"] = per_tick(1000 if a.quick else 3000, 2 if a.quick else 4)
    print(f"\n## CPU per tick of both sites (lockstep pair, median of {t['blocks']} blocks of "
          f"{t['ticks']} ticks each)\n\nbefore {t['old_us']:.1f} µs, now {t['new_us']:.1f} µs "
          f"({t['ratio']:.3f}×)")
    r = out["round_trip"] = round_trip(2000 if a.quick else 10000, 500)
    print("\n## Round trip on the loopback (seal, send, echo process opens and seals, open)\n\n"
          "| link | p50 µs | p99 µs | max µs | pings |\n|---|---|---|---|---|")
    for link in ("old", "new"):
        v = r[link]
        print(f"| {'before' if link == 'old' else 'now'} | {v['p50_us']:.0f} | "
              f"{v['p99_us']:.0f} | {v['max_us']:.0f} | {v['n']} |")
    print(f"\np99 now / before: {r['p99_ratio']:.2f}×")
    if a.prep:
        out["prep"] = [prep(False), prep(True)]
        print("\n## Preparing a process for the loop (realtime(): a full collection, …), s\n")
        for p in out["prep"]:
            print(f"{'one busy process per core' if p['busy'] else 'idle'}: "
                  f"{', '.join(f'{s:.2f}' for s in p['seconds'])} ({p['load']})")
    if a.sessions:
        s = out["sessions"] = sessions(a.sessions, a.seconds, a.busy)
        print(f"\n## {a.sessions} real-time sessions of {a.seconds:g} s"
              f"{', one busy process per core' if a.busy else ''} ({s['load']})\n\n"
              "| run | patient's faults | clinician's faults | rendered as asked | engaged at s "
              "| round trip p50 / p99 ms | skipped ticks |\n|---|---|---|---|---|---|---|")
        for k, run in enumerate(s["runs"]):
            print(f"| {k} | {run['patient_faults'] or 'none'} | "
                  f"{run['clinician_faults'] or 'none'} | "
                  f"{run['patient_complete'] and run['clinician_complete']} | "
                  f"{run['engaged_at_s']:.2f} | {run['rtt_p50_ms']:.2f} / "
                  f"{run['rtt_p99_ms']:.2f} | {run['skipped_ticks']} |")
    out["load_end"] = load_line()
    print(f"\n{out['load_end']}")
    if a.json:
        print(json.dumps(out, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
