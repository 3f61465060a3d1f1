"""Numeric factorizations of a symmetric positive definite CSC matrix behind one interface.

Each backend is built from a fixed pattern (``indptr``, ``indices`` of a
canonical CSC matrix storing both triangles), computes its fill-reducing
ordering and symbolic analysis there, once, and then only refactors new
values (``factorize(data)``) and solves (``solve(b)``):

- ``cholmod`` (CHOLMOD from SuiteSparse, shipped by the optional package
  ``cvxopt``; called directly where :mod:`~manopt_lie.linalg._cholmod`'s checks pass,
  else through CVXOPT's interface, :class:`_CHOLMOD` below): ordering and symbolic
  analysis once, numeric factorization of one triangle per call. A given fill-reducing ordering (the structure's
  AMD on the variables' graph) spares CHOLMOD its own AMD on the coordinates,
  the bulk of its analysis memory. CHOLMOD chooses between its two kinds from the
  analysis (flops per entry of the factor): dense, well-connected graphs fill in
  and profit from BLAS-3 supernodes (``LLᵀ``: 26 ms vs QDLDL's 97 ms per
  factorization on ``sphere2500``, d = 6), sparse 2-D graphs from the simplicial
  ``LDLᵀ``, as fast there and ~30 MB lighter per 10⁵ poses than supernodes
  (``benchmarks/bench_linalg.py``, ``benchmarks/bench_scaling.py``); a solver bound
  to a structure of 3-D poses asks for supernodes (``CholeskySolver``). ``LDLᵀ``
  does not fail on an indefinite matrix, so the signs of ``D`` are read after
  every factorization.
- ``ldl`` (compiled here: needs a C compiler, and ``cvxopt`` for AMD): a simplicial ``LDLᵀ`` in
  C (:mod:`~manopt_lie.linalg._ldl`), from AMD's order and the column counts of its own
  compiled analysis, or from a structure's early analysis, which makes both on a worker thread:
  the automatic choice for a structure whose analysis found CHOLMOD's simplicial kind (2-D pose
  graphs), a factorization 0.69–0.72× CHOLMOD's there, and nothing of CHOLMOD's made in the first
  solve.
- ``qdldl`` (optional package ``qdldl``): AMD ordering and elimination tree
  computed once, LDLᵀ of the upper triangle refactored by ``Solver.update``.
- ``superlu`` (SciPy, always present): SuperLU's multiple minimum degree
  ordering of ``HᵀH`` computed once; every factorization then runs on the
  symmetrically permuted matrix in natural order with diagonal pivots only
  (``SymmetricMode``, ``diag_pivot_thresh=0``), which for an SPD matrix is
  the Cholesky factorization written as LU. On pose graphs this ordering
  factorizes faster under SuperLU than COLAMD or minimum degree on ``H + Hᵀ``
  (which fills less but runs slower), see ``benchmarks/bench_linalg.py``.
- ``dense`` (SciPy's LAPACK, always present): ``H`` scattered into a dense matrix and
  factored by ``potrf``, no ordering and no analysis beyond the scatter positions. For
  small systems, where a sparse factorization is all call overhead (:data:`DENSE_MAX`).
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable
from typing import Protocol

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray
from scipy.linalg import lapack

from ._ldl import available as ldl_available
from ._ldl import ldl_backend
from ._memory import TRIM_ENTRIES, release_freed_memory
from ._triangles import check_diagonal, columns, coordinate_major_triangle, triangle, values_view
from .errors import SingularSystemError

__all__ = ["BACKENDS", "DENSE_MAX", "Backend", "available_backends", "surrogate_values"]

FloatArray = NDArray[np.float64]
IndexArray = NDArray[np.signedinteger]

# CVXOPT's CHOLMOD options are one module-global dict: analyses in two threads
# must not interleave their save/set/restore of it.
_CHOLMOD_OPTIONS_LOCK = threading.Lock()


class Backend(Protocol):
    """A factorization whose symbolic part was computed from a fixed pattern."""

    def factorize(self, data: FloatArray) -> None: ...

    def solve(self, b: FloatArray) -> FloatArray: ...


def surrogate_values(indptr: IndexArray, indices: IndexArray) -> FloatArray:
    """Values of a strictly diagonally dominant SPD matrix with the given pattern.

    Off-diagonal entries are ``−1`` and each diagonal entry is the number of
    entries of its column, so orderings and symbolic analyses that need a
    numeric matrix can run on the pattern alone.
    """
    cols = columns(indptr)
    diag = indices == cols
    check_diagonal(cols, diag)
    values = np.full(indices.size, -1.0)
    values[diag] = np.diff(indptr)
    return values


class _SuperLU:
    """SuperLU on ``P H Pᵀ`` with the ordering ``P`` fixed at construction."""

    def __init__(self, indptr: IndexArray, indices: IndexArray) -> None:
        n, nnz = indptr.size - 1, indices.size
        values = surrogate_values(indptr, indices)
        lu = spla.splu(
            sp.csc_matrix((values, indices, indptr), shape=(n, n)),
            permc_spec="MMD_ATA",
            diag_pivot_thresh=0.0,
            options={"SymmetricMode": True},
        )
        # SuperLU factors A[:, perm_c]; its inverse is the order in which the
        # variables are eliminated, so the permuted matrix is H[order][:, order].
        self._order = np.argsort(lu.perm_c)
        # Permute a matrix holding "1 + position in H.data" to learn where each
        # entry of the permuted matrix comes from (exact in float64 below 2⁵³).
        tagged = sp.csc_matrix((np.arange(1.0, nnz + 1.0), indices, indptr), shape=(n, n))
        permuted = tagged[self._order][:, self._order].tocsc()
        permuted.sort_indices()
        self._gather = permuted.data.astype(np.intp) - 1
        self._indices, self._indptr = permuted.indices, permuted.indptr
        self._n = n
        self._lu: spla.SuperLU | None = None

    def factorize(self, data: FloatArray) -> None:
        Hp = sp.csc_matrix((np.take(data, self._gather), self._indices, self._indptr), shape=(self._n, self._n))
        try:
            self._lu = spla.splu(Hp, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        except RuntimeError as err:
            self._lu = None
            raise SingularSystemError(f"SuperLU factorization failed ({err})") from None

    def solve(self, b: FloatArray) -> FloatArray:
        assert self._lu is not None, "factorize() before solve()"
        x = np.empty_like(b)
        x[self._order] = self._lu.solve(b[self._order])
        return x


class _QDLDL:
    """QDLDL's LDLᵀ of the upper triangle, analysed once and updated in place."""

    def __init__(self, indptr: IndexArray, indices: IndexArray) -> None:
        import qdldl

        cols = columns(indptr)
        upper = indices <= cols
        self._upper = np.flatnonzero(upper)
        n = indptr.size - 1
        self._indptr = np.zeros(n + 1, dtype=indptr.dtype)
        np.cumsum(np.bincount(cols[upper], minlength=n), out=self._indptr[1:])
        self._indices = indices[upper]
        self._n = n
        self._solver = qdldl.Solver(self._triu(surrogate_values(indptr, indices)), upper=True)

    def _triu(self, data: FloatArray) -> sp.csc_matrix:
        return sp.csc_matrix((np.take(data, self._upper), self._indices, self._indptr), shape=(self._n, self._n))

    def factorize(self, data: FloatArray) -> None:
        # ``update`` reports no zero pivot: the caller's residual checks catch it.
        try:
            self._solver.update(self._triu(data), upper=True)
        except (RuntimeError, ValueError) as err:
            raise SingularSystemError(f"QDLDL factorization failed ({err})") from None

    def solve(self, b: FloatArray) -> FloatArray:
        return np.asarray(self._solver.solve(b), dtype=np.float64)


DENSE_MAX = 128
"""Systems of at most this order are factored dense (``dense``) by a solver bound to a structure
with the backend chosen automatically (:meth:`~manopt_lie.linalg.CholeskySolver.bind`), and a
least-squares problem of at most this many unknowns stores its ``H`` dense
(``BlockStructure(…, dense=True)``)."""


class _Dense:
    """LAPACK's Cholesky ``H = LLᵀ`` (``potrf``) of ``H`` scattered into a dense matrix (or, for a
    pattern of every entry, a dense structure's, of its values as they are)."""

    def __init__(self, indptr: IndexArray, indices: IndexArray) -> None:
        n = indptr.size - 1
        # Entry (i, j) of the column-major (Fortran) matrix LAPACK reads sits at j·n + i: where a
        # canonical pattern stores all n² entries, that is where they already are.
        self._position: IndexArray | None = None
        if indptr[-1] != n * n:
            cols = columns(indptr)
            check_diagonal(cols, indices == cols)
            self._position = cols.astype(np.intp) * n + indices
        self._n = n
        self._factor: FloatArray | None = None
        self.matrix: FloatArray | None = None
        """The last factorized ``H`` itself, dense: the solver checks its solutions with it (a
        product without sparse machinery, 0.8 against 2.6 µs at order 54)."""

    def factorize(self, data: FloatArray) -> None:
        n = self._n
        if self._position is None:
            a = data.copy()
        else:
            a = np.zeros(n * n)
            a[self._position] = data
        self.matrix = a.reshape((n, n), order="F")
        factor, info = lapack.dpotrf(self.matrix, lower=1, clean=0, overwrite_a=0)
        self._factor = factor if info == 0 else None
        if info > 0:  # (info < 0 would be an invalid argument: a bug here)
            raise SingularSystemError(f"dense Cholesky factorization failed: leading minor {info} not positive")
        assert info == 0, f"dpotrf: argument {-info} invalid"

    def solve(self, b: FloatArray) -> FloatArray:
        assert self._factor is not None, "factorize() before solve()"
        x, info = lapack.dpotrs(self._factor, b, lower=1)
        assert info == 0, f"dpotrs: argument {-info} invalid"
        return np.asarray(x, dtype=np.float64)


SUPERNODAL = 1
"""CHOLMOD's ``options["supernodal"]`` unless the solver asks for a kind: 1, its own choice of
supernodal ``LLᵀ`` or simplicial ``LDLᵀ`` (2 forces supernodes, 0 forbids them)."""


def supernodal_setting(supernodal: bool | None) -> int:
    """CHOLMOD's ``supernodal`` setting for a solver's request (``None``: :data:`SUPERNODAL`)."""
    return SUPERNODAL if supernodal is None else 2 if supernodal else 0


GRID_ENTRIES = 1 << 13
"""Lower-triangle entries from which a pattern given by its blocks is built as a grid of copies
of the block pattern (:func:`~manopt_lie.linalg._triangles.coordinate_major_triangle`): below,
triplets are faster (tinyGrid3D, 585 entries: 0.04 against 0.17 ms; CSAIL, 1.7·10⁴: equal).
From :data:`TRIM_ENTRIES` on, triplets in pieces again: the grid raised LM's peak memory
(cube-22 126 → 132 MB, grid2d-316 304 → 311 MB, ``benchmarks/bench_scaling.py``)."""


class _CHOLMOD:
    """CHOLMOD's ``LLᵀ`` (supernodal) or ``LDLᵀ`` (simplicial) of one triangle, as its
    analysis chooses (through CVXOPT).

    One CVXOPT sparse matrix is built at analysis; each factorization only
    overwrites its values (``A.V``, gathered from ``H.data`` in CVXOPT's column-major order).
    Given the pattern's blocks, the matrix is ``H`` in the coordinate-major order
    (:func:`~manopt_lie.linalg._triangles.coordinate_major_triangle`), with the ordering and
    the solves' vectors reordered to match; otherwise it is ``H``'s own order.

    The triangle is the one CHOLMOD's factorization permutes with the fewest transposes
    (``cholmod_factorize``): its simplicial ``LDLᵀ`` takes the lower one (``P A Pᵀ``'s upper
    triangle in one transpose), its supernodal ``LLᵀ`` the upper one (``tril(P A Pᵀ)`` in
    one transpose, where the lower one costs two). So a forced supernodal analysis hands
    CHOLMOD the upper triangle (built as directly as the lower one), the same factor.
    """

    def __init__(
        self, indptr: IndexArray, indices: IndexArray, ordering: NDArray[np.intp] | None = None,
        supernodal: bool | None = None, blocks: tuple[IndexArray, IndexArray, IndexArray] | None = None,
    ) -> None:
        import cvxopt
        from cvxopt import cholmod

        self._cvxopt, self._cholmod = cvxopt, cholmod
        # ``coords``: the coordinate of H at each row of CHOLMOD's matrix (None: H's own order).
        self._coords: NDArray[np.intp] | None = None
        self._supernodal = supernodal is True  # forced LLᵀ: a factor without pivots to read
        self.uplo = "U" if supernodal else "L"
        """The triangle of ``H`` that CHOLMOD reads: ``"L"`` or ``"U"`` (forced supernodes)."""
        upper = self.uplo == "U"
        # A symmetric pattern with its whole diagonal has (nnz + n) / 2 lower entries.
        if blocks is not None and GRID_ENTRIES <= (indices.size + indptr.size - 1) // 2 < TRIM_ENTRIES:
            # ``blocks``: the pattern's own block form (dims, block indptr, block rows), trusted.
            self._A, self._gather, self._coords = coordinate_major_triangle(cvxopt, indptr, *blocks, upper=upper)
            if ordering is not None:  # the k-th pivot, in the reordered numbering
                position = np.empty_like(self._coords)
                position[self._coords] = np.arange(self._coords.size)
                ordering = position[ordering]
        else:
            self._A, self._gather = triangle(cvxopt, indptr, indices, upper=upper)
        self._values = values_view(cvxopt, self._A, self._gather.size)  # where new values are written
        self.pivots: FloatArray | None = None
        """``D`` of the last factorization if it is an ``LDLᵀ`` (in the factor's order), else ``None``."""
        self._symbolic = False  # whether factor_csc left the factor symbolic
        with _CHOLMOD_OPTIONS_LOCK:
            saved = dict(cholmod.options)
            # Options are module-global: set for this analysis only.
            cholmod.options["supernodal"] = supernodal_setting(supernodal)
            try:
                if ordering is None:
                    self._factor = cholmod.symbolic(self._A, uplo=self.uplo)
                else:
                    # Only the given ordering: CHOLMOD would also run its AMD on the coordinates and
                    # keep the lesser fill, which on pose graphs is within 0.5 % of the variables'
                    # AMD, for 2-3.5× the analysis time and ~40 % more of its memory.
                    cholmod.options["nmethods"] = 1
                    p = cvxopt.matrix(np.asarray(ordering, dtype=np.int64))
                    self._factor = cholmod.symbolic(self._A, p=p, uplo=self.uplo)
            finally:
                cholmod.options.clear()
                cholmod.options.update(saved)
        if self._gather.size >= TRIM_ENTRIES:
            release_freed_memory()  # the analysis's transients, kept by malloc, would stay resident

    def factorize(self, data: FloatArray) -> None:
        data = np.asarray(data, dtype=np.float64)
        if self._values is not None:  # mode="clip": unbuffered (the positions are H's by construction)
            np.take(data, self._gather, out=self._values, mode="clip")
        else:
            self._A.V = self._cvxopt.matrix(np.take(data, self._gather))
        self._numeric()

    def _numeric(self) -> None:
        """Factor the values in ``A`` (kept there, so :meth:`factor_csc` can have them factored again)."""
        self._symbolic = False
        try:
            self._cholmod.numeric(self._A, self._factor)
        except ArithmeticError as err:
            raise SingularSystemError(f"CHOLMOD factorization failed: not positive definite ({err})") from None
        if self._supernodal:  # LLᵀ: positive pivots, or numeric failed above
            return
        # D⁻¹·1 (1 for LLᵀ, whose D = I): positive and finite iff every pivot of LDLᵀ is.
        inverse_pivots = self._cvxopt.matrix(1.0, (self._A.size[0], 1))
        self._cholmod.solve(self._factor, inverse_pivots, sys=6)
        d = np.asarray(inverse_pivots).reshape(-1)
        if not (np.isfinite(d).all() and (d > 0.0).all()):
            raise SingularSystemError(
                f"CHOLMOD factorization: not positive definite ({int(np.sum(~(d > 0.0)))} pivots of LDLᵀ ≤ 0 or nan)"
            )
        self.pivots = None if (d == 1.0).all() else 1.0 / d

    def factor_csc(self) -> tuple[FloatArray, IndexArray, IndexArray]:
        """``(data, indices, indptr)`` of the last factorization's ``L`` (``LDLᵀ``: ``D`` on its
        diagonal), in the factor's order. CVXOPT's ``getfactor`` leaves the factor symbolic and
        simplicial: the next solve factors ``A``'s values again, an ``LDLᵀ`` from then on."""
        colptr, rowind, values = self._cholmod.getfactor(self._factor).CCS
        self._symbolic, self._supernodal = True, False
        return np.asarray(values).reshape(-1), np.asarray(rowind).reshape(-1), np.asarray(colptr).reshape(-1)

    def solve(self, b: FloatArray) -> FloatArray:
        """``H⁻¹b`` for ``b`` of shape ``(n,)`` or ``(n, k)``."""
        if self._symbolic:
            self._numeric()
        b = np.asarray(b, dtype=np.float64)
        x = self._cvxopt.matrix(np.asfortranarray(b if self._coords is None else b[self._coords]))
        self._cholmod.solve(self._factor, x)
        solution = np.asarray(x, dtype=np.float64).reshape(b.shape, order="F")
        if self._coords is None:
            return solution
        out = np.empty_like(solution)
        out[self._coords] = solution
        return out

    def permutation(self) -> NDArray[np.intp]:
        """The factor's order in ``H``'s coordinates: ``P H Pᵀ = L D Lᵀ`` with
        ``(P H Pᵀ)[i, j] = H[perm[i], perm[j]]``."""
        p = self._cvxopt.matrix(np.arange(self._A.size[0], dtype=np.float64))
        self._cholmod.solve(self._factor, p, sys=7)  # P b = b[perm]
        perm = np.asarray(p, dtype=np.float64).reshape(-1).astype(np.intp)
        return perm if self._coords is None else self._coords[perm]


BACKENDS: dict[str, Callable[[IndexArray, IndexArray], Backend]] = {
    "cholmod": _CHOLMOD,
    "ldl": ldl_backend,
    "qdldl": _QDLDL,
    "superlu": _SuperLU,
    "dense": _Dense,
}
_PACKAGES = {"cholmod": "cvxopt", "ldl": "cvxopt", "qdldl": "qdldl"}


@functools.cache
def available_backends() -> tuple[str, ...]:
    """Names of the sparse backends usable here, fastest first (``superlu`` always), then ``dense``;
    found once per process (each solver asks: every run binds one)."""
    usable = []
    for name, package in _PACKAGES.items():
        try:
            __import__(package)
        except ImportError:
            continue
        if name != "ldl" or ldl_available():
            usable.append(name)
    return (*usable, "superlu", "dense")
