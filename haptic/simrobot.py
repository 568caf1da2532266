"""The simulated robot: a planar handle with mass and friction, held by a simulated operator.

It is a first-class device speaking the wire protocol (:mod:`haptic.protocol`), so everything
between the host loop and the motor current is exercised for real: framing, CRC, sequence
numbers, handshake, arming, the device-side force limit and the watchdog.

Physics (robot frame, SI), integrated with semi-implicit Euler at ``substep_s``::

    m a = F_cmd + F_op − b v − f_c tanh(v / v_c)
    F_op = K_op (r(t) − x) + B_op (ṙ(t) − v)           the operator's hand impedance

r(t) is a scripted reference motion (:mod:`haptic.motions`). With a virtual patient attached
(``patient=…``, :mod:`haptic.patient`) the operator is gone and F_op is the force of the
patient's relaxed hand on the handle instead. F_cmd is the last FORCE received,
clamped to the device force limit, zero while disarmed; if no FORCE arrives for ``watchdog_ms``
while armed, the device zeroes the force, sets the watchdog flag and disarms (the host must
send ARM again).

Two timing modes:

- ``lockstep``: physics advances one host tick (1 / HELLO rate) per FORCE received and a STATE
  is sent in reply, so tests run faster than real time and are deterministic;
- ``realtime``: physics follows the wall clock and STATE frames go out at the host rate whether
  or not commands arrive (the watchdog is live).

:class:`SimDevice` is the byte-level core (``feed`` bytes in, ``take_output`` bytes out). It is
reached as ``sim://`` through pyserial (:mod:`haptic.protocol_sim`) or runs on the device end of
a pty pair in a thread or a separate process (:class:`PtyRobot`), so the host opens the other end
as a real serial port. Fault injection hooks (corrupt, drop, freeze, NaN) serve the tests.

The handle carries a force sensor: after SENSOR_ON the device sends, before every STATE, the
force the hand (operator or patient) puts on the handle, with ``force_noise_n`` of Gaussian
noise; ``position_noise_m`` is the encoders' noise on the reported position (both 0 by default,
0.2 N and 0.02 mm with a patient attached; :mod:`haptic.patient`).
"""

from __future__ import annotations

import json
import math
import os
import random
import select
import signal
import subprocess
import sys
import threading
import time
import tty
from dataclasses import asdict, dataclass, fields
from urllib.parse import parse_qsl, urlencode

from fieldbank.errors import ParameterError
from fieldbank.haptic import protocol as P
from fieldbank.haptic.clock import Grant, collector_off, cpu_plan, enter_device_realtime
from fieldbank.haptic.motions import MOTIONS, MotionFn, make_motion, parse_path, wander
from fieldbank.haptic.patient import (
    DEFAULT_FORCE_NOISE_N,
    DEFAULT_POSITION_NOISE_M,
    PatientPlacement,
    VirtualPatient,
)
from fieldbank.validation import Interval, check_fields

#: Allowed range of every numeric field of :class:`SimRobotConfig` (messages are generated).
SIM_BOUNDS: dict[str, Interval] = {
    "x0_m": Interval(None, None, "m"),
    "y0_m": Interval(None, None, "m"),
    "motion_duration_s": Interval(None, None, "s"),
    "motion_distance_m": Interval(None, None, "m"),
    "seed": Interval.whole(None, None),
    "operator_wander_m": Interval(0.0, 0.1, "m"),
    "handle_mass_kg": Interval(0.0, None, "kg", low_closed=False),
    "viscous_n_s_per_m": Interval(None, None, "N·s/m"),
    "coulomb_n": Interval(None, None, "N"),
    "coulomb_v_m_per_s": Interval(None, None, "m/s"),
    "operator_k_n_per_m": Interval(None, None, "N/m"),
    "operator_b_n_s_per_m": Interval(None, None, "N·s/m"),
    "force_limit_n": Interval(None, None, "N"),
    "watchdog_ms": Interval(0.0, None, "ms", low_closed=False),
    "max_rate_hz": Interval(None, None, "Hz"),
    "substep_s": Interval(0.0, None, "s", low_closed=False),
    "patient_x_m": Interval(-2.0, 2.0, "m"),
    "patient_y_m": Interval(-2.0, 2.0, "m"),
    "force_noise_n": Interval(None, 10.0, "N"),
    "position_noise_m": Interval(None, 0.01, "m"),
}


@dataclass(frozen=True)
class SimRobotConfig:
    """Simulated device and operator, SI; ranges in :data:`SIM_BOUNDS`. Every field can be set
    from a ``sim://`` query."""

    mode: str = "lockstep"              # 'lockstep' | 'realtime'
    motion: str = "hold"                # see haptic.motions.MOTIONS
    x0_m: float = 0.0                   # start of the motion (robot frame)
    y0_m: float = 0.35
    motion_duration_s: float = -1.0     # < 0: the motion's default
    motion_distance_m: float = -1.0     # < 0: the motion's default
    seed: int = 0
    motion_path: str = ""               # motion 'path': t:x:y;… (haptic.motions.format_path)
    operator_wander_m: float = 0.0      # smooth wander of the operator's hand off the motion
    handle_mass_kg: float = 1.0         # apparent handle mass (assumption, typical planar robot)
    viscous_n_s_per_m: float = 2.0
    coulomb_n: float = 0.3
    coulomb_v_m_per_s: float = 0.005    # tanh smoothing speed of Coulomb friction
    operator_k_n_per_m: float = 600.0   # operator's hand impedance (assumption)
    operator_b_n_s_per_m: float = 40.0
    force_limit_n: float = 60.0         # device-side clamp (the host's limit is lower)
    watchdog_ms: int = 20
    max_rate_hz: int = 4000
    substep_s: float = 2.5e-4
    device_id: str = "fieldbank-sim"
    patient: str = ""                   # virtual patient (haptic.patient): id, file:, severity
    patient_x_m: float = 0.0            # the patient's shoulder in robot coordinates
    patient_y_m: float = 0.0
    force_noise_n: float = -1.0         # < 0: 0.2 N with a patient, else 0
    position_noise_m: float = -1.0      # < 0: 2e-5 m with a patient, else 0

    def __post_init__(self) -> None:
        if self.mode not in ("lockstep", "realtime"):
            raise ParameterError(f"sim mode must be 'lockstep' or 'realtime'; got {self.mode!r}")
        if self.motion not in MOTIONS:
            raise ParameterError(f"sim motion must be one of {', '.join(MOTIONS)}; "
                                 f"got {self.motion!r}")
        if self.motion == "path":
            try:
                parse_path(self.motion_path)
            except ValueError as exc:
                raise ParameterError(f"sim motion_path: {exc}") from None
        check_fields(self, SIM_BOUNDS, what="sim parameter")

    @classmethod
    def from_query(cls, query: str) -> SimRobotConfig:
        """Build from a URL query string (``mode=realtime&motion=pull&x0_m=0.1``)."""
        known = {f.name: f.type for f in fields(cls)}
        values: dict[str, object] = {}
        for key, raw in parse_qsl(query, keep_blank_values=True):
            if key not in known:
                raise ParameterError(f"unknown sim:// option {key!r}; known: {', '.join(known)}")
            default = getattr(cls, key)
            try:
                values[key] = type(default)(raw)
            except ValueError:
                raise ParameterError(
                    f"sim:// option {key}={raw!r} is not a {type(default).__name__}"
                ) from None
        return cls(**values)  # type: ignore[arg-type]

    @property
    def force_noise(self) -> float:
        """Force-sensor noise in force, N (the default resolved)."""
        if self.force_noise_n >= 0:
            return self.force_noise_n
        return DEFAULT_FORCE_NOISE_N if self.patient else 0.0

    @property
    def position_noise(self) -> float:
        """Position noise in force, m (the default resolved)."""
        if self.position_noise_m >= 0:
            return self.position_noise_m
        return DEFAULT_POSITION_NOISE_M if self.patient else 0.0

    def to_query(self) -> str:
        d = asdict(self)
        return urlencode({k: v for k, v in d.items() if v != getattr(SimRobotConfig, k)})

    def make_motion(self) -> MotionFn:
        m = make_motion(self.motion, self.x0_m, self.y0_m, self.seed,
                        self.motion_duration_s if self.motion_duration_s >= 0 else None,
                        self.motion_distance_m if self.motion_distance_m >= 0 else None,
                        self.motion_path)
        return wander(m, self.operator_wander_m, self.seed)


class SimDevice:
    """Device-side protocol endpoint and handle physics. Not thread-safe: one owner at a time."""

    def __init__(self, config: SimRobotConfig, clock: object = time.perf_counter) -> None:
        self.config = config
        self._clock = clock
        self._reader = P.FrameReader()
        self._out = bytearray()
        self._seq = 0
        self.motion = config.make_motion()
        x, y, _, _ = self.motion(0.0)
        self.x, self.y, self.vx, self.vy = x, y, 0.0, 0.0
        self.patient: VirtualPatient | None = None
        if config.patient:
            self.patient = VirtualPatient.from_spec(
                config.patient, PatientPlacement(config.patient_x_m, config.patient_y_m),
                config.substep_s)
            self.patient.grasp(x, y)
        self.hand_fx = self.hand_fy = 0.0   # force of the hand on the handle (last substep)
        self.sensor_on = False
        self._rng = random.Random(config.seed)
        self._force_noise = config.force_noise
        self._position_noise = config.position_noise
        self.t_s = 0.0                    # device physics time
        self.fx_cmd = 0.0
        self.fy_cmd = 0.0
        self.armed = False
        self.watchdog_tripped = False
        self.connected = False            # HELLO received
        self.tick_s = 1e-3                # host tick (from HELLO)
        self.watchdog_s = config.watchdog_ms * 1e-3
        self.last_force_seq = 0
        self.last_force_wall = 0.0
        self.forces_received = 0
        self.frames_rejected = 0
        # fault injection (tests)
        self.corrupt_frames = 0
        self.drop_frames = 0
        self.nan_frames = 0
        self.frozen = False
        #: the device's own fault (flag bit 2 in every STATE while set; it disarms itself)
        self.device_fault = False
        self._wall0: float | None = None
        self._next_state_wall = 0.0

    # --- bytes in / out ---------------------------------------------------------------------
    def feed(self, data: bytes) -> None:
        """Process bytes from the host."""
        if self.frozen:
            return
        for frame in self._reader.feed(data):
            self._handle(frame)
        self.frames_rejected = sum(self._reader.errors.values())

    def take_output(self) -> bytes:
        """Bytes waiting to go to the host (and clear them)."""
        out = bytes(self._out)
        self._out.clear()
        return out

    def _send(self, msg_type: int, payload: bytes = b"") -> None:
        frame = P.encode_frame(msg_type, self._seq, payload)
        self._seq = (self._seq + 1) & 0xFFFF
        if msg_type == P.MsgType.STATE:
            if self.drop_frames > 0:
                self.drop_frames -= 1
                return
            if self.corrupt_frames > 0:
                self.corrupt_frames -= 1
                b = bytearray(frame)
                b[len(b) // 2] ^= 0x5A if b[len(b) // 2] != 0x5A else 0x33
                frame = bytes(b)
        self._out += frame

    def _handle(self, frame: P.Frame) -> None:
        t = frame.type
        now = self._clock()  # type: ignore[operator]
        if t == P.MsgType.FORCE:
            fx, fy = P.FORCE_FMT.unpack(frame.payload)
            self.last_force_seq = frame.seq
            self.last_force_wall = now
            self.forces_received += 1
            if self.armed and math.isfinite(fx) and math.isfinite(fy):
                lim = self.config.force_limit_n
                n = math.hypot(fx, fy)
                if n > lim:
                    fx, fy = fx * lim / n, fy * lim / n
                self.fx_cmd, self.fy_cmd = fx, fy
            else:
                self.fx_cmd = self.fy_cmd = 0.0
            if self.config.mode == "lockstep":
                self.step(self.tick_s)
                self.send_state()
        elif t == P.MsgType.HELLO:
            version, rate_hz, wd_ms = P.HELLO_FMT.unpack(frame.payload)
            if version != P.PROTOCOL_VERSION or not 1 <= rate_hz <= self.config.max_rate_hz:
                self._send(P.MsgType.FAULT, P.FAULT_FMT.pack(P.FaultCode.DEVICE, 1))
                return
            self.tick_s = 1.0 / rate_hz
            self.connected = True
            # the host may ask for a shorter watchdog, never a longer one
            self.watchdog_s = min(wd_ms if wd_ms > 0 else self.config.watchdog_ms,
                                  self.config.watchdog_ms) * 1e-3
            info = P.DeviceInfo(P.PROTOCOL_VERSION, self.config.device_id,
                                self.config.max_rate_hz, self.config.force_limit_n,
                                round(self.watchdog_s * 1e3))
            self._send(P.MsgType.HELLO_ACK, info.to_payload())
            self.send_state()
            self._wall0 = now
            self._next_state_wall = now + self.tick_s
        elif t == P.MsgType.ARM:
            self.armed = True
            self.watchdog_tripped = False
            self.last_force_wall = now
        elif t == P.MsgType.DISARM:
            self.armed = False
            self.fx_cmd = self.fy_cmd = 0.0
        elif t == P.MsgType.SENSOR_ON:
            self.sensor_on = True
        # HEARTBEAT and FAULT from the host need no action beyond being received

    def send_state(self) -> None:
        if self.device_fault and self.armed:  # a device disarms on its own faults
            self.armed = False
            self.fx_cmd = self.fy_cmd = 0.0
        flags = ((P.FLAG_FAULT if self.device_fault else 0)
                 | (P.FLAG_ARMED if self.armed else 0)
                 | (P.FLAG_WATCHDOG if self.watchdog_tripped else 0))
        x, y, vx, vy = self.x, self.y, self.vx, self.vy
        t_us = int(self.t_s * 1e6) & 0xFFFFFFFF
        if self._position_noise > 0.0:
            x += self._rng.gauss(0.0, self._position_noise)
            y += self._rng.gauss(0.0, self._position_noise)
        if self.sensor_on:
            fx, fy = self.hand_fx, self.hand_fy
            if self._force_noise > 0.0:
                fx += self._rng.gauss(0.0, self._force_noise)
                fy += self._rng.gauss(0.0, self._force_noise)
            self._send(P.MsgType.SENSOR, P.SENSOR_FMT.pack(t_us, fx, fy))
        if self.nan_frames > 0:
            self.nan_frames -= 1
            x = float("nan")
        payload = P.STATE_FMT.pack(t_us, x, y, vx, vy, flags,
                                   self.last_force_seq)
        self._send(P.MsgType.STATE, payload)

    def perform(self, motion: MotionFn) -> None:
        """The simulated operator starts ``motion`` now: its time 0 is the device's present."""
        t0 = self.t_s
        self.motion = lambda t: motion(t - t0)

    # --- physics ----------------------------------------------------------------------------
    def step(self, dt_s: float) -> None:
        """Advance the handle by ``dt_s`` in substeps."""
        c = self.config
        h = c.substep_s
        n = max(1, round(dt_s / h))
        h = dt_s / n
        m = c.handle_mass_kg
        x, y, vx, vy, t = self.x, self.y, self.vx, self.vy, self.t_s
        fx_c, fy_c = self.fx_cmd, self.fy_cmd
        kop, bop = c.operator_k_n_per_m, c.operator_b_n_s_per_m
        b, fc, vc = c.viscous_n_s_per_m, c.coulomb_n, c.coulomb_v_m_per_s
        motion = self.motion
        patient = self.patient
        hx = hy = 0.0
        for _ in range(n):
            if patient is None:
                rx, ry, rvx, rvy = motion(t)
                hx = kop * (rx - x) + bop * (rvx - vx)
                hy = kop * (ry - y) + bop * (rvy - vy)
            else:
                hx, hy = patient.force(x, y, vx, vy)
            ax = (fx_c + hx - b * vx - fc * math.tanh(vx / vc)) / m
            ay = (fy_c + hy - b * vy - fc * math.tanh(vy / vc)) / m
            vx += h * ax
            vy += h * ay
            x += h * vx
            y += h * vy
            t += h
        self.x, self.y, self.vx, self.vy, self.t_s = x, y, vx, vy, t
        self.hand_fx, self.hand_fy = hx, hy

    def poll_realtime(self, now: float) -> None:
        """Realtime mode: run the watchdog, advance physics to ``now``, emit due STATE frames."""
        if self.frozen or self._wall0 is None:
            return
        if self.armed and now - self.last_force_wall > self.watchdog_s:
            self.armed = False
            self.watchdog_tripped = True
            self.fx_cmd = self.fy_cmd = 0.0
        behind = 0
        while now >= self._next_state_wall:
            self.step(self.tick_s)
            self.send_state()
            self._next_state_wall += self.tick_s
            behind += 1
            if behind > 50:  # far behind (process was suspended): skip ahead
                self._next_state_wall = now + self.tick_s
                break


# --- running on a pty -------------------------------------------------------------------------
class PtyRobot:
    """The simulated device on the master end of a pty; the host opens :attr:`port`.

    ``PtyRobot(config).start_thread()`` runs it in a thread of this process (fault injection
    through :attr:`device`); ``start_process()`` runs it in its own process, so its physics does
    not compete with the host loop for the interpreter lock, at real-time priority and on a
    core of its own where the machine has two (:func:`haptic.clock.cpu_plan`), like a robot's
    firmware.
    """

    def __init__(self, config: SimRobotConfig) -> None:
        self.config = config
        self.master_fd, self.slave_fd = os.openpty()
        tty.setraw(self.slave_fd)
        tty.setraw(self.master_fd)
        self.port = os.ttyname(self.slave_fd)
        self.device = SimDevice(config)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._proc: subprocess.Popen[str] | None = None
        #: What the OS granted the device's own process (:meth:`start_process`).
        self.grant: Grant | None = None

    def start_thread(self) -> PtyRobot:
        self._thread = threading.Thread(target=self._run_thread, name="sim-robot", daemon=True)
        self._thread.start()
        return self

    def _run_thread(self) -> None:
        try:
            # no spinning in a thread: it would hold the interpreter the host loop needs
            serve_fd(self.device, self.master_fd, self._stop.is_set, spin=False)
        except OSError:
            pass

    def start_process(self, pin: bool = True, timeout_s: float = 20.0) -> PtyRobot:
        """Run the device in its own process at real-time priority, pinned to the device's
        core of :func:`haptic.clock.cpu_plan` (``pin``); :attr:`grant` says what the OS
        granted it (also when it refused)."""
        cmd = [sys.executable, "-m", "fieldbank.haptic.simrobot", "--fd", str(self.master_fd),
               "--config", json.dumps(asdict(self.config))]
        cpu = cpu_plan()[1] if pin else None
        if cpu is not None:
            cmd += ["--cpu", str(cpu)]
        # the child must import this package from wherever this process imported it
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [root, env.get("PYTHONPATH")]))
        self._proc = subprocess.Popen(cmd, pass_fds=(self.master_fd,), env=env,
                                      stdout=subprocess.PIPE, text=True)
        assert self._proc.stdout is not None
        ready, _, _ = select.select([self._proc.stdout], [], [], timeout_s)
        line = self._proc.stdout.readline() if ready else ""
        if line.startswith("GRANT "):
            self.grant = Grant.from_dict(json.loads(line[6:]))
        return self

    def inject_device_fault(self, on: bool = True) -> None:
        """Put the device in fault (it disarms and sets flag bit 2 in every STATE) or clear
        it: in its own process by a signal, in a thread directly."""
        if self._proc is not None:
            os.kill(self._proc.pid, signal.SIGUSR1 if on else signal.SIGUSR2)
        else:
            self.device.device_fault = on

    @property
    def pid(self) -> int | None:
        """The device process's id (None: not running in a process of its own)."""
        return None if self._proc is None else self._proc.pid

    def unplug(self) -> None:
        """Close the device end, as if the cable were pulled."""
        self._stop.set()
        if self._proc is not None:
            self._proc.kill()
            self._proc.wait()
            self._proc = None
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        if self.master_fd >= 0:
            os.close(self.master_fd)
            self.master_fd = -1

    def close(self) -> None:
        self.unplug()
        if self.slave_fd >= 0:
            os.close(self.slave_fd)
            self.slave_fd = -1

    def __enter__(self) -> PtyRobot:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def serve_fd(device: SimDevice, fd: int, stop: object = lambda: False, spin: bool = True) -> None:
    """Run ``device`` on file descriptor ``fd`` until ``stop()`` or the fd fails.

    In realtime mode the loop sleeps in ``select`` until about 200 µs before the next STATE is
    due and then, with ``spin``, busy-waits to the deadline for a steady period.
    """
    realtime = device.config.mode == "realtime"
    clock = time.perf_counter
    while not stop():  # type: ignore[operator]
        if realtime and device._wall0 is not None:
            wait = max(0.0, device._next_state_wall - clock() - 2e-4)
            wait = min(wait, 0.01)
        else:
            wait = 0.01
        r, _, _ = select.select([fd], [], [], wait)
        if r:
            data = os.read(fd, 4096)
            if not data:
                return
            device.feed(data)
        if realtime:
            while (spin and not r and device._wall0 is not None
                   and clock() < device._next_state_wall):
                pass  # spin the last ~200 µs to the STATE deadline
            device.poll_realtime(clock())
        out = device.take_output()
        while out:
            n = os.write(fd, out)
            out = out[n:]


def main(argv: list[str] | None = None) -> int:
    """Device process entry point: ``python -m haptic.simrobot --fd N --config JSON``."""
    import argparse

    ap = argparse.ArgumentParser(description="simulated planar robot on a file descriptor")
    ap.add_argument("--fd", type=int, required=True)
    ap.add_argument("--config", default="{}")
    ap.add_argument("--cpu", type=int, default=None, help="core to pin the device to")
    a = ap.parse_args(argv)
    cfg = SimRobotConfig(**json.loads(a.config))
    # a robot's firmware runs real-time: so does the simulation, in every mode, on a core of
    # its own where there is one (one step below the host loop's priority); what the OS
    # granted goes to the parent as the first line on stdout
    grant = enter_device_realtime(a.cpu)
    device = SimDevice(cfg)
    # fault injection for tests and demonstrations: SIGUSR1 puts the device in fault (it
    # disarms and reports flag bit 2), SIGUSR2 clears it
    signal.signal(signal.SIGUSR1, lambda *_: setattr(device, "device_fault", True))
    signal.signal(signal.SIGUSR2, lambda *_: setattr(device, "device_fault", False))
    print("GRANT " + json.dumps(grant.to_dict()), flush=True)
    # nor does firmware stop for a garbage collector (a full collection here took ≈ 15 ms: a
    # STATE frame later than the host's timeout)
    try:
        with collector_off():
            serve_fd(device, a.fd)
    except (OSError, KeyboardInterrupt):
        pass
    return 0



if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
