"""Euclidean space ``R^{n₁×n₂×…}`` as a manifold."""

from __future__ import annotations

from math import prod
from typing import Any

import numpy as np

from ..lie._checks import FloatArray
from .embedded import EmbeddedManifold


class Euclidean(EmbeddedManifold):
    """Arrays of shape ``shape`` with ``⟨u, v⟩ = Σ u ⊙ v``; ``R_x(v) = x + v``."""

    def __init__(self, *shape: int) -> None:
        if not shape or any(int(n) < 1 for n in shape):
            raise ValueError(f"Euclidean: shape must be positive integers, got {shape}")
        self.point_shape = tuple(int(n) for n in shape)

    def __repr__(self) -> str:
        return f"Euclidean({', '.join(map(str, self.point_shape))})"

    @property
    def dim(self) -> int:
        return prod(self.point_shape)

    def proj(self, x: FloatArray, u: FloatArray) -> FloatArray:
        return np.asarray(u, dtype=np.float64)

    def retr(self, x: FloatArray, v: FloatArray) -> FloatArray:
        return x + v

    exp = retr

    def log(self, x: FloatArray, y: FloatArray) -> FloatArray:
        return y - x

    def dist(self, x: FloatArray, y: FloatArray) -> Any:
        return self.norm(x, y - x)

    def transp(self, x: FloatArray, y: FloatArray, v: FloatArray) -> FloatArray:
        return v

    def ehess2rhess(self, x: FloatArray, egrad: FloatArray, ehess: FloatArray, v: FloatArray) -> FloatArray:
        return np.asarray(ehess, dtype=np.float64)

    def _random_point(self, rng: np.random.Generator, batch: tuple[int, ...]) -> FloatArray:
        return rng.standard_normal(batch + self.point_shape)

    def random_tangent(self, x: FloatArray, rng: np.random.Generator | int | None = None) -> FloatArray:
        return self.unit(x, np.random.default_rng(rng).standard_normal(np.shape(x)))
