"""Which candidate arm made a recorded trace (seed, "Future directions": the likelihood of the
recorded forces given the recorded motion names the impaired group and its severity).

An :class:`Observation` is one recorded probing motion: the handle's positions and velocities
and the force the arm put on the handle, in the shoulder frame. Each candidate predicts the
force *for the recorded motion* - with its velocity, so the stretch reflex counts:

* ``replay`` (default) - the recorded handle motion drives the candidate's virtual arm through
  the virtual coupling, tick by tick (:class:`fieldbank.sim.ArmSim`), from rest at the first
  sample (or where a renderer put it): for a rendered trace this reproduces the force the
  renderer computed, arm inertia and coupling included; for a measured one it is the model of a
  hand holding the arm through a stiff, damped coupling;
* ``rigid`` - a hand holding the rigid arm: the endpoint force at the recorded position and
  velocity plus the arm's inertia (:func:`fieldbank.dynamics.hand_inertial_force`), the
  acceleration from a Savitzky-Golay derivative of the recorded velocity over
  :data:`ACCELERATION_WINDOW_S` - for traces measured on a patient;
* ``static`` - the kinematic probe of :mod:`fieldbank.evaluate.probing`: the endpoint force at
  the recorded position and velocity (inertia left out).

Predictions are saturated at the renderer's force limit when the observation says it had one.

Likelihood (the noise model of :mod:`fieldbank.evaluate.design`): the recorded force is the
prediction plus Gaussian noise of SD σ per axis that decorrelates over τ, so each sample k
counts Δt_k/τ times::

    log L_c = −Σ_k (Δt_k/τ) |F_rec,k − F_c,k|² / (2σ²)

summed over the observations. The posterior over candidates is prior × likelihood, normalised;
the group's probability sums its severities.

**Does any candidate explain the trace?** Under the noise model the best candidate's whitened
residual Q = Σ_k (Δt_k/τ) |F_rec,k − F_c,k|²/σ² has mean 2 Σ_k Δt_k/τ and a variance that
follows from the noise's correlation (an Ornstein-Uhlenbeck process of time constant τ/2,
:func:`with_force_noise`: ρ(Δt) = e^(−2|Δt|/τ)): Var Q = 4 Σ_k Σ_l (Δt_k/τ)(Δt_l/τ) ρ²(t_k − t_l).
Q is compared with the χ² distribution of that mean and variance (Satterthwaite); below the
p-value :data:`FIT_LEVEL` no candidate explains the trace within the noise - an arm outside
the candidates (a flexor group alone among joint groups), a noise larger than assumed, or a
recording that is not what it claims to be - and the read-out says so (``explains``).

**Calibration: model error is not noise.** The likelihood counts one independent sample per τ,
which is right for sensor noise but not for the part of the residual the candidates cannot
produce: a patient between two candidates' severities, or outside them, leaves a systematic
residual, smooth over the whole probe, and the likelihood ratio between two wrong candidates
then grows with the recording's length without meaning anything. The classifier estimates
that model error from the best candidate's residual beyond what the noise explains - the
excess over :data:`MODEL_ERROR_SDS` standard deviations of Q, so that the noise's own scatter
is not taken for model error: σ_m² = σ² · max(0, Q − E[Q] − 2 √Var Q) / E[Q] per axis - and
counts it as a noise correlated over the whole recording (the same arm's mismatch in every
probe: one independent sample in all): the noise's variance-time product σ²τ gains σ_m² D (D
the recording's duration), which divides the log-likelihoods by T = 1 + (σ_m²/σ²) · n_eff
(n_eff = Σ Δt/τ) - a temperature set by the trace itself. A trace one candidate explains within
the noise keeps T = 1 and its full confidence. (Counting one independent sample per probe
instead was measured too: it left more confident wrong answers.) A global temperature
(:data:`TEMPERATURE`) multiplies it; ``benchmarks/bench_probe_design.py --trials`` measures
the reliability (stated probability against observed accuracy) with and without both on
simulated patients on and between the candidates' severities at several noise levels
(``docs/probing.md``). ``log_likelihood`` stays the stated likelihood;
``raw_posterior`` is its posterior before the correction.

The classification designs the next probe - the stroke carrying the most information about
the candidates still in play, with the posterior as the prior
(:func:`fieldbank.evaluate.design.design`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.signal import savgol_filter
from scipy.stats import chi2

from fieldbank.dynamics import hand_inertial_force
from fieldbank.errors import ParameterError, UnreachableError
from fieldbank.evaluate.design import (
    Candidate,
    NoiseModel,
    Perception,
    ProbeDesign,
    ProbeLimits,
    check_candidates,
    check_prior,
    design,
    saturate,
)
from fieldbank.evaluate.observation import Observation
from fieldbank.model import Arm, FloatArray
from fieldbank.probechoices import DEFAULT_PREDICTOR, PREDICTORS
from fieldbank.sim import ArmSim

#: Window of the Savitzky-Golay derivative giving the ``rigid`` predictor's accelerations, s.
ACCELERATION_WINDOW_S = 0.025
#: Stop suggesting probes when the most probable candidate has at least this probability.
STOP_PROBABILITY = 0.99
#: Candidates below this posterior are out of play for the next probe.
REMAINING_PROBABILITY = 1e-3
#: p-value of the best candidate's residual below which no candidate explains the trace.
FIT_LEVEL = 1e-3
#: Standard deviations of the fit statistic the noise is allowed before the rest of the
#: residual counts as model error (module docstring).
MODEL_ERROR_SDS = 2.0
#: Global temperature on the (model-error corrected) log-likelihoods: 1, the value the
#: reliability benchmark supports (docs/probing.md, "Are the probabilities right?").
TEMPERATURE = 1.0
#: Replay accepts sample periods within this fraction of the median period.
RATE_TOLERANCE = 0.25

def recorded_accelerations(obs: Observation) -> FloatArray:
    """Hand accelerations (T, 2), m/s²: a Savitzky-Golay derivative (quadratic, window
    :data:`ACCELERATION_WINDOW_S`) of the recorded velocity, which smooths what differencing
    would amplify."""
    dt = float(np.median(np.diff(obs.times_s)))
    n = len(obs.times_s)
    win = max(5, round(ACCELERATION_WINDOW_S / dt) | 1)
    if win > n:
        win = n if n % 2 else n - 1
    if win < 3:
        return np.asarray(np.gradient(obs.velocities_m_per_s, obs.times_s, axis=0), dtype=float)
    return np.asarray(savgol_filter(obs.velocities_m_per_s, win, min(2, win - 1), deriv=1,
                                    delta=dt, axis=0), dtype=float)


def predict_observation(arm: Arm, obs: Observation,
                        predictor: str = DEFAULT_PREDICTOR) -> FloatArray:
    """The force (T, 2), N, the arm puts on the handle for the recorded motion of ``obs``."""
    if predictor in ("static", "rigid"):
        try:
            f = arm.endpoint_force(obs.positions_m, obs.velocities_m_per_s)
            if predictor == "rigid":
                f = f + hand_inertial_force(arm, obs.positions_m, obs.velocities_m_per_s,
                                            recorded_accelerations(obs))
        except UnreachableError as exc:
            raise UnreachableError(f"{obs.source or obs.name}: {exc}") from None
    elif predictor == "replay":
        dt = np.diff(obs.times_s)
        period = float(np.median(dt))
        if np.any(np.abs(dt - period) > RATE_TOLERANCE * period) or not 2.5e-4 <= period <= 0.01:
            raise ParameterError(
                f"{obs.source or obs.name}: replay needs evenly spaced samples at 100 Hz-4 kHz "
                f"(median period {period * 1e3:.3g} ms, from {dt.min() * 1e3:.3g} to "
                f"{dt.max() * 1e3:.3g} ms); use the static predictor.")
        sim = ArmSim(arm, dt_s=period)
        rx, ry = obs.reset_m if obs.reset_m is not None else obs.positions_m[0]
        try:
            sim.reset_at_hand(float(rx), float(ry))
        except UnreachableError as exc:
            raise UnreachableError(f"{obs.source or obs.name}: the first position: {exc}") \
                from None
        tick = sim.tick
        x, v = obs.positions_m.tolist(), obs.velocities_m_per_s.tolist()
        f = np.array([tick(p[0], p[1], u[0], u[1]) for p, u in zip(x, v, strict=True)])
    else:
        raise ParameterError(f"Unknown predictor {predictor!r}; known: {', '.join(PREDICTORS)}.")
    if obs.output_gain is not None:
        f = f * obs.output_gain[:, None]
    return f if obs.force_limit_n is None else saturate(f, obs.force_limit_n)


@dataclass(frozen=True, eq=False)
class Classification:
    """The candidates scored against recorded observations.

    Attributes
    ----------
    candidates : tuple of Candidate
    observations : tuple of Observation
    prior, log_likelihood, posterior : ndarray, shape (n,)
    rms_residual_n : ndarray, shape (n,), N
        RMS of the recorded minus the predicted force (both axes) over all samples.
    predictions : tuple of ndarray (n, T, 2)
        Each candidate's predicted force per observation.
    noise : NoiseModel
    predictor : str
    next_probe : ProbeDesign or None
        The stroke that best separates the candidates still in play.
    next_reason : str
        Why there is no next probe, or what it is for.
    raw_posterior : ndarray, shape (n,)
        The posterior of the stated likelihood, before the model-error correction.
    temperature : float
        What the log-likelihoods were divided by (model-error correction × global).
    fit_statistic, fit_expected, fit_variance : float
        The best candidate's whitened residual Q, its mean and variance under the noise model.
    fit_p_value : float
        P(Q at least as large | the best candidate and the noise model) (module docstring).
    """

    candidates: tuple[Candidate, ...]
    observations: tuple[Observation, ...]
    prior: FloatArray
    log_likelihood: FloatArray
    posterior: FloatArray
    rms_residual_n: FloatArray
    predictions: tuple[FloatArray, ...]
    noise: NoiseModel
    predictor: str
    next_probe: ProbeDesign | None
    next_reason: str
    raw_posterior: FloatArray | None = None
    temperature: float = 1.0
    fit_statistic: float = 0.0
    fit_expected: float = 0.0
    fit_variance: float = 0.0
    fit_p_value: float = 1.0

    @property
    def best(self) -> Candidate:
        return self.candidates[int(np.argmax(self.posterior))]

    @property
    def probability(self) -> float:
        return float(self.posterior.max())

    def _marginal(self, key: str) -> dict[str, float]:
        out: dict[str, float] = {}
        for c, p in zip(self.candidates, self.posterior, strict=True):
            k = c.label if key == "group" else (c.level or c.name)
            out[k] = out.get(k, 0.0) + float(p)
        return dict(sorted(out.items(), key=lambda kv: -kv[1]))

    @property
    def group_posterior(self) -> dict[str, float]:
        """Probability of each impaired group (its severities summed), most probable first."""
        return self._marginal("group")

    @property
    def level_posterior(self) -> dict[str, float]:
        """Probability of each severity level (groups summed), most probable first."""
        return self._marginal("level")

    @property
    def group(self) -> str:
        return next(iter(self.group_posterior))

    @property
    def answer(self) -> tuple[str, float]:
        """The most probable impaired group (or set of groups, ``ef+bf``) with its
        probability."""
        gp = self.group_posterior
        g = next(iter(gp))
        return g, gp[g]

    @property
    def log10_likelihood_ratio(self) -> float:
        """log₁₀ of the likelihood of the best candidate over the runner-up."""
        ll = np.sort(self.log_likelihood)[::-1]
        return float((ll[0] - ll[1]) / math.log(10.0)) if len(ll) > 1 else math.inf

    @property
    def explains(self) -> bool:
        """Whether the best-fitting candidate explains the trace within the noise model: its
        residual's p-value is at least :data:`FIT_LEVEL` (module docstring)."""
        return bool(self.fit_p_value >= FIT_LEVEL)

    @property
    def model_error_n(self) -> float:
        """The residual the best-fitting candidate leaves beyond the noise, N RMS per axis
        (σ_m of the module docstring)."""
        return float(self.noise.force_sd_n * math.sqrt(model_error_ratio(
            self.fit_statistic, self.fit_expected, self.fit_variance)))

    @property
    def knows_groups(self) -> bool:
        """Whether the candidates say which group is impaired (synthetic severities)."""
        return all(c.group is not None or c.level == "unimpaired" for c in self.candidates)

    def verdict(self) -> str:
        """One sentence for a clinician."""
        b = self.best
        text = f"most probable: {b.name} (p = {self.probability:.3g})"
        if self.knows_groups:
            g = self.group_posterior
            text += f"; impaired group {self.group} (p = {g[self.group]:.3g})"
        if not self.explains:
            k = int(np.argmin(self.rms_residual_n))
            text += (f"; but no candidate explains the recording (p = {self.fit_p_value:.2g}): "
                     f"the closest, {self.candidates[k].name}, leaves "
                     f"{self.rms_residual_n[k]:.2f} N RMS against a noise of "
                     f"{self.noise.force_sd_n:g} N per axis - the arm may be none of these")
        elif self.temperature > 1.05:
            text += (f" (tempered ×1/{self.temperature:.2g} for ≈ {self.model_error_n:.2g} N "
                     "of model error beyond the noise)")
        return text

    def to_dict(self, shoulder_offset_m: tuple[float, float] = (0.0, 0.0)
                ) -> dict[str, object]:
        order = np.argsort(-self.posterior, kind="stable")
        return {
            "verdict": self.verdict(),
            "best": {"candidate": self.best.name, "group": self.best.label,
                     "level": self.best.level, "probability": self.probability},
            "group_posterior": {k: round(v, 6) for k, v in self.group_posterior.items()},
            "level_posterior": {k: round(v, 6) for k, v in self.level_posterior.items()},
            "log10_likelihood_ratio": round(self.log10_likelihood_ratio, 3),
            "explains_recording": self.explains,
            "fit_test": {"statistic": round(self.fit_statistic, 3),
                         "expected": round(self.fit_expected, 3),
                         "variance": round(self.fit_variance, 3),
                         "p_value": float(f"{self.fit_p_value:.4g}"), "level": FIT_LEVEL},
            "calibration": {"temperature": round(self.temperature, 4),
                            "model_error_n": round(self.model_error_n, 4),
                            "global_temperature": TEMPERATURE},
            "candidates": [{
                "candidate": self.candidates[k].name, "group": self.candidates[k].label,
                "level": self.candidates[k].level,
                "prior": round(float(self.prior[k]), 6),
                "posterior": float(f"{self.posterior[k]:.6g}"),
                "raw_posterior": float(f"{self.raw_posterior[k]:.6g}")
                if self.raw_posterior is not None else None,
                "log_likelihood": round(float(self.log_likelihood[k]), 3),
                "rms_residual_n": round(float(self.rms_residual_n[k]), 4),
                "notes": list(self.candidates[k].notes),
            } for k in order],
            "observations": [{"name": o.name, "source": o.source, "samples": len(o.times_s),
                              "duration_s": round(o.duration_s, 4),
                              "effective_samples": round(float(o.weights(self.noise).sum()), 2)}
                             for o in self.observations],
            "predictor": self.predictor,
            "noise": self.noise.to_dict(),
            "next_probe": None if self.next_probe is None
            else self.next_probe.to_dict(shoulder_offset_m),
            "next_reason": self.next_reason,
        }


def predict_all(observations: Sequence[Observation], candidates: Sequence[Candidate],
                predictor: str = DEFAULT_PREDICTOR) -> tuple[FloatArray, ...]:
    """Every candidate's predicted force for every observation: per observation (n, T, 2)."""
    if predictor not in PREDICTORS:
        raise ParameterError(f"Unknown predictor {predictor!r}; known: {', '.join(PREDICTORS)}.")
    return tuple(np.stack([predict_observation(c.arm, o, predictor) for c in candidates])
                 for o in observations)


def classify(observations: Sequence[Observation], candidates: Sequence[Candidate], *,
             noise: NoiseModel | None = None, prior: Sequence[float] | FloatArray | None = None,
             predictor: str = DEFAULT_PREDICTOR, next_probe: bool = True,
             perception: Perception | None = None, limits: ProbeLimits | None = None,
             stop_probability: float = STOP_PROBABILITY,
             remaining_probability: float = REMAINING_PROBABILITY,
             predictions: Sequence[FloatArray] | None = None) -> Classification:
    """Score every candidate by the likelihood of the recorded forces given the recorded motion.

    Parameters
    ----------
    observations : sequence of Observation
        One or more recorded probes of the same arm.
    candidates : sequence of Candidate
    noise : NoiseModel, optional
        Force noise σ and correlation time τ of the likelihood (motion noise only shapes the
        next probe).
    prior : sequence of float, optional
    predictor : {'replay', 'rigid', 'static'}
    next_probe : bool
        Design the stroke that best separates the candidates still in play (posterior
        ≥ ``remaining_probability``) unless the best has ``stop_probability`` already.
    predictions : sequence of ndarray (n, T, 2), optional
        The candidates' predictions for these motions (:func:`predict_all`), when already made
        (the same motion met with other recorded forces).
    """
    cands = check_candidates(candidates, 2)
    obs = tuple(observations)
    if not obs:
        raise ParameterError("Give at least one recorded observation to classify.")
    if predictor not in PREDICTORS:
        raise ParameterError(f"Unknown predictor {predictor!r}; known: {', '.join(PREDICTORS)}.")
    noise = noise or NoiseModel()
    p0 = check_prior(prior, len(cands))
    preds = tuple(predictions) if predictions is not None else \
        predict_all(obs, cands, predictor)
    if len(preds) != len(obs) or any(pr.shape != (len(cands), *o.force_n.shape)
                                     for pr, o in zip(preds, obs, strict=False)):
        raise ParameterError("The predictions do not match the observations and candidates.")
    ll = np.zeros(len(cands))
    sq = np.zeros(len(cands))
    count = 0
    expected = variance = n_eff = 0.0
    for o, pr in zip(obs, preds, strict=True):
        w = o.weights(noise)
        r2 = ((o.force_n[None] - pr) ** 2).sum(axis=-1)
        ll -= (r2 * w[None]).sum(axis=1) / (2.0 * noise.force_sd_n ** 2)
        used = np.ones(len(o.times_s), dtype=bool) if o.counted is None else o.counted
        sq += r2[:, used].sum(axis=1)
        count += int(used.sum())
        n_eff += float(w.sum())
        expected += 2.0 * float(w.sum())
        variance += 4.0 * correlated_weight_sum(o.times_s, w, 4.0 / noise.correlation_s)
    q = float((-2.0 * ll).min())  # Σ w |r|² / σ² of the best-fitting candidate
    p_fit = p_of_fit(q, expected, variance)
    temperature = TEMPERATURE * (1.0 + model_error_ratio(q, expected, variance) * n_eff)
    raw = _posterior(p0, ll)
    post = _posterior(p0, ll / temperature)
    rms = np.sqrt(sq / count)
    nxt: ProbeDesign | None = None
    if not next_probe:
        reason = "not asked for"
    elif post.max() >= stop_probability:
        reason = (f"none needed: {cands[int(np.argmax(post))].name} has p = {post.max():.3g} "
                  f"≥ {stop_probability:g}")
    else:
        keep = np.flatnonzero(post >= remaining_probability)
        if len(keep) < 2:
            keep = np.argsort(-post, kind="stable")[:2]
        rest = [cands[k] for k in keep]
        nxt = design(rest, criterion="information", max_probes=1, prior=post[keep],
                     perception=perception, noise=noise, limits=limits, names=["next probe"])
        reason = ("separates the candidates still in play: "
                  + ", ".join(f"{c.name} (p = {post[k]:.2g})"
                              for c, k in zip(rest, keep, strict=True)))
    return Classification(cands, obs, p0, ll, post, rms, tuple(preds), noise, predictor, nxt,
                          reason, raw, temperature, q, expected, variance, p_fit)


def model_error_ratio(q: float, expected: float, variance: float) -> float:
    """σ_m²/σ² of the module docstring: the fit statistic's excess beyond
    :data:`MODEL_ERROR_SDS` of its SD, per unit of its mean."""
    if expected <= 0:
        return 0.0
    return max(0.0, q - expected - MODEL_ERROR_SDS * math.sqrt(max(variance, 0.0))) / expected


def _posterior(prior: FloatArray, log_likelihood: FloatArray) -> FloatArray:
    with np.errstate(divide="ignore"):
        logpost = np.log(prior) + log_likelihood
    post = np.exp(logpost - logpost.max())
    return np.asarray(post / post.sum(), dtype=float)


def correlated_weight_sum(times_s: FloatArray, w: FloatArray, rate: float) -> float:
    """Σ_k Σ_l w_k w_l e^(−rate |t_k − t_l|), by one pass of an exponential filter."""
    decay = np.exp(-rate * np.diff(times_s))
    total = 0.0
    carried = 0.0  # Σ_{l<k} w_l e^(−rate (t_k − t_l))
    for k in range(len(w)):
        if k:
            carried = decay[k - 1] * (carried + w[k - 1])
        total += w[k] * (w[k] + 2.0 * carried)
    return total


def p_of_fit(q: float, expected: float, variance: float) -> float:
    """P(Q ≥ q) for Q of mean ``expected`` and ``variance``, as a scaled χ² (Satterthwaite)."""
    if expected <= 0 or variance <= 0:
        return 1.0
    scale = variance / (2.0 * expected)
    dof = 2.0 * expected ** 2 / variance
    return float(chi2.sf(q / scale, dof))


__all__ = ["FIT_LEVEL", "TEMPERATURE", "Classification", "classify",
           "predict_all", "predict_observation", "recorded_accelerations"]
