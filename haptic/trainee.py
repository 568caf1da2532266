"""A simulated trainee runs the whole training protocol on the simulated robot, faster than
real time.

The trainee is the simulated operator of :mod:`haptic.simrobot` (a hand of stated impedance
pulling the handle toward a reference path) driven through the same renderer commands as the
station's buttons (``train_start``, ``train_next``, ``train_answer``), so the protocol, the
rendering, the push fades and the records are the real ones; only the person is simulated.

In each trial the trainee

- *instructed*: follows every probe drawn for the trial (the seed's fast pull and
  semi-ellipse, and any designed probe): moves to the path's start, holds, follows it, settles;
- *non-instructed*: explores freely for ``explore_s`` (the seeded sum of slow sinusoids of
  :func:`haptic.motions.explore`);

and feels the force the robot puts on the handle. Its stated answering rule
(:class:`DirectionRule`), per probe a direction:

- *instructed*: the direction of the *extra* force - the mean force along the probe minus the
  mean force the unimpaired arm of familiarisation gave along the same probe. The same probe on
  every arm makes the arm's own inertia and the unimpaired tone cancel, so what is left points
  where the hypertonic group pulls, at any severity (a trained hand learns the normal arm's
  feel first, as in the seed's familiarisation);
- *non-instructed*: every exploration differs, so nothing cancels; the direction of the force
  at its peak magnitude.

During familiarisation it keeps the mean direction per probe for each maximally impaired group
(the legend names the group); in the assessment it answers the group whose directions are
nearest (sum of the angles between them), with the perceived directions blurred by a seeded
Gaussian error of ``direction_noise_deg`` (assumption: 0 by default; set it to model a hand's
direction discrimination). Low severities push less hard, so their extra force is small and
the blur matters most there, as the seed's trainees found.

Instructed, it also judges the **severity** (the seed's protocol asks only the group; the
trainee's severity judgement is kept beside its answers): the size of the extra force along the
probes against the size it felt for the answered group in familiarisation (the severe arm),
the level whose expected share of it is nearest on a log scale — on the severity scale the
extra force grows as the level's ratio to unimpaired less one (:data:`SEVERITY_SHARE`: very
mild 0.16, mild 0.32, moderate 0.58 of severe). Perceived sizes are blurred by a seeded
log-normal error of ``magnitude_noise`` (a fraction; assumption, 0 by default: the force JND is
≈ 10 %).

The renderer can tick something else than the compiled arms (``environment``: a simulated
remote link, :func:`haptic.remote.simulate.linked_environment`), so the same protocol runs
through a delayed link.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

from fieldbank.evaluate.severity import LEVEL_RATIO
from fieldbank.haptic import commands as C
from fieldbank.haptic.activities.training import Training
from fieldbank.haptic.clock import VirtualClock
from fieldbank.haptic.commandbase import RendererCommand
from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.motions import explore
from fieldbank.haptic.pair import Environment
from fieldbank.haptic.probe import sim_url
from fieldbank.haptic.recording import Trace
from fieldbank.haptic.renderer import Renderer
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.safety import SafetyConfig
from fieldbank.haptic.simrobot import SimDevice
from fieldbank.haptic.training import TrainingProtocol
from fieldbank.probepath import ProbePath
from fieldbank.validation import Interval, check_fields

#: Allowed range of each field of :class:`DirectionRule` and :class:`TraineeMotion`.
TRAINEE_BOUNDS: dict[str, Interval] = {
    "direction_noise_deg": Interval(0.0, 180.0, "°"),
    "magnitude_noise": Interval(0.0, 2.0, "1"),
    "approach_s": Interval(0.05, 10.0, "s"),
    "hold_s": Interval(0.0, 10.0, "s"),
    "settle_s": Interval(0.0, 10.0, "s"),
    "explore_s": Interval(0.5, 600.0, "s"),
    "explore_amplitude_m": Interval(0.0, 0.2, "m"),
}
#: Groups a trainee can answer, and the answer of each (the seed's buttons).
GROUP_ANSWER = {"shoulder": "shoulder", "elbow": "elbow", "biarticular": "both"}
ANSWER_GROUP = {v: k for k, v in GROUP_ANSWER.items()}
#: The extra force of each level as a share of the severe arm's, on the severity scale.
SEVERITY_SHARE = {lvl: (LEVEL_RATIO[lvl] - 1.0) / (LEVEL_RATIO["severe"] - 1.0)
                  for lvl in ("very mild", "mild", "moderate", "severe")}
Say = Callable[[str], None]


def _quiet(msg: str) -> None:
    del msg


@dataclass(frozen=True)
class DirectionRule:
    """The answering rule: nearest familiarisation template of peak-force directions.

    Attributes
    ----------
    direction_noise_deg : float, °
        Standard deviation of the error in each perceived direction (assumption).
    magnitude_noise : float
        Standard deviation of the log of each perceived force size (assumption).
    seed : int
        Seeds those errors.
    """

    direction_noise_deg: float = 0.0
    seed: int = 0
    magnitude_noise: float = 0.0

    def __post_init__(self) -> None:
        check_fields(self, TRAINEE_BOUNDS, what="trainee parameter",
                     names=("direction_noise_deg", "magnitude_noise"))


@dataclass(frozen=True)
class TraineeMotion:
    """How the simulated hand moves in a trial (assumptions, each overridable)."""

    approach_s: float = 0.5          # minimum-jerk move to a probe's start
    hold_s: float = 0.2              # still before the probe
    settle_s: float = 0.4            # still after it
    explore_s: float = 4.0           # free exploration per non-instructed trial
    explore_amplitude_m: float = 0.06

    def __post_init__(self) -> None:
        check_fields(self, TRAINEE_BOUNDS, what="trainee parameter",
                     names=("approach_s", "hold_s", "settle_s", "explore_s",
                            "explore_amplitude_m"))


@dataclass
class DirectionTrainee:
    """Learns peak-force directions per group in familiarisation, answers by the nearest."""

    rule: DirectionRule = field(default_factory=DirectionRule)
    templates: dict[str, list[list[tuple[float, float]]]] = field(default_factory=dict)
    sizes: dict[str, list[float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._rng = random.Random(self.rule.seed)

    def perceive(self, directions: Sequence[float]) -> list[float]:
        """Peak-force directions (rad) as felt: with the rule's seeded error."""
        sd = math.radians(self.rule.direction_noise_deg)
        return [a + (self._rng.gauss(0.0, sd) if sd > 0 else 0.0) for a in directions]

    def learn(self, group: str | None, directions: Sequence[float]) -> None:
        """Keep a familiarisation trial's directions under its (legend's) group; the
        unimpaired arm (no group) names no answer."""
        if group is None:
            return
        self.templates.setdefault(group, []).append(
            [(math.cos(a), math.sin(a)) for a in self.perceive(directions)])

    def _template(self, group: str) -> list[float]:
        trials = self.templates[group]
        out = []
        for k in range(len(trials[0])):
            sx = sum(t[k][0] for t in trials)
            sy = sum(t[k][1] for t in trials)
            out.append(math.atan2(sy, sx))
        return out

    def feel_size(self, size_n: float) -> float:
        """A force size (N) as felt: with the rule's seeded log-normal error."""
        sd = self.rule.magnitude_noise
        return size_n * (math.exp(self._rng.gauss(0.0, sd)) if sd > 0 else 1.0)

    def learn_size(self, group: str | None, size_n: float) -> None:
        """Keep a familiarisation trial's extra-force size under its (legend's) group."""
        if group is not None:
            self.sizes.setdefault(group, []).append(self.feel_size(size_n))

    def severity(self, answer: str, size_n: float) -> str | None:
        """The level whose share of the answered group's familiarisation size is nearest (log
        scale); None when that group was never felt."""
        ref = self.sizes.get(ANSWER_GROUP.get(answer, answer))
        if not ref:
            return None
        felt = max(self.feel_size(size_n), 1e-9) / max(sum(ref) / len(ref), 1e-9)
        return min(SEVERITY_SHARE, key=lambda lvl: abs(math.log(felt / SEVERITY_SHARE[lvl])))

    def answer(self, directions: Sequence[float]) -> str:
        """'shoulder', 'elbow' or 'both': the group whose template is nearest."""
        if not self.templates:
            raise HapticError("the trainee has felt no familiarisation trial to answer from")
        felt = self.perceive(directions)

        def distance(group: str) -> float:
            return sum(abs(math.remainder(a - b, 2 * math.pi))
                       for a, b in zip(felt, self._template(group), strict=True))

        best = min(sorted(self.templates), key=distance)
        return GROUP_ANSWER[best]


@dataclass(frozen=True)
class SimulationResult:
    """A simulated training session: the session's trace (its metadata holds the training
    result) and that result."""

    trace: Trace
    result: dict[str, Any]
    simulated_s: float
    severities: list[dict[str, Any]] = field(default_factory=list)

    @property
    def summary(self) -> dict[str, Any]:
        return dict(self.result["summary"])


def _approach(x0: float, y0: float, path: ProbePath, m: TraineeMotion) -> ProbePath:
    """Move from (x0, y0) to the path's start, hold, follow it, settle (one reference path)."""
    ts: list[float] = []
    ps: list[tuple[float, float]] = []
    sx, sy = path.points_m[0]
    n = 20
    for k in range(n + 1):
        tau = k / n
        s = tau ** 3 * (10 - 15 * tau + 6 * tau * tau)
        ts.append(m.approach_s * tau)
        ps.append((x0 + (sx - x0) * s, y0 + (sy - y0) * s))
    t0 = m.approach_s + m.hold_s
    for t, p in zip(path.times_s, path.points_m, strict=True):
        ts.append(t0 + t - path.times_s[0])
        ps.append(p)
    ts.append(ts[-1] + m.settle_s)
    ps.append(ps[-1])
    return ProbePath(path.name, path.description, tuple(ts), tuple(ps))


class _Driver:
    """Ticks the renderer by hand (lockstep device, no waiting) and submits commands."""

    def __init__(self, rd: Renderer, device: SimDevice) -> None:
        self.rd = rd
        self.device = device

    def run(self, cmd: RendererCommand) -> dict[str, Any]:
        req = self.rd.submit(cmd)
        while not req.done.is_set():
            self.rd.tick()
        return req.wait()

    def settle_models(self) -> None:
        """Tick through a pushed model's fade out, swap and fade in."""
        rd = self.rd
        for _ in range(100_000):
            if not rd.pair.swapping:
                return
            rd.tick()

    def follow(self, path: ProbePath, offset: tuple[float, float],
               start_s: float, end_s: float) -> tuple[float, tuple[float, float]]:
        """Perform ``path`` (times from 0); between ``start_s`` and ``end_s`` of it, the
        direction (rad) of the largest force on the handle and the mean force (N, N)."""
        ox, oy = offset
        self.device.perform(lambda t: _robot(path.at(t), ox, oy))
        rd = self.rd
        n = max(1, round(path.duration_s / rd.dt_s))
        best, direction = -1.0, 0.0
        sx = sy = 0.0
        count = 0
        for k in range(n):
            rd.tick()
            t = k * rd.dt_s
            if start_s <= t <= end_s:
                f = math.hypot(rd.fx, rd.fy)
                sx += rd.fx
                sy += rd.fy
                count += 1
                if f > best:
                    best, direction = f, math.atan2(rd.fy, rd.fx)
        return direction, (sx / max(count, 1), sy / max(count, 1))


def _extras(means: Sequence[tuple[float, float]],
            normal: Sequence[Sequence[tuple[float, float]]]) -> list[tuple[float, float]]:
    """Per probe, the mean force minus the unimpaired arm's mean force along the same probe
    (averaged over its familiarisation trials; none felt yet: zero), N."""
    out = []
    for k, (fx, fy) in enumerate(means):
        nx = sum(t[k][0] for t in normal) / len(normal) if normal else 0.0
        ny = sum(t[k][1] for t in normal) / len(normal) if normal else 0.0
        out.append((fx - nx, fy - ny))
    return out


def _extra_directions(means: Sequence[tuple[float, float]],
                      normal: Sequence[Sequence[tuple[float, float]]]) -> list[float]:
    """Per probe, the direction (rad) of the extra force (:func:`_extras`)."""
    return [math.atan2(ey, ex) for ex, ey in _extras(means, normal)]


def _extra_size(means: Sequence[tuple[float, float]],
                normal: Sequence[Sequence[tuple[float, float]]]) -> float:
    """The size of the extra force over the probes (root mean square of each probe's), N."""
    e = _extras(means, normal)
    return math.sqrt(sum(ex * ex + ey * ey for ex, ey in e) / max(1, len(e)))


def _robot(state: tuple[float, float, float, float], ox: float,
           oy: float) -> tuple[float, float, float, float]:
    x, y, vx, vy = state
    return x + ox, y + oy, vx, vy


def simulate(protocol: TrainingProtocol, rule: DirectionRule | None = None,
             motion: TraineeMotion | None = None, rate_hz: int = 1000,
             say: Say = _quiet, environment: Environment | None = None,
             safety: SafetyConfig | None = None) -> SimulationResult:
    """Run ``protocol`` with a simulated trainee on the simulated robot (lockstep, faster than
    real time).

    Parameters
    ----------
    protocol : TrainingProtocol
    rule : DirectionRule, optional
        The trainee's answering rule.
    motion : TraineeMotion, optional
        How the simulated hand moves.
    rate_hz : int, Hz
        The loop's rate.
    say : callable(str), optional
        One line per trial.
    environment : callable, optional
        What the renderer ticks in place of the compiled arms (a simulated remote link).
    safety : SafetyConfig, optional
        The renderer's limits (a link brings its own passivity controller: turn the handle
        port's off).

    Returns
    -------
    SimulationResult
    """
    rule = rule or DirectionRule()
    m = motion or TraineeMotion()
    base = protocol.base()
    url = sim_url(base, "hold", seed=protocol.seed)
    link = RobotLink.open(url)
    try:
        link.handshake(rate_hz, 20)
        rd = Renderer(link, base, base,
                      RendererConfig(rate_hz=rate_hz, state_wait_s=0.05,
                                     realtime_priority=False),
                      safety=safety, clock=VirtualClock(), environment=environment)
        rd.metadata.update({"robot": url, "simulated_trainee": {
            "rule": "nearest familiarisation template of force directions (instructed: the "
                    "mean force beyond the unimpaired arm's along each probe; free "
                    "exploration: the force at its peak)",
            **asdict(rule), **asdict(m)}})
        device = link.port.device
        assert isinstance(device, SimDevice)
        drive = _Driver(rd, device)
        trainee = DirectionTrainee(rule)
        normal: list[list[tuple[float, float]]] = []  # unimpaired arm's mean force per probe
        felt: list[tuple[str | None, list[tuple[float, float]]]] = []
        learned = False
        severities: list[dict[str, Any]] = []
        offset = rd.config.shoulder_offset_m
        rd.start()
        try:
            drive.run(C.TrainStart(protocol))
            while True:
                state = drive.run(C.TrainNext())
                if state["done"]:
                    break
                drive.settle_models()
                act = rd.activities.addressed(Training.kind)
                assert isinstance(act, Training)
                tr = act.session
                trial = tr.current
                assert trial is not None
                directions: list[float] = []
                means: list[tuple[float, float]] = []
                if protocol.instruction == "instructed":
                    for p in tr.paths:
                        x, y = link.state.x - offset[0], link.state.y - offset[1]
                        ref = _approach(x, y, p, m)
                        t0 = m.approach_s + m.hold_s
                        means.append(drive.follow(ref, offset, t0, ref.duration_s)[1])
                    if trial.phase == "familiarisation" and trial.group is None:
                        normal.append(means)
                    directions = _extra_directions(means, normal)
                else:
                    x, y = link.state.x - offset[0], link.state.y - offset[1]
                    wander = explore(x, y, m.explore_amplitude_m,
                                     seed=protocol.seed * 100_003 + trial.index)
                    n = round(m.explore_s * rate_hz)
                    ts = tuple(k / rate_hz for k in range(0, n + 1, 5))
                    path = ProbePath("explore", "free exploration", ts,
                                     tuple(wander(t)[:2] for t in ts))
                    directions.append(drive.follow(path, offset, 0.0, path.duration_s)[0])
                if trial.phase == "familiarisation":
                    if protocol.instruction == "instructed":
                        felt.append((trial.group, means))
                    else:
                        trainee.learn(trial.group, directions)
                    say(f"trial {trial.index + 1}/{len(tr.trials)}: felt {trial.legend}")
                else:
                    if protocol.instruction == "instructed" and not learned:
                        # the whole familiarisation is felt: templates relative to the
                        # unimpaired arm, whatever order the arms came in
                        for group, ms in felt:
                            trainee.learn(group, _extra_directions(ms, normal))
                            trainee.learn_size(group, _extra_size(ms, normal))
                        learned = True
                    said = trainee.answer(directions)
                    if protocol.instruction == "instructed":
                        severities.append({
                            "trial": trial.index, "group": trial.group, "severity": trial.severity,
                            "answer": said, "answered_severity":
                                trainee.severity(said, _extra_size(means, normal)),
                            "extra_force_n": round(_extra_size(means, normal), 4)})
                    reply = drive.run(C.TrainAnswer(said))
                    rec = tr.records[-1]
                    say(f"trial {trial.index + 1}/{len(tr.trials)}: answered {rec['answer']} "
                        f"({'right' if rec['correct'] else 'wrong'})")
                    if reply["done"]:
                        break
        finally:
            trace = rd.finish()
    finally:
        link.close()
    results = trace.metadata.get("training") or []
    if not results:
        raise HapticError("the simulated training session recorded no result")
    return SimulationResult(trace, results[-1], rd.t_s, severities)
