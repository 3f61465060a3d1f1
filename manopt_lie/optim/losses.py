"""Robust losses for least squares, applied by iteratively reweighted least squares.

A factor with squared residual norm ``s = ‖r‖²`` contributes ``½ ρ(s)`` to the
cost. Each loss has ``ρ(s) ≈ s`` near 0 (the plain least-squares case), so a
scale parameter ``c`` marks where residuals start to count as outliers. IRLS
uses the weight ``w = ρ'(s)``: the gradient ``Σ w Jᵀr`` is exact and
``Σ w JᵀJ`` is the Gauss-Newton model of the Hessian.

================  ===========================  ==============================
loss              ρ(s)                         w = ρ'(s)
================  ===========================  ==============================
``Trivial``       ``s``                        ``1``
``Huber(c)``      ``s`` if ``s ≤ c²``,         ``1``, else ``c/√s``
                  else ``2c√s − c²``
``Cauchy(c)``     ``c² log(1 + s/c²)``         ``1/(1 + s/c²)``
``GemanMcClure``  ``c² s/(c² + s)``            ``c⁴/(c² + s)²``
``TruncatedL2``   ``min(s, c²)``               ``1`` if ``s < c²`` else ``0``
``L1(c)``         ``2c²(√(1 + s/c²) − 1)``     ``1/√(1 + s/c²)``
================  ===========================  ==============================

``L1`` is the smoothed absolute value (pseudo-Huber): ``½ρ ≈ c‖r‖`` once
``‖r‖ ≫ c``, so IRLS with it is the L1 averaging of Chatterjee & Govindu with
their weights ``1/‖r‖`` kept finite at ``r = 0``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["RobustLoss", "Trivial", "Huber", "Cauchy", "GemanMcClure", "TruncatedL2", "L1", "parse_loss"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RobustLoss(ABC):
    """``ρ(s)`` of the squared residual norm ``s`` and its derivative, the IRLS weight."""

    @abstractmethod
    def rho(self, s: FloatArray) -> FloatArray:
        """``ρ(s)`` elementwise, for squared residual norms ``s ≥ 0`` of any shape; ``ρ(s) ≈ s`` near 0."""
        ...

    @abstractmethod
    def weight(self, s: FloatArray) -> FloatArray:
        """The IRLS weight ``w = ρ'(s)`` elementwise, same shape as ``s``; ``w(0) = 1``."""
        ...


@dataclass(frozen=True)
class Trivial(RobustLoss):
    """Plain least squares."""

    def rho(self, s: FloatArray) -> FloatArray:
        return s

    def weight(self, s: FloatArray) -> FloatArray:
        return np.ones_like(s)


@dataclass(frozen=True)
class _Scaled(RobustLoss):
    c: float = 1.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.c) and self.c > 0):
            raise ValueError(f"{type(self).__name__}: the scale c must be positive, got {self.c!r}")


@dataclass(frozen=True)
class Huber(_Scaled):
    """Quadratic up to ``|r| = c``, linear beyond."""

    def rho(self, s: FloatArray) -> FloatArray:
        root = np.sqrt(s)
        return np.where(root <= self.c, s, 2.0 * self.c * root - self.c**2)

    def weight(self, s: FloatArray) -> FloatArray:
        root = np.sqrt(s)
        return np.where(root <= self.c, 1.0, self.c / np.maximum(root, self.c))


@dataclass(frozen=True)
class Cauchy(_Scaled):
    """Logarithmic growth: outliers keep a small, decaying influence."""

    def rho(self, s: FloatArray) -> FloatArray:
        return self.c**2 * np.log1p(s / self.c**2)

    def weight(self, s: FloatArray) -> FloatArray:
        return 1.0 / (1.0 + s / self.c**2)


@dataclass(frozen=True)
class GemanMcClure(_Scaled):
    """Bounded by ``c²``: large residuals lose all influence (non-convex)."""

    def rho(self, s: FloatArray) -> FloatArray:
        return self.c**2 * s / (self.c**2 + s)

    def weight(self, s: FloatArray) -> FloatArray:
        return self.c**4 / (self.c**2 + s) ** 2


@dataclass(frozen=True)
class TruncatedL2(_Scaled):
    """Least squares below ``|r| = c``, constant beyond (residuals past ``c`` are ignored)."""

    def rho(self, s: FloatArray) -> FloatArray:
        return np.minimum(s, self.c**2)

    def weight(self, s: FloatArray) -> FloatArray:
        return (s < self.c**2).astype(np.float64)


@dataclass(frozen=True)
class L1(_Scaled):
    """Smoothed absolute value: least squares below ``|r| ≈ c``, linear growth beyond."""

    def rho(self, s: FloatArray) -> FloatArray:
        return 2.0 * self.c**2 * (np.sqrt(1.0 + s / self.c**2) - 1.0)

    def weight(self, s: FloatArray) -> FloatArray:
        return 1.0 / np.sqrt(1.0 + s / self.c**2)


_BY_NAME: dict[str, type[_Scaled]] = {
    "huber": Huber,
    "cauchy": Cauchy,
    "geman-mcclure": GemanMcClure,
    "truncated": TruncatedL2,
    "l1": L1,
}


def parse_loss(spec: str | RobustLoss | None) -> RobustLoss:
    """A loss from ``None`` (plain least squares), an instance, or ``"name:c"``
    such as ``"huber:1.0"`` (names: huber, cauchy, geman-mcclure, truncated, l1)."""
    if spec is None:
        return Trivial()
    if isinstance(spec, RobustLoss):
        return spec
    name, _, scale = str(spec).partition(":")
    if name.lower() not in _BY_NAME:
        raise ValueError(f"unknown robust loss {name!r}; choose from {', '.join(_BY_NAME)}")
    try:
        return _BY_NAME[name.lower()](float(scale) if scale else 1.0)
    except ValueError as err:
        raise ValueError(f"robust loss {spec!r}: {err}") from None
