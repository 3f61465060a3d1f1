"""What every synthetic generator shares: the :class:`Instance` it returns, argument
checks, the noise and outlier model (see :mod:`manopt_lie.problems.synthetic`)."""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from manopt_lie.lie.base import LieGroup

from .. import evaluation
from ..graph import MeasurementGraph
from ..pose_graph import PoseGraph

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]
Orientation = Literal["path", "random"]

EXACT_WEIGHT = 1.0
"""Information weight of a noise-free component (``σ = 0``), and ``κ`` of noise-free rotation averaging."""

DEFAULT_TRANSLATION_NOISE = 0.05  # metres
"""Standard deviation ``σ_t`` (metres) of the translation noise of each measurement, per axis."""
DEFAULT_ROTATION_NOISE = 0.01  # radians
"""Standard deviation ``σ_R`` (radians) of the rotation noise, ``R̃ = R·Exp(ε)``, ``ε ~ N(0, σ_R² I)``."""


@dataclass(frozen=True, eq=False)
class Instance:
    """A synthetic problem with its ground truth.

    Attributes
    ----------
    graph : PoseGraph or RotationAveraging (a MeasurementGraph)
        The problem; its measurements were sampled from ``truth``.
    truth : group element, batch ``(n,)``
        The ground-truth poses or rotations.
    outliers : bool ``(m,)``
        Edges whose measurement was replaced by a random one.
    params : dict
        The generator's arguments (including ``seed``).
    backbone : bool ``(m,)``
        Edges guaranteeing connectivity (odometry, or a Hamiltonian path), never outliers.
    """

    graph: MeasurementGraph
    truth: LieGroup
    outliers: BoolArray
    params: dict[str, Any]
    backbone: BoolArray

    @property
    def n(self) -> int:
        """Number of variables (poses or rotations) of the graph."""
        return self.graph.n

    @property
    def m(self) -> int:
        """Number of measurements (edges) of the graph."""
        return self.graph.m

    def errors(self, estimate: LieGroup) -> evaluation.Errors:
        """Per-element rotation (rad) and translation errors of ``estimate`` after the
        best global alignment to :attr:`truth` (:func:`problems.evaluation.errors`)."""
        return evaluation.errors(estimate, self.truth)

    def __repr__(self) -> str:
        return f"Instance({self.graph!r}, outliers={int(self.outliers.sum())})"


# ---- argument checks ----------------------------------------------------------------


def _size(name: str, value: Any, minimum: int = 2) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be an integer ≥ {minimum}, got {value!r}")
    if value < minimum:
        raise ValueError(f"{name} must be ≥ {minimum}, got {value}")
    return int(value)


def _real(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite real number, got {value!r}")
    return float(value)


def _probability(name: str, value: Any) -> float:
    p = _real(name, value)
    if not 0.0 <= p <= 1.0:
        raise ValueError(f"{name} must lie in [0, 1], got {value}")
    return p


def _nonnegative(name: str, value: Any) -> float:
    x = _real(name, value)
    if x < 0.0:
        raise ValueError(f"{name} must be ≥ 0, got {value}")
    return x


def _positive(name: str, value: Any) -> float:
    x = _real(name, value)
    if x <= 0.0:
        raise ValueError(f"{name} must be > 0, got {value}")
    return x


def _orientation(value: Any) -> Orientation:
    if value not in ("path", "random"):
        raise ValueError(f"orientation must be 'path' or 'random', got {value!r}")
    return value  # type: ignore[no-any-return]


def _check_noise(params: dict[str, Any]) -> None:
    _nonnegative("translation_noise", params["translation_noise"])
    _nonnegative("rotation_noise", params["rotation_noise"])
    _probability("outlier_rate", params["outlier_rate"])
    _probability("loop_closure_probability", params["loop_closure_probability"])


# ---- shared machinery ---------------------------------------------------------------


def _weights(sigma: FloatArray) -> FloatArray:
    """``1/σ²``, and :data:`EXACT_WEIGHT` where ``σ = 0``."""
    return np.where(sigma > 0, 1.0 / np.where(sigma > 0, sigma, 1.0) ** 2, EXACT_WEIGHT)


def _replace(measurements: LieGroup, mask: BoolArray, values: LieGroup) -> LieGroup:
    """``measurements`` with the entries under ``mask`` replaced, in order, by ``values``."""
    index = np.arange(len(mask))
    index[mask] = len(mask) + np.arange(int(mask.sum()))
    return type(measurements).concatenate([measurements, values])[index]


def _sorted_pairs(pairs: IntArray) -> IntArray:
    """Rows ``(min, max)``, in lexicographic order."""
    pairs = np.sort(pairs, axis=1)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def _trajectory_instance(
    group: type[LieGroup],
    rotations: LieGroup,
    positions: FloatArray,
    candidates: IntArray,
    rng: np.random.Generator,
    name: str,
    params: dict[str, Any],
) -> Instance:
    """Poses along a trajectory ``0, 1, …, n−1``: odometry ``(k, k+1)`` plus each loop-closure
    candidate kept with ``loop_closure_probability``; noise and outliers as in the module doc."""
    n, d = positions.shape
    truth = group.from_rotation_translation(rotations, positions)  # type: ignore[attr-defined]
    candidates = _sorted_pairs(candidates)
    closures = candidates[rng.random(len(candidates)) < params["loop_closure_probability"]]
    odometry = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    edges = np.concatenate([odometry, closures]).astype(np.int64)
    m, k = len(edges), group.dim
    backbone = np.arange(m) < n - 1

    sigma = np.repeat([params["translation_noise"], params["rotation_noise"]], [d, k - d]).astype(np.float64)
    measurements = truth[edges[:, 0]].between(truth[edges[:, 1]]).rplus(rng.standard_normal((m, k)) * sigma)

    outliers = ~backbone & (rng.random(m) < params["outlier_rate"])
    count = int(outliers.sum())
    extent = np.ptp(positions, axis=0)
    wild = group.from_rotation_translation(  # type: ignore[attr-defined]
        group.rotation_group.random(rng, (count,)),  # type: ignore[attr-defined]
        rng.uniform(-extent, extent, (count, d)),
    )
    measurements = _replace(measurements, outliers, wild)

    information = np.broadcast_to(np.diag(_weights(sigma)), (m, k, k)).copy()
    graph = PoseGraph(group, edges, measurements, information, name=name)
    return Instance(graph, truth, outliers, params, backbone)
