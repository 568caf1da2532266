"""What the maps do not identify, and the fit's effective number of parameters.

(The parameters' SDs and intervals: :mod:`fieldbank.fitting.uncertainty`.)

Effective parameters. At the optimum the Gauss-Newton information is H = JᵀJ + w·diag(1/σ²),
with J the Jacobian of the whitened residuals and the prior (weight w, SDs σ) added;
p_eff = trace(JᵀJ H⁻¹) is the effective number of parameters and s² = χ²_data / (M - p_eff)
the residual variance per degree of freedom (s² = 1 when M ≤ p_eff).

Identifiability. In units of each parameter's prior SD the data information is F = S JᵀJ S
(S = diag σ). Against a reference prior of weight 1 the relative posterior SD is
ρ_k = √[(F + I)⁻¹]_kk: near 0 when the maps pin the parameter down, 1 when they say nothing.
A parameter with ρ_k > :data:`UNIDENTIFIED_RATIO` is reported as not identified, with the
reason: its column of J is (nearly) zero (and why: static maps, a muscle never lengthened, a
muscle slack everywhere, a zero gain), or it trades off with other parameters (posterior
correlation above :data:`TRADE_OFF_CORRELATION`), or the maps barely constrain it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fieldbank.fitting.problem import FitProblem
from fieldbank.fitting.uncertainty import spd_inverse
from fieldbank.model import FloatArray
from fieldbank.params import GROUPS

UNIDENTIFIED_RATIO = 0.5
TRADE_OFF_CORRELATION = 0.9
#: A column whose information (in prior-SD units) is below this counts as zero.
ZERO_INFORMATION = 1e-8


@dataclass(frozen=True)
class Unidentified:
    """One parameter the maps do not identify."""

    name: str
    reason: str
    posterior_to_prior_sd: float

    def to_dict(self) -> dict[str, object]:
        return {"name": self.name, "reason": self.reason,
                "posterior_to_prior_sd": self.posterior_to_prior_sd}


@dataclass(frozen=True)
class Identification:
    relative_sd: FloatArray  # ρ_k (nan where not fitted)
    unidentified: tuple[Unidentified, ...]
    residual_variance: float
    effective_parameters: float


def _reflex_cause(problem: FitProblem, theta: FloatArray, i: int, kind: str) -> str:
    g = GROUPS[i]
    pair = "reflex gains β and α" if kind in ("alpha", "beta") else kind
    moving = np.abs(problem.c).sum() > 0
    if not moving:
        return (f"{pair} of {g} not identifiable: all stiffness maps are static (velocity 0), "
                "where the reflex force is zero")
    if not np.any(problem.c[:, i] > 0):
        return (f"{pair} of {g} not identifiable: no measured movement lengthens {g}, so its "
                "stretch reflex never fires in these maps")
    if kind == "beta" and theta[6 + i] <= 1e-9:
        return f"β of {g} not identifiable: the fitted α of {g} is 0, so the gain has no effect"
    if kind == "alpha" and theta[12 + i] <= 1e-9:
        return f"α of {g} not identifiable: the fitted β of {g} is 0, so the reflex is silent"
    return f"{pair} of {g} not identifiable: the reflex of {g} does not change any measured value"


def _zero_cause(problem: FitProblem, theta: FloatArray, k: int) -> str:
    s = problem.space
    kind = s.kinds[k]
    if kind in ("alpha", "beta"):
        return _reflex_cause(problem, theta, k % 6, kind)
    if kind == "km":
        g = GROUPS[k]
        return (f"Km of {g} not identifiable: {g} is slack (shorter than its rest length) at "
                "every measured position, so its passive force is zero there")
    if kind == "slack":
        g = s.names[k].rpartition("_")[2]
        return (f"slack length of {g} not identifiable: {g} is slack at every measured "
                "position (or its Km is 0), so no measured value shows where its passive "
                "force starts; postures that stretch it would")
    return f"{s.names[k]} not identifiable: no measured value depends on it"


def identify(problem: FitProblem, theta: FloatArray) -> Identification:
    """Identifiability and effective parameters at ``theta`` (see module docstring)."""
    s = problem.space
    fit = np.flatnonzero(s.fitted)
    jac = problem.jacobian(theta)[:, fit]
    r = problem.residuals(theta)
    sig = s.prior_sd[fit]
    jtj = jac.T @ jac
    h = jtj + np.diag(s.prior_weight / sig**2)
    h_inv = spd_inverse(h, sig)  # no pseudo-inverse cut-off (fieldbank.fitting.uncertainty)
    m = r.size
    p_eff = float(np.trace(jtj @ h_inv))
    s2 = float(r @ r) / (m - p_eff) if m > p_eff + 1e-9 else 1.0

    fisher = jtj * np.outer(sig, sig)
    post = np.linalg.inv(fisher + np.eye(fit.size))
    rel = np.full(s.size, np.nan)
    rel[fit] = np.sqrt(np.diag(post))
    dpost = np.sqrt(np.diag(post))
    corr = post / np.outer(dpost, dpost)
    flagged: list[Unidentified] = []
    for a, k in enumerate(fit):
        if rel[k] <= UNIDENTIFIED_RATIO:
            continue
        if fisher[a, a] < ZERO_INFORMATION:
            reason = _zero_cause(problem, theta, int(k))
        else:
            partners = [s.names[fit[b]] for b in range(fit.size)
                        if b != a and abs(corr[a, b]) > TRADE_OFF_CORRELATION]
            if partners:
                worst = max(abs(corr[a, b]) for b in range(fit.size) if b != a)
                reason = (f"{s.names[k]} not identifiable: it trades off with "
                          f"{', '.join(partners)} (posterior correlation up to {worst:.2f}); "
                          "the maps fix only their combination")
            else:
                reason = (f"{s.names[k]} not identifiable: the maps barely constrain it "
                          f"(posterior SD {100 * rel[k]:.0f}% of the prior SD)")
        flagged.append(Unidentified(s.names[k], reason, float(rel[k])))
    return Identification(rel, tuple(flagged), s2, p_eff)
