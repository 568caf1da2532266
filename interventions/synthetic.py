"""Seeded synthetic patients for checking predictions: the truth of a plan's effect is known.

Used by the coverage test of the realised fraction (``tests/test_validate_calibration.py``)
and by the false-alarm benchmark (``benchmarks/bench_validate.py``); not patient data.

A patient (:func:`cohort`) has one muscle group hypertonic - both components, or the stretch
reflex alone (a dynamic-only, spastic group) - at a severity level of the one scale, a body of
its own (55-95 kg, 1.55-1.90 m, right or left arm), and was given botulinum toxin A into that
group (100-200 onabotulinumtoxinA units, seen 3-8 weeks later). Its first session is measured
with one of :data:`MAP_SETS`, the model before is fitted to it (the fit's parameter samples
travel with it, :class:`~fieldbank.interventions.spread.FitSpread`), and a later session is
measured from the truth with a chosen fraction of the toxin's predicted effect (the catalogue's
``emax`` scaled, so the force change is exactly that fraction), with the same map set at the
same positions (the protocol repeated) or at new ones, and new noise. Noise: each value's sd
is ``noise`` × the size of the value at its position
(:func:`fieldbank.fitting.problem.relative_scale`), stored with the map.

Seeds and positions are the cohort's own (:data:`COHORT_SEED`), apart from those of the
project's other tests and of the shipped samples.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from datetime import date, timedelta

import numpy as np

from fieldbank.evaluate.severity import synthesize
from fieldbank.fitting import ArmFitter
from fieldbank.fitting.problem import relative_scale
from fieldbank.fitting.synthetic import MOVE_DIRECTION, scattered_positions
from fieldbank.interventions.catalogue import Botulinum
from fieldbank.interventions.plan import Plan
from fieldbank.interventions.spread import FitSpread
from fieldbank.interventions.validate import LaterSession, SessionCheck, check_session
from fieldbank.maps import FieldMap, postural_map, stiffness_map
from fieldbank.model import Arm, FloatArray
from fieldbank.params import GROUPS, ArmParams

#: The cohort's own seed (positions, noise, bodies, doses).
COHORT_SEED = 24_240
#: Positions of the postural map and of the stiffness maps.
N_POSTURAL = 25
N_STIFFNESS = 9
#: The day the plan is given (the first session's day).
GIVEN_ON = date(2024, 3, 4)
LEVELS = ("mild", "moderate", "severe")


@dataclass(frozen=True)
class MapSet:
    """A measurement protocol: a postural map, a static stiffness map and stiffness maps at
    these hand velocities (m/s, shoulder frame)."""

    name: str
    description: str
    moving_m_per_s: tuple[tuple[float, float], ...]


def _along(speed: float) -> tuple[float, float]:
    ux, uy = MOVE_DIRECTION
    n = math.hypot(ux, uy)
    return (speed * ux / n, speed * uy / n)


#: The protocols: static maps only (they cannot see a change of the stretch reflex), one slow
#: moving map in one direction (sees little of it), and moving maps both ways at 1 m/s.
MAP_SETS: dict[str, MapSet] = {
    "static": MapSet("static", "postural + static stiffness", ()),
    "slow": MapSet("slow", "+ stiffness moving at 0.5 m/s, one direction", (_along(0.5),)),
    "moving": MapSet("moving", "+ stiffness moving at 1 m/s, both directions",
                     (_along(1.0), _along(-1.0))),
}


@dataclass(frozen=True)
class CheckPatient:
    """One synthetic patient of the cohort (module docstring)."""

    code: str
    group: str
    target: str
    level: str
    truth: ArmParams
    base: ArmParams
    units: float
    weeks: float
    seed: int

    @property
    def plan(self) -> Plan:
        """The plan given: botulinum into the hypertonic group, seen ``weeks`` later."""
        return Plan.of(Botulinum({self.group: self.units}, weeks_since=self.weeks),
                       label=f"botulinum {self.units:g} U into {self.group}")

    def truth_after(self, fraction: float) -> ArmParams:
        """The truth at the later session with ``fraction`` of the predicted effect."""
        steps = tuple(dataclasses.replace(s, emax=s.emax * fraction)
                      if isinstance(s, Botulinum) else s for s in self.plan.steps)
        return Plan(steps).apply(self.truth)


def cohort(n: int, seed: int = COHORT_SEED,
           contracture: bool = False) -> tuple[CheckPatient, ...]:
    """``n`` patients: the six groups in turn, each severity level, every fourth one with a
    reflex-only (dynamic) impairment. ``contracture``: the hypertonic group is also 5-15 mm
    short (its slack length, drawn uniform; the rest of the cohort as without it)."""
    out = []
    for i in range(n):
        rng = np.random.default_rng([seed, i])
        g = GROUPS[i % len(GROUPS)]
        level = LEVELS[(i // len(GROUPS)) % len(LEVELS)]
        target = f"{g}:dynamic" if i % 4 == 3 else g
        base = ArmParams.from_anthropometry(float(rng.uniform(55.0, 95.0)),
                                            float(rng.uniform(1.55, 1.90)),
                                            "left" if rng.uniform() < 0.3 else "right")
        truth = synthesize({target: level}, base)
        units = float(np.round(rng.uniform(100.0, 200.0), 0))
        weeks = float(np.round(rng.uniform(3.0, 8.0), 1))
        if contracture:
            short = float(np.random.default_rng([seed, i, 5]).uniform(0.005, 0.015))
            truth = truth.with_group(g, slack_offset_m=-short)
        out.append(CheckPatient(f"CHK-{i:03d}", g, target, level, truth, base, units, weeks,
                                seed + 97 * i))
    return tuple(out)


def measure(params: ArmParams, map_set: MapSet, noise: float, rng: np.random.Generator,
            positions: tuple[FloatArray, FloatArray] | None = None) -> list[FieldMap]:
    """The maps of ``map_set`` measured on the arm ``params`` with ``noise``; positions drawn
    from ``rng`` unless given (postural, stiffness)."""
    arm = Arm.from_params(params)
    pp, ps = positions if positions is not None else (
        scattered_positions(arm, N_POSTURAL, rng), scattered_positions(arm, N_STIFFNESS, rng))
    clean = [postural_map(arm, pp), stiffness_map(arm, ps)]
    clean += [stiffness_map(arm, ps, v) for v in map_set.moving_m_per_s]
    out = []
    for m in clean:
        sd = np.broadcast_to(relative_scale(m.values)[(...,) + (None,) * (m.values.ndim - 1)],
                             m.values.shape) * noise
        out.append(FieldMap(kind=m.kind, positions_m=m.positions_m,
                            values=m.values + rng.normal(size=m.values.shape) * sd, sd=sd,
                            velocity_m_per_s=m.velocity_m_per_s,
                            source=f"synthetic check patient, {100 * noise:g}% noise"))
    return out


@dataclass(frozen=True, eq=False)
class Fitted:
    """The model before of a patient: fitted to its first session, with the fit's samples."""

    patient: CheckPatient
    map_set: str
    noise: float
    before: ArmParams
    spread: FitSpread
    status: str
    #: The first session's positions (postural, stiffness), m.
    positions: tuple[FloatArray, FloatArray]


def fit_first_session(p: CheckPatient, map_set: str, noise: float,
                      replicates: int = 40,
                      fit_kinds: tuple[str, ...] = ("km", "alpha", "beta")) -> Fitted:
    """Measure the first session with ``map_set`` and fit the model before to it (the
    parameter kinds ``fit_kinds``)."""
    rng = np.random.default_rng([p.seed, 1, round(noise * 1000), _key(map_set)])
    maps = measure(p.truth, MAP_SETS[map_set], noise, rng)
    fit = ArmFitter(seed=p.seed % 10_000, replicates=replicates,
                    fit=fit_kinds).fit(maps, p.base)
    spread = FitSpread.from_report(1, fit.report(), fit.params_, True, 1, maps)
    return Fitted(p, map_set, noise, fit.params_, spread, fit.status_,
                  (maps[0].positions_m, maps[1].positions_m))


def later_session(fitted: Fitted, fraction: float, repeat: int = 0,
                  new_positions: bool = False) -> LaterSession:
    """The later session: the truth with ``fraction`` of the predicted effect, measured with
    the first session's map set and positions (the protocol repeated; ``new_positions``: at
    positions of its own) and with new noise (``repeat`` draws another)."""
    p = fitted.patient
    rng = np.random.default_rng([p.seed, 2, round(fitted.noise * 1000),
                                 _key(fitted.map_set), round(fraction * 1000), repeat])
    maps = measure(p.truth_after(fraction), MAP_SETS[fitted.map_set], fitted.noise, rng,
                   None if new_positions else fitted.positions)
    day = GIVEN_ON + timedelta(days=round(7 * p.weeks))
    return LaterSession(f"after-{repeat}", day, tuple(enumerate(maps, 1)))


def check(fitted: Fitted, fraction: float, repeat: int = 0,
          new_positions: bool = False) -> SessionCheck:
    """``fieldbank validate``'s check of the patient's plan against a later session
    (:func:`later_session`)."""
    plan = fitted.patient.plan
    return check_session(fitted.before, plan, plan.apply(fitted.before), GIVEN_ON,
                         later_session(fitted, fraction, repeat, new_positions),
                         spread=fitted.spread)


def _key(name: str) -> int:
    return sum(ord(c) * 31**k for k, c in enumerate(name)) % 1_000_003
