"""The settings of a remote site: its loop and clock (:class:`SiteConfig`) and its end of the
link (:class:`LinkConfig`), each checked against one bounds table where it is made."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from fieldbank.errors import ParameterError
from fieldbank.haptic.remote.channel import Impairment
from fieldbank.haptic.remote.passivity import DEFAULT_RESERVE_J, PASSIVITY_MODES
from fieldbank.haptic.rendererconfig import RENDERER_BOUNDS
from fieldbank.haptic.safety import SafetyConfig
from fieldbank.validation import Interval, check_fields

#: Allowed range of every numeric field of :class:`LinkConfig`.
LINK_BOUNDS: dict[str, Interval] = {
    "watchdog_s": Interval(0.005, 2.0, "s"),
    "resume_s": Interval(0.0, 10.0, "s"),
    "ramp_s": Interval(0.01, 2.0, "s"),
    "lockstep_wait_s": Interval(0.01, 60.0, "s"),
    "start_wait_s": Interval(0.01, 3600.0, "s"),
    "drift_time_s": Interval(0.01, 5.0, "s"),
    "extrapolate_s": Interval(0.0, 0.2, "s"),
    "servo_k_n_per_m": Interval(100.0, 50000.0, "N/m"),
    "servo_b_n_s_per_m": Interval(0.0, 2000.0, "N·s/m"),
    "servo_ff": Interval(0.0, 1.0, "1"),
    "reserve_j": Interval(0.0, 1.0, "J"),
    "patient_reserve_j": Interval(0.0, 1.0, "J"),
    "damping_n_s_per_m": Interval(0.0, 200.0, "N·s/m"),
    "force_filter_hz": Interval(0.0, 500.0, "Hz"),
    "ready_s": Interval(0.0, 10.0, "s"),
    "peer_force_slew_n_per_s": Interval(100.0, 1e5, "N/s"),
    "peer_step_margin_m": Interval(0.0, 0.05, "m"),
}


@dataclass(frozen=True)
class LinkConfig:
    """Settings of a port (ranges in :data:`LINK_BOUNDS`); both sites should agree.

    Attributes
    ----------
    watchdog_s : float, s
        No STATE from the peer for this long: the link is lost.
    resume_s : float, s
        STATEs must flow this long again before the force ramps back in.
    ramp_s : float, s
        Raised-cosine ramp of the force out (link lost) and in (engaged, resumed).
    lockstep_wait_s : float, s
        Lockstep: longest wall-clock wait for the peer's previous tick.
    start_wait_s : float, s
        Lockstep: longest wait for the peer's first STATE (its loop may start later: a station
        to launch, a robot to arm).
    drift_time_s : float, s
        Patient's side: time constant of the pull of the robot's reference back to the
        clinician's position.
    extrapolate_s : float, s
        Patient's side: the clinician's position is carried forward at its last velocity for
        at most this long after the newest STATE (lost datagrams).
    servo_k_n_per_m, servo_b_n_s_per_m : float
        Patient's side: the servo that moves the patient's robot (assumption: stiff enough
        that a hypertonic arm moves it ≤ 2 mm, damped enough for ≈ 3 kg of handle and arm).
    servo_ff : float
        Patient's side: fraction of the patient's measured force the servo compensates.
    reserve_j : float, J
        Energy the clinician's port keeps in its tank before handing the rest to the
        patient's (:mod:`haptic.remote.passivity`): it pays the small give of a hand holding
        still against a force without waiting a round trip. The patient's port keeps none: it
        hands back at once whatever the patient returns.
    damping_n_s_per_m : float, N·s/m
        Clinician's side: a damper added to what is displayed (0: none).
    force_filter_hz : float, Hz
        Patient's side: cut-off of the low-pass filter (second-order Butterworth) on the
        patient's measured force before it is used and sent (0: none). A hand gripping a
        handle through a stiff grip rings at a few hundred hertz, and the force sensor reads
        it; nobody feels it at the hand, but it would shake the clinician's handle.
    ready_s : float, s
        A site engages only after its robot has been armed, free of faults and its loop on
        time (no tick a whole period late) for this long without a break.
    peer_force_slew_n_per_s : float, N/s
        The fastest change of the peer's force a site that displays it accepts, applied per
        tick (:mod:`haptic.remote.plausible`; 10 N per tick at 1 kHz).
    peer_step_margin_m : float, m
        What a peer's position may move between two STATEs beyond what the speed limit allows
        (encoder noise, rounding).
    passivity : str
        'tdpa' (time-domain passivity controller) or 'off' (observer only).
    """

    watchdog_s: float = 0.1
    resume_s: float = 0.5
    ramp_s: float = 0.2
    lockstep_wait_s: float = 5.0
    start_wait_s: float = 120.0
    drift_time_s: float = 0.2
    extrapolate_s: float = 0.02
    servo_k_n_per_m: float = 8000.0
    servo_b_n_s_per_m: float = 120.0
    servo_ff: float = 0.0
    reserve_j: float = DEFAULT_RESERVE_J
    patient_reserve_j: float = 0.0
    damping_n_s_per_m: float = 0.0
    force_filter_hz: float = 80.0
    ready_s: float = 0.3
    peer_force_slew_n_per_s: float = 10_000.0
    peer_step_margin_m: float = 0.001
    passivity: str = "tdpa"

    def __post_init__(self) -> None:
        check_fields(self, LINK_BOUNDS, what="remote link setting")
        if self.passivity not in PASSIVITY_MODES:
            raise ParameterError(f"passivity must be one of {', '.join(PASSIVITY_MODES)}; got "
                             f"{self.passivity!r}")

    def to_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


#: The loop's rate: the renderer's range (the clinician's site is a rendering session).
RATE_BOUNDS: Interval = RENDERER_BOUNDS["rate_hz"]
#: Allowed range of every numeric field of :class:`SiteConfig`.
SITE_BOUNDS: dict[str, Interval] = {
    "rate_hz": RATE_BOUNDS,
    "state_wait_s": Interval(0.0, 10.0, "s"),
}


@dataclass(frozen=True)
class SiteConfig:
    """Settings of either site's loop (ranges in :data:`SITE_BOUNDS`).

    Attributes
    ----------
    rate_hz : int, Hz
        The loop's rate (both sites must agree: the handshake refuses a difference).
    lockstep : bool
        Virtual clocks advancing together (both sites simulated; faster than real time).
    link : LinkConfig
    impairment : Impairment
        What this site does to the STATE datagrams it receives (tests and benchmarks).
    safety : SafetyConfig
        The limits of this site's robot (the handle port's passivity controller is off: the
        link's controller is in the port); they also bound what the peer may send
        (:mod:`haptic.remote.plausible`).
    state_wait_s : float, s
        Lockstep robots: how long to wait for each STATE.
    """

    rate_hz: int = 1000
    lockstep: bool = False
    link: LinkConfig = field(default_factory=LinkConfig)
    impairment: Impairment = field(default_factory=Impairment)
    safety: SafetyConfig = field(default_factory=lambda: SafetyConfig(passivity=False))
    state_wait_s: float = 0.05

    def __post_init__(self) -> None:
        check_fields(self, SITE_BOUNDS, what="remote site setting")
        if self.safety.passivity:
            raise ParameterError("a remote site's robot runs without the handle port's "
                                 "passivity controller (the link's controller replaces it): "
                                 "give SafetyConfig(passivity=False)")

    def hello(self) -> dict[str, Any]:
        return {"rate_hz": self.rate_hz, "lockstep": self.lockstep}
