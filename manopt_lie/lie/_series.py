"""Scalar coefficient functions of the rotation angle, stable at and near 0.

Each function takes the angle ``θ ≥ 0`` as an array and returns the closed form
for ``θ ≥ SMALL`` and its Taylor series in ``θ²`` (through ``θ⁸``) below, chosen
elementwise with ``np.where`` on a safe denominator, so no branch ever divides
by zero. At ``SMALL = 0.1`` the first omitted term is below 3e-18 and the closed
forms lose at most ~1e-12 to cancellation, so both sides agree to ~1e-15.
"""

from __future__ import annotations

import numpy as np

from ._checks import FloatArray

SMALL = 0.1


def _series(t: FloatArray, coefficients: tuple[float, ...]) -> FloatArray:
    """``Σ_k c_k t^k`` by Horner's rule."""
    out = np.full_like(t, coefficients[-1])
    for c in coefficients[-2::-1]:
        out = out * t + c
    return out


def _split(theta: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``(small mask, θ², θ with small entries replaced by 1)``."""
    small = theta < SMALL
    return small, theta * theta, np.where(small, 1.0, theta)


def sinc(theta: FloatArray) -> FloatArray:
    """``sin θ / θ``."""
    small, t, th = _split(theta)
    series = _series(t, (1.0, -1 / 6, 1 / 120, -1 / 5040, 1 / 362880))
    return np.where(small, series, np.sin(th) / th)


def cosc(theta: FloatArray) -> FloatArray:
    """``(1 − cos θ) / θ²``, written ``2 sin²(θ/2) / θ²`` to avoid cancellation."""
    small, t, th = _split(theta)
    series = _series(t, (1 / 2, -1 / 24, 1 / 720, -1 / 40320, 1 / 3628800))
    s = np.sin(0.5 * th)
    return np.where(small, series, 2.0 * s * s / (th * th))


def sinc3(theta: FloatArray) -> FloatArray:
    """``(θ − sin θ) / θ³``."""
    small, t, th = _split(theta)
    series = _series(t, (1 / 6, -1 / 120, 1 / 5040, -1 / 362880, 1 / 39916800))
    return np.where(small, series, (th - np.sin(th)) / (th * th * th))


def jinv_coef(theta: FloatArray) -> FloatArray:
    """``1/θ² − (1 + cos θ)/(2θ sin θ) = 1/θ² − cot(θ/2)/(2θ)``.

    The coefficient of ``(θ^)²`` in ``Jr(θ)⁻¹`` and ``Jl(θ)⁻¹``; finite up to
    (not including) ``θ = 2π``, and ``(π² − 0)/π²·…`` stays exact at ``θ = π``
    because it is written with ``cot(θ/2)``.
    """
    small, t, th = _split(theta)
    series = _series(t, (1 / 12, 1 / 720, 1 / 30240, 1 / 1209600, 1 / 47900160))
    half = 0.5 * th
    return np.where(small, series, 1.0 / (th * th) - np.cos(half) / (np.sin(half) * 2.0 * th))


def q_coef2(theta: FloatArray) -> FloatArray:
    """``(θ² + 2 cos θ − 2) / (2θ⁴)`` of Barfoot's ``Q(ρ, θ)``."""
    small, t, th = _split(theta)
    series = _series(t, (1 / 24, -1 / 720, 1 / 40320, -1 / 3628800, 1 / 479001600))
    return np.where(small, series, (th * th + 2.0 * np.cos(th) - 2.0) / (2.0 * th**4))


def q_coef3(theta: FloatArray) -> FloatArray:
    """``(2θ − 3 sin θ + θ cos θ) / (2θ⁵)`` of Barfoot's ``Q(ρ, θ)``."""
    small, t, th = _split(theta)
    series = _series(t, (1 / 120, -1 / 2520, 1 / 120960, -1 / 9979200, 1 / 1245404160))
    return np.where(
        small, series, (2.0 * th - 3.0 * np.sin(th) + th * np.cos(th)) / (2.0 * th**5)
    )
