"""A solve's set-up in compiled code (``patterns.c``): the index arrays of a
:class:`~manopt_lie.linalg.BlockStructure`, the triangle CHOLMOD factors, and the variables'
symbolic factorization (``linalg._cholmod`` expands the latter, and CHOLMOD's supernodes of the
variables, to the coordinates).

All of it is paid once per pattern: NumPy built the structure and the triangle in a few dozen
calls over every entry (CSAIL: 0.83 and 0.40 ms), the C takes a few passes over the blocks
(0.17 and 0.04 ms). The arrays are NumPy's, entry for entry (``tests/linalg/test_patterns.py``).
Each function returns ``None`` where the C cannot serve — no compiler (``_native.enabled``), an
index of ``H`` past 32 bits, a factor's scatter too large to keep whole
(:data:`~manopt_lie.linalg._factors.WHOLE_SCATTER_BYTES`, made per chunk instead), a factor that
fills in too much for the variables' simplicial analysis — and the callers keep their other
builds (NumPy's, CHOLMOD's).
"""

from __future__ import annotations

import ctypes
import functools
import itertools
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import _native
from . import _factors
from ._factors import FactorIndex

__all__ = ["StructureBuild", "analysis_layout", "block_symbolic", "hessian_pattern", "permuted_block_triangle"]

SIMPLICIAL_FILL = 8
"""The most blocks of ``L`` per stored block of ``H`` :func:`block_symbolic` counts before it leaves
the variables' analysis to CHOLMOD: a factor that fills in more is a supernodal one's."""

Int32 = NDArray[np.int32]
INT32_MAX = np.iinfo(np.int32).max
INT64_MAX = np.iinfo(np.int64).max
Pattern = tuple[tuple[Int32, Int32], Int32, Int32, Int32, list[tuple[Int32, Int32]], NDArray[np.intp]]
Triangle = tuple[Int32, Int32, Int32]  # a permuted triangle's indptr, rows, and positions in H.data

_P = ctypes.c_void_p
_I = ctypes.c_int64
_SIGNATURES: dict[str, tuple[Any, list[Any]]] = {
    "build_structure": (ctypes.c_int, [_P]),
    "permuted_triangle": (ctypes.c_int, [_I, _P, _P, _P, _P, _P, ctypes.c_int, _I, _P, _P, _P, _P]),
    "expand_supernodes": (ctypes.c_int, [_I, _P, _P, _P, _P, _P, _P, _P, _P, _P, _P]),
    "block_symbolic": (ctypes.c_int, [_I, _P, _P, _P, _I, _P, _P]),
    "early_start": (_P, [_P, _P, ctypes.c_double]),
    "early_built": (ctypes.c_int, [_P, _P]),
    "early_join": (ctypes.c_int, [_P, _P]),
}


ANALYSIS_ARGUMENTS = 19
"""``patterns.c: early_start``'s packed arguments."""


def analysis_layout(nv: int, n: int, entries: int) -> tuple[list[int], list[int]]:
    """The lengths of the int64 and of the int32 arrays an early analysis (``_early``) of ``nv`` variables
    and ``n`` coordinates, ``H`` holding at most ``entries`` entries, keeps: its outputs, statuses and
    packed arguments, and its triangle (:func:`carve`)."""
    size = (entries + n) // 2  # the triangle, its diagonal included
    return [nv, nv, nv, n, 3, 2, 1, ANALYSIS_ARGUMENTS], [nv, n, n + 1, size, size]


@functools.cache
def _library() -> Any:
    """``patterns.c`` compiled (once per machine, like the kernels), or ``None``."""
    return _native.load_source(__package__, "patterns.c", _SIGNATURES)


_at = _native.address


def carve(dtype: type[np.number], sizes: Sequence[int]) -> tuple[list[NDArray[Any]], list[int]]:
    """Arrays of these sizes cut from one new buffer, and their addresses: one allocation and one
    address taken, not one per array (each ~1 µs in a loop, several in a cold solve)."""
    starts = list(itertools.accumulate(sizes, initial=0))
    buffer = np.empty(starts[-1], dtype=dtype)
    base, itemsize = _at(buffer) if starts[-1] else 0, buffer.itemsize
    return [buffer[a:b] for a, b in itertools.pairwise(starts)], [base + itemsize * a for a in starts[:-1]]


class StructureBuild:
    """A structure's compiled build (``patterns.c: build_structure``), planned: its arrays made empty
    and its arguments packed in one array for the C, which fills them now (:meth:`run`) or on the
    worker thread, before the structure's analysis there (``_early.EarlyAnalysis``, ``build=``),
    while the caller goes on. :meth:`result` then reads them. Made by :func:`hessian_pattern`, with
    the arrays of that analysis (``analysis``) cut from the same two buffers.

    Attributes
    ----------
    room : int
        The most entries ``H`` may store (no two edges joining the same variables).
    block_ptr, candidates, indptr : ndarray of int32
        The block pattern's ``indptr``, the room its rows are gathered in (the ``nb`` rows first,
        once built) and ``H``'s ``indptr``: what the analysis reads.
    analysis : tuple or None
        The analysis's int64 arrays and their addresses, then its int32 arrays and theirs
        (:func:`analysis_layout`), where asked for.
    """

    def __init__(
        self, dims: NDArray[np.intp], n: int, room: int, factors: Sequence[FactorIndex], analysis: bool = False
    ) -> None:
        nv, k = dims.size, len(factors)
        self._factors, self._dims, self.room = factors, dims, room
        ids = self._ids = [np.ascontiguousarray(f.var_ids, dtype=np.int64) for f in factors]
        arities = [a.shape[1] for a in ids]
        # m, arity and the slots' dimensions of every factor, after build's 17 arguments and the 3 k
        # pointers they point to (the edges, the positions, the columns); then nb and nnz, the offsets.
        head = [*(f.m for f in factors), *arities, *(d for f in factors for d in f.slot_dims)]
        packed = 17 + 3 * k
        wide, narrow = analysis_layout(nv, n, room) if analysis else ([], [])
        (args, self._sizes, self._offsets, *wide_arrays), at64 = carve(np.int64, [packed + len(head), 2, nv + 1, *wide])
        self.candidates = np.empty(nv + sum(f.m * a * (a - 1) for f, a in zip(factors, arities, strict=True)), np.int32)
        # H's index arrays stand alone: SciPy copies a view of a larger buffer into its matrices, whose
        # patterns a solver then no longer recognizes as the structure's. The rest is cut from one buffer.
        self.block_ptr, self.indptr = np.empty(nv + 1, np.int32), np.empty(n + 1, np.int32)
        self._indices = np.empty(room, np.int32)
        lengths = [n, *(f.m * f.width**2 for f in factors), *(f.m * f.width for f in factors)]
        (self._diagonal, *arrays), at = carve(np.int32, [*lengths, *narrow])
        self._scatters = arrays[: 2 * k]
        self.analysis = (wide_arrays, at64[3:], arrays[2 * k :], at[1 + 2 * k :]) if analysis else None
        self._dims64 = np.ascontiguousarray(dims, dtype=np.int64)
        self.address, heads, pointers = at64[0], at64[0] + 8 * packed, at64[0] + 8 * 17
        args[:] = [
            nv, k, _at(self._dims64), at64[2], heads, heads + 8 * k, heads + 16 * k, pointers,
            _at(self.block_ptr), _at(self.candidates), _at(self.indptr), _at(self._indices), room, at[0],
            pointers + 8 * k, pointers + 16 * k, at64[1], *(_at(a) for a in ids), *at[1 : 1 + 2 * k], *head,
        ]  # fmt: skip

    def run(self) -> Pattern:
        """Build here and now: :meth:`result`."""
        return self.result(_library().build_structure(self.address))

    def result(self, status: int) -> Pattern:
        """The built arrays, given the build's status: the block pattern ``(indptr, rows)``, ``H``'s
        ``indptr``, ``indices`` and diagonal positions, and per factor its scatter into ``H.data``
        (every edge's ``W²`` positions) and into ``g`` (every edge's ``W`` coordinates), all 32-bit;
        then the variables' offsets.

        Raises
        ------
        ValueError
            As :func:`~manopt_lie.linalg._factors.check_edges`, for the first factor type with an edge
            out of range, on a variable twice, or on a variable of another dimension than its slot's.
        """
        if status == -3:  # NumPy's checks name the edge
            f = int(self._sizes[0])
            _factors.check_edges(f, self._factors[f].var_ids, self._dims)
        if status == -1:
            raise MemoryError("patterns.c: no memory for the structure")
        if status != 0:  # the room bounds every pattern of these edges
            raise RuntimeError(f"patterns.c: the structure's build failed ({status})")
        nb, nnz = (int(c) for c in self._sizes)
        block_rows = self.candidates[:nb].copy()  # not the candidates' room
        indices = self._indices if nnz == self.room else self._indices[:nnz].copy()  # edges joining the same variables
        k = len(self._factors)
        scatters = list(zip(self._scatters[:k], self._scatters[k:], strict=True))
        offsets = self._offsets.astype(np.intp, copy=False)
        return (self.block_ptr, block_rows), self.indptr, indices, self._diagonal, scatters, offsets


def hessian_pattern(
    dims: NDArray[np.intp], n: int, squares: int, factors: Sequence[FactorIndex], analysis_entries: int = 0
) -> StructureBuild | None:
    """The compiled build of a structure's arrays from its variables' dimensions (``n`` in all,
    ``squares`` their squares' sum) and factor types, planned (:class:`StructureBuild`, with the
    arrays of an analysis where ``H`` holds at most ``analysis_entries`` entries), or ``None``."""
    # H's entries where no two edges join the same variables: the diagonal blocks, and each edge's
    # blocks off the diagonal (W² less the slots' own d²); fewer where some do.
    room = squares + sum(f.m * (f.width**2 - sum(d * d for d in f.slot_dims)) for f in factors)
    if (
        _library() is None or max(n, room) >= INT32_MAX
        or any(f.m * f.width**2 * 4 > _factors.WHOLE_SCATTER_BYTES for f in factors)
    ):  # fmt: skip
        return None
    return StructureBuild(dims, n, room, factors, room <= analysis_entries)


def _int32(*arrays: NDArray[np.signedinteger]) -> bool:
    return all(a.dtype == np.int32 for a in arrays)


def permuted_block_triangle(
    indptr: NDArray[np.signedinteger], dims: NDArray[np.signedinteger], block_indptr: NDArray[np.signedinteger],
    block_rows: NDArray[np.signedinteger], order: NDArray[np.intp], upper: bool = False,
) -> tuple[Triangle, NDArray[np.intp]] | None:
    """:func:`~manopt_lie.linalg._triangles.permuted_block_triangle` (the same arrays) and ``P`` as
    the coordinates of ``H`` in ``B``'s order (``_factors.coordinates`` of ``order``), for a 32-bit
    ``H`` and block pattern; else ``None``."""
    library = _library()
    if library is None or not _int32(indptr, block_indptr, block_rows):
        return None
    nv, n = dims.size, indptr.size - 1
    size = (int(indptr[-1]) + n) // 2  # one triangle of a symmetric pattern, its diagonal included
    out_ptr, rows, gather = np.empty(n + 1, np.int32), np.empty(size, np.int32), np.empty(size, np.int32)
    perm = np.empty(n, dtype=np.int64)
    dims64, order64 = (np.ascontiguousarray(a, dtype=np.int64) for a in (dims, order))
    status = library.permuted_triangle(nv, *(_at(a) for a in (dims64, indptr, block_indptr, block_rows, order64)),
                                       int(upper), size, _at(out_ptr), _at(rows), _at(gather), _at(perm))  # fmt: skip
    if status == -1:
        raise MemoryError("patterns.c: no memory for the permuted triangle")
    if status < 0 or out_ptr[-1] != size:
        raise ValueError("permuted_block_triangle: the blocks do not make H's pattern (its indptr)")
    return (out_ptr, rows, gather), perm.astype(np.intp, copy=False)


def block_symbolic(
    block_indptr: NDArray[np.signedinteger], block_rows: NDArray[np.signedinteger], order: NDArray[np.intp],
    bounded: bool = True,
) -> tuple[NDArray[np.intp], NDArray[np.int64]] | None:
    """The variables' simplicial symbolic factorization in ``order`` (``patterns.c:
    block_symbolic``): their postordered order and the blocks in each column of ``L`` (its diagonal
    block included), in that order; ``None`` without the library or where ``L`` would hold more
    than :data:`SIMPLICIAL_FILL` blocks per stored block (CHOLMOD then analyses), unless not
    ``bounded``."""
    library = _library()
    if library is None or not _int32(block_indptr, block_rows):
        return None
    nv = block_indptr.size - 1
    order64 = np.ascontiguousarray(order, dtype=np.int64)
    variables, counts = np.empty(nv, dtype=np.int64), np.empty(nv, dtype=np.int64)
    budget = SIMPLICIAL_FILL * block_rows.size if bounded else INT64_MAX
    status = library.block_symbolic(nv, _at(block_indptr), _at(block_rows), _at(order64),
                                    budget, _at(variables), _at(counts))  # fmt: skip
    if status == -1:
        raise MemoryError("patterns.c: no memory for the variables' symbolic factorization")
    return (variables.astype(np.intp, copy=False), counts) if status == 0 else None
