"""The fused kernel of the between factor on SE(2) and SE(3): residuals, right Jacobians and
whitening of all edges in one pass, the Jacobians of both slots side by side in one array.

With ``Y = X_i⁻¹ X_j`` and ``E = Z⁻¹ Y`` (homogeneous matrices, batched), the whitened
residual and its right Jacobians (CONVENTIONS §4) are

    r = L Log(E),   ∂r/∂X_j = L Jr⁻¹(Log E),   ∂r/∂X_i = −(L Jr⁻¹(Log E)) Ad_{Y⁻¹},

with ``L`` the noise model's square root of the information (``LᵀL = Ω``). ``L Jr⁻¹`` is
written straight into the right half of a fresh ``(m, k, 2k)`` array and its product with
``Ad_{Y⁻¹}`` into the left half, so the least-squares problem reads both slots' blocks
without concatenating them. ``Log``, ``Jr⁻¹`` and ``Ad`` are the groups' array kernels
(:mod:`manopt_lie.lie._se2`, :mod:`manopt_lie.lie._se3`), small-angle and near-π forms
included, without the group objects' validation and wrapping on every call.
"""

from __future__ import annotations

from collections.abc import Callable
from types import ModuleType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..lie import SE2, SE3, LieGroup, _se2, _se3

__all__ = ["FUSED_GROUPS", "between_kernel"]

FloatArray = NDArray[np.float64]

FUSED_GROUPS: dict[type[LieGroup], tuple[ModuleType, int]] = {SE2: (_se2, 2), SE3: (_se3, 3)}
"""Groups with a fused between kernel: their array kernels and the dimension ``d`` of ``SE(d)``."""


def _inverse(m: FloatArray, d: int) -> FloatArray:
    """``[[Rᵀ, −Rᵀt], [0, 1]]`` of homogeneous matrices ``(m, d+1, d+1)``."""
    out = np.zeros_like(m)
    rt = np.swapaxes(m[:, :d, :d], -1, -2)
    out[:, :d, :d] = rt
    np.matmul(rt, -m[:, :d, d, None], out=out[:, :d, d:])
    out[:, d, d] = 1.0
    return out


def between_kernel(group: type[LieGroup], z_inv: FloatArray, sqrt_information: FloatArray | None) -> Callable[..., Any]:
    """The residual function ``(xi, xj, jac) ↦ r | (r, [J_i, J_j])`` of whitened between
    measurements on ``SE(2)`` or ``SE(3)`` (see the module doc).

    Parameters
    ----------
    group : SE2 or SE3
    z_inv : array ``(m, d+1, d+1)``
        The inverse measurements ``Z⁻¹`` as matrices.
    sqrt_information : array ``(k, k)`` (shared), ``(m, k, k)`` (per edge) or None (unit noise)
        ``L``.

    Returns
    -------
    callable
        Whitened residuals ``(m, k)``; with ``jac=True`` also ``[J_i, J_j]``, each
        ``(m, k, k)``: the two halves of one fresh ``(m, k, 2k)`` array.
    """
    kernels, d = FUSED_GROUPS[group]
    k = group.dim
    L = sqrt_information

    def whiten(r: FloatArray) -> FloatArray:
        if L is None:
            return r
        if L.ndim == 2:
            return r @ L.T
        return np.matmul(L, r[:, :, None])[:, :, 0]

    def residual(xi: LieGroup, xj: LieGroup, jac: bool = False) -> Any:
        y = np.matmul(_inverse(xi.as_matrix(), d), xj.as_matrix())
        r = kernels.log(np.matmul(z_inv, y))
        if not jac:
            return whiten(r)
        out = np.empty((len(r), k, 2 * k))
        j_i, j_j = out[:, :, :k], out[:, :, k:]
        jr_inv = kernels.jr_inv(r)
        if L is None:
            j_j[...] = jr_inv
        else:
            np.matmul(L, jr_inv, out=j_j)
        np.matmul(j_j, kernels.adjoint(_inverse(y, d)), out=j_i)
        np.negative(j_i, out=j_i)
        return whiten(r), [j_i, j_j]

    return residual
