"""Uncertainty on Lie groups: Gaussians ``X = X̄ ⊕ τ``, ``τ ~ N(0, P)`` (Solà et al., §III).

Covariances live in the tangent space at the mean. With the default right
(local) perturbation ``X = X̄·Exp(τ)``; the left (global) one ``X = Exp(τ)·X̄``
has covariance ``Ad_X̄ P Ad_X̄ᵀ``.
"""

from __future__ import annotations

import warnings
from typing import TypeVar

import numpy as np
from numpy.typing import ArrayLike

from ..errors import IndefiniteMatrixError, ShapeError
from ._checks import FloatArray, as_batch
from .base import LieGroup

G = TypeVar("G", bound=LieGroup)


def _square(p: ArrayLike, n: int, name: str) -> FloatArray:
    return as_batch(p, (n, n), name)


def propagate_covariance(J: ArrayLike, P: ArrayLike) -> FloatArray:
    """First-order propagation ``J P Jᵀ``, batched and broadcast.

    ``J`` is ``(..., m, n)``, ``P`` is ``(..., n, n)``; the result is ``(..., m, m)``.
    """
    j = np.asarray(J, dtype=np.float64)
    if j.ndim < 2:
        raise ShapeError(f"J: expected shape (..., m, n), got {j.shape}")
    j = as_batch(j, j.shape[-2:], "J")
    p = _square(P, j.shape[-1], "P")
    return j @ p @ np.swapaxes(j, -1, -2)


def _sqrt_psd(p: FloatArray, name: str) -> FloatArray:
    """``L`` with ``L Lᵀ = P`` for symmetric positive semidefinite ``P`` (via ``eigh``)."""
    asym = np.abs(p - np.swapaxes(p, -1, -2)).max(initial=0.0)
    w, v = np.linalg.eigh(p)
    scale = np.maximum(np.abs(w).max(axis=-1, keepdims=True), 1e-300)
    if asym > 1e-9 * scale.max() or (w < -1e-12 * scale).any():
        raise IndefiniteMatrixError(f"{name}: not symmetric positive semidefinite")
    return v * np.sqrt(np.clip(w, 0.0, None))[..., None, :]


def sample(mean: G, cov: ArrayLike, rng: np.random.Generator | int | None, size: tuple[int, ...] = ()) -> G:
    """Draw ``X̄ ⊕ τ`` with ``τ ~ N(0, P)`` in the tangent space at ``X̄``.

    Returns an element of batch shape ``size + broadcast(X̄.batch_shape, P.shape[:-2])``.
    """
    p = _square(cov, mean.dim, "cov")
    root = _sqrt_psd(p, "cov")
    batch = np.broadcast_shapes(mean.batch_shape, p.shape[:-2])
    z = np.random.default_rng(rng).standard_normal(tuple(size) + batch + (mean.dim,))
    return mean.rplus(np.einsum("...ij,...j->...i", root, z))


def mean_and_covariance(
    samples: G, axis: int = 0, *, max_iterations: int = 100, tol: float = 1e-12, ddof: int = 0
) -> tuple[G, FloatArray]:
    """Tangent-space mean and covariance of samples along a batch ``axis``.

    Iterates ``X̄ ← X̄ ⊕ mean_i(X_i ⊖ X̄)`` (the Karcher/Fréchet mean for the
    right-invariant chart) from the first sample until the step is below
    ``tol``; then ``P = Σ τ_i τ_iᵀ / (N − ddof)`` with ``τ_i = X_i ⊖ X̄``.
    """
    n_batch = len(samples.batch_shape)
    if not -n_batch <= axis < n_batch:
        raise ShapeError(f"axis {axis} out of range for batch shape {samples.batch_shape}")
    ax = axis % n_batch
    data = np.moveaxis(samples.data, ax, 0)
    xs = type(samples)._wrap(data)
    n = data.shape[0]
    if n - ddof <= 0:
        raise ValueError(f"mean_and_covariance: need more than ddof={ddof} samples, got {n}")
    mean = xs[0]
    for _ in range(max_iterations):
        step = xs.rminus(mean).mean(axis=0)
        mean = mean.rplus(step)
        if np.abs(step).max(initial=0.0) <= tol:
            break
    else:
        message = f"mean_and_covariance: not converged in {max_iterations} iterations"
        warnings.warn(message, RuntimeWarning, stacklevel=2)
    tau = xs.rminus(mean)
    cov = np.einsum("n...i,n...j->...ij", tau, tau) / (n - ddof)
    return mean, cov


def right_to_left_covariance(x: LieGroup, cov: ArrayLike) -> FloatArray:
    """``Ad_X P Ad_Xᵀ``: covariance of a right perturbation expressed as a left one."""
    ad = x.adjoint()
    return ad @ _square(cov, x.dim, "cov") @ np.swapaxes(ad, -1, -2)


def left_to_right_covariance(x: LieGroup, cov: ArrayLike) -> FloatArray:
    """``Ad_X⁻¹ P Ad_X⁻ᵀ``: the inverse of :func:`right_to_left_covariance`."""
    return right_to_left_covariance(x.inverse(), cov)
