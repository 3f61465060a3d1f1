"""Products ``M₁ × M₂ × …`` and powers ``Mᵏ`` of manifolds.

A product's points are tuples and its tangent vectors :class:`ProductVector`\\ s
(tuples with vector arithmetic); metric, retraction and every other operation
act factor by factor, the metric being the sum ``⟨u, v⟩ = Σᵢ ⟨uᵢ, vᵢ⟩``.

A power ``Mᵏ`` stores its ``k`` points as *one* point of ``M`` with leading
batch axes ``(k,)`` — for ``Power(LieGroupManifold(SO3), n)`` a single SO(3)
element of batch shape ``(n,)``, i.e. one ``(n, 3, 3)`` array — so each
operation is a single vectorized call of ``M``'s kernels.
"""

from __future__ import annotations

from math import prod
from typing import Any

import numpy as np

from ..errors import ShapeError
from .base import Manifold, Point, Tangent


class ProductVector(tuple):  # type: ignore[type-arg]
    """A tangent vector of a product manifold: a tuple supporting ``+``, ``−``,
    scalar ``*`` and ``/`` componentwise."""

    __slots__ = ()
    __array_ufunc__ = None  # NumPy scalars defer to the reflected operators below

    def __add__(self, other: Any) -> ProductVector:  # type: ignore[override]
        return ProductVector(a + b for a, b in zip(self, other, strict=True))

    def __sub__(self, other: Any) -> ProductVector:
        return ProductVector(a - b for a, b in zip(self, other, strict=True))

    def __neg__(self) -> ProductVector:
        return ProductVector(-a for a in self)

    def __mul__(self, s: Any) -> ProductVector:  # type: ignore[override]
        return ProductVector(a * s for a in self)

    __rmul__ = __mul__

    def __truediv__(self, s: Any) -> ProductVector:
        return ProductVector(a / s for a in self)


class Product(Manifold):
    """The product manifold ``M₁ × M₂ × …`` with the sum metric."""

    def __init__(self, *manifolds: Manifold) -> None:
        if not manifolds or not all(isinstance(m, Manifold) for m in manifolds):
            raise TypeError("Product: pass one or more Manifold instances")
        self.manifolds = tuple(manifolds)

    def __repr__(self) -> str:
        return f"Product({', '.join(map(repr, self.manifolds))})"

    def _zip(self, *parts: Any) -> Any:
        for p in parts:
            if not isinstance(p, tuple) or len(p) != len(self.manifolds):
                raise ValueError(f"{self!r}: expected a tuple of {len(self.manifolds)} parts, got {type(p).__name__}")
        return zip(self.manifolds, *parts, strict=True)

    @property
    def dim(self) -> int:
        return sum(m.dim for m in self.manifolds)

    @property
    def typical_dist(self) -> float:
        return float(np.sqrt(sum(m.typical_dist**2 for m in self.manifolds)))

    def inner(self, x: Point, u: Tangent, v: Tangent) -> Any:
        return sum(m.inner(xi, ui, vi) for m, xi, ui, vi in self._zip(x, u, v))

    def total_inner(self, x: Point, u: Tangent, v: Tangent) -> float:
        return sum(m.total_inner(xi, ui, vi) for m, xi, ui, vi in zip(self.manifolds, x, u, v, strict=True))

    def scale(self, v: Tangent, s: Any) -> Tangent:
        return ProductVector(m.scale(vi, s) for m, vi in self._zip(v))

    def proj(self, x: Point, u: Any) -> Tangent:
        return ProductVector(m.proj(xi, ui) for m, xi, ui in self._zip(x, u))

    def retr(self, x: Point, v: Tangent) -> Point:
        return tuple(m.retr(xi, vi) for m, xi, vi in self._zip(x, v))

    def _random_point(self, rng: np.random.Generator, batch: tuple[int, ...]) -> Point:
        return tuple(m._random_point(rng, batch) for m in self.manifolds)

    def random_tangent(self, x: Point, rng: np.random.Generator | int | None = None) -> Tangent:
        g = np.random.default_rng(rng)
        return self.unit(x, ProductVector(m.random_tangent(xi, g) for m, xi in self._zip(x)))

    def zero_vector(self, x: Point) -> Tangent:
        return ProductVector(m.zero_vector(xi) for m, xi in self._zip(x))

    def to_ambient(self, x: Point, v: Tangent) -> Any:
        return tuple(m.to_ambient(xi, vi) for m, xi, vi in self._zip(x, v))

    def check_point(self, x: Point, name: str = "x") -> None:
        for i, (m, xi) in enumerate(self._zip(x)):
            m.check_point(xi, f"{name}[{i}]")

    def batch_shape_of(self, x: Point) -> tuple[int, ...]:
        return self.manifolds[0].batch_shape_of(x[0])

    def egrad2rgrad(self, x: Point, egrad: Any) -> Tangent:
        return ProductVector(m.egrad2rgrad(xi, gi) for m, xi, gi in self._zip(x, egrad))

    def ehess2rhess(self, x: Point, egrad: Any, ehess: Any, v: Tangent) -> Tangent:
        return ProductVector(m.ehess2rhess(*a) for m, *a in self._zip(x, egrad, ehess, v))

    def exp(self, x: Point, v: Tangent) -> Point:
        return tuple(m.exp(xi, vi) for m, xi, vi in self._zip(x, v))

    def log(self, x: Point, y: Point) -> Tangent:
        return ProductVector(m.log(xi, yi) for m, xi, yi in self._zip(x, y))

    def transp(self, x: Point, y: Point, v: Tangent) -> Tangent:
        return ProductVector(m.transp(xi, yi, vi) for m, xi, yi, vi in self._zip(x, y, v))

    def dist(self, x: Point, y: Point) -> Any:
        return np.sqrt(sum(m.dist(xi, yi) ** 2 for m, xi, yi in self._zip(x, y)))


class Power(Manifold):
    """``Mᵏ``: ``k`` points of ``M`` (``k`` an int or a shape) stored as one batched point.

    Every operation is one call of ``M``'s batched kernels; the metric sums the
    ``k`` factors' metrics.
    """

    def __init__(self, manifold: Manifold, k: int | tuple[int, ...]) -> None:
        shape = tuple(int(n) for n in ((k,) if isinstance(k, (int, np.integer)) else k))
        if not shape or min(shape) < 1:
            raise ValueError(f"Power: k must be a positive integer or shape, got {k!r}")
        if isinstance(manifold, Power):  # (Mᵃ)ᵇ = M^(b, a)
            shape, manifold = shape + manifold.shape, manifold.manifold
        self.manifold: Manifold = manifold
        self.shape: tuple[int, ...] = shape
        self.tangent_ndim = manifold.tangent_ndim + len(self.shape)

    def __repr__(self) -> str:
        k = self.shape[0] if len(self.shape) == 1 else self.shape
        return f"Power({self.manifold!r}, {k})"

    def _sum(self, values: Any) -> Any:
        return np.sum(values, axis=tuple(range(-len(self.shape), 0)))

    @property
    def dim(self) -> int:
        return prod(self.shape) * self.manifold.dim

    @property
    def typical_dist(self) -> float:
        return float(np.sqrt(prod(self.shape))) * self.manifold.typical_dist

    def inner(self, x: Point, u: Tangent, v: Tangent) -> Any:
        return self._sum(self.manifold.inner(x, u, v))

    def total_inner(self, x: Point, u: Tangent, v: Tangent) -> float:
        return self.manifold.total_inner(x, u, v)

    def scale(self, v: Tangent, s: Any) -> Tangent:
        s = np.asarray(s, dtype=np.float64)
        return self.manifold.scale(v, s.reshape(s.shape + (1,) * len(self.shape)))

    def proj(self, x: Point, u: Any) -> Tangent:
        return self.manifold.proj(x, u)

    def retr(self, x: Point, v: Tangent) -> Point:
        return self.manifold.retr(x, v)

    def _random_point(self, rng: np.random.Generator, batch: tuple[int, ...]) -> Point:
        return self.manifold._random_point(rng, batch + self.shape)

    def random_tangent(self, x: Point, rng: np.random.Generator | int | None = None) -> Tangent:
        return self.unit(x, self.manifold.random_tangent(x, np.random.default_rng(rng)))

    def zero_vector(self, x: Point) -> Tangent:
        return self.manifold.zero_vector(x)

    def to_ambient(self, x: Point, v: Tangent) -> Any:
        return self.manifold.to_ambient(x, v)

    def check_point(self, x: Point, name: str = "x") -> None:
        self.manifold.check_point(x, name)
        batch = self.manifold.batch_shape_of(x)
        if batch[len(batch) - len(self.shape) :] != self.shape:
            raise ShapeError(f"{name}: a point of {self!r} needs batch shape (..., {self.shape}), got {batch}")

    def batch_shape_of(self, x: Point) -> tuple[int, ...]:
        batch = self.manifold.batch_shape_of(x)
        return batch[: len(batch) - len(self.shape)]

    def egrad2rgrad(self, x: Point, egrad: Any) -> Tangent:
        return self.manifold.egrad2rgrad(x, egrad)

    def ehess2rhess(self, x: Point, egrad: Any, ehess: Any, v: Tangent) -> Tangent:
        return self.manifold.ehess2rhess(x, egrad, ehess, v)

    def exp(self, x: Point, v: Tangent) -> Point:
        return self.manifold.exp(x, v)

    def log(self, x: Point, y: Point) -> Tangent:
        return self.manifold.log(x, y)

    def transp(self, x: Point, y: Point, v: Tangent) -> Tangent:
        return self.manifold.transp(x, y, v)

    def dist(self, x: Point, y: Point) -> Any:
        return np.sqrt(self._sum(self.manifold.dist(x, y) ** 2))
