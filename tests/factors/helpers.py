"""Central finite differences of factors, through ``X ⊕ δ`` for group points and ``+`` for vectors."""

from __future__ import annotations

from typing import Any

import numpy as np

from manopt_lie.lie import LieGroup
from manopt_lie.optim import Factor


def tangent_dim(x: Any) -> int:
    return x.dim if isinstance(x, LieGroup) else np.shape(x)[-1]


def perturb(x: Any, delta: np.ndarray) -> Any:
    """``x ⊕ δ`` for group elements (``Rn`` included), ``x + δ`` for arrays."""
    return x.rplus(delta) if isinstance(x, LieGroup) else np.asarray(x) + delta


def numeric_jacobians(factor: Factor, points: list[Any], h: float = 1e-6) -> list[np.ndarray]:
    """``(r(x ⊕ h e_k) − r(x ⊕ −h e_k)) / 2h`` per slot and coordinate, ``(m, k, d)`` per slot."""
    out = []
    for s, x in enumerate(points):
        m, d = len(x), tangent_dim(x)
        columns = []
        for k in range(d):
            e = np.zeros((m, d))
            e[:, k] = h
            plus = [perturb(p, e) if i == s else p for i, p in enumerate(points)]
            minus = [perturb(p, -e) if i == s else p for i, p in enumerate(points)]
            columns.append((factor.residual(*plus, jac=False) - factor.residual(*minus, jac=False)) / (2 * h))
        out.append(np.stack(columns, axis=-1))
    return out


def assert_jacobians(factor: Factor, points: list[Any], tol: float = 1e-6, h: float = 1e-6) -> None:
    """The factor's Jacobians match central differences to ``tol`` relative to ``max(1, |J|)``;
    the residual of ``jac=True`` is the residual of ``jac=False``; everything finite."""
    r, jacobians = factor.residual(*points, jac=True)
    r_plain = factor.residual(*points, jac=False)
    np.testing.assert_array_equal(r, r_plain)
    assert np.isfinite(r).all()
    assert len(jacobians) == len(points)
    for s, (j, fd) in enumerate(zip(jacobians, numeric_jacobians(factor, points, h), strict=True)):
        assert j.shape == fd.shape == (len(r), r.shape[1], tangent_dim(points[s])), (j.shape, fd.shape)
        assert np.isfinite(j).all()
        scale = np.maximum(1.0, np.abs(j).max(axis=(1, 2), keepdims=True))
        err = np.abs(j - fd) / scale
        assert err.max() < tol, (
            f"slot {s}: max relative error {err.max():.2e} at edge {np.unravel_index(err.argmax(), err.shape)}"
        )
