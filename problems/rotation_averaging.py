"""Rotation averaging: SO(2)/SO(3) rotations from noisy relative rotations.

An edge ``e = (i, j)`` carries a measurement ``R̃_e ≈ R_iᵀ R_j`` and a weight
``κ_e > 0``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from manopt_lie import SO2, SO3
from manopt_lie.errors import ShapeError
from manopt_lie.lie.base import LieGroup
from manopt_lie.manifolds import LieGroupManifold, Power
from manopt_lie.optim import LeastSquaresProblem
from manopt_lie.optim.losses import RobustLoss

from . import costs, initialization

if TYPE_CHECKING:
    from .pose_graph import PoseGraph

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


COSTS = ("chordal", "geodesic")


@dataclass(frozen=True, eq=False)
class RotationAveraging:
    """A rotation-averaging instance with ``n`` rotations and ``m`` relative measurements.

    Costs (CONVENTIONS §8): chordal ``Σ κ‖R_j − R_i R̃‖_F²`` and geodesic
    ``½ Σ κ‖Log(R̃⁻¹R_iᵀR_j)‖²``; robust variants apply a loss to each edge's
    squared residual (``"huber:0.1"``, or ``"l1:0.01"`` for the L1 averaging of
    Chatterjee & Govindu by IRLS). Rotation ``0`` fixes the gauge.

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
    kappa: FloatArray = None  # type: ignore[assignment]  # default: ones, set in __post_init__
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

    @property
    def manifold(self) -> Power:
        return Power(LieGroupManifold(self.group), self.n)

    def _weights(self) -> FloatArray:
        return np.repeat(np.sqrt(self.kappa)[:, None], self.d, axis=1)

    def cost(self, x: LieGroup, cost: str = "chordal") -> float:
        """The CONVENTIONS §8 value at rotations ``x``."""
        self.manifold.check_point(x)
        if cost == "chordal":
            return costs.chordal_cost(x, self.edges, self.measurements, self._weights())
        if cost == "geodesic":
            r = costs.geodesic_residuals(x, self.edges, self.measurements)
            return 0.5 * float(np.sum(self.kappa * np.einsum("ei,ei->e", r, r)))
        raise ValueError(f"cost must be one of {COSTS}, got {cost!r}")

    def problem(self, cost: str = "chordal", *, robust: RobustLoss | str | None = None) -> LeastSquaresProblem:
        """The least-squares problem on ``Power(SO(d), n)`` with rotation 0 fixed; the
        chordal one (without a robust loss) carries its exact Riemannian Hessian."""
        fixed = np.array([0])
        if cost == "chordal":
            w = self._weights()
            factor = costs.chordal_factor(self.edges, self.measurements, w, robust)
            hessian = (
                None
                if robust is not None
                else costs.ChordalHessian(self.manifold, self.edges, self.measurements, w, fixed)
            )
            return LeastSquaresProblem(self.manifold, [factor], fixed=fixed, hessian=hessian)
        if cost == "geodesic":
            sqrt_info = np.sqrt(self.kappa)[:, None, None] * np.eye(self.group.dim)
            factor = costs.geodesic_factor(self.edges, self.measurements, sqrt_info, robust)
            return LeastSquaresProblem(self.manifold, [factor], fixed=fixed)
        raise ValueError(f"cost must be one of {COSTS}, got {cost!r}")

    def chordal_initialization(self) -> LieGroup:
        """Linear least squares on the rotation entries, projected onto SO(d)
        (:func:`problems.initialization.chordal_rotations`), rotation 0 at ``I``."""
        r = initialization.chordal_rotations(self.n, self.edges, self.measurements.as_matrix(), self.kappa)
        return self.group.from_matrix(r)

    def spanning_tree_initialization(self) -> LieGroup:
        """Rotations composed along a spanning tree from rotation 0."""
        return initialization.spanning_tree(self.group, self.n, self.edges, self.measurements)


def from_pose_graph(graph: PoseGraph) -> RotationAveraging:
    """The rotation part of a pose graph, with SE-Sync's rotation weights ``κ``."""
    kappa, _ = graph.se_sync_weights
    d = graph.d
    group = SO2 if d == 2 else SO3
    rotations = group.from_matrix(graph.measurements.as_matrix()[:, :d, :d])
    return RotationAveraging(group, graph.edges, rotations, kappa, n=graph.n, name=f"{graph.name} (rotations)")
