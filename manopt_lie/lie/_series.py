"""Scalar coefficient functions of the rotation angle, stable at and near 0.

Each function takes the angle ``θ ≥ 0`` as an array and returns its closed form
above a threshold and its Taylor series in ``t = θ²`` (six terms) below, chosen
elementwise with ``np.where`` on a safe denominator, so no branch ever divides
by zero. Each threshold balances the closed form's cancellation against the
series' truncation: against 60-digit references the largest relative error is
below 1e-13 for every function and angle in ``[0, 2π)``.
"""

from __future__ import annotations

from collections.abc import Callable
from math import factorial

import numpy as np

from ._checks import FloatArray

_TERMS = range(6)
# Bernoulli numbers B₂, B₄, …, B₁₂ for the series of x·cot(x).
_BERNOULLI = (1 / 6, -1 / 30, 1 / 42, -1 / 30, 5 / 66, -691 / 2730)


def _blend(
    theta: FloatArray, threshold: float, coefficients: list[float], closed: Callable[[FloatArray], FloatArray]
) -> FloatArray:
    """``Σ_j c_j θ^{2j}`` (Horner) where ``θ < threshold``, else ``closed(θ)``."""
    small = theta < threshold
    t = theta * theta
    series = np.full_like(t, coefficients[-1])
    for c in coefficients[-2::-1]:
        series = series * t + c
    return np.where(small, series, closed(np.where(small, 1.0, theta)))


def sinc(theta: FloatArray) -> FloatArray:
    """``sin θ / θ``."""
    return _blend(theta, 0.3, [(-1) ** j / factorial(2 * j + 1) for j in _TERMS], lambda th: np.sin(th) / th)


def cosc(theta: FloatArray) -> FloatArray:
    """``(1 − cos θ) / θ²``, written ``2 sin²(θ/2) / θ²`` to avoid cancellation."""
    return _blend(
        theta, 0.3, [(-1) ** j / factorial(2 * j + 2) for j in _TERMS], lambda th: 2.0 * (np.sin(0.5 * th) / th) ** 2
    )


def sinc3(theta: FloatArray) -> FloatArray:
    """``(θ − sin θ) / θ³``."""
    return _blend(theta, 0.5, [(-1) ** j / factorial(2 * j + 3) for j in _TERMS], lambda th: (th - np.sin(th)) / th**3)


def jinv_coef(theta: FloatArray) -> FloatArray:
    """``1/θ² − (1 + cos θ)/(2θ sin θ) = 1/θ² − cot(θ/2)/(2θ)``.

    The coefficient of ``[θ]×²`` in ``Jr(θ)⁻¹``; finite up to (excluding) ``2π``
    and exact at ``π``, being written with ``cot(θ/2)``.
    """
    return _blend(
        theta,
        0.3,
        [(-1) ** j * _BERNOULLI[j] / factorial(2 * j + 2) for j in _TERMS],
        lambda th: 1.0 / th**2 - np.cos(0.5 * th) / (2.0 * th * np.sin(0.5 * th)),
    )


def q_coef2(theta: FloatArray) -> FloatArray:
    """``(θ² + 2 cos θ − 2) / (2θ⁴)`` of Barfoot's ``Q(ρ, θ)``."""
    return _blend(
        theta,
        0.7,
        [(-1) ** j / factorial(2 * j + 4) for j in _TERMS],
        lambda th: (th * th + 2.0 * np.cos(th) - 2.0) / (2.0 * th**4),
    )


def q_coef3(theta: FloatArray) -> FloatArray:
    """``(2θ − 3 sin θ + θ cos θ) / (2θ⁵)`` of Barfoot's ``Q(ρ, θ)``."""
    return _blend(
        theta,
        0.7,
        [(-1) ** j * (j + 1) / factorial(2 * j + 5) for j in _TERMS],
        lambda th: (2.0 * th - 3.0 * np.sin(th) + th * np.cos(th)) / (2.0 * th**5),
    )
