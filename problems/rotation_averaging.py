"""Rotation averaging: SO(2)/SO(3) rotations from noisy relative rotations.

An edge ``e = (i, j)`` carries a measurement ``R̃_e ≈ R_iᵀ R_j`` and a weight
``κ_e > 0``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from manopt_lie import SO2, SO3
from manopt_lie.errors import ShapeError
from manopt_lie.lie.base import LieGroup

from .costs import InformationMatrixError
from .graph import MeasurementGraph
from .pose_graph import PoseGraph

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(frozen=True, eq=False, repr=False)
class RotationAveraging(MeasurementGraph):
    """A rotation-averaging instance with ``n`` rotations and ``m`` relative measurements.

    Costs (CONVENTIONS §8): chordal ``Σ κ‖R_j − R_i R̃‖_F²`` (the default) and geodesic
    ``½ Σ κ‖Log(R̃⁻¹R_iᵀR_j)‖²`` (``Ω_e = κ_e I``); robust variants apply a loss to each
    edge's squared residual (``"huber:0.1"``, or ``"l1:0.01"`` for the L1 averaging of
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
    rotations : group element, batch ``(n,)``, optional
        Vertex estimates from the source.
    source : PoseGraph, optional
        The pose graph whose rotations these are (:func:`from_pose_graph`): a solution is
        written back into it, keeping its translations.
    """

    kind: ClassVar[str] = "rotation-averaging"
    noun: ClassVar[str] = "rotations"
    costs: ClassVar[tuple[str, ...]] = ("chordal", "geodesic")

    group: type[LieGroup]
    edges: IntArray
    measurements: LieGroup
    kappa: FloatArray = None  # type: ignore[assignment]  # default: ones, set in __post_init__
    n: int = -1  # type: ignore[assignment]  # a field here, a property in the base
    name: str = "rotation averaging"
    rotations: LieGroup | None = None
    source: PoseGraph | None = None
    ids: IntArray = field(default=None, repr=False)  # type: ignore[arg-type]  # default 0..n-1
    fixed: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64), repr=False)
    edge_lines: IntArray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        n = self._validate((SO2, SO3), None if self.n < 0 else int(self.n), allow_empty=False)
        object.__setattr__(self, "n", n)
        m = self.m
        kappa = np.ones(m) if self.kappa is None else np.asarray(self.kappa, dtype=np.float64)
        if kappa.shape != (m,):
            raise ShapeError(f"{self.name}: kappa must have shape ({m},), got {kappa.shape}")
        if not np.all(np.isfinite(kappa) & (kappa > 0)):
            bad = np.flatnonzero(~(np.isfinite(kappa) & (kappa > 0)))
            raise InformationMatrixError(
                f"{self.name}: kappa must be finite and positive; not so on {bad.size} edges: "
                f"{', '.join(self.edge_names(bad[:10]))}"
            )
        object.__setattr__(self, "kappa", kappa)

    @property
    def estimates(self) -> LieGroup | None:
        """The source's vertex rotations (:attr:`rotations`)."""
        return self.rotations

    @property
    def information(self) -> FloatArray:  # type: ignore[override]  # a field in the base's other kinds
        """``Ω_e = κ_e I``: the geodesic cost is ``½ Σ κ‖Log(R̃⁻¹R_iᵀR_j)‖²``."""
        return self.kappa[:, None, None] * np.eye(self.group.dim)

    def chordal_parameters(self) -> tuple[FloatArray, None]:
        return self.kappa, None

    def to_g2o(self, x: LieGroup) -> tuple[PoseGraph, LieGroup]:
        """The source pose graph with its poses' rotations replaced by ``x`` and their
        translations kept.

        Raises
        ------
        ValueError
            Without a source pose graph with vertex poses: the solution has no
            translations a g2o file could carry.
        """
        source = self.source
        if source is None or source.poses is None:
            raise ValueError(
                f"{self.name}: a rotation-averaging solution is written back into its source's poses, "
                "and there are none (no pose graph, or a file without VERTEX lines)"
            )
        matrices = np.array(source.poses.as_matrix())
        matrices[:, : self.d, : self.d] = x.as_matrix()
        return source, source.group.from_matrix(matrices)


def from_pose_graph(graph: PoseGraph) -> RotationAveraging:
    """The rotation part of a pose graph, with SE-Sync's rotation weights ``κ``; it keeps the
    graph's ids, anchor and (rotations of its) poses."""
    kappa, _ = graph.se_sync_weights
    d = graph.d
    group = SO2 if d == 2 else SO3
    rotations = group.from_matrix(graph.measurements.as_matrix()[:, :d, :d])
    estimates = None if graph.poses is None else graph.poses.rotation()  # type: ignore[attr-defined]
    return RotationAveraging(
        group, graph.edges, rotations, kappa, n=graph.n, name=f"{graph.name} (rotations)", rotations=estimates,
        source=graph, ids=graph.ids, fixed=graph.fixed, edge_lines=graph.edge_lines,
    )  # fmt: skip
