"""Numeric factorizations of a symmetric positive definite CSC matrix behind one interface.

Each backend is built from a fixed pattern (``indptr``, ``indices`` of a
canonical CSC matrix storing both triangles), computes its fill-reducing
ordering and symbolic analysis there, once, and then only refactors new
values (``factorize(data)``) and solves (``solve(b)``):

- ``cholmod`` (CHOLMOD from SuiteSparse, through the optional package
  ``cvxopt``): ordering and symbolic analysis once, numeric factorization of
  the lower triangle per call. A given fill-reducing ordering (the structure's
  AMD on the variables' graph) spares CHOLMOD its own AMD on the coordinates,
  the bulk of its analysis memory. CHOLMOD chooses between its two kinds from the
  analysis (flops per entry of the factor): dense, well-connected graphs fill in
  and profit from BLAS-3 supernodes (``LLᵀ``: 26 ms vs QDLDL's 97 ms per
  factorization on ``sphere2500``, d = 6), sparse 2-D graphs from the simplicial
  ``LDLᵀ``, as fast there and ~30 MB lighter per 10⁵ poses than supernodes
  (``benchmarks/bench_linalg.py``, ``benchmarks/bench_scaling.py``); a solver bound
  to a structure of 3-D poses asks for supernodes (``CholeskySolver``). ``LDLᵀ``
  does not fail on an indefinite matrix, so the signs of ``D`` are read after
  every factorization (one diagonal solve).
- ``qdldl`` (optional package ``qdldl``): AMD ordering and elimination tree
  computed once, LDLᵀ of the upper triangle refactored by ``Solver.update``.
- ``superlu`` (SciPy, always present): SuperLU's multiple minimum degree
  ordering of ``HᵀH`` computed once; every factorization then runs on the
  symmetrically permuted matrix in natural order with diagonal pivots only
  (``SymmetricMode``, ``diag_pivot_thresh=0``), which for an SPD matrix is
  the Cholesky factorization written as LU. On pose graphs this ordering
  factorizes faster under SuperLU than COLAMD or minimum degree on ``H + Hᵀ``
  (which fills less but runs slower), see ``benchmarks/bench_linalg.py``.
"""

from __future__ import annotations

import threading
from typing import Any, Protocol

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from ._factors import exclusive_cumsum
from ._memory import TRIM_ENTRIES, release_freed_memory
from .errors import SingularSystemError

__all__ = ["BACKENDS", "Backend", "available_backends", "surrogate_values"]

FloatArray = NDArray[np.float64]
IndexArray = NDArray[np.signedinteger]

# CVXOPT's CHOLMOD options are one module-global dict: analyses in two threads
# must not interleave their save/set/restore of it.
_CHOLMOD_OPTIONS_LOCK = threading.Lock()


class Backend(Protocol):
    """A factorization whose symbolic part was computed from a fixed pattern."""

    def factorize(self, data: FloatArray) -> None: ...

    def solve(self, b: FloatArray) -> FloatArray: ...


def _columns(indptr: IndexArray) -> NDArray[np.signedinteger]:
    """Column of every stored entry of a CSC matrix (in the index dtype: half the memory of intp
    for int32 patterns)."""
    return np.repeat(np.arange(indptr.size - 1, dtype=indptr.dtype), np.diff(indptr))


def _check_diagonal(
    cols: NDArray[np.signedinteger], diag: NDArray[np.bool_], c0: int = 0, c1: int | None = None
) -> None:
    """Raise if some column of ``c0 … c1 − 1`` (all of ``cols`` by default) stores no diagonal
    entry (``cols``: the column of each stored entry; ``diag``: entries on the diagonal)."""
    if c1 is None:
        c1 = int(cols[-1]) + 1 if cols.size else 0
    if np.count_nonzero(diag) != c1 - c0:
        missing = np.setdiff1d(np.arange(c0, c1), cols[diag])[0]
        raise ValueError(f"H stores no diagonal entry in column {missing}: it cannot be positive definite")


def surrogate_values(indptr: IndexArray, indices: IndexArray) -> FloatArray:
    """Values of a strictly diagonally dominant SPD matrix with the given pattern.

    Off-diagonal entries are ``−1`` and each diagonal entry is the number of
    entries of its column, so orderings and symbolic analyses that need a
    numeric matrix can run on the pattern alone.
    """
    cols = _columns(indptr)
    diag = indices == cols
    _check_diagonal(cols, diag)
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
        Hp = sp.csc_matrix((data[self._gather], self._indices, self._indptr), shape=(self._n, self._n))
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

        cols = _columns(indptr)
        upper = indices <= cols
        self._upper = np.flatnonzero(upper)
        n = indptr.size - 1
        self._indptr = np.zeros(n + 1, dtype=indptr.dtype)
        np.cumsum(np.bincount(cols[upper], minlength=n), out=self._indptr[1:])
        self._indices = indices[upper]
        self._n = n
        self._solver = qdldl.Solver(self._triu(surrogate_values(indptr, indices)), upper=True)

    def _triu(self, data: FloatArray) -> sp.csc_matrix:
        return sp.csc_matrix((data[self._upper], self._indices, self._indptr), shape=(self._n, self._n))

    def factorize(self, data: FloatArray) -> None:
        # ``update`` reports no zero pivot: the caller's residual checks catch it.
        try:
            self._solver.update(self._triu(data), upper=True)
        except (RuntimeError, ValueError) as err:
            raise SingularSystemError(f"QDLDL factorization failed ({err})") from None

    def solve(self, b: FloatArray) -> FloatArray:
        return np.asarray(self._solver.solve(b), dtype=np.float64)


SUPERNODAL = 1
"""CHOLMOD's ``options["supernodal"]`` unless the solver asks for a kind: 1, its own choice of
supernodal ``LLᵀ`` or simplicial ``LDLᵀ`` (2 forces supernodes, 0 forbids them)."""


CHUNK = 1 << 16
"""Entries of ``H`` per piece of CVXOPT's lower triangle (:func:`_lower_triangle`)."""


def _lower_triangle(cvxopt: Any, indptr: IndexArray, indices: IndexArray) -> tuple[Any, NDArray[np.signedinteger]]:
    """The lower triangle of the pattern as a CVXOPT sparse matrix of ones (the symbolic
    analysis reads the pattern only), built column range by column range and joined, and
    the positions of its entries among ``H``'s (in the index dtype: int32 for int32 patterns).

    CVXOPT builds a sparse matrix from triplets only, through 64-bit row and column
    indices and a sorting workspace, each as large as the matrix itself; built in pieces of
    :data:`CHUNK` entries of ``H`` these transients stay a few MiB (a 10⁵-pose grid's
    analysis peaks ~70 MB lower) and in cache (faster too), and ``cvxopt.sparse`` joins the
    pieces' columns in one linear pass.

    Raises
    ------
    ValueError
        If a column stores no diagonal entry, or the pattern is not canonical CSC (unsorted
        indices or duplicates in a column), which CVXOPT would silently reorder.
    """
    n = indptr.size - 1
    bounds = np.unique(np.concatenate([np.searchsorted(indptr, np.arange(0, int(indptr[-1]), CHUNK)), [n]]))
    pieces, positions = [], []
    for c0, c1 in zip(bounds[:-1].tolist(), bounds[1:].tolist(), strict=True):
        start, stop = int(indptr[c0]), int(indptr[c1])
        cols = np.repeat(np.arange(c0, c1, dtype=np.int64), np.diff(indptr[c0 : c1 + 1]))
        rows = indices[start:stop]
        _check_diagonal(cols, rows == cols, c0, c1)
        lower = rows >= cols
        rows, cols = rows[lower].astype(np.int64), cols[lower] - c0
        piece = cvxopt.spmatrix(1.0, cvxopt.matrix(rows), cvxopt.matrix(cols), (n, c1 - c0))
        same = np.array_equal(np.asarray(piece.I).ravel(), rows) and np.array_equal(np.asarray(piece.J).ravel(), cols)
        if not same:
            raise ValueError("CHOLMOD backend: H must be canonical CSC (sorted indices, no duplicates)")
        pieces.append([piece])
        positions.append((start + np.flatnonzero(lower)).astype(indices.dtype))
    joined = pieces[0][0] if len(pieces) == 1 else cvxopt.sparse(pieces)
    return joined, np.concatenate(positions)


def _lower_triangle_of_blocks(cvxopt: Any, dims: IndexArray, block_indptr: IndexArray, block_rows: IndexArray) -> Any:
    """The lower triangle of a block pattern's scalar expansion as a CVXOPT sparse matrix of
    ones, through sparse products: ``E·S·Eᵀ + D``, where ``S`` holds one entry per strictly
    lower block, ``E`` (``n × n_vars``) expands each variable into its coordinates and ``D``
    holds the lower triangles of the diagonal blocks.

    CVXOPT's triplet constructor scans a column's whole length for every entry it inserts
    (``k²`` per column of ``k`` entries: ~50 ns per entry of a 3-D pose graph's triangle); its
    products run through a sparse accumulator in linear time, and the constructor here only
    sees ``S``, ``E`` and ``D``, of at most ``d`` entries per column: twice as fast as
    :func:`_lower_triangle` on parking-garage (9.1 against 19.0 ms). The products hold the
    whole triangle at once (about two copies), hence only below :data:`TRIM_ENTRIES` entries.
    """
    def ints(a: NDArray[np.signedinteger]) -> Any:  # CVXOPT's index matrices are 64-bit
        return cvxopt.matrix(np.asarray(a, dtype=np.int64))

    nv, n = dims.size, int(dims.sum())
    block_cols = _columns(block_indptr)
    strict = block_rows > block_cols
    S = cvxopt.spmatrix(1.0, ints(block_rows[strict]), ints(block_cols[strict]), (nv, nv))
    var = _columns(exclusive_cumsum(dims))  # the variable of each coordinate
    E = cvxopt.spmatrix(1.0, ints(np.arange(n)), ints(var), (n, nv))
    # Column c of variable v holds rows c … o_v + d_v − 1 of its diagonal block.
    diagonal_indptr = exclusive_cumsum(np.cumsum(dims)[var] - np.arange(n))
    cols = _columns(diagonal_indptr)
    rows = cols + np.arange(cols.size) - diagonal_indptr[cols]
    D = cvxopt.spmatrix(1.0, ints(rows), ints(cols), (n, n))
    return E * (S * E.T) + D


class _CHOLMOD:
    """CHOLMOD's ``LLᵀ`` (supernodal) or ``LDLᵀ`` (simplicial) of the lower triangle, as its
    analysis chooses (through CVXOPT).

    One CVXOPT sparse matrix is built at analysis; each factorization only
    overwrites its values (``A.V``), in CVXOPT's column-major order, which is
    the order of the lower triangle of a canonical CSC matrix.
    """

    def __init__(
        self, indptr: IndexArray, indices: IndexArray, ordering: NDArray[np.intp] | None = None,
        supernodal: bool | None = None, blocks: tuple[IndexArray, IndexArray, IndexArray] | None = None,
    ) -> None:
        import cvxopt
        from cvxopt import cholmod

        self._cvxopt, self._cholmod = cvxopt, cholmod
        # A symmetric pattern with its whole diagonal has (nnz + n) / 2 lower entries.
        if blocks is not None and (indices.size + indptr.size - 1) // 2 < TRIM_ENTRIES:
            # ``blocks``: the pattern's own block form (dims, block indptr, block rows), trusted.
            self._A = _lower_triangle_of_blocks(cvxopt, *blocks)
            self._lower = np.flatnonzero(indices >= _columns(indptr)).astype(indices.dtype)
        else:
            self._A, self._lower = _lower_triangle(cvxopt, indptr, indices)
        self.pivots: FloatArray | None = None
        """``D`` of the last factorization if it is an ``LDLᵀ`` (in the factor's order), else ``None``."""
        with _CHOLMOD_OPTIONS_LOCK:
            saved = dict(cholmod.options)
            # Options are module-global: set for this analysis only.
            cholmod.options["supernodal"] = SUPERNODAL if supernodal is None else 2 if supernodal else 0
            try:
                if ordering is None:
                    self._factor = cholmod.symbolic(self._A, uplo="L")
                else:
                    # Only the given ordering: CHOLMOD would also run its AMD on the coordinates and
                    # keep the lesser fill, which on pose graphs is within 0.5 % of the variables'
                    # AMD, for 2-3.5× the analysis time and ~40 % more of its memory.
                    cholmod.options["nmethods"] = 1
                    p = cvxopt.matrix(np.asarray(ordering, dtype=np.int64))
                    self._factor = cholmod.symbolic(self._A, p=p, uplo="L")
            finally:
                cholmod.options.clear()
                cholmod.options.update(saved)
        if self._lower.size >= TRIM_ENTRIES:
            release_freed_memory()  # the analysis's transients, kept by malloc, would stay resident

    def factorize(self, data: FloatArray) -> None:
        self._A.V = self._cvxopt.matrix(np.ascontiguousarray(data[self._lower], dtype=np.float64))
        try:
            self._cholmod.numeric(self._A, self._factor)
        except ArithmeticError as err:
            raise SingularSystemError(f"CHOLMOD factorization failed: not positive definite ({err})") from None
        # D⁻¹·1 (1 for LLᵀ, whose D = I): positive and finite iff every pivot of LDLᵀ is.
        inverse_pivots = self._cvxopt.matrix(1.0, (self._A.size[0], 1))
        self._cholmod.solve(self._factor, inverse_pivots, sys=6)
        d = np.asarray(inverse_pivots).reshape(-1)
        if not (np.isfinite(d).all() and (d > 0.0).all()):
            raise SingularSystemError(
                f"CHOLMOD factorization: not positive definite ({int(np.sum(~(d > 0.0)))} pivots of LDLᵀ ≤ 0 or nan)"
            )
        self.pivots = None if (d == 1.0).all() else 1.0 / d

    def solve(self, b: FloatArray) -> FloatArray:
        x = self._cvxopt.matrix(np.array(b, dtype=np.float64))
        self._cholmod.solve(self._factor, x)
        return np.asarray(x, dtype=np.float64).reshape(-1)


BACKENDS: dict[str, type[_SuperLU] | type[_QDLDL] | type[_CHOLMOD]] = {
    "cholmod": _CHOLMOD,
    "qdldl": _QDLDL,
    "superlu": _SuperLU,
}
_PACKAGES = {"cholmod": "cvxopt", "qdldl": "qdldl"}


def available_backends() -> tuple[str, ...]:
    """Names of the backends usable here, fastest first (``superlu`` is always last)."""
    usable = []
    for name, package in _PACKAGES.items():
        try:
            __import__(package)
        except ImportError:
            continue
        usable.append(name)
    return (*usable, "superlu")
