"""Manifolds embedded in a vector space of arrays, with the induced Frobenius metric.

Points and tangent vectors are arrays of the embedding's shape ``point_shape``
(after any leading batch axes); ``to_ambient`` is the identity, and the
Riemannian gradient is the projection of the Euclidean one (CONVENTIONS §6).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import NotOnManifoldError
from ..lie._checks import FloatArray, as_batch
from .base import Manifold, coordinate_inner


class EmbeddedManifold(Manifold):
    """Base of the array manifolds: ``point_shape`` and the Frobenius metric."""

    point_shape: tuple[int, ...]

    @property
    def tangent_ndim(self) -> int:  # type: ignore[override]
        return len(self.point_shape)

    def _axes(self) -> tuple[int, ...]:
        return tuple(range(-len(self.point_shape), 0))

    def inner(self, x: FloatArray, u: FloatArray, v: FloatArray) -> Any:
        """``⟨u, v⟩ = Σ u ⊙ v`` over the point axes."""
        return np.sum(np.multiply(u, v), axis=self._axes())

    def total_inner(self, x: FloatArray, u: FloatArray, v: FloatArray) -> float:
        """``Σ u ⊙ v`` over every entry, batch included (one ``np.vdot``)."""
        return coordinate_inner(u, v)

    def zero_vector(self, x: FloatArray) -> FloatArray:
        return np.zeros(np.shape(x))

    def batch_shape_of(self, x: FloatArray) -> tuple[int, ...]:
        return np.shape(x)[: np.ndim(x) - len(self.point_shape)]

    def egrad2rgrad(self, x: FloatArray, egrad: FloatArray) -> FloatArray:
        """``grad f(x) = proj_x(∇f(x))`` (the metric is induced by the embedding)."""
        return self.proj(x, egrad)

    def transp(self, x: FloatArray, y: FloatArray, v: FloatArray) -> FloatArray:
        """Transport by projection onto the tangent space at ``y``."""
        return self.proj(y, v)

    def _checked_array(self, x: Any, name: str) -> FloatArray:
        return as_batch(x, self.point_shape, name)

    def _require(self, err: FloatArray, tol: float, name: str, what: str) -> None:
        """Raise :class:`NotOnManifoldError` where a per-point constraint error exceeds ``tol``."""
        if np.any(err > tol):
            raise NotOnManifoldError(f"{name}: not a point of {self!r} ({what} off by {np.max(err):.3g} > {tol:g})")

    def check_point(self, x: Any, name: str = "x") -> None:
        self._checked_array(x, name)


def transpose(a: FloatArray) -> FloatArray:
    """``Aᵀ`` on the last two axes (a view; the array method where it is one, without the
    dispatch of ``np.swapaxes``, which the projections call several times per product)."""
    return a.swapaxes(-1, -2) if type(a) is np.ndarray else np.swapaxes(a, -1, -2)


def sym(a: FloatArray) -> FloatArray:
    """``(A + Aᵀ)/2`` on the last two axes."""
    return 0.5 * (a + transpose(a))


def skew(a: FloatArray) -> FloatArray:
    """``(A − Aᵀ)/2`` on the last two axes."""
    return 0.5 * (a - transpose(a))
