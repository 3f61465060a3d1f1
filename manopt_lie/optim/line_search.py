"""Stateless backtracking line search along a retraction curve.

Everything the search needs from earlier iterations is passed in (here the
previous cost, for the initial step), so one search never leaks into the next.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..manifolds.base import Manifold


@dataclass(frozen=True)
class LineSearchResult:
    """``x = R_{x₀}(α d)`` with ``alpha = α``; ``step`` is ``α‖d‖``."""

    x: Any
    fun: float
    alpha: float
    step: float
    nfev: int
    success: bool


def initial_step(f0: float, f_prev: float | None, slope: float, d_norm: float, max_step: float) -> float:
    """Manopt's adaptive first trial ``α``: ``2(f_prev − f₀)/|df₀|`` (the step that the
    last decrease predicts for a quadratic, Nocedal–Wright eq. 3.60), else a unit-length
    step ``1/‖d‖``; at most ``max_step/‖d‖``."""
    alpha = 2.0 * (f_prev - f0) / -slope if f_prev is not None and slope < 0 else math.nan
    if not (math.isfinite(alpha) and alpha > 0):
        alpha = 1.0 / d_norm
    return min(alpha, max_step / d_norm)


def armijo(
    cost: Callable[[Any], float],
    manifold: Manifold,
    x0: Any,
    f0: float,
    d: Any,
    d_norm: float,
    slope: float,
    alpha: float,
    *,
    sufficient_decrease: float = 1e-4,
    contraction: float = 0.5,
    max_backtracks: int = 30,
) -> LineSearchResult:
    """Backtrack from ``alpha`` until ``f(R_x(α d)) ≤ f₀ + c·α·slope`` (Armijo).

    ``slope = ⟨grad f(x₀), d⟩ < 0`` is the directional derivative and ``d_norm = ‖d‖``. Fails
    (``success=False``, returning ``x₀``) when ``max_backtracks`` contractions
    find no sufficient decrease.
    """
    for k in range(max_backtracks + 1):
        y = manifold.retr(x0, d * alpha)
        f = cost(y)
        if f <= f0 + sufficient_decrease * alpha * slope:
            return LineSearchResult(y, f, alpha, alpha * d_norm, k + 1, True)
        alpha *= contraction
    return LineSearchResult(x0, f0, 0.0, 0.0, max_backtracks + 1, False)


@dataclass(frozen=True)
class Backtracking:
    """The settings of :func:`armijo` with :func:`initial_step`'s first trial, shared by
    the line-search optimizers."""

    sufficient_decrease: float = 1e-4
    contraction: float = 0.5
    max_backtracks: int = 30

    def __post_init__(self) -> None:
        if not (0 < self.sufficient_decrease < 1 and 0 < self.contraction < 1):
            raise ValueError("line search: need 0 < sufficient_decrease < 1 and 0 < contraction < 1")

    def search(
        self,
        cost: Callable[[Any], float],
        manifold: Manifold,
        x0: Any,
        f0: float,
        f_prev: float | None,
        d: Any,
        d_norm: float,
        slope: float,
    ) -> LineSearchResult:
        """Armijo backtracking along ``R_{x₀}(α d)`` from Manopt's adaptive first trial."""
        alpha = initial_step(f0, f_prev, slope, d_norm, manifold.typical_dist)
        return armijo(
            cost, manifold, x0, f0, d, d_norm, slope, alpha,
            sufficient_decrease=self.sufficient_decrease, contraction=self.contraction,
            max_backtracks=self.max_backtracks,
        )  # fmt: skip
