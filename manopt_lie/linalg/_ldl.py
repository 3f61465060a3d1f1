"""A simplicial ``LDLᵀ`` factorization in compiled code (``ldl.c``): the backend ``ldl``.

It factors ``B = P H Pᵀ`` from the upper triangle of ``B`` and the column counts of ``L``, which a
symbolic analysis gives: a structure's early analysis (:mod:`~manopt_lie.linalg._early`) makes both
on its worker thread, so a solver of the automatic choice whose structure's analysis found the
simplicial kind factors with no analysis of its own (``CholeskySolver.analyze``). Otherwise
:func:`ldl_backend` analyses here, with the same compiled steps: AMD's order (of the variables,
for a structure), the elimination tree, its postorder and the column counts
(``patterns.c: block_symbolic``), and the permuted triangle (``permuted_triangle``).

The numeric factorization is the up-looking one: row ``k`` of ``L`` is a sparse triangular solve
with the rows above it, its pattern the nodes reached from the rows of ``B[:k, k]`` up the
elimination tree (which the factorization reads off ``L`` as it fills it), a variable's chain of
columns updated in one pass. It reads ``H.data`` through the triangle's positions in it, with no
gathered copy. Against CHOLMOD's simplicial ``LDLᵀ`` of the same ``H`` (this machine, alternated in
one process, ``CholeskySolver("cholmod")`` bound to the structure): a factorization CSAIL 0.30 →
0.21 ms, intel 1.16 → 0.84 ms, manhattan 4.53 → 3.28 ms, a solve 0.71–0.81×; and a solver that
takes its analysis from the structure makes no CHOLMOD workspace, factor or matrix in its first
solve.
"""

from __future__ import annotations

import ctypes
import functools
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import _native
from . import _amd, _patterns
from ._early import Analysis, analyse_here
from ._memory import TRIM_ENTRIES, release_freed_memory
from ._patterns import INT32_MAX, Triangle
from ._triangles import check_diagonal, columns
from .errors import SingularSystemError

__all__ = ["SimplicialLDL", "available", "ldl_backend"]

FloatArray = NDArray[np.float64]
IndexArray = NDArray[np.signedinteger]

_at = _native.address
_P = ctypes.c_void_p
_I = ctypes.c_int64
_SIGNATURES: dict[str, tuple[Any, list[Any]]] = {
    "ldl_new": (_P, [_I, _P, _P, _P, _P, _I]),
    "ldl_free": (None, [_P]),
    "ldl_factor": (_I, [_P, _P]),
    "ldl_solve": (None, [_P, _I, _I, _P]),
    "ldl_solve_permuted": (None, [_P, _P, _P, _P]),
    "ldl_below": (_I, [_P]),
    "ldl_read": (None, [_P, _P, _P, _P, _P]),
}


@functools.cache
def _library() -> Any:
    """``ldl.c`` compiled (once per machine, like the kernels), or ``None``."""
    return _native.load_source(__package__, "ldl.c", _SIGNATURES)


def available() -> bool:
    """Whether the backend ``ldl`` can analyse and factor here: the compiled code and AMD."""
    return _library() is not None and _patterns._library() is not None and _amd.amd_order_address() is not None


class SimplicialLDL:
    """``B = P H Pᵀ = L D Lᵀ``, factored by ``ldl.c`` from a symbolic analysis.

    Parameters
    ----------
    triangle : (indptr, rows, gather) of int32
        The upper triangle of ``B`` (CSC, rows sorted) and the position in ``H.data`` of each entry
        (read, not copied: they must not change).
    perm : ndarray of intp, shape (n,)
        ``P``: the coordinate of ``H`` of each of ``B``'s.
    column_counts : ndarray of int32, shape (n,)
        The entries of each column of ``L``, its diagonal included.
    entries : int
        ``H``'s stored entries (the length of the ``data`` :meth:`factorize` reads).
    width : int
        Where ≥ 2, every ``width`` columns of ``B`` are a variable's, whose diagonal block of ``L`` is
        dense (a structure's variables of one dimension); else the chains of columns that share
        their rows are found from ``B``'s elimination tree (``ldl.c``).
    cost : (float, float), optional
        ``(Σ_j c_j, Σ_j c_j²)`` over the column counts ``c_j``, where the analysis summed them.

    Attributes
    ----------
    cost : (float, float)
        ``(Σ_j c_j, Σ_j c_j²)`` (as ``Cholmod.cost``).
    supernodal : bool
        ``False``: the factor is simplicial ``LDLᵀ``.

    The factor's arrays are the C's (one allocation each for its integers and its floats, freed
    with this object): a structure's first solve makes no NumPy array for them. One thread at a
    time factors and solves with it (its workspaces are its own), as with CHOLMOD's factor: the
    pool of analyses lends it to one solver at a time.
    """

    supernodal = False
    _handle: int | None = None

    def __init__(
        self, triangle: Triangle, perm: NDArray[np.intp], column_counts: NDArray[np.int32], entries: int,
        width: int = 1, cost: tuple[float, float] | None = None,
    ) -> None:  # fmt: skip
        indptr, rows, gather = triangle
        lib = _library()
        if cost is None:
            counts = column_counts.astype(np.float64)
            cost = (float(counts.sum()), float(np.dot(counts, counts)))
        self.cost = cost
        self._n, self._entries, self._triangle, self._perm = indptr.size - 1, entries, triangle, perm
        self._handle = lib.ldl_new(self._n, _at(indptr), _at(rows), _at(gather), _at(column_counts), width)
        if not self._handle:
            raise MemoryError("ldl.c: no memory for the factor (or its entries pass 32-bit indices)")
        self._lib, self._factored, self._perm_at = lib, False, _at(perm)

    def __del__(self) -> None:
        if self._handle:
            self._lib.ldl_free(self._handle)

    def factorize(self, data: FloatArray) -> None:
        """Factor ``H`` of these values (``H.data``, in the analysed pattern).

        Raises
        ------
        SingularSystemError
            If a pivot ``d_k`` is not a positive finite number (``H`` is not positive definite, or
            holds a non-finite value).
        """
        if data.size != self._entries or data.dtype != np.float64 or not data.flags.c_contiguous:
            data = np.ascontiguousarray(data, dtype=np.float64)
            if data.size != self._entries:
                raise ValueError(f"H.data holds {data.size} values; the analysed pattern stores {self._entries}")
        self._factored = False
        status = self._lib.ldl_factor(self._handle, _at(data))
        if status == -1:
            raise RuntimeError("ldl.c: L's pattern is not the one its symbolic analysis laid out")
        if status < self._n:
            what = "≤ 0" if np.isfinite(data).all() else "not finite: H holds a non-finite value"
            where = self._perm[status]
            raise SingularSystemError(
                f"LDLᵀ factorization: not positive definite (the pivot of H's coordinate {where} is {what})"
            )
        self._factored = True

    def solve(self, b: FloatArray) -> FloatArray:
        """``H⁻¹b`` for ``b`` of shape ``(n,)`` or ``(n, k)``: ``Pᵀ B⁻¹ P b``."""
        if not self._factored:
            raise SingularSystemError("LDLᵀ: no factorization to solve with")
        b = np.asarray(b, dtype=np.float64)
        out = np.empty(b.shape)
        if b.ndim == 1:
            b = np.ascontiguousarray(b)
            self._lib.ldl_solve_permuted(self._handle, self._perm_at, _at(b), _at(out))
            return out
        rhs = np.asfortranarray(b[self._perm])
        self._lib.ldl_solve(self._handle, rhs.shape[1], self._n, rhs.ctypes.data)  # (column-major)
        out[self._perm] = rhs
        return out

    def permutation(self) -> NDArray[np.intp]:
        """The factor's order in ``H``'s coordinates: ``P H Pᵀ = L D Lᵀ`` with
        ``(P H Pᵀ)[i, j] = H[perm[i], perm[j]]``."""
        return self._perm.copy()

    def _read(self) -> tuple[NDArray[np.int32], NDArray[np.int32], FloatArray, FloatArray]:
        """Copies of ``L``'s column pointers (below the diagonal), rows and values, and ``D``."""
        if not self._factored:
            raise SingularSystemError("LDLᵀ: no factorization to read")
        n, below = self._n, self._lib.ldl_below(self._handle)
        lp, li, lx, d = np.empty(n + 1, np.int32), np.empty(below, np.int32), np.empty(below), np.empty(n)
        self._lib.ldl_read(self._handle, *(a.ctypes.data for a in (lp, li, lx, d)))  # (empty ones too)
        return lp, li, lx, d

    @property
    def pivots(self) -> FloatArray | None:
        """``D`` of the last factorization (in the factor's order), a copy; ``None`` before one."""
        return self._read()[3] if self._factored else None

    def factor_csc(self) -> tuple[FloatArray, NDArray[np.int32], NDArray[np.int32]]:
        """``(data, indices, indptr)`` of the last factorization's ``L`` with ``D`` on its diagonal
        (the head of each column, as CHOLMOD's simplicial factor), in the factor's order."""
        lp, li, lx, d = self._read()
        n = self._n
        indptr = lp + np.arange(n + 1, dtype=np.int32)
        heads, below = indptr[:-1], np.ones(int(indptr[-1]), dtype=bool)
        below[heads] = False
        data, indices = np.empty(below.size), np.empty(below.size, dtype=np.int32)
        data[heads], indices[heads] = d, np.arange(n, dtype=np.int32)
        data[below], indices[below] = lx, li
        return data, indices, indptr.astype(np.int32, copy=False)


def ldl_backend(
    indptr: IndexArray, indices: IndexArray, blocks: tuple[IndexArray, IndexArray, IndexArray] | None = None,
    variables: NDArray[np.intp] | None = None, early: Analysis | None = None,
) -> SimplicialLDL:  # fmt: skip
    """The backend ``ldl`` of ``H``'s pattern (both triangles stored): analysed by a structure's
    early analysis where ``early`` made ``B``'s simplicial factor in ``variables`` (its order); else
    here, in the variables' order ``variables`` of the block form ``blocks`` (``(dims, block indptr,
    block rows)``, trusted), else in AMD's order of the coordinates.

    Raises
    ------
    ValueError
        If ``H`` stores 2³¹ entries or more, or misses a diagonal entry.
    RuntimeError
        If the compiled code or AMD is not :func:`available`.
    """
    if not available():
        raise RuntimeError("the backend 'ldl' needs a C compiler and CVXOPT's AMD")
    entries = int(indptr[-1])
    if indptr.dtype != np.int32 or indices.dtype != np.int32:
        if max(entries, indptr.size) >= INT32_MAX:
            raise ValueError("the backend 'ldl' factors patterns of 32-bit indices: H stores too many entries")
        indptr, indices = indptr.astype(np.int32), indices.astype(np.int32)
    if early is None or early.simplicial is None or variables is None or early.order is not variables:
        if blocks is None or variables is None:
            cols = columns(indptr)
            check_diagonal(cols, indices == cols)
            variables = _amd.amd_order(indptr, indices)
            if variables is None:
                raise RuntimeError("AMD failed on H's pattern")
            blocks = (np.ones(indptr.size - 1, dtype=np.intp), indptr, indices)
        dims = blocks[0]
        dimension = int(dims[0]) if int(dims.min()) == int(dims.max()) else 0  # 0: several
        early = analyse_here(dims, dimension, indptr, blocks[1], blocks[2], variables, True)
        if early.simplicial is not None and early.simplicial.triangle[2].size >= TRIM_ENTRIES:
            release_freed_memory()  # the analysis's transients, kept by malloc, would stay resident
    made = early.simplicial
    if made is None:  # only without memory (raised) or the compiled code (checked above)
        raise RuntimeError("ldl: the symbolic analysis failed")
    return SimplicialLDL(made.triangle, made.perm, made.column_counts, entries, early.dimension, made.cost)
