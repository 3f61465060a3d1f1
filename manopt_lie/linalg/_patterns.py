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
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import _native
from . import _amd, _factors
from ._cholmod_types import _DEFAULTS
from ._factors import FactorIndex

__all__ = ["Plan", "StructureBuild", "block_symbolic", "hessian_pattern", "permuted_block_triangle"]

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
    "block_symbolic": (ctypes.c_int, [_I, _P, _P, _P, _I, _P, _P, _P]),
    "early_start": (_P, [_P, _P, ctypes.c_double]),
    "early_built": (ctypes.c_int, [_P, _P]),
    "early_join": (ctypes.c_int, [_P, _P]),
    "plan_structure": (_I, [_P, ctypes.c_double]),
}


@functools.cache
def _library() -> Any:
    """``patterns.c`` and ``early.c`` compiled into one library (once per machine, like the kernels),
    or ``None``."""
    return _native.load_source(__package__, ("patterns.c", "early.c"), _SIGNATURES)


_at = _native.address

PLAN_BUILD, PLAN_ANALYSIS, PLAN_START = 1, 2, 4
"""``early.c: plan_structure``'s flags: the build's arrays, the analysis's, and the analysis started."""
# The entries of its table (early.c's PLAN_* enum): where each array starts in one of the two
# buffers (then every factor type's positions and columns), and the triangle's room.
(_BUILD_ARGS, _EARLY_ARGS, SIZES, OFFSETS, ORDER, VARIABLES, COUNTS, PERM, STATUS, COST, BUILD_STATUS, BPTR,
 CANDIDATES, DIAGONAL, AMD_ORDER, COLCOUNT, TRI_INDPTR, TRI_ROWS, TRI_GATHER, TRI_SIZE, _TABLE) = range(21)  # fmt: skip


class Plan:
    """The arrays of a structure's build and of its analysis (``flags``), cut from two new buffers by
    ``early.c: plan_structure``, which packs the C's arguments there and, with :data:`PLAN_START`,
    starts the analysis on the worker thread (after the build where one is planned): one call, and
    views made only of the arrays read, when they are read (:meth:`int64`, :meth:`int32`).

    Parameters
    ----------
    nv, n, room : int
        Variables, coordinates, and the most entries ``H`` may store.
    flags : int
        :data:`PLAN_BUILD`, :data:`PLAN_ANALYSIS` and :data:`PLAN_START`, or'ed.
    dims : ndarray of int64, shape (nv,)
    indptr : ndarray of int32, shape (n + 1,)
        ``H``'s (written by the build; read by the analysis).
    indices : ndarray of int32, shape (room,), optional
        ``H``'s, written by the build.
    block_pattern : (indptr, rows) of int32, optional
        The pattern an analysis without a build reads.
    factors : sequence of FactorIndex
        The build's factor types.
    dimension : int
        The variables' one dimension (the analysis's).

    Attributes
    ----------
    handle : int or None
        The analysis started (``early.c: early_start``'s handle), until :meth:`join`.
    """

    handle: int | None = None

    def __init__(
        self, nv: int, n: int, room: int, flags: int, dims: NDArray[np.int64], indptr: Int32,
        indices: Int32 | None = None, block_pattern: tuple[Int32, Int32] | None = None,
        factors: Sequence[FactorIndex] = (), dimension: int = 0,
    ) -> None:  # fmt: skip
        k = len(factors)
        ids = [np.ascontiguousarray(f.var_ids, dtype=np.int64) for f in factors]
        arities = [a.shape[1] for a in ids]
        len64, len32 = _TABLE + 2 * k, 0  # as plan_structure lays them out (it checks them)
        if flags & PLAN_BUILD:
            len64 += 17 + 3 * k + 2 + nv + 1
            per_edge = [a * (a - 1) + f.width**2 + f.width for f, a in zip(factors, arities, strict=True)]
            len32 += 2 * nv + 1 + n + sum(f.m * e for f, e in zip(factors, per_edge, strict=True))
        if flags & PLAN_ANALYSIS:
            len64 += 19 + 3 * nv + n + 6
            len32 += nv + 2 * n + 1 + 2 * ((room + n) // 2)
        self._buffers = self._int64, self._int32 = np.empty(len64, np.int64), np.empty(len32, np.int32)
        bptr, brows = (0, 0) if block_pattern is None else (_at(block_pattern[0]), _at(block_pattern[1]))
        amd = _amd.amd_order_address() if flags & PLAN_ANALYSIS else 0
        head = np.array(
            [nv, k, n, room, flags, dimension, _at(dims), _at(indptr), 0 if indices is None else _at(indices), bptr,
             brows, _at(self._int64), len64, _at(self._int32), len32, amd or 0, SIMPLICIAL_FILL,
             *(_at(a) for a in ids), *(f.m for f in factors), *arities, *(d for f in factors for d in f.slot_dims)],
            dtype=np.int64,
        )  # fmt: skip
        self._inputs = (head, dims, indptr, indices, block_pattern, ids)  # what the C reads, kept with the plan
        self._library, self._base64 = _library(), _at(self._int64)  # (for __del__, also at exit)
        handle = self._library.plan_structure(_at(head), _DEFAULTS["supernodal_switch"])
        if handle == -2:
            raise MemoryError("early.c: no memory to start the analysis")
        if handle < 0:
            raise RuntimeError("early.c: the plan's buffers are not as long as the plan")
        self.handle = handle or None
        self._table: list[int] = self._int64[: _TABLE + 2 * k].tolist()
        # where the thread writes its statuses (no module global read: join runs in __del__, also at exit)
        self._status_at, self._build_status_at = self.address64(STATUS), self.address64(BUILD_STATUS)

    def int64(self, entry: int, length: int) -> NDArray[np.int64]:
        """The int64 array of this table ``entry`` (its first ``length`` entries)."""
        start = self._table[entry]
        return self._int64[start : start + length]

    def int32(self, entry: int, length: int) -> Int32:
        """The int32 array of this table ``entry`` (its first ``length`` entries)."""
        start = self._table[entry]
        return self._int32[start : start + length]

    def address64(self, entry: int) -> int:
        """The address of the int64 array of this table ``entry``."""
        return self._base64 + 8 * self._table[entry]

    def built(self) -> int | None:
        """Waits for the build planned with the analysis and returns its status, or ``None`` in a process
        forked from the one that started it (its arrays are unwritten: build them here)."""
        if self.handle is None or self._library.early_built(self.handle, self._build_status_at) != 0:
            return None
        return int(self._int64[self._table[BUILD_STATUS]])

    def join(self) -> bool:
        """Wait for the analysis's thread (once): whether its statuses were written (not in a forked
        process, where the thread stayed in the parent). Until then, this plan keeps every array the
        thread touches."""
        handle, self.handle = self.handle, None
        return handle is not None and self._library.early_join(handle, self._status_at) == 0

    def __del__(self) -> None:
        self.join()  # never free what the thread may still write

    def build_arguments(self) -> int:
        """The address of ``build_structure``'s packed arguments."""
        return self.address64(_BUILD_ARGS)


class StructureBuild:
    """A structure's compiled build (``patterns.c: build_structure``), planned: its arrays made empty
    and its arguments packed for the C (:class:`Plan`), which fills them now (:meth:`run`) or on the
    worker thread, before the structure's analysis there (``dimension``: planned and started with it,
    ``_early.EarlyAnalysis.start_with``), while the caller goes on. :meth:`result` then reads them.
    Made by :func:`hessian_pattern`.

    Attributes
    ----------
    room : int
        The most entries ``H`` may store (no two edges joining the same variables).
    plan : Plan
        The build's arrays, and the analysis's where it is planned (``plan.handle``: started).
    """

    def __init__(
        self, dims: NDArray[np.intp], n: int, room: int, factors: Sequence[FactorIndex], dimension: int = 0
    ) -> None:
        self._factors, self._dims, self.room = factors, dims, room
        # H's index arrays stand alone: SciPy copies a view of a larger buffer into its matrices, whose
        # patterns a solver then no longer recognizes as the structure's. The rest is cut from the plan's.
        self.indptr, self._indices = np.empty(n + 1, np.int32), np.empty(room, np.int32)
        flags = PLAN_BUILD | (PLAN_ANALYSIS | PLAN_START if dimension else 0)
        dims64 = np.ascontiguousarray(dims, dtype=np.int64)
        self.plan = Plan(dims.size, n, room, flags, dims64, self.indptr, self._indices, None, factors, dimension)

    def run(self) -> Pattern:
        """Build here and now: :meth:`result`."""
        return self.result(self.plan._library.build_structure(self.plan.build_arguments()))

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
        plan, nv, k = self.plan, self._dims.size, len(self._factors)
        nb, nnz = plan.int64(SIZES, 2).tolist()
        if status == -3:  # NumPy's checks name the edge
            _factors.check_edges(nb, self._factors[nb].var_ids, self._dims)
        if status == -1:
            raise MemoryError("patterns.c: no memory for the structure")
        if status != 0:  # the room bounds every pattern of these edges
            raise RuntimeError(f"patterns.c: the structure's build failed ({status})")
        block_rows = plan.int32(CANDIDATES, nb).copy()  # not the candidates' room
        indices = self._indices if nnz == self.room else self._indices[:nnz].copy()  # edges joining the same variables
        scatters = [(plan.int32(_TABLE + f, x.m * x.width**2), plan.int32(_TABLE + k + f, x.m * x.width))
                    for f, x in enumerate(self._factors)]  # fmt: skip
        offsets = plan.int64(OFFSETS, nv + 1).astype(np.intp, copy=False)
        diagonal = plan.int32(DIAGONAL, self.indptr.size - 1)
        return (plan.int32(BPTR, nv + 1), block_rows), self.indptr, indices, diagonal, scatters, offsets


def hessian_pattern(
    dims: NDArray[np.intp], n: int, squares: int, factors: Sequence[FactorIndex], analysis_entries: int = 0,
    dimension: int = 0,
) -> StructureBuild | None:  # fmt: skip
    """The compiled build of a structure's arrays from its variables' dimensions (``n`` in all,
    ``squares`` their squares' sum) and factor types, planned (:class:`StructureBuild`, with the
    analysis of its variables of one ``dimension`` planned and started after it where ``H`` holds at
    most ``analysis_entries`` entries), or ``None``."""
    # H's entries where no two edges join the same variables: the diagonal blocks, and each edge's
    # blocks off the diagonal (W² less the slots' own d²); fewer where some do.
    room = squares + sum(f.m * (f.width**2 - sum(d * d for d in f.slot_dims)) for f in factors)
    if (
        _library() is None or max(n, room) >= INT32_MAX
        or any(f.m * f.width**2 * 4 > _factors.WHOLE_SCATTER_BYTES for f in factors)
    ):  # fmt: skip
        return None
    return StructureBuild(dims, n, room, factors, dimension if room <= analysis_entries else 0)


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
    bounded: bool = True, weights: NDArray[np.signedinteger] | None = None,
) -> tuple[NDArray[np.intp], NDArray[np.int64]] | None:  # fmt: skip
    """The variables' simplicial symbolic factorization in ``order`` (``patterns.c:
    block_symbolic``): their postordered order and the blocks in each column of ``L`` (its diagonal
    block included), in that order — with ``weights`` (the variables' dimensions) the rows, each
    block counting its variable's; ``None`` without the library or where ``L`` would hold more
    than :data:`SIMPLICIAL_FILL` blocks per stored block (CHOLMOD then analyses), unless not
    ``bounded``."""
    library = _library()
    if library is None or not _int32(block_indptr, block_rows):
        return None
    nv = block_indptr.size - 1
    order64 = np.ascontiguousarray(order, dtype=np.int64)
    variables, counts = np.empty(nv, dtype=np.int64), np.empty(nv, dtype=np.int64)
    budget = SIMPLICIAL_FILL * block_rows.size if bounded else INT64_MAX
    weights64 = None if weights is None else np.ascontiguousarray(weights, dtype=np.int64)
    status = library.block_symbolic(nv, _at(block_indptr), _at(block_rows), _at(order64), budget, _at(variables),
                                    _at(counts), None if weights64 is None else _at(weights64))  # fmt: skip
    if status == -1:
        raise MemoryError("patterns.c: no memory for the variables' symbolic factorization")
    return (variables.astype(np.intp, copy=False), counts) if status == 0 else None
