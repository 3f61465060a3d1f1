"""Pose graphs: SE(2)/SE(3) poses linked by noisy relative-pose measurements.

An edge ``e = (i, j)`` carries a measurement ``Z_e ≈ X_i⁻¹ X_j`` and an
information matrix ``Ω_e`` in tangent order ``(ρ, θ)`` (g2o's order).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from manopt_lie import SE2, SE3
from manopt_lie.errors import ShapeError
from manopt_lie.lie._matrix import assemble
from manopt_lie.lie.base import LieGroup
from manopt_lie.manifolds import LieGroupManifold, Power
from manopt_lie.optim import LeastSquaresProblem
from manopt_lie.optim.losses import RobustLoss

from . import costs, initialization

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


COSTS = ("geodesic", "chordal")


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
    ids: IntArray = None  # type: ignore[assignment]  # default 0..n-1, set in __post_init__
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
        return len(self.ids)

    @property
    def m(self) -> int:
        """Number of edges."""
        return len(self.edges)

    def __repr__(self) -> str:
        return f"PoseGraph({self.name!r}, {self.group.__name__}, n={self.n}, m={self.m})"

    # ---- derived data --------------------------------------------------------------

    @property
    def anchor(self) -> int:
        """The vertex fixing the gauge: the first ``FIX``-ed one, else vertex 0."""
        return int(self.fixed[0]) if self.fixed.size else 0

    @property
    def manifold(self) -> Power:
        """``Power(SE(d), n)`` with the group's retraction ``X ⊕ δ``."""
        return Power(LieGroupManifold(self.group), self.n)

    @cached_property
    def se_sync_weights(self) -> tuple[FloatArray, FloatArray]:
        """SE-Sync's isotropic ``(κ, τ)`` per edge (``datasets/README.md``):
        ``τ = d / tr(Ω_tt⁻¹)``; ``κ = Ω_θθ`` (2-D) or ``3 / (2 tr(Ω_RR⁻¹))`` (3-D)."""
        return costs.se_sync_weights(self.information, self.d)

    def _chordal_weights(self) -> FloatArray:
        kappa, tau = self.se_sync_weights
        if not (np.all(kappa > 0) and np.all(tau > 0)):
            bad = np.flatnonzero(~((kappa > 0) & (tau > 0)))
            raise costs.IndefiniteInformationError(
                f"{self.name}: the chordal cost needs κ, τ > 0; not so on edges {self.edge_names(bad[:10])}"
            )
        return np.concatenate([np.repeat(np.sqrt(kappa)[:, None], self.d, axis=1), np.sqrt(tau)[:, None]], axis=1)

    def edge_names(self, edges: Any) -> list[str]:
        """``"i→j"`` in the source's vertex ids, for messages."""
        ij = self.ids[self.edges[np.asarray(edges, dtype=np.int64)]]
        return [f"{a}→{b}" for a, b in ij]

    # ---- costs and problems --------------------------------------------------------

    def cost(self, x: LieGroup, cost: str = "geodesic") -> float:
        """The CONVENTIONS §8 value at poses ``x``: geodesic ``½ Σ rᵀΩr``,
        ``r = Log(Z⁻¹ X_i⁻¹ X_j)``, or chordal ``Σ κ‖R_j − R_i R̃‖² + τ‖t_j − t_i − R_i t̃‖²``."""
        self.manifold.check_point(x)
        if cost == "geodesic":
            return costs.geodesic_cost(x, self.edges, self.measurements, self.information)
        if cost == "chordal":
            return costs.chordal_cost(x, self.edges, self.measurements, self._chordal_weights())
        raise ValueError(f"cost must be one of {COSTS}, got {cost!r}")

    def problem(
        self,
        cost: str = "geodesic",
        *,
        robust: RobustLoss | str | None = None,
        repair_information: bool = False,
    ) -> LeastSquaresProblem:
        """The least-squares problem on ``Power(SE(d), n)`` with the anchor fixed.

        Parameters
        ----------
        cost : {"geodesic", "chordal"}
            The objective is exactly :meth:`cost`. The chordal problem carries its
            exact Riemannian Hessian (without a robust loss), so
            :class:`~manopt_lie.optim.TrustRegion` runs on the true model; every
            least-squares problem also offers the Gauss-Newton model.
        robust : RobustLoss or str, optional
            A robust loss on each edge's squared residual, e.g. ``"huber:1.0"``.
        repair_information : bool
            The geodesic cost needs positive definite ``Ω``; by default edges
            that are not raise :class:`~problems.costs.IndefiniteInformationError`
            naming them. ``True`` replaces them by the nearest positive definite
            matrix (eigenvalues clipped at ``1e-9 λ_max``). The chordal cost only
            needs ``κ, τ > 0``.
        """
        fixed = np.array([self.anchor])
        if cost == "geodesic":
            sqrt_info = costs.information_sqrt(self.information, _Names(self), repair=repair_information)
            factor = costs.geodesic_factor(self.edges, self.measurements, sqrt_info, robust)
            return LeastSquaresProblem(self.manifold, [factor], fixed=fixed)
        if cost == "chordal":
            weights = self._chordal_weights()
            factor = costs.chordal_factor(self.edges, self.measurements, weights, robust)
            hessian = None
            if robust is None:
                hessian = costs.ChordalHessian(self.manifold, self.edges, self.measurements, weights, fixed)
            return LeastSquaresProblem(self.manifold, [factor], fixed=fixed, hessian=hessian)
        raise ValueError(f"cost must be one of {COSTS}, got {cost!r}")

    # ---- initializations -----------------------------------------------------------

    def _in_source_frame(self, x: LieGroup) -> LieGroup:
        """Move the anchor to its pose in the source (if the source had poses)."""
        if self.poses is None:
            return x
        return self.poses[self.anchor] @ x[self.anchor].inverse() @ x  # type: ignore[operator]

    def odometry_initialization(self) -> LieGroup:
        """Poses composed along a spanning tree from the anchor, preferring odometry
        edges ``(i, i+1)`` (see :func:`problems.initialization.spanning_tree`)."""
        initialization.check_connected(self.n, self.edges, self.ids, self.anchor)
        x = initialization.spanning_tree(self.group, self.n, self.edges, self.measurements, self.anchor)
        return self._in_source_frame(x)

    def chordal_initialization(self) -> LieGroup:
        """Carlone et al. (2015): rotations from the linear least squares relaxation of
        ``Σ κ‖R_j − R_i R̃‖²`` projected onto SO(d), then translations from the linear
        least squares ``Σ τ‖t_j − t_i − R_i t̃‖²``, with SE-Sync's ``κ, τ`` (their magnitudes, so that
        graphs with indefinite information matrices still initialize)."""
        initialization.check_connected(self.n, self.edges, self.ids, self.anchor)
        kappa, tau = self.se_sync_weights
        z, d = self.measurements.as_matrix(), self.d
        r = initialization.chordal_rotations(self.n, self.edges, z[:, :d, :d], np.abs(kappa), self.anchor)
        t = initialization.chordal_translations(self.n, self.edges, r, z[:, :d, d], np.abs(tau), self.anchor)
        x = self.group.from_matrix(assemble(r, t))
        return self._in_source_frame(x)

    # ---- checks --------------------------------------------------------------------

    def validate(self) -> Any:
        """A :class:`problems.g2o.LintReport`: indefinite information matrices,
        duplicate edges, isolated vertices, connectivity."""
        from .g2o import lint

        return lint(self)


class _Names:
    """Lazy ``names[e]`` → ``"i→j"`` in source ids, for error messages."""

    def __init__(self, graph: PoseGraph) -> None:
        self.graph = graph

    def __getitem__(self, e: int) -> str:
        return self.graph.edge_names([e])[0]
