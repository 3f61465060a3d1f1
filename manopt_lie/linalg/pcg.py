"""Preconditioned conjugate gradients with a block-Jacobi preconditioner, for very large systems.

:func:`pcg_solve` is the algorithm; :class:`PCGSolver` wraps it as a
:class:`~manopt_lie.linalg.LinearSolver` for Gauss-Newton and
Levenberg-Marquardt (``linear_solver="pcg"``), taking the block sizes from the
problem's :class:`~manopt_lie.linalg.BlockStructure` when bound to a run.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from ..errors import ShapeError
from ._vector import dot, norm
from .errors import SingularSystemError

if TYPE_CHECKING:
    from .structure import BlockStructure

__all__ = ["PCGResult", "PCGSolver", "block_jacobi", "pcg_solve"]

PRECONDITIONERS = ("block-jacobi", "jacobi", None)

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class PCGResult:
    """Outcome of :func:`pcg_solve`.

    Attributes
    ----------
    x : ndarray, shape (n,)
        The last iterate (a useful truncated step even when not converged).
    nit : int
        Iterations run.
    residual : float
        Relative residual ``‖b − Hx‖ / ‖b‖`` (recursively updated).
    converged : bool
        Whether ``residual ≤ tol``.
    """

    x: FloatArray
    nit: int
    residual: float
    converged: bool


def block_jacobi(H: sp.spmatrix | sp.sparray, dims: ArrayLike) -> sp.csr_matrix:
    """The inverse of the block diagonal of ``H``, ``M⁻¹ = blkdiag(H_vv)⁻¹``.

    Parameters
    ----------
    H : sparse matrix, shape (n, n)
        Symmetric; its diagonal blocks must be positive definite.
    dims : array_like of int, shape (n_vars,)
        Sizes of the diagonal blocks (the variables' tangent dimensions),
        ``Σ dims = n``.

    Returns
    -------
    scipy.sparse.csr_matrix
        Block-diagonal ``M⁻¹``; each block inverted through its Cholesky
        factor, batched over the variables of each block size.

    Raises
    ------
    SingularSystemError
        If a diagonal block is not positive definite (naming the variable).
    """
    d = np.asarray(dims, dtype=np.intp)
    n = H.shape[0]
    if d.ndim != 1 or int(d.sum()) != n or (d < 1).any():
        raise ValueError(f"dims must be positive block sizes summing to n = {n}, got {d.size} summing to {d.sum()}")
    offsets = np.concatenate(([0], np.cumsum(d)))
    var_of = np.repeat(np.arange(d.size), d)
    coo = sp.coo_matrix(H)
    v = var_of[coo.row]
    inside = v == var_of[coo.col]
    v, row, col = v[inside], coo.row[inside] - offsets[v[inside]], coo.col[inside] - offsets[v[inside]]
    # Block v stored densely and row-major at start[v]: laid end to end, the
    # blocks are exactly the CSR data of the block-diagonal matrix.
    start = np.concatenate(([0], np.cumsum(d * d)))
    dense = np.zeros(int(start[-1]))
    np.add.at(dense, start[v] + row * d[v] + col, coo.data[inside])
    for k in np.unique(d):
        group = np.flatnonzero(d == k)
        pos = start[group, None] + np.arange(k * k)
        blocks = dense[pos].reshape(-1, k, k)
        try:
            L_inv = np.linalg.inv(np.linalg.cholesky(blocks))
        except np.linalg.LinAlgError:
            bad = group[np.argmin(np.linalg.eigvalsh(blocks)[:, 0])]
            raise SingularSystemError(
                f"block-Jacobi: the diagonal block of variable {bad} is not positive definite"
            ) from None
        dense[pos] = (np.swapaxes(L_inv, 1, 2) @ L_inv).reshape(group.size, k * k)
    row_len = d[var_of]
    indptr = np.concatenate(([0], np.cumsum(row_len)))
    indices = np.repeat(offsets[var_of], row_len) + np.arange(indptr[-1]) - np.repeat(indptr[:-1], row_len)
    return sp.csr_matrix((dense, indices, indptr), shape=(n, n))


def pcg_solve(
    H: sp.spmatrix | sp.sparray,
    b: ArrayLike,
    *,
    tol: float = 1e-8,
    maxiter: int | None = None,
    preconditioner: str | None = "block-jacobi",
    dims: ArrayLike | None = None,
) -> PCGResult:
    """Solve ``H x = b`` for sparse SPD ``H`` by preconditioned conjugate gradients.

    Iterates from ``x₀ = 0`` with ``r = b − Hx``, ``z = M⁻¹r``, ``α = rᵀz / pᵀHp``,
    ``β = r₊ᵀz₊ / rᵀz`` until ``‖r‖ ≤ tol·‖b‖``.

    Parameters
    ----------
    H : sparse matrix, shape (n, n)
        Symmetric positive (semi)definite, e.g. from
        :meth:`BlockStructure.normal_equations`.
    b : array_like, shape (n,)
    tol : float
        Relative residual at which to stop.
    maxiter : int, optional
        Iteration limit (default ``n``).
    preconditioner : {"block-jacobi", "jacobi", None}
        ``M`` = block diagonal of ``H`` (blocks of sizes ``dims``), its
        diagonal, or the identity.
    dims : array_like of int, optional
        Block sizes for ``"block-jacobi"`` (e.g. ``structure.dims``).

    Returns
    -------
    PCGResult
        Not converging within ``maxiter`` is reported, not raised: a
        truncated step is still a descent direction for Gauss-Newton.

    Raises
    ------
    SingularSystemError
        On non-positive curvature ``pᵀHp ≤ 0`` (``H`` indefinite or singular
        along the search direction) or a non-positive-definite diagonal block.
        A consistent singular system (an unfixed gauge with ``b`` in the range
        of ``H``) can still converge: fix the gauge for a unique step.
    """
    n = H.shape[0]
    b_ = np.asarray(b, dtype=np.float64)
    if b_.shape != (n,):
        raise ShapeError(f"b: expected shape {(n,)}, got {b_.shape}")
    if preconditioner == "block-jacobi":
        if dims is None:
            raise ValueError("preconditioner='block-jacobi' needs dims (the variables' block sizes)")
        M = block_jacobi(H, dims)
    elif preconditioner == "jacobi":
        diag = H.diagonal()
        if (diag <= 0).any():
            raise SingularSystemError(f"Jacobi: diagonal entry {int(np.argmin(diag))} of H is not positive")
        M = sp.diags(1.0 / diag).tocsr()
    elif preconditioner is None:
        M = sp.identity(n, format="csr")
    else:
        raise ValueError(f"unknown preconditioner {preconditioner!r}; use 'block-jacobi', 'jacobi' or None")
    # H is symmetric, so the transpose of a CSC matrix is H itself as CSR (no copy).
    op = H.T if H.format == "csc" else H.tocsr()
    maxiter = n if maxiter is None else int(maxiter)
    b_norm = norm(b_)
    x = np.zeros(n)
    if b_norm == 0.0:
        return PCGResult(x, 0, 0.0, True)
    r = b_.copy()
    z = M @ r
    p = z.copy()
    rz = dot(r, z)
    residual = 1.0
    for it in range(1, maxiter + 1):
        Hp = op @ p
        curvature = dot(p, Hp)
        if not curvature > 0:
            raise SingularSystemError(f"PCG iteration {it}: non-positive curvature pᵀHp = {curvature:.2e}")
        alpha = rz / curvature
        x += alpha * p
        r -= alpha * Hp
        residual = norm(r) / b_norm
        if residual <= tol:
            return PCGResult(x, it, residual, True)
        z = M @ r
        rz, rz_old = dot(r, z), rz
        p = z + (rz / rz_old) * p
    return PCGResult(x, maxiter, residual, False)


class PCGSolver:
    """:func:`pcg_solve` as a :class:`~manopt_lie.linalg.LinearSolver`: ``x ≈ H⁻¹b`` with
    ``‖b − Hx‖ ≤ tol·‖b‖``, preconditioned by the inverse diagonal blocks of ``H``.

    An inexact Newton step: Gauss-Newton and Levenberg-Marquardt converge with
    truncated solves (each CG iterate from ``x₀ = 0`` decreases the quadratic
    model, so ``−gᵀH⁻¹g`` is approximated by a descent direction), at a linear
    rate of about ``tol`` instead of quadratically. No factorization, so the
    memory is that of ``H``: for systems whose Cholesky factor fills in.

    Parameters
    ----------
    tol : float
        Relative residual at which CG stops, in ``(0, 1)``.
    maxiter : int, optional
        Iteration cap per solve (default: the system's size ``n``). A solve
        stopped by it returns its last iterate, reported in :attr:`stats`.
    preconditioner : {"block-jacobi", "jacobi", None}
        See :func:`pcg_solve`.
    dims : array_like of int, optional
        The variables' block sizes; :meth:`bind` sets them from the structure
        (``"block-jacobi"`` needs them).

    Attributes
    ----------
    last : PCGResult or None
        The outcome of the last call.
    """

    def __init__(
        self,
        *,
        tol: float = 1e-6,
        maxiter: int | None = None,
        preconditioner: str | None = "block-jacobi",
        dims: ArrayLike | None = None,
    ) -> None:
        if not 0 < tol < 1:
            raise ValueError(f"PCGSolver: tol must be in (0, 1), got {tol!r}")
        if maxiter is not None and not (int(maxiter) == maxiter and maxiter >= 1):
            raise ValueError(f"PCGSolver: maxiter must be a positive integer or None, got {maxiter!r}")
        if preconditioner not in PRECONDITIONERS:
            raise ValueError(
                f"PCGSolver: unknown preconditioner {preconditioner!r}; use 'block-jacobi', 'jacobi' or None"
            )
        self.tol, self.preconditioner = float(tol), preconditioner
        self.maxiter = None if maxiter is None else int(maxiter)
        self.dims = None if dims is None else np.asarray(dims, dtype=np.intp)
        self.last: PCGResult | None = None

    def __repr__(self) -> str:
        return f"PCGSolver(tol={self.tol!r}, maxiter={self.maxiter!r}, preconditioner={self.preconditioner!r})"

    def bind(self, structure: BlockStructure) -> PCGSolver:
        """A fresh solver with these settings and the structure's block sizes, for one run."""
        return PCGSolver(tol=self.tol, maxiter=self.maxiter, preconditioner=self.preconditioner, dims=structure.dims)

    def __call__(self, H: sp.csc_matrix, b: ArrayLike) -> FloatArray:
        """``x ≈ H⁻¹b`` (see :func:`pcg_solve`, whose errors it raises)."""
        self.last = None
        result = pcg_solve(H, b, tol=self.tol, maxiter=self.maxiter, preconditioner=self.preconditioner, dims=self.dims)
        self.last = result
        return result.x

    @property
    def stats(self) -> Mapping[str, float]:
        """``linear_iterations``, ``linear_residual`` (``‖b − Hx‖/‖b‖``) and
        ``linear_converged`` (1.0 or 0.0: stopped by ``maxiter``) of the last call."""
        r = self.last
        if r is None:
            return MappingProxyType({})
        return MappingProxyType(
            {"linear_iterations": float(r.nit), "linear_residual": r.residual, "linear_converged": float(r.converged)}
        )
