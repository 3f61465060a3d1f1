"""``Jr`` of a group whose closed form is out of reach (Sim(2), Sim(3)), numerically exact by doubling.

``Exp(2τ) = Exp(τ)²`` gives ``Jr(2τ) = ½ (I + Ad_{Exp τ}⁻¹) Jr(τ)``. With ``K`` the smallest
integer such that ``‖ad_τ‖_F / 2ᴷ ≤ 0.25`` (one ``K`` for the batch), the 13-term series
``Jr = Σₖ (−ad_τ)ᵏ/(k+1)!`` at ``τ/2ᴷ`` (remainder below 1e-19) is doubled back ``K`` times:
``K`` batched compositions, no loop over elements (``K ≈ 5`` for ``|τ| ≈ 3``). ``Jr`` of these
groups is linear in the translation ``ρ`` (only its top-right blocks depend on it), so ``ρ``
is scaled to ``|ρ|∞ ≤ 1`` first and those blocks scaled back: ``K`` depends on the rotation and
the scale only.
"""

from __future__ import annotations

from collections.abc import Callable
from math import factorial

import numpy as np

from ._checks import FloatArray

DOUBLING_NORM = 0.25
_SERIES = tuple(1.0 / factorial(k + 1) for k in range(13))  # 1/(k+1)!

Kernel = Callable[[FloatArray], FloatArray]


def jr(
    tau: FloatArray,
    n_rho: int,
    ad: Kernel,
    exp: Kernel,
    inverse: Kernel,
    adjoint: Kernel,
    step: Callable[[FloatArray, FloatArray], FloatArray] | None = None,
) -> FloatArray:
    """``Jr(τ)`` for tangents ``(ρ, …)`` whose first ``n_rho`` coordinates enter ``Jr`` linearly.

    ``step(J, τ_l)``, if given, returns ``½ (I + Ad_{Exp τ_l}⁻¹) J`` faster than the generic
    ``adjoint(inverse(exp(τ_l)))`` product (e.g. by blocks).
    """
    m = np.maximum(np.abs(tau[..., :n_rho]).max(axis=-1), 1.0)
    unit = np.concatenate([tau[..., :n_rho] / m[..., None], tau[..., n_rho:]], axis=-1)
    a = ad(unit)
    big = np.abs(a).max(axis=(-2, -1), keepdims=True)
    safe = np.where(big > 0.0, big, 1.0)
    scaled = a / safe
    # log₂ ‖ad‖_F, formed from the scaled matrix (‖ad‖_F itself may overflow for huge tangents)
    log_fro = np.log2(safe[..., 0, 0]) + 0.5 * np.log2(np.maximum(np.einsum("...ij,...ij->...", scaled, scaled), 1.0))
    top = float(np.where(big[..., 0, 0] > 0.0, log_fro, -np.inf).max(initial=-np.inf))
    n = a.shape[-1]
    k = max(0, int(np.ceil(top - np.log2(DOUBLING_NORM)))) if np.isfinite(top) else 0
    x = np.ldexp(-a, -k)
    diag = (..., np.arange(n), np.arange(n))
    j = _SERIES[-1] * x
    j[diag] += _SERIES[-2]
    spare = np.empty_like(j)
    for c in _SERIES[-3::-1]:  # Horner, in place: two buffers, the identity added on the diagonal only
        np.matmul(j, x, out=spare)
        spare[diag] += c
        j, spare = spare, j
    half = np.ldexp(unit, -k)
    for level in range(k):
        tau_l = np.ldexp(half, level)
        j = step(j, tau_l) if step is not None else 0.5 * (j + adjoint(inverse(exp(tau_l))) @ j)
    j[..., :n_rho, n_rho:] *= m[..., None, None]
    return j
