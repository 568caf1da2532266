"""The muscle equations of the arm model (eqs. 3-5 of the model, ``fieldbank.model``'s
docstring): passive tension Ψ(λ) and the velocity-dependent stretch reflex Φ(λ, λ̇), each with
the slopes the stiffness and damping need.

Element-wise over NumPy arrays: one arm's (N, 6) lengths against (6,) muscle values, or S
parameter sets' (S, N, 6) against (S, 1, 6) (:class:`fieldbank.armbatch.ArmBatch`). Units: m,
m/s, N, N/m, N·s/m.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def passive_force(lam: FloatArray, lam_slack: FloatArray, km: FloatArray,
                  excursion: FloatArray, w: float) -> FloatArray:
    """The passive force Ψ of eq. 5 (module docstring), N: the value of
    :func:`passive_tension` without its slope, for evaluations that need forces only."""
    return _passive(lam, lam_slack, km, excursion, w)[0]


def passive_tension(lam: FloatArray, lam_slack: FloatArray, km: FloatArray,
                    excursion: FloatArray, w: float) -> tuple[FloatArray, FloatArray]:
    """The passive force of eq. 5 (module docstring) and its slope ∂Ψ/∂λ: N and N/m.

    Element-wise: every muscle array (``lam_slack``, ``km``, ``excursion``) broadcasts against
    ``lam``, so ``lam`` (N, 6) with arrays (6,) is one arm, and ``lam`` (S, N, 6) with arrays
    (S, 1, 6) is S parameter sets of one geometry (:class:`fieldbank.armbatch.ArmBatch`).
    """
    psi, d, z, sp, g = _passive(lam, lam_slack, km, excursion, w)
    sig = np.exp(z - sp / w)  # the logistic 1/(1 + e^-z) as e^(z - ln(1 + e^z)): stable both ends
    dpsi = km * g * (sig - sp * 2.0 * d / (excursion * excursion))
    return psi, dpsi


def _passive(lam: FloatArray, lam_slack: FloatArray, km: FloatArray, excursion: FloatArray,
             w: float) -> tuple[FloatArray, ...]:
    """Ψ and the intermediate terms its slope reuses: (Ψ, d, d/w, s_w(d), e^{-(d/ℓ)²})."""
    d = lam - lam_slack
    z = d / w
    sp = w * np.logaddexp(0.0, z)
    g = np.exp(-((d / excursion) ** 2))
    return km * sp * g, d, z, sp, g


def reflex_force(lam: FloatArray, ldot: FloatArray, ldot_max: FloatArray, alpha: FloatArray,
                 beta: FloatArray, excursion: FloatArray, lam_rest: FloatArray,
                 lam_min: FloatArray, lam_max: FloatArray) -> FloatArray:
    """The reflex force Φ of eqs. 3-4, N: the value of :func:`reflex_tension` without its
    slopes. Zero wherever λ̇ ≤ 0 (the reflex acts on lengthening muscles only)."""
    return _reflex(lam, ldot, ldot_max, alpha, beta, excursion, lam_rest, lam_min, lam_max)[0]


def reflex_tension(lam: FloatArray, ldot: FloatArray, ldot_max: FloatArray, alpha: FloatArray,
                   beta: FloatArray, excursion: FloatArray, lam_rest: FloatArray,
                   lam_min: FloatArray, lam_max: FloatArray
                   ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The reflex force of eqs. 3-4 and its slopes ∂Φ/∂λ, ∂Φ/∂λ̇: N, N/m, N·s/m; element-wise
    like :func:`passive_tension`."""
    phi, r, u, k, gam, e, h = _reflex(lam, ldot, ldot_max, alpha, beta, excursion, lam_rest,
                                      lam_min, lam_max)
    dc = np.where((r > 0) & (r < 1), 1.0, 0.0)
    dc = np.where((r == 0) | (r == 1), 0.5, dc) / ldot_max
    ell = excursion
    dh_dlam = alpha * u * e * (1.0 - 2.0 * gam * gam) / ell
    dh_du = alpha * (gam * e + u * e * (1.0 - 2.0 * gam * gam) * k)
    # max(0, h): active where h > 0; where u == 0 (h == 0) the lengthening side is active
    # exactly when h would grow with u, and dc already halves that slope.
    on = (h > 0) | ((h == 0) & (dh_du > 0))
    dphi_dlam = np.where(on, dh_dlam, 0.0)
    dphi_dldot = np.where(on, dh_du * beta * dc, 0.0)
    return phi, dphi_dlam, dphi_dldot


def _reflex(lam: FloatArray, ldot: FloatArray, ldot_max: FloatArray, alpha: FloatArray,
            beta: FloatArray, excursion: FloatArray, lam_rest: FloatArray, lam_min: FloatArray,
            lam_max: FloatArray) -> tuple[FloatArray, ...]:
    """Φ and the intermediate terms its slopes reuse: (Φ, λ̇/λ̇_max, u, λ_rest/λ_max, Γ,
    e^{-Γ²}, h)."""
    r = ldot / ldot_max
    u = beta * np.clip(r, 0.0, 1.0)
    k = lam_rest / lam_max
    gam = (lam - lam_min) / excursion - k * (1.0 - u)
    e = np.exp(-gam * gam)
    h = alpha * u * gam * e
    return np.where(h > 0, h, 0.0), r, u, k, gam, e, h
