"""The two arms behind the handle and the fades between them (:class:`ModelPair`).

Model A (before) and model B (after) are compiled once, outside the loop, into two
:class:`fieldbank.sim.ArmSim`; the loop ticks both with the same handle state and blends their
forces, F = g · ((1 − w) F_A + w F_B):

* the blend w follows a raised-cosine ramp (:class:`Ramp`) over ``crossfade_s`` on each switch,
  so the force has no step;
* the gain g fades out over ``push_fade_s`` before a pushed pair is swapped in, and back in
  after it (also raised-cosine); arming, faults and disarming set it too (:mod:`haptic.renderer`).

What the pair was told about its models (ids, :class:`~haptic.modelinfo.ModelInfo`) goes into the
trace's metadata when the pair is swapped in.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, TypeAlias

from fieldbank.armkernel import ArmPair
from fieldbank.errors import UnreachableError
from fieldbank.haptic.errors import CommandError
from fieldbank.haptic.modelinfo import ModelIds, ModelInfoPair, to_wire
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.sim import ArmSim, CouplingConfig

#: Compiled arms A (before) and B (after), built outside the loop.
SimPair: TypeAlias = ArmPair


class Ramp:
    """Raised-cosine ramp from its value to ``end`` over ``n`` ticks (:meth:`go`)."""

    __slots__ = ("end", "k", "n", "start", "value")

    def __init__(self, value: float) -> None:
        self.value = self.start = self.end = value
        self.k = self.n = 0

    def go(self, end: float, n: int) -> None:
        self.start = self.value
        self.end = end
        self.k = 0
        self.n = max(1, n)

    def step(self) -> float:
        if self.k < self.n:
            self.k += 1
            s = self.k / self.n
            self.value = self.start + (self.end - self.start) * (0.5 - 0.5 * math.cos(math.pi * s))
        return self.value

    @property
    def moving(self) -> bool:
        return self.k < self.n

    def set(self, value: float) -> None:
        self.value = self.start = self.end = value
        self.k = self.n = 0


def build_sim(params: ArmParams, dt_s: float, coupling: CouplingConfig | None = None) -> ArmSim:
    """Compile a model for the loop (slow part, done outside the loop)."""
    return ArmSim(Arm.from_params(params), dt_s=dt_s, coupling=coupling)


#: What the loop ticks in place of a compiled arm: built from a model, the loop's period and
#: the coupling, it answers ``tick(x, y, vx, vy) -> (fx, fy)``, keeps a ``state`` (q1, q2,
#: qd1, qd2) and can be ``reset``/``reset_at_hand`` like :class:`fieldbank.sim.ArmSim` (the
#: remote link, :mod:`haptic.remote`, puts a distant patient there). It may raise
#: :class:`~haptic.errors.CommandError` to refuse a model (a push).
Environment = Callable[[ArmParams, float, CouplingConfig | None], ArmSim]


class ModelPair:
    """Arms A and B, the blend between them and the gain around a swap.

    Parameters
    ----------
    before, after : ArmParams
    dt_s : float, s
        The loop's period.
    crossfade_s, push_fade_s : float, s
        Ramp of an A↔B switch; fade out before and in after a swap.
    coupling : CouplingConfig, optional
    compiled : bool
        Tick both arms and the blend in one compiled call (:class:`fieldbank.armkernel.ArmPair`);
        False: the plain-Python reference tick of each arm.
    environment : callable, optional
        Builds what is ticked for each model instead of a compiled arm (:data:`Environment`:
        the remote link); ticked one after the other like the reference path.
    """

    def __init__(self, before: ArmParams, after: ArmParams, dt_s: float, crossfade_s: float,
                 push_fade_s: float, coupling: CouplingConfig | None = None,
                 compiled: bool = True, environment: Environment | None = None) -> None:
        self.dt_s = dt_s
        self.coupling = coupling
        self.compiled = compiled
        self.environment = environment
        self.crossfade_ticks = round(crossfade_s / dt_s)
        self.push_fade_ticks = round(push_fade_s / dt_s)
        self.params = (before, after)
        #: The session's models (the clinician's choice), whatever a training renders now.
        self.session_params = self.params
        self.sims = self.compile(before, after)
        self.blend = Ramp(0.0)
        self.gain = Ramp(0.0)
        #: compiled models waiting for the gain to reach zero, with their ids and descriptions,
        #: and whether they become the session's models
        self.pending: tuple[SimPair, tuple[ArmParams, ArmParams], ModelIds | None,
                            ModelInfoPair | None, bool] | None = None

    def compile(self, before: ArmParams, after: ArmParams) -> SimPair:
        """Both models compiled for this loop's period (slow: call outside the loop)."""
        make = self.environment
        if make is None:
            return ArmPair(Arm.from_params(before), Arm.from_params(after), self.dt_s,
                           self.coupling, self.compiled)
        return ArmPair.of(make(before, self.dt_s, self.coupling),
                          make(after, self.dt_s, self.coupling))

    def reset_at(self, hx: float, hy: float) -> None:
        """Both arms at rest with the hand at (hx, hy), m, shoulder frame (at their rest
        posture where that is not a number or out of reach)."""
        for sim in self.sims:
            try:
                if math.isfinite(hx) and math.isfinite(hy):
                    sim.reset_at_hand(hx, hy)
                else:
                    sim.reset()
            except (UnreachableError, ValueError):
                sim.reset()

    def crossfade(self, weight: float) -> None:
        """Ramp the blend to ``weight`` (0 = A, 1 = B) over ``crossfade_s``."""
        self.blend.go(weight, self.crossfade_ticks)

    def fade(self, gain: float) -> None:
        """Ramp the gain to ``gain`` over ``push_fade_s``."""
        self.gain.go(gain, self.push_fade_ticks)

    def queue(self, sims: SimPair, params: tuple[ArmParams, ArmParams],
              model_ids: ModelIds | None, model_info: ModelInfoPair | None,
              session: bool = True) -> None:
        """Hold compiled models for :meth:`swap` (``session``: they become the session's
        models; False: a training arm, rendered but not the session's)."""
        self.pending = (sims, params, model_ids, model_info, session)

    def tick(self, x: float, y: float, vx: float, vy: float) -> tuple[float, float, bool]:
        """One tick of both arms with the handle at (x, y) m moving at (vx, vy) m/s, shoulder
        frame, after this tick's blend and gain steps (the compiled call blends as it ticks):
        the force on the handle F = g · ((1 − w) F_A + w F_B), N, and False when an arm
        diverged (its force not a number; the force is then 0). A state that is not a number
        leaves the arms as they are and gives 0."""
        w = self.blend.step()
        g = self.gain.step()
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(vx)
                and math.isfinite(vy)):
            return 0.0, 0.0, True
        try:
            mx, my, fa_x, fa_y, fb_x, fb_y = self.sims.tick(x, y, vx, vy, w, g)
        except (ArithmeticError, ValueError):  # overflow inside a diverging arm
            return 0.0, 0.0, False
        if math.isfinite(fa_x + fa_y) and math.isfinite(fb_x + fb_y):
            return mx, my, True
        return 0.0, 0.0, False

    def current(self) -> tuple[SimPair, tuple[ArmParams, ArmParams]]:
        """The pair rendered now, to be put back later (refused while pushed models wait to be
        swapped in: they would be lost)."""
        if self.pending is not None:
            raise CommandError("pushed models are being swapped in")
        return self.sims, self.params

    @property
    def swapping(self) -> bool:
        """True while pushed models fade out, wait to be swapped or fade in."""
        return self.pending is not None or self.gain.moving

    @property
    def swap_due(self) -> bool:
        """Pushed models wait and the gain has reached zero."""
        return self.pending is not None and self.gain.value == 0.0 and not self.gain.moving

    def swap(self, metadata: dict[str, Any]) -> None:
        """Put the pending models in place; the session's models' ids and descriptions replace
        those in the trace's ``metadata`` (a training arm's do not)."""
        assert self.pending is not None
        sims, params, ids, info, session = self.pending
        self.pending = None
        self.sims = sims
        self.params = params
        if not session:
            return
        self.session_params = params
        if ids:
            metadata["model_ids"] = dict(ids)
        else:
            metadata.pop("model_ids", None)
        if info:
            metadata["model_info"] = to_wire(info)
        else:
            metadata.pop("model_info", None)
