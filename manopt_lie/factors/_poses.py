"""The fused kernel of the between factor on SE(2) and SE(3): residuals, right Jacobians and
whitening of the edges in one pass per :data:`EDGE_CHUNK` edges, the Jacobians of both slots side
by side in one array.

With ``Y = X_i⁻¹ X_j`` and ``E = Z⁻¹ Y`` (homogeneous matrices, batched), the whitened
residual and its right Jacobians (CONVENTIONS §4) are

    r = L Log(E),   ∂r/∂X_j = L Jr⁻¹(Log E),   ∂r/∂X_i = −(L Jr⁻¹(Log E)) Ad_{Y⁻¹},

with ``L`` the noise model's square root of the information (``LᵀL = Ω``). ``L Jr⁻¹`` is
written straight into the right half of a fresh ``(m, k, 2k)`` array and its product with
``Ad_{Y⁻¹}`` into the left half, so the least-squares problem reads both slots' blocks
without concatenating them. ``Log``, ``Jr⁻¹`` and ``Ad`` are the groups' array kernels
(:mod:`manopt_lie.lie._se2`, :mod:`manopt_lie.lie._se3`), small-angle and near-π forms
included, without the group objects' validation and wrapping on every call.

These array kernels are the last of three paths (:mod:`manopt_lie._kernels`): where native code
can be built the whole kernel runs compiled, and without it up to ``VM_EDGES`` edges run on
CasADi's virtual machine; the three agree to round-off.
"""

from __future__ import annotations

from collections.abc import Callable
from types import ModuleType
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from .. import _kernels
from .._kernels import flat_rows
from .._native import Pinned
from ..lie import SE2, SE3, LieGroup, _se2, _se3
from ..optim import SideBySide

__all__ = ["EDGE_CHUNK", "FUSED_GROUPS", "NativeBetween", "between_kernel"]

FloatArray = NDArray[np.float64]

EDGE_CHUNK = 8192
"""Edges per pass of the kernel: the temporaries of 8192 edges (up to a few MiB) are reused
from pass to pass; those of a whole 10⁵-edge graph would be paged in anew by every step
(measured: SE(3), 1.2·10⁵ edges, 120 ms in passes of 8192, 176 ms in one; SE(2), 1.1·10⁶
edges, 468 against 1197 ms)."""

FUSED_GROUPS: dict[type[LieGroup], tuple[ModuleType, int]] = {SE2: (_se2, 2), SE3: (_se3, 3)}
"""Groups with a fused between kernel: their array kernels and the dimension ``d`` of ``SE(d)``."""


class NativeBetween(NamedTuple):
    """What compiled code needs to evaluate a between kernel's edges itself (the compiled
    least squares of :mod:`manopt_lie.optim._small_system`): its group and its constants as the
    native kernels read them. A kernel's residual function carries it as ``native_between``."""

    group: type[LieGroup]
    z_inv: Pinned
    """``Z⁻¹``, ``(m, (d+1)²)``: each edge's matrix, row after row."""
    sqrt_information: Pinned | None
    """``L``, ``(k²,)`` shared or ``(m, k²)`` per edge, row after row; ``None`` for unit noise."""


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
        ``(m, k, k)``: the two halves of one fresh ``(m, k, 2k)`` array, returned as a
        :class:`~manopt_lie.optim.SideBySide` of it.
    """
    kernels, d = FUSED_GROUPS[group]
    k = group.dim
    L = sqrt_information
    per_edge = L is not None and L.ndim == 3

    def whiten(r: FloatArray, a: int, b: int) -> FloatArray:
        if L is None:
            return r
        if not per_edge:
            return r @ L.T
        return np.matmul(L[a:b], r[:, :, None])[:, :, 0]

    def write(
        tau: FloatArray, jr_inv: FloatArray | None, adjoint_y_inv: FloatArray | None, a: int, b: int,
        r_out: FloatArray, j_out: FloatArray | None,
    ) -> None:  # fmt: skip
        """Edges ``a:b`` from ``Log E`` (and ``Jr⁻¹``, ``Ad_{Y⁻¹}``, consumed): ``r_out[a:b]`` and,
        unless ``j_out`` is None, ``j_out[a:b]``."""
        r_out[a:b] = whiten(tau, a, b)
        if j_out is None or jr_inv is None or adjoint_y_inv is None:
            return
        j_i, j_j = j_out[a:b, :, :k], j_out[a:b, :, k:]
        if L is None:
            j_j[...] = jr_inv
        else:
            np.matmul(L[a:b] if per_edge else L, jr_inv, out=j_j)
        np.negative(adjoint_y_inv, out=adjoint_y_inv)  # contiguous: ~10× faster than negating the view j_i
        np.matmul(j_j, adjoint_y_inv, out=j_i)

    def one_pass(mi: FloatArray, mj: FloatArray, a: int, b: int, r_out: FloatArray, j_out: FloatArray | None) -> None:
        """Edges ``a:b`` through the array kernels."""
        y = np.matmul(_inverse(mi[a:b], d), mj[a:b])
        r = kernels.log(np.matmul(z_inv[a:b], y))
        if j_out is None:
            write(r, None, None, a, b, r_out, None)
        else:
            write(r, kernels.jr_inv(r), kernels.adjoint(_inverse(y, d)), a, b, r_out, j_out)

    # The measurements, constant: their addresses taken once for every native call.
    z_flat = [Pinned(a) for a in flat_rows(z_inv)]
    l_flat = [] if L is None else [Pinned(a) for a in (flat_rows(L) if per_edge else [np.ravel(L)])]
    kinds = [("whitened " if L is not None else "") + kind for kind in ("log", "between")]  # [jac]

    def residual(xi: LieGroup, xj: LieGroup, jac: bool = False) -> Any:
        mi, mj = xi.as_matrix(), xj.as_matrix()
        m = len(mi)
        r_out = np.empty((m, k))
        j_out = np.empty((m, k, 2 * k)) if jac else None
        native = _kernels.native_kernel(group, kinds[jac])
        if native is not None:  # the whole kernel in native code
            outs = [r_out] if j_out is None else [r_out, j_out.reshape(m, -1)]
            native(m, [*flat_rows(mi, mj), *z_flat, *l_flat], outs)
        elif m <= _kernels.VM_EDGES:  # Log, Jr⁻¹ and Ad on CasADi's virtual machine, the products here
            write(*_kernels.between_terms(group, mi, mj, z_inv, jac), 0, m, r_out, j_out)
        else:
            for a in range(0, m, EDGE_CHUNK):  # a few chunks: their temporaries are reused, not paged in anew
                one_pass(mi, mj, a, min(a + EDGE_CHUNK, m), r_out, j_out)
        return r_out if j_out is None else (r_out, SideBySide(j_out, (k, k)))

    residual.native_between = NativeBetween(group, z_flat[0], l_flat[0] if l_flat else None)  # type: ignore[attr-defined]
    return residual
