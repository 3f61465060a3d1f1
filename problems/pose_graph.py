"""Pose graphs: SE(2)/SE(3) poses linked by noisy relative-pose measurements.

An edge ``e = (i, j)`` carries a measurement ``Z_e ≈ X_i⁻¹ X_j`` and an
information matrix ``Ω_e`` in tangent order ``(ρ, θ)`` (g2o's order).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from manopt_lie import SE2, SE3
from manopt_lie.errors import ShapeError
from manopt_lie.lie.base import LieGroup

from . import costs
from .graph import MeasurementGraph

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(frozen=True, eq=False, repr=False)
class PoseGraph(MeasurementGraph):
    """A pose graph with ``n`` vertices and ``m`` edges, stored as arrays.

    Costs (CONVENTIONS §8): ``"geodesic"`` (the default; GTSAM's error) and
    ``"chordal"`` (SE-Sync's); see :class:`~manopt_lie.problems.graph.MeasurementGraph`.

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
    edge_lines : int array ``(m,)``, optional
        The line of each edge in its source file (messages name them).
    """

    kind: ClassVar[str] = "pose-graph"
    noun: ClassVar[str] = "poses"
    costs: ClassVar[tuple[str, ...]] = ("geodesic", "chordal")

    group: type[LieGroup]
    edges: IntArray
    measurements: LieGroup
    information: FloatArray  # type: ignore[misc]  # a field here, an abstract property in the base
    ids: IntArray = None  # type: ignore[assignment]  # default 0..n-1, set in __post_init__
    poses: LieGroup | None = None
    fixed: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    name: str = "pose graph"
    edge_lines: IntArray | None = None

    def __post_init__(self) -> None:
        self._validate((SE2, SE3), None, allow_empty=True)
        m, k = self.m, self.group.dim
        info = np.asarray(self.information, dtype=np.float64)
        if info.shape != (m, k, k):
            raise ShapeError(f"{self.name}: information must have shape ({m}, {k}, {k}), got {info.shape}")
        if not np.all(np.isfinite(info)):
            bad = np.flatnonzero(~np.isfinite(info).all(axis=(1, 2)))
            names = ", ".join(self.edge_names(bad[:10]))
            raise costs.InformationMatrixError(
                f"{self.name}: non-finite information matrices on {bad.size} edges: {names}"
            )
        object.__setattr__(self, "information", info)

    @property
    def estimates(self) -> LieGroup | None:
        """The source's vertex poses (:attr:`poses`)."""
        return self.poses

    @cached_property
    def se_sync_weights(self) -> tuple[FloatArray, FloatArray]:
        """SE-Sync's isotropic ``(κ, τ)`` per edge (``datasets/README.md``):
        ``τ = d / tr(Ω_tt⁻¹)``; ``κ = Ω_θθ`` (2-D) or ``3 / (2 tr(Ω_RR⁻¹))`` (3-D)."""
        return costs.se_sync_weights(self.information, self.d)

    def chordal_parameters(self) -> tuple[FloatArray, FloatArray]:
        return self.se_sync_weights

    def to_g2o(self, x: LieGroup) -> tuple[PoseGraph, LieGroup]:
        """This graph with the poses ``x``."""
        return self, x

    def pose_graph(self) -> PoseGraph:
        return self
