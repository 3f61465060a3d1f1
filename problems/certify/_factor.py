"""A sparse symmetric factorization that also *decides positive definiteness*, with
multi-column solves: what the certificate and the staircase's preconditioner need.

:class:`manopt_lie.linalg.CholeskySolver` solves one right-hand side at a time (each
checked) and, on its QDLDL/SuperLU backends, cannot tell an indefinite matrix from a
definite one. Here the pattern is analysed once and each :meth:`SymmetricFactor.factorize`
returns whether the matrix is positive definite:

- ``cholmod`` (CHOLMOD through the optional package ``cvxopt``): the supernodal ``LLᵀ``,
  which fails on the first non-positive pivot;
- ``superlu`` (SciPy): ``LU`` of the symmetrically permuted matrix with diagonal pivots
  only, i.e. ``LDLᵀ`` written as ``LU``; by Sylvester's law of inertia the matrix is
  positive definite iff every pivot (the diagonal of ``U``) is positive.

A successful factorization in floating point proves ``λ_min(A + E) > 0`` for a backward
error ``‖E‖`` of a small multiple of ``ε‖A‖`` (Demmel 1989), which is why the certificate
never asks for less than :data:`~manopt_lie.problems.certify.data.EIG_FLOOR` times the scale
of its matrix.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def _cholmod_available() -> bool:
    try:
        import cvxopt  # noqa: F401
        from cvxopt import cholmod  # noqa: F401
    except ImportError:
        return False
    return True


class SymmetricFactor:
    """Factorizations of symmetric matrices sharing one sparsity pattern.

    Parameters
    ----------
    pattern : scipy.sparse matrix
        Canonical CSC, both triangles stored, with the diagonal; its values are ignored.
    backend : {"auto", "cholmod", "superlu"}
        ``"auto"``: CHOLMOD when ``cvxopt`` is importable, else SuperLU.
    """

    def __init__(self, pattern: sp.csc_matrix, backend: str = "auto") -> None:
        if backend == "auto":
            backend = "cholmod" if _cholmod_available() else "superlu"
        if backend not in ("cholmod", "superlu"):
            raise ValueError(f"SymmetricFactor: backend must be 'auto', 'cholmod' or 'superlu', got {backend!r}")
        self.backend = backend
        self.shape = pattern.shape
        self._indptr, self._indices = pattern.indptr, pattern.indices
        cols = np.repeat(np.arange(pattern.shape[0]), np.diff(pattern.indptr))
        self._ready = False
        if backend == "cholmod":
            import cvxopt
            from cvxopt import cholmod

            self._cvxopt, self._cholmod = cvxopt, cholmod
            self._lower = np.flatnonzero(pattern.indices >= cols)
            rows = pattern.indices[self._lower].astype(np.int64)
            self._A = cvxopt.spmatrix(
                cvxopt.matrix(np.where(rows == cols[self._lower], float(pattern.shape[0]), -1.0)),
                cvxopt.matrix(rows), cvxopt.matrix(cols[self._lower].astype(np.int64)), pattern.shape,
            )  # fmt: skip
            saved = dict(cholmod.options)
            cholmod.options["supernodal"] = 2
            cholmod.options["postorder"] = True
            try:
                self._symbolic = cholmod.symbolic(self._A, uplo="L")
            finally:
                cholmod.options.clear()
                cholmod.options.update(saved)
        else:
            values = np.where(pattern.indices == cols, float(pattern.shape[0]), -1.0)
            lu = spla.splu(
                sp.csc_matrix((values, pattern.indices, pattern.indptr), shape=pattern.shape),
                permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True},
            )  # fmt: skip
            self._order = np.argsort(lu.perm_c)
            tagged = sp.csc_matrix(
                (np.arange(1.0, pattern.nnz + 1.0), pattern.indices, pattern.indptr), shape=pattern.shape
            )
            permuted = tagged[self._order][:, self._order].tocsc()
            permuted.sort_indices()
            self._gather = permuted.data.astype(np.intp) - 1
            self._pindices, self._pindptr = permuted.indices, permuted.indptr

    def factorize(self, data: FloatArray) -> bool:
        """Factor the matrix with values ``data`` (in the pattern's CSC order); return
        whether it is positive definite (then :meth:`solve` may be used)."""
        self._ready = False
        if self.backend == "cholmod":
            self._A.V = self._cvxopt.matrix(np.ascontiguousarray(data[self._lower], dtype=np.float64))
            try:
                self._cholmod.numeric(self._A, self._symbolic)
            except ArithmeticError:
                return False
            self._ready = True
            return True
        a = sp.csc_matrix((data[self._gather], self._pindices, self._pindptr), shape=self.shape)
        try:
            self._lu = spla.splu(a, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        except RuntimeError:  # an exactly zero pivot
            return False
        pivots = self._lu.U.diagonal()
        self._ready = bool(np.all(pivots > 0) and np.all(np.isfinite(pivots)))
        return self._ready

    def solve(self, b: FloatArray) -> FloatArray:
        """``A⁻¹ B`` for ``B`` of shape ``(N,)`` or ``(N, k)`` with the last positive definite factorization."""
        if not self._ready:
            raise RuntimeError("SymmetricFactor.solve needs a successful factorize() first")
        b = np.asarray(b, dtype=np.float64)
        if self.backend == "cholmod":
            x = self._cvxopt.matrix(np.array(b.reshape(b.shape[0], -1), dtype=np.float64, order="F"))
            self._cholmod.solve(self._symbolic, x)
            return np.asarray(x, dtype=np.float64).reshape(b.shape)
        out = np.empty_like(b)
        out[self._order] = self._lu.solve(np.ascontiguousarray(b[self._order]))
        return out
