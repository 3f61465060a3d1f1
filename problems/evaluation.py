"""Errors against ground truth up to the gauge, and per-edge residual statistics.

Estimates of relative-measurement problems are defined up to a global motion
``X_i ↦ G X_i``. :func:`align` finds the best ``G``: its rotation solves the
Procrustes problem ``min_R Σ‖R R̂_i − R_i‖_F²``, i.e. ``R = proj_SO(Σ R_i R̂_iᵀ)``,
and its translation then matches the centroids of the positions.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from manopt_lie.errors import ShapeError
from manopt_lie.lie._matrix import project_rotation
from manopt_lie.lie.base import LieGroup

from . import costs

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Stats:
    """Summary of non-negative errors."""

    rms: float
    mean: float
    median: float
    max: float

    @classmethod
    def of(cls, e: FloatArray) -> Stats:
        return cls(float(np.sqrt(np.mean(e**2))), float(np.mean(e)), float(np.median(e)), float(np.max(e)))


@dataclass(frozen=True)
class Errors:
    """Per-element errors after alignment: rotation angles (radians) and, for poses,
    translation distances."""

    rotation: FloatArray
    translation: FloatArray | None

    @property
    def rotation_stats(self) -> Stats:
        return Stats.of(self.rotation)

    @property
    def translation_stats(self) -> Stats | None:
        return None if self.translation is None else Stats.of(self.translation)


def _rotation_part(x: LieGroup) -> FloatArray:
    d = x.point_dim  # type: ignore[attr-defined]
    return x.as_matrix()[..., :d, :d]


def align(estimate: LieGroup, truth: LieGroup) -> LieGroup:
    """``G · estimate`` for the global motion ``G`` closest to ``truth`` (see module doc)."""
    if type(estimate) is not type(truth) or estimate.batch_shape != truth.batch_shape or len(estimate.batch_shape) != 1:
        raise ShapeError(f"align: need two batches (n,) of one group, got {estimate!r} and {truth!r}")
    r_est, r_true = _rotation_part(estimate), _rotation_part(truth)
    rot = project_rotation(np.einsum("nij,nkj->ik", r_true, r_est))
    d = rot.shape[0]
    g = np.eye(estimate.as_matrix().shape[-1])
    g[:d, :d] = rot
    if g.shape[0] > d:  # poses: match the centroids of the positions
        g[:d, d] = np.mean(truth.as_matrix()[:, :d, d] - estimate.as_matrix()[:, :d, d] @ rot.T, axis=0)
    return type(estimate).from_matrix(g) @ estimate


def errors(estimate: LieGroup, truth: LieGroup) -> Errors:
    """Rotation angles ``|Log(R_iᵀ R̂_i)|`` and translation distances ``‖t̂_i − t_i‖`` after :func:`align`."""
    aligned = align(estimate, truth)
    rotations = getattr(type(truth), "rotation_group", type(truth))
    r_rel = np.einsum("nji,njk->nik", _rotation_part(truth), _rotation_part(aligned))
    angle = np.linalg.norm(rotations.from_matrix(r_rel).log(), axis=-1)
    d = r_rel.shape[-1]
    translation = None
    if aligned.as_matrix().shape[-1] > d:
        translation = np.linalg.norm(aligned.as_matrix()[:, :d, d] - truth.as_matrix()[:, :d, d], axis=1)
    return Errors(angle, translation)


def edge_residuals(graph: Any, x: LieGroup) -> dict[str, Any]:
    """Per-edge whitened residual norms ``‖Lᵀr_e‖`` of a measurement graph at ``x``
    (geodesic residuals ``r_e = Log(Z_e⁻¹X_i⁻¹X_j)``, ``Ω_e = L Lᵀ`` its
    ``information``), with summary statistics and the ``chi2`` value ``Σ rᵀΩr`` —
    large entries point at outliers."""
    r = costs.geodesic_residuals(x, graph.edges, graph.measurements)
    chi2 = np.einsum("ei,eij,ej->e", r, graph.information, r)
    norms = np.sqrt(np.maximum(chi2, 0.0))
    return {"norms": norms, "stats": Stats.of(norms), "chi2": float(np.sum(chi2))}
