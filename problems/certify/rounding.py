"""From a point of the rank-``p`` relaxation to rotations, and back (SE-Sync's Algorithm 2).

A relaxation point is an array ``Y`` of ``n`` blocks ``Y_i ∈ St(p, d)`` (``(n, p, d)``,
orthonormal columns), the factor of ``Z = YᵀY``; rotations are the case ``p = d``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from manopt_lie.lie._matrix import project_rotation

from .data import stacked

FloatArray = NDArray[np.float64]


def lift(y: FloatArray, p: int) -> FloatArray:
    """``Y`` (``(n, q, d)``, ``q ≤ p``) as a point of rank ``p``: ``[Y_i; 0]``, the same ``YᵀY``."""
    n, q, d = y.shape
    if q > p:
        raise ValueError(f"lift: cannot lift rank {q} to the lower rank {p}")
    out = np.zeros((n, p, d))
    out[:, :q, :] = y
    return out


def round_solution(y: FloatArray) -> FloatArray:
    """Rotations ``(n, d, d)`` from a relaxation point ``Y`` (``(n, p, d)``).

    The best rank-``d`` approximation of ``Y`` (SE-Sync, Algorithm 2): with the ``d``
    leading eigenvectors ``U_d`` of the ``p × p`` matrix ``Y Yᵀ = U Σ² Uᵀ`` (the left
    singular vectors of ``Y``, without an SVD of the ``p × nd`` matrix), the blocks
    ``U_dᵀ Y_i = (Σ_d V_dᵀ)_i``; if fewer than half of them have a positive determinant
    the last row changes sign (``Y`` and its reflection give the same ``YᵀY``); then each
    block is projected onto SO(d) (``U diag(1, …, det UVᵀ) Vᵀ``). A point of rank ``d``
    is only projected (rotations come back unchanged up to round-off).
    """
    n, p, d = y.shape
    if p == d:  # Y Yᵀ = nI: any basis is a leading one, and the identity keeps Y as it is
        blocks = np.array(y)
        orthonormal = np.abs(np.swapaxes(blocks, 1, 2) @ blocks - np.eye(d)).max() <= 1e-12
        if orthonormal and np.all(np.linalg.det(blocks) > 0):
            return blocks  # already rotations: no SVD
    else:
        yt = stacked(y)
        _, u = np.linalg.eigh(yt.T @ yt)  # ascending
        blocks = u[:, ::-1][:, :d].T @ y  # U_dᵀ Y_i
    if np.count_nonzero(np.linalg.det(blocks) > 0) < n / 2:
        blocks[:, -1, :] *= -1.0
    return project_rotation(blocks)
