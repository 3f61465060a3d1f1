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


def jr(tau: FloatArray, n_rho: int, ad: Kernel, exp: Kernel, inverse: Kernel, adjoint: Kernel) -> FloatArray:
    """``Jr(τ)`` for tangents ``(ρ, …)`` whose first ``n_rho`` coordinates enter ``Jr`` linearly."""
    m = np.maximum(np.abs(tau[..., :n_rho]).max(axis=-1), 1.0)
    unit = np.concatenate([tau[..., :n_rho] / m[..., None], tau[..., n_rho:]], axis=-1)
    a = ad(unit)
    big = np.abs(a).max(initial=0.0)  # n·big ≥ ‖ad‖_F (and log₂ of it never overflows)
    n = a.shape[-1]
    k = int(np.ceil(np.log2(big) + np.log2(n / DOUBLING_NORM))) if big > DOUBLING_NORM / n else 0
    x = np.ldexp(-a, -k)
    eye = np.eye(n)
    j = _SERIES[-1] * x + _SERIES[-2] * eye
    for c in _SERIES[-3::-1]:
        j = j @ x + c * eye
    half = np.ldexp(unit, -k)
    for level in range(k):
        j = 0.5 * (j + adjoint(inverse(exp(np.ldexp(half, level)))) @ j)
    j[..., :n_rho, n_rho:] *= m[..., None, None]
    return j
