"""How sure the model before a plan is: the fit behind it, the maps it used, its samples.

A plan's prediction is checked against maps measured after it
(:mod:`fieldbank.interventions.realised`); what the check may lay on the plan depends on what
is known about the model the plan was applied to:

* :class:`FitSpread` - the fit's parameter samples written into the model before (its
  uncertainty, carried into the realised fraction's SE), the parameters the fit did not
  identify or held at a guess, and the maps it used (:class:`Footprint`: where and how each
  was measured; a later map measured like none of them may misfit because the model does not
  describe the arm there, not because of the plan);
* :func:`first_session_se` - what the first session's own noise allows along the predicted
  change: the floor of the SE's fit part.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fieldbank.errors import ParameterError
from fieldbank.fitting.problem import map_sd
from fieldbank.fitting.uncertainty import FitSamples
from fieldbank.maps import FieldMap, model_map_like
from fieldbank.model import Arm, FloatArray
from fieldbank.params import ArmParams

#: A later map is "like" a map the fit used when it has the same kind, a hand velocity within
#: this much (m/s) and every position within :data:`COVER_DISTANCE_M` of one of its positions.
COVER_SPEED_M_PER_S = 0.05
COVER_DISTANCE_M = 0.01


@dataclass(frozen=True, eq=False)
class Footprint:
    """Where and how a map the fit used was measured: kind, hand velocity (m/s), positions
    (N, 2) m."""

    kind: str
    velocity_m_per_s: tuple[float, float]
    positions_m: FloatArray
    #: The map itself (its sd sets what the first session can tell: :func:`first_session_se`).
    measured: FieldMap | None = None

    @classmethod
    def of(cls, m: FieldMap) -> Footprint:
        return cls(m.kind, m.velocity_m_per_s, np.asarray(m.positions_m, dtype=float), m)

    def covers(self, m: FieldMap) -> bool:
        """``m`` was measured like this map: same kind and velocity, positions among its."""
        if m.kind != self.kind or math.dist(m.velocity_m_per_s,
                                            self.velocity_m_per_s) > COVER_SPEED_M_PER_S:
            return False
        d = np.linalg.norm(m.positions_m[:, None, :] - self.positions_m[None, :, :], axis=2)
        return bool(np.all(d.min(axis=1) <= COVER_DISTANCE_M))


@dataclass(frozen=True, eq=False)
class FitSpread:
    """How sure the model before is: the fit's parameter samples written into it, the
    parameters the fit did not identify, and why samples are missing when they are.

    ``samples`` empty: the SE counts the later maps' noise only (``note`` says why).
    """

    fit_id: int | None = None
    samples: tuple[ArmParams, ...] = ()
    unidentified: tuple[str, ...] = ()
    varied: frozenset[str] = frozenset()
    held: tuple[str, ...] = ()
    note: str = "the model before is not a fitted model: no fit uncertainty to carry"
    #: The maps the fit used (None: no fit lies behind the model, which is taken as it is).
    footprints: tuple[Footprint, ...] | None = None

    def covers(self, m: FieldMap) -> bool:
        """The model before was fitted to a map measured like ``m`` (always, without a fit):
        where it was not, a misfit may be the model's, not a change."""
        return self.footprints is None or any(f.covers(m) for f in self.footprints)

    @classmethod
    def from_report(cls, fit_id: int, report: Mapping[str, Any], before: ArmParams,
                    same_model: bool, fitted_model_id: int | None = None,
                    fit_maps: Sequence[FieldMap] = ()) -> FitSpread:
        """From a stored fit report (:meth:`fieldbank.fitting.ArmFitter.report`) and the maps
        the fit used (none given: no later map counts as measured like them)."""
        unid = tuple(str(u.get("name")) for u in report.get("unidentified", [])
                     if isinstance(u, Mapping))
        held = tuple(str(h) for h in report.get("held_at_unimpaired", []) or [])
        prints = tuple(Footprint.of(m.as_arm_on_handle()) for m in fit_maps)
        found = FitSamples.from_report(report)
        if found is None:
            return cls(fit_id, (), unid, frozenset(), held,
                       f"fit {fit_id} stored no parameter samples (refit to get them): the SE "
                       "counts the later maps' noise only", prints)
        if not same_model:
            return cls(fit_id, (), unid, frozenset(), held,
                       f"the model before is derived from fitted model {fitted_model_id} by "
                       "earlier plans: the SE counts the later maps' noise only")
        spread = np.ptp(found.values, axis=0) if found.values.size else np.zeros(0)
        varied = frozenset(n for n, s in zip(found.names, spread, strict=True) if s > 0)
        return cls(fit_id, tuple(found.params(before)), unid, varied, held,
                   f"{found.values.shape[0]} parameter samples of fit {fit_id}", prints)


NO_FIT = FitSpread()


def arm_like(compiled: Arm, p: ArmParams) -> Arm:
    """The compiled arm of ``p``, sharing ``compiled``'s geometry when only muscle values
    differ."""
    try:  # a sample or a plan changes muscle values only: the geometry is compiled once
        return compiled.with_muscles(p)
    except ParameterError:
        return Arm.from_params(p)


def whitened_change(arm_b: Arm, arm_x: Arm, maps: Sequence[FieldMap]) -> float:
    """Whitened size (sd, each map's own sd) of the change from ``arm_b`` to ``arm_x``."""
    total = 0.0
    for raw in maps:
        m = raw.as_arm_on_handle()
        sd = map_sd(m).reshape(m.values.shape)
        d = model_map_like(arm_x, m).values - model_map_like(arm_b, m).values
        total += float(np.sum((d / sd) ** 2))
    return math.sqrt(total)


def first_session_se(spread: FitSpread, before: ArmParams, after: ArmParams) -> float | None:
    """1/S₀: the SE the first session's maps allow along the predicted change from ``before``
    to ``after`` (S₀ its whitened size on them, each map's own sd;
    :mod:`fieldbank.interventions.realised`); None when the maps the fit used are not known or
    do not see the change."""
    maps = [f.measured for f in spread.footprints or () if f.measured is not None]
    if not maps:
        return None
    arm_b = Arm.from_params(before)
    try:
        s0 = whitened_change(arm_b, arm_like(arm_b, after), maps)
    except (ParameterError, ValueError):
        return None
    return 1.0 / s0 if s0 > 0 else None
