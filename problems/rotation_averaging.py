"""Rotation averaging: SO(2)/SO(3) rotations from noisy relative rotations.

An edge ``e = (i, j)`` carries a measurement ``R̃_e ≈ R_iᵀ R_j`` and a weight
``κ_e > 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from manopt_lie import SO2, SO3
from manopt_lie.errors import ShapeError
from manopt_lie.lie.base import LieGroup

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(frozen=True, eq=False)
class RotationAveraging:
    """A rotation-averaging instance with ``n`` rotations and ``m`` relative measurements.

    Parameters
    ----------
    group : SO2 or SO3
    edges : int array ``(m, 2)``
        Vertex indices ``(i, j)`` in ``0..n-1``.
    measurements : group element, batch ``(m,)``
        ``R̃_e``, the measured ``R_iᵀ R_j``.
    kappa : ``(m,)``, optional
        Positive weights ``κ_e`` (default 1).
    n : int, optional
        Number of rotations (default ``max(edges) + 1``).
    name : str
    """

    group: type[LieGroup]
    edges: IntArray
    measurements: LieGroup
    kappa: FloatArray | None = None
    n: int = -1
    name: str = "rotation averaging"

    def __post_init__(self) -> None:
        if self.group not in (SO2, SO3):
            raise TypeError(f"RotationAveraging: group must be SO2 or SO3, got {self.group!r}")
        edges = np.asarray(self.edges)
        if edges.ndim != 2 or edges.shape[1] != 2 or not np.issubdtype(edges.dtype, np.integer) or not len(edges):
            raise ShapeError(f"{self.name}: edges must be a non-empty integer array (m, 2), got {edges.shape}")
        m = len(edges)
        if not isinstance(self.measurements, self.group) or self.measurements.batch_shape != (m,):
            raise ShapeError(f"{self.name}: measurements must be {self.group.__name__} with batch shape ({m},)")
        kappa = np.ones(m) if self.kappa is None else np.asarray(self.kappa, dtype=np.float64)
        if kappa.shape != (m,):
            raise ShapeError(f"{self.name}: kappa must have shape ({m},), got {kappa.shape}")
        if not np.all(np.isfinite(kappa) & (kappa > 0)):
            bad = np.flatnonzero(~(np.isfinite(kappa) & (kappa > 0)))
            raise ValueError(f"{self.name}: kappa must be finite and positive (edges {bad[:10].tolist()})")
        n = int(edges.max()) + 1 if self.n < 0 else int(self.n)
        if edges.min() < 0 or edges.max() >= n:
            raise ValueError(f"{self.name}: edge indices must lie in 0..{n - 1}")
        if np.any(edges[:, 0] == edges[:, 1]):
            raise ValueError(f"{self.name}: self-loop edges {np.flatnonzero(edges[:, 0] == edges[:, 1])[:10].tolist()}")
        object.__setattr__(self, "edges", edges.astype(np.int64))
        object.__setattr__(self, "kappa", kappa)
        object.__setattr__(self, "n", n)

    @property
    def d(self) -> int:
        """2 or 3."""
        return int(self.group.point_dim)

    @property
    def m(self) -> int:
        return len(self.edges)

    def __repr__(self) -> str:
        return f"RotationAveraging({self.name!r}, {self.group.__name__}, n={self.n}, m={self.m})"
