"""Pose graphs: SE(2)/SE(3) poses linked by noisy relative-pose measurements.

An edge ``e = (i, j)`` carries a measurement ``Z_e ≈ X_i⁻¹ X_j`` and an
information matrix ``Ω_e`` in tangent order ``(ρ, θ)`` (g2o's order).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from manopt_lie import SE2, SE3
from manopt_lie.errors import ShapeError
from manopt_lie.lie.base import LieGroup

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(frozen=True, eq=False)
class PoseGraph:
    """A pose graph with ``n`` vertices and ``m`` edges, stored as arrays.

    Parameters
    ----------
    group : SE2 or SE3
    edges : int array ``(m, 2)``
        Vertex *indices* ``(i, j)`` in ``0..n-1``.
    measurements : group element, batch ``(m,)``
        ``Z_e``, the measured ``X_i⁻¹ X_j``.
    information : ``(m, k, k)``
        Information matrices ``Ω_e``, ``k = group.dim``, tangent order ``(ρ, θ)``.
    ids : int array ``(n,)``, optional
        The vertices' ids in the source (a g2o file's, kept for writing);
        default ``0..n-1``.
    poses : group element, batch ``(n,)``, optional
        Vertex estimates from the source, if it had any.
    fixed : int array, optional
        Vertex indices held fixed by the source (g2o ``FIX``).
    name : str
    """

    group: type[LieGroup]
    edges: IntArray
    measurements: LieGroup
    information: FloatArray
    ids: IntArray | None = None
    poses: LieGroup | None = None
    fixed: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    name: str = "pose graph"

    def __post_init__(self) -> None:
        if self.group not in (SE2, SE3):
            raise TypeError(f"PoseGraph: group must be SE2 or SE3, got {self.group!r}")
        edges = np.asarray(self.edges)
        if edges.ndim != 2 or edges.shape[1] != 2 or not np.issubdtype(edges.dtype, np.integer):
            raise ShapeError(f"{self.name}: edges must be an integer array (m, 2), got {edges.shape} {edges.dtype}")
        m, k = len(edges), self.group.dim
        if not isinstance(self.measurements, self.group) or self.measurements.batch_shape != (m,):
            raise ShapeError(f"{self.name}: measurements must be {self.group.__name__} with batch shape ({m},)")
        info = np.asarray(self.information, dtype=np.float64)
        if info.shape != (m, k, k):
            raise ShapeError(f"{self.name}: information must have shape ({m}, {k}, {k}), got {info.shape}")
        if not np.all(np.isfinite(info)):
            bad = np.flatnonzero(~np.isfinite(info).all(axis=(1, 2)))
            raise ValueError(f"{self.name}: non-finite information matrix on edges {bad[:10].tolist()}")
        if self.ids is None:
            n = int(edges.max()) + 1 if m else 0
            if self.poses is not None:
                n = max(n, self.poses.batch_shape[0])
            ids = np.arange(n, dtype=np.int64)
        else:
            ids = np.asarray(self.ids, dtype=np.int64)
            if ids.ndim != 1 or len(np.unique(ids)) != len(ids):
                raise ValueError(f"{self.name}: ids must be a 1-D array of distinct integers")
        n = len(ids)
        if m and (edges.min() < 0 or edges.max() >= n):
            raise ValueError(f"{self.name}: edge indices must lie in 0..{n - 1}")
        if np.any(edges[:, 0] == edges[:, 1]):
            raise ValueError(f"{self.name}: self-loop edges {np.flatnonzero(edges[:, 0] == edges[:, 1])[:10].tolist()}")
        if self.poses is not None and (not isinstance(self.poses, self.group) or self.poses.batch_shape != (n,)):
            raise ShapeError(f"{self.name}: poses must be {self.group.__name__} with batch shape ({n},)")
        fixed = np.asarray(self.fixed, dtype=np.int64).reshape(-1)
        if fixed.size and (fixed.min() < 0 or fixed.max() >= n):
            raise ValueError(f"{self.name}: fixed vertex indices must lie in 0..{n - 1}")
        object.__setattr__(self, "edges", edges.astype(np.int64))
        object.__setattr__(self, "information", info)
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "fixed", fixed)

    @property
    def d(self) -> int:
        """The dimension of the space the poses live in (2 or 3)."""
        return int(self.group.point_dim)

    @property
    def n(self) -> int:
        """Number of vertices."""
        return len(self.ids)  # type: ignore[arg-type]

    @property
    def m(self) -> int:
        """Number of edges."""
        return len(self.edges)

    def __repr__(self) -> str:
        return f"PoseGraph({self.name!r}, {self.group.__name__}, n={self.n}, m={self.m})"
