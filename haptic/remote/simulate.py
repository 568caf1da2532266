"""Both sites of a remote assessment in one process, faster than real time.

:func:`run_link` joins the clinician's site (the renderer with the link as its environment, the
simulated clinician's robot following a script) and the patient's site (a simulated patient's
robot with the arm as its virtual patient) through an in-memory transport, with the same
handshake, sealed datagrams, impairment, ports, passivity controllers and safety layers as
two processes over UDP, on virtual clocks advancing together. The benchmark
(``benchmarks/bench_remote.py``) and the simulated trainee through a link use it; the
two-process version is :mod:`haptic.remote.clinician_site` and
:mod:`haptic.remote.patient_site`.

:func:`stretch_script` is the scripted probing: slow and fast stretches of the arm along a
direction from its resting hand, each held and released. :func:`transparency` reads a run: the
stiffness and velocity-dependent resistance the clinician felt against the patient's own (a
least-squares fit of resistance = R₀ + K d + B ḋ along the stretch on each side: the
clinician's force against the clinician's motion, the patient's force against the patient's
motion), the peaks, the energy the link created, and the passivity controllers' activity.
"""

from __future__ import annotations

import math
import secrets
import urllib.parse
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from fieldbank.errors import ParameterError
from fieldbank.haptic.clock import VirtualClock
from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.motions import LEAD_IN_S, format_path
from fieldbank.haptic.pair import Environment
from fieldbank.haptic.patient import PatientPlacement, VirtualPatient
from fieldbank.haptic.recording import Trace
from fieldbank.haptic.remote.channel import Endpoint, Impairment, MemoryTransport
from fieldbank.haptic.remote.config import SiteConfig
from fieldbank.haptic.remote.environment import Follower, RemoteArm, remote_environment
from fieldbank.haptic.remote.handshake import Initiator, Responder
from fieldbank.haptic.remote.patient_site import WATCHDOG_MS, PatientSite
from fieldbank.haptic.remote.ports import ClinicianPort
from fieldbank.haptic.remote.wire import SessionCipher, new_key
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.safety import Mode
from fieldbank.haptic.simrobot import SimDevice
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.probepath import ProbePath
from fieldbank.sim import ArmSim, CouplingConfig

#: Sensor noise of the simulated patient's robot (BRIEF §16: 0.1–0.5 N, ≪ 1 mm).
PATIENT_FORCE_NOISE_N = 0.2
#: The clinician's felt peak force against the patient's over a 30 s probing session at 100 ms
#: one-way delay and 5 % loss: measured −20 % … −5 % over 5 seeds by benchmarks/bench_remote.py
#: (docs/remote.md); the bounds the two-process test holds the link to.
PEAK_ERROR_100MS_5PCT = (-0.25, 0.05)
#: The simulated clinician's hand and forearm moving with the handle, kg (assumption: Winter's
#: forearm + hand, 2.2 % of a 75 kg body; the simulated operator's spring and damper are its
#: hand's impedance, the mass is the limb's).
CLINICIAN_HAND_KG = 1.65


@dataclass(frozen=True)
class Stretch:
    """One stretch of the script: ``distance_m`` along the direction in ``duration_s``, held
    ``hold_s``, back in ``return_s``, rest ``rest_s``."""

    distance_m: float
    duration_s: float
    hold_s: float = 1.0
    return_s: float = 1.5
    rest_s: float = 1.0


#: The default script: a slow stretch (≈ 3 cm/s) and a fast one (≈ 0.3 m/s peak), each 5 cm.
DEFAULT_STRETCHES = (Stretch(0.05, 2.5), Stretch(0.05, 0.3))


def _min_jerk(tau: float) -> float:
    tau = min(1.0, max(0.0, tau))
    return tau ** 3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)


@dataclass(frozen=True)
class Script:
    """A scripted probing: the path the clinician's hand follows and its phases.

    Attributes
    ----------
    path : ProbePath
        Robot frame of the clinician's robot.
    direction : (float, float)
        Unit vector of the stretches, shoulder frame.
    phases : tuple of (name, start_s, end_s)
        Session times (s from the first tick: the simulated operator starts the path after
        its lead-in) of each stretch's moving part: ``stretch k``, ``hold k``, ``return k``.
    stretches : tuple of Stretch
    """

    path: ProbePath
    direction: tuple[float, float]
    phases: tuple[tuple[str, float, float], ...]
    stretches: tuple[Stretch, ...]

    def phase(self, name: str) -> tuple[float, float]:
        for n, a, b in self.phases:
            if n == name:
                return a, b
        raise KeyError(f"no phase {name!r}; the script has {[n for n, _, _ in self.phases]}")


def stretch_script(hand_m: tuple[float, float], direction: tuple[float, float],
                   stretches: tuple[Stretch, ...] = DEFAULT_STRETCHES, repeat: int = 1,
                   sample_s: float = 0.025, offset_m: tuple[float, float] = (0.0, 0.0),
                   name: str = "stretches") -> Script:
    """The scripted clinician: from ``hand_m`` (shoulder frame), each stretch along
    ``direction`` (minimum jerk), held, returned, rested; ``repeat`` times. Points in the robot
    frame (shoulder frame + ``offset_m``)."""
    n = math.hypot(*direction) or 1.0
    ux, uy = direction[0] / n, direction[1] / n
    segs: list[tuple[str, float, float, float]] = [("rest", 0.5, 0.0, 0.0)]
    k_stretch = 0
    for _ in range(repeat):
        for s in stretches:
            k_stretch += 1
            segs += [(f"stretch {k_stretch}", s.duration_s, 0.0, s.distance_m),
                     (f"hold {k_stretch}", s.hold_s, s.distance_m, s.distance_m),
                     (f"return {k_stretch}", s.return_s, s.distance_m, 0.0),
                     ("rest", s.rest_s, 0.0, 0.0)]
    ts: list[float] = []
    ps: list[tuple[float, float]] = []
    phases = []
    t0 = 0.0
    for label, dur, a, b in segs:
        k = 2 if a == b else max(12, round(dur / sample_s))
        for i in range(k):
            d = a + (b - a) * _min_jerk(i / k)
            ts.append(round(t0 + i * dur / k, 6))
            ps.append((hand_m[0] + ux * d + offset_m[0], hand_m[1] + uy * d + offset_m[1]))
        if label != "rest":
            phases.append((label, LEAD_IN_S + t0, LEAD_IN_S + t0 + dur))
        t0 += dur
    ts.append(round(t0, 6))
    ps.append((hand_m[0] + offset_m[0], hand_m[1] + offset_m[1]))
    desc = ", ".join(f"{s.distance_m * 100:g} cm in {s.duration_s:g} s" for s in stretches)
    path = ProbePath(name, f"stretches along ({ux:.2f}, {uy:.2f}): {desc}", tuple(ts),
                     tuple(ps), shoulder_offset_m=offset_m)
    return Script(path, (ux, uy), tuple(phases), tuple(stretches) * repeat)


def patient_robot(params: ArmParams, rate_hz: int, shoulder_m: tuple[float, float] = (0.0, 0.0),
                  seed: int = 0, force_noise_n: float = PATIENT_FORCE_NOISE_N) -> RobotLink:
    """A simulated patient's robot in this process (lockstep), the arm gripping its handle at
    rest; handshake done, force sensor on."""
    hand = Arm.from_params(params).rest_position()
    sx, sy = shoulder_m
    q = {"mode": "lockstep", "x0_m": f"{float(hand[0]) + sx:.6f}",
         "y0_m": f"{float(hand[1]) + sy:.6f}", "patient_x_m": f"{sx}", "patient_y_m": f"{sy}",
         "seed": str(seed), "force_noise_n": f"{force_noise_n}", "position_noise_m": "2e-5"}
    link = RobotLink.open("sim://?" + urllib.parse.urlencode(q))
    dev = link.port.device
    assert isinstance(dev, SimDevice)
    dev.patient = VirtualPatient(params, PatientPlacement(sx, sy), dev.config.substep_s,
                                 "simulated patient")
    dev.patient.grasp(dev.x, dev.y)
    link.handshake(rate_hz, WATCHDOG_MS)
    link.sensor_on()
    link.send_force(0.0, 0.0)
    link.wait_state(0.05)
    return link


def clinician_robot(hand_m: tuple[float, float], rate_hz: int,
                    script: ProbePath | None = None, seed: int = 0,
                    hand_mass_kg: float = CLINICIAN_HAND_KG) -> RobotLink:
    """The simulated clinician's robot (lockstep) at ``hand_m`` (robot frame), its operator
    following ``script`` (None: holding still; :meth:`SimDevice.perform` can start one); the
    clinician's hand and forearm add ``hand_mass_kg`` to the handle's 1 kg."""
    q = {"mode": "lockstep", "motion": "hold", "x0_m": f"{hand_m[0]:.6f}",
         "handle_mass_kg": f"{1.0 + hand_mass_kg:g}",
         "y0_m": f"{hand_m[1]:.6f}", "seed": str(seed)}
    if script is not None:
        q["motion"] = "path"
        q["motion_path"] = format_path([(t, p[0], p[1]) for t, p in
                                        zip(script.times_s, script.points_m, strict=True)])
    link = RobotLink.open("sim://?" + urllib.parse.urlencode(q))
    link.handshake(rate_hz, WATCHDOG_MS)
    return link


def handshake_in_memory(key: bytes, rate_hz: int) -> tuple[SessionCipher, SessionCipher]:
    """The clinician's and the patient's ciphers of one session, from the handshake the two
    sites run over UDP (:mod:`haptic.remote.handshake`), its datagrams handed over here."""
    hello = {"rate_hz": rate_hz, "lockstep": True}
    ini = Initiator(key, secrets.randbits(63), hello)
    resp = Responder(key)
    opened = resp.open_hello(ini.hello)
    got = None if opened is None else ini.answer(resp.welcome(opened, "memory", hello))
    if not isinstance(got, tuple):
        raise HapticError(f"the in-memory handshake failed: {got!r}")
    confirmed = resp.confirm(ini.confirm(got[0]), "memory")
    if confirmed is None:
        raise HapticError("the in-memory handshake was not confirmed")
    return got[0], confirmed[0]


def linked_endpoints(impairment: Impairment, tick_s: float, key: bytes | None = None
                     ) -> tuple[Endpoint, Endpoint]:
    """The clinician's and the patient's endpoints of an in-memory link (lockstep) after the
    handshake, each impairing what it receives (the patient's side with the next seed)."""
    c, p = handshake_in_memory(key or new_key(), round(1.0 / tick_s))
    a, b = MemoryTransport.pair()
    ce = Endpoint(a, c, impairment, True, tick_s)
    pe = Endpoint(b, p, replace(impairment, seed=impairment.seed + 1), True, tick_s)
    return ce, pe


@dataclass
class LinkRun:
    """One simulated remote session."""

    clinician: dict[str, np.ndarray]
    patient: dict[str, np.ndarray]
    trace: Trace
    clinician_summary: dict[str, Any]
    patient_summary: dict[str, Any]
    settings: dict[str, Any] = field(default_factory=dict)


class Pair:
    """Both sites joined, ready to tick (:meth:`tick` advances both by one period)."""

    def __init__(self, patient: ArmParams, config: SiteConfig, clinician_link: RobotLink,
                 patient_seed: int = 0, force_noise_n: float = PATIENT_FORCE_NOISE_N) -> None:
        self.config = config
        dt = 1.0 / config.rate_hz
        ce, pe = linked_endpoints(config.impairment, dt)
        self.plink = patient_robot(patient, config.rate_hz, seed=patient_seed,
                                   force_noise_n=force_noise_n)
        self.patient = PatientSite(self.plink, pe, config, (0.0, 0.0))
        self.patient.arm()
        self.port = ClinicianPort.for_site(ce, config, (0.0, 0.0))
        drawing = patient.with_unimpaired_muscles()
        self.link = clinician_link
        rd = Renderer(clinician_link, drawing, drawing,
                      RendererConfig(rate_hz=config.rate_hz, state_wait_s=config.state_wait_s,
                                     realtime_priority=False),
                      safety=config.safety, clock=VirtualClock(),
                      environment=remote_environment(self.port, drawing))
        self.renderer = rd
        self.port.robot_ok = lambda: rd.safety.mode == Mode.ARMED
        self.port.latched = lambda: rd.safety.latched
        self.port.commanded = lambda: (rd.fx, rd.fy)
        self.port.on_end = rd.stop_now  # as the clinician's site: a stop ramps out first
        rd.wind_down = lambda: self.port.end_now("stopped by the clinician")
        rd.start()

    def tick(self) -> None:
        self.renderer.tick()
        self.patient.tick()

    def finish(self) -> LinkRun:
        trace = self.renderer.finish()
        self.port.finish()
        self.patient.finish()
        self.plink.close()
        self.link.close()
        return LinkRun(self.port.log.arrays(), self.patient.port.log.arrays(), trace,
                       self.port.summary(), self.patient.port.summary())


class LinkChain:
    """One simulated link kept for a whole session: the clinician's port, and the patient's
    site in this process (a simulated patient's robot), whose virtual patient is swapped for
    each model felt through it (:class:`LinkedArm`)."""

    def __init__(self, params: ArmParams, dt_s: float, config: SiteConfig, seed: int = 0
                 ) -> None:
        ce, pe = linked_endpoints(replace(config.impairment, seed=config.impairment.seed + seed),
                                  dt_s)
        self.dt_s = dt_s
        config = replace(config, rate_hz=round(1.0 / dt_s))
        self.port = ClinicianPort.for_site(ce, config, (0.0, 0.0))
        self.plink = patient_robot(params, config.rate_hz, seed=seed)
        self.site = PatientSite(self.plink, pe, config, (0.0, 0.0))
        self.site.arm()
        self.current: ArmParams = params

    @property
    def device(self) -> SimDevice:
        dev = self.plink.port.device
        assert isinstance(dev, SimDevice)
        return dev

    def feel(self, params: ArmParams) -> None:
        """From now on the patient is ``params``, relaxed where its hand holds the handle (an
        arm it cannot reach there starts at rest)."""
        if params is self.current:
            return
        dev = self.device
        vp = VirtualPatient(params, PatientPlacement(0.0, 0.0), dev.config.substep_s,
                            "simulated patient")
        try:
            vp.grasp(dev.x, dev.y)
        except ParameterError:
            hx, hy = Arm.from_params(params).rest_position()
            vp.grasp(float(hx), float(hy))
        dev.patient = vp
        self.current = params

    def close(self) -> None:
        self.plink.close()


class LinkedArm(RemoteArm):
    """A model felt through a :class:`LinkChain`: ticking it ticks both ends of the link; its
    first tick makes the model the chain's patient. The renderer's output gain and limits are
    outside the link's books here (the two-process clinician's site books what its robot was
    given)."""

    def __init__(self, params: ArmParams, chain: LinkChain) -> None:
        super().__init__(chain.port, Arm.from_params(params.with_unimpaired_muscles()),
                         chain.dt_s)
        self.params = params
        self.chain = chain

    def _tick(self, x: float, y: float, vx: float, vy: float) -> tuple[float, float]:
        chain = self.chain
        if chain.current is not self.params:
            chain.feel(self.params)
        f = super()._tick(x, y, vx, vy)
        chain.site.tick()
        return f


def linked_environment(config: SiteConfig | None = None) -> tuple[Environment, list[LinkChain]]:
    """The renderer's environment for simulations through a link, and its links (close them
    when done): model A is felt through one link, model B through a second (made when B first
    differs from A; while they are the same, B follows A)."""
    cfg = config or SiteConfig(lockstep=True)
    chains: list[LinkChain] = []
    calls = [0]

    def make(params: ArmParams, dt_s: float, coupling: CouplingConfig | None) -> ArmSim:
        del coupling
        slot = calls[0] % 2
        calls[0] += 1
        if slot == 1 and make.last_a is params:  # type: ignore[attr-defined]
            return Follower(make.last_arm)  # type: ignore[attr-defined]
        while len(chains) <= slot:
            chains.append(LinkChain(params, dt_s, cfg, seed=len(chains)))
        arm = LinkedArm(params, chains[slot])
        if slot == 0:
            make.last_a, make.last_arm = params, arm  # type: ignore[attr-defined]
        return arm

    return make, chains


def push_patient(pair: Pair, at_s: float, force_n: tuple[float, float]) -> None:
    """From ``at_s`` of the session on, the simulated patient's hand pushes ``force_n`` more on
    its handle (shoulder frame, N): a step of the patient's force (the force step response)."""
    dev = pair.plink.port.device
    assert isinstance(dev, SimDevice) and dev.patient is not None
    inner = dev.patient.force
    port = pair.patient.port
    fx0, fy0 = force_n

    def force(x: float, y: float, vx: float, vy: float) -> tuple[float, float]:
        fx, fy = inner(x, y, vx, vy)
        if port.tick_n * port.dt >= at_s:
            return fx + fx0, fy + fy0
        return fx, fy

    dev.patient.force = force  # type: ignore[method-assign]


def run_link(patient: ArmParams, script: ProbePath | Script, *,
             config: SiteConfig | None = None,
             seed: int = 0, tail_s: float = 0.5,
             hand_mass_kg: float = CLINICIAN_HAND_KG,
             on_tick: Callable[[Pair], None] | None = None) -> LinkRun:
    """Both sites in this process for the length of ``script`` (robot frame = the patient's
    shoulder frame; it should start at the patient's resting hand)."""
    cfg = config or SiteConfig(lockstep=True)
    if not cfg.lockstep:
        cfg = replace(cfg, lockstep=True)
    path = script.path if isinstance(script, Script) else script
    start = path.points_m[0]
    clink = clinician_robot((float(start[0]), float(start[1])), cfg.rate_hz, path, seed,
                            hand_mass_kg)
    pair = Pair(patient, cfg, clink, patient_seed=seed)
    n = round((LEAD_IN_S + path.duration_s + tail_s) * cfg.rate_hz)
    for _ in range(n):
        pair.tick()
        if on_tick is not None:
            on_tick(pair)
    run = pair.finish()
    run.settings = {"impairment": cfg.impairment.to_dict(), "link": cfg.link.to_dict(),
                    "rate_hz": cfg.rate_hz, "script": path.description,
                    "clinician_hand_mass_kg": hand_mass_kg}
    return run


def created_energy(run: LinkRun) -> np.ndarray:
    """Energy the link created up to each tick, J (≤ 0: passive): what left it at both ports
    minus what entered, the ticks of both sites aligned."""
    c, p = run.clinician, run.patient
    n = min(len(c["tick"]), len(p["tick"]))
    return (c["e_out_j"][:n] + p["e_out_j"][:n]) - (c["e_in_j"][:n] + p["e_in_j"][:n])


@dataclass(frozen=True)
class Side:
    """One side's read-outs of a stretch script (module docstring of :func:`transparency`)."""

    stiffness_n_per_m: float        # slope of resistance over displacement, slow stretch
    velocity_resistance_n: float    # fast minus slow resistance at the same displacement
    peak_n: float                   # largest force from the fast stretch to its release


def _side(t: np.ndarray, x: np.ndarray, f: np.ndarray, u: np.ndarray, script: Script,
          lag_s: float) -> Side:
    """Each slow stretch (odd) gives a stiffness; the fast one after it (even) its excess over
    that slow stretch's line; means over the repeats; the peak over every fast stretch."""
    d = (x - x[np.searchsorted(t, script.phases[0][1])]) @ u
    r = -(f @ u)
    ks, excesses, peaks = [], [], []
    for j in range(0, len(script.stretches) - 1, 2):
        a, b = script.phase(f"stretch {j + 1}")
        slow = (t >= a) & (t <= b + lag_s)
        dmax = float(np.max(d[slow]))
        use = slow & (d > 0.1 * dmax) & (d < 0.9 * dmax)
        k, r0 = np.polyfit(d[use], r[use], 1)
        a2, b2 = script.phase(f"stretch {j + 2}")
        fast = (t >= a2) & (t <= b2 + lag_s)
        dmax2 = float(np.max(d[fast]))
        use2 = fast & (d > 0.1 * dmax2) & (d < 0.9 * min(dmax, dmax2))
        ks.append(float(k))
        if use2.any():
            excesses.append(float(np.mean(r[use2] - (r0 + k * d[use2]))))
        _, hold_end = script.phase(f"hold {j + 2}")
        win = (t >= a2) & (t <= hold_end)
        peaks.append(float(np.max(np.hypot(f[win, 0], f[win, 1]))))
    return Side(float(np.mean(ks)), float(np.mean(excesses)) if excesses else math.nan,
                max(peaks))


def transparency(run: LinkRun, script: Script) -> dict[str, float]:
    """What the clinician felt against what the patient's arm did, in the clinic's terms.

    Each side against its own motion along the script's direction (resistance = the force
    against the stretch): **stiffness** — the slope of resistance over displacement on each slow
    stretch (between 10 and 90 % of its length: position-dependent resistance, contracture);
    **velocity-dependent resistance** — on each fast stretch, the mean of the resistance minus
    the slow stretch's before it at the same displacement (spasticity), N; both averaged over
    the script's repeats; **peak** force from a fast stretch to the end of its hold, the
    largest. The felt side is the clinician's handle and the force its
    robot was commanded; the patient's side is the patient's handle and the force of the hand
    on it (the patient's robot's sensor). Windows reach one round trip past each phase (the
    clinician feels it that much later). Also: the energy the link created (its largest value
    over the session: ≤ 0 is passive), what the passivity controllers dissipated and on what
    share of the ticks they acted, the largest drift of the patient's robot from the
    clinician's position, the round trip and the loss measured.
    """
    c, p = run.clinician, run.patient
    tr = run.trace
    m = min(len(tr), len(c["t_s"]))
    u = np.asarray(script.direction)
    cs, ps = run.clinician_summary, run.patient_summary
    rtt = (cs["link"]["rtt_ms"] or 0.0) * 1e-3
    felt = _side(c["t_s"][:m], np.column_stack([c["x_m"][:m], c["y_m"][:m]]),
                 np.column_stack([tr.column("fx_n")[:m], tr.column("fy_n")[:m]]).astype(float),
                 u, script, rtt)
    pat = _side(p["t_s"], np.column_stack([p["x_m"], p["y_m"]]),
                np.column_stack([p["hand_fx_n"], p["hand_fy_n"]]), u, script, rtt)
    e = created_energy(run)
    track = np.hypot(p["cmd_x_m"] - p["target_x_m"], p["cmd_y_m"] - p["target_y_m"])

    def rel(a: float, b: float) -> float:
        return a / b - 1.0 if b else math.nan

    return {
        "stiffness_felt_n_per_m": felt.stiffness_n_per_m,
        "stiffness_patient_n_per_m": pat.stiffness_n_per_m,
        "stiffness_error": rel(felt.stiffness_n_per_m, pat.stiffness_n_per_m),
        "velocity_resistance_felt_n": felt.velocity_resistance_n,
        "velocity_resistance_patient_n": pat.velocity_resistance_n,
        "velocity_resistance_error": rel(felt.velocity_resistance_n,
                                         pat.velocity_resistance_n),
        "peak_felt_n": felt.peak_n, "peak_patient_n": pat.peak_n,
        "peak_error": rel(felt.peak_n, pat.peak_n),
        "created_max_j": float(np.max(e)) if len(e) else 0.0,
        "created_end_j": float(e[-1]) if len(e) else 0.0,
        "dissipated_j": cs["passivity_dissipated_j"] + ps["passivity_dissipated_j"],
        "pc_active_clinician": cs["passivity_active_ticks"] / max(1, cs["ticks"]),
        "pc_active_patient": ps["passivity_active_ticks"] / max(1, ps["ticks"]),
        "drift_max_m": float(np.nanmax(track)) if np.isfinite(track).any() else 0.0,
        "rtt_ms": rtt * 1e3,
        "loss_measured": cs["link"]["loss_fraction"],
    }
