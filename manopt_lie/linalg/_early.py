"""A new structure's analysis, run on a thread of its own while its first linearization goes on.

The first solve of a pattern orders the variables (AMD), analyses the variables' graph in that
order (``patterns.c: block_symbolic``), expands that to the symbolic factor of ``B = P H Pᵀ`` and
builds the triangle of ``B`` that CHOLMOD factors (``permuted_triangle``). None of it reads the
values of ``H``, only the block pattern, which :class:`~manopt_lie.linalg.BlockStructure` has as
soon as it is built, before the first linearization assembles ``H`` and ``g`` (CSAIL: 0.3 ms,
about what the analysis takes). So the structure starts these steps in C (``patterns.c:
early_start``) on a worker thread, which needs no GIL, and the first analysis takes what they made
(:meth:`EarlyAnalysis.result`) instead of making it. A structure whose build can wait (a problem's,
its residuals' lengths declared) has the thread build it first, while the problem evaluates its
first residuals (:meth:`EarlyAnalysis.start_with`).

Each step runs where the one before succeeded; one that did not run or failed leaves its result
``None``, and the analysis makes it as before. ``B``'s factor and triangle are made only where
CHOLMOD's default choice of kind is simplicial: a supernodal factor is CHOLMOD's analysis, its
triangle the other one, in the supernodes' order.

Only structures of at most :data:`EARLY_ENTRIES` stored entries start one: the set-up weighs in a
small solve, and a structure that is never factored (a matrix-free solver's) then costs at most a
few MB of triangle.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from . import _amd, _patterns
from ._cholmod_types import _DEFAULTS
from ._patterns import Int32, StructureBuild, Triangle

__all__ = ["EARLY_ENTRIES", "Analysis", "EarlyAnalysis", "Simplicial"]

EARLY_ENTRIES = 1 << 20
"""The most stored entries of ``H`` for which a structure starts its analysis early (the triangle's rows
and their positions in ``H.data``, half as many each: at most 4 MB of 32-bit indices)."""


@dataclass(frozen=True)
class Analysis:
    """What the early analysis made, each ``None`` where its step did not run or failed."""

    order: NDArray[np.intp] | None
    """AMD's order of the variables (:func:`~manopt_lie.linalg._amd.variable_order`'s)."""
    symbolic: tuple[NDArray[np.intp], NDArray[np.int64]] | None
    """:func:`~manopt_lie.linalg._patterns.block_symbolic` in :attr:`order`."""
    simplicial: Simplicial | None
    """``B``'s simplicial factor in the symbolic's postordered variables, where CHOLMOD's default
    choice of kind is simplicial."""
    dimension: int = 0
    """Every variable's dimension (an analysis runs for variables of one dimension only; 0 where
    nothing was made)."""


@dataclass(frozen=True)
class Simplicial:
    """``B``'s simplicial symbolic factor, from the variables' (``Cholmod._analyze_blocks``)."""

    cost: tuple[float, float]
    """``(Σ_j c_j, Σ_j c_j²)`` over ``B``'s columns (``Cholmod.cost``)."""
    column_counts: Int32
    """The entries ``c_j`` of each column of ``L`` (what ``Cholmod._expand`` writes)."""
    triangle: Triangle
    """The upper triangle of ``B`` (:func:`~manopt_lie.linalg._patterns.permuted_block_triangle`,
    ``upper=True``)."""
    perm: NDArray[np.intp]
    """``P``: the coordinate of ``H`` of each of ``B``'s."""


_NOTHING = Analysis(None, None, None)


class EarlyAnalysis:
    """The analysis of a block pattern, started on a thread at construction (see the module).

    Parameters
    ----------
    dims : ndarray of int64, shape (n_vars,)
        The variables' dimensions, all ``dimension``.
    dimension : int
    indptr : ndarray of int32, shape (n + 1,)
        ``H``'s CSC ``indptr``.
    block_indptr, block_rows : ndarray of int32
        The block pattern (both triangles, every diagonal block).
    build : StructureBuild, optional
        The structure's build, not run yet: the thread runs it first (:meth:`built` waits for it),
        and the pattern is what it makes (``indptr``, ``block_indptr`` and ``block_rows`` are
        then its arrays).

    The arrays must not change until :meth:`result` (the structure's never do).
    """

    _handle: int | None = None  # patterns.c's, until joined

    def __init__(
        self, dims: NDArray[np.int64], dimension: int, indptr: Int32, block_indptr: Int32, block_rows: Int32,
        build: StructureBuild | None = None,
    ) -> None:  # fmt: skip
        self._library = library = _patterns._library()  # found by start(), with AMD
        nv, n = dims.size, indptr.size - 1
        # What the thread writes, kept until it is joined (as what it reads), and its arguments: cut
        # from two buffers, the build's where it has them.
        if build is not None and build.analysis is not None:
            wide, at_wide, narrow, at_narrow = build.analysis
        else:
            lengths64, lengths32 = _patterns.analysis_layout(nv, n, int(indptr[-1]))
            wide, at_wide = _patterns.carve(np.int64, lengths64)
            narrow, at_narrow = _patterns.carve(np.int32, lengths32)
        *self._outputs, self._perm, self._status, cost, self._build_status, args = wide
        self._cost = cost.view(np.float64)  # (lnz, fl)
        self._order32, self._columns, *triangle = narrow
        self._triangle: Triangle = (triangle[0], triangle[1], triangle[2])
        self._inputs = (dims, indptr, block_indptr, block_rows, build)
        self._dimension = dimension
        self._status_at, self._build_status_at = at_wide[4], at_wide[6]  # for __del__ (also at exit) and built()
        at = _patterns._at
        args[:] = [
            _amd.amd_order_address(), nv, dimension, *(at(a) for a in self._inputs[:4]), _patterns.SIMPLICIAL_FILL,
            triangle[1].size, at_narrow[0], *at_wide[:3], *at_narrow[2:], at_wide[3], at_narrow[1], at_wide[5],
        ]  # fmt: skip
        build_at = None if build is None else build.address
        handle = library.early_start(build_at, at_wide[7], _DEFAULTS["supernodal_switch"])
        if not handle:
            raise MemoryError("patterns.c: no memory to start the analysis")
        self._handle = handle
        self._lock = threading.Lock()
        self._result: Analysis | None = None

    @classmethod
    def start(
        cls, dims: NDArray[np.intp], dimension: int, indptr: NDArray[np.signedinteger],
        block_indptr: NDArray[np.signedinteger], block_rows: NDArray[np.signedinteger],
    ) -> EarlyAnalysis | None:  # fmt: skip
        """An analysis started for this pattern of variables of one ``dimension`` (0: of several), or
        ``None`` where none is: more than :data:`EARLY_ENTRIES` entries, variables of several
        dimensions, indices that are not 32-bit, or no compiled library or AMD here."""
        if int(indptr[-1]) > EARLY_ENTRIES or not all(a.dtype == np.int32 for a in (indptr, block_indptr, block_rows)):
            return None
        return cls(dims, dimension, indptr, block_indptr, block_rows) if cls._runs(dims, dimension) else None

    @classmethod
    def start_with(cls, dims: NDArray[np.intp], dimension: int, build: StructureBuild) -> EarlyAnalysis | None:
        """An analysis started after ``build`` on the thread, as :meth:`start` would start one after it,
        where ``build`` holds its arrays (:meth:`entries`); else ``None``."""
        if build.analysis is None:
            return None
        return cls(dims, dimension, build.indptr, build.block_ptr, build.candidates, build)

    @classmethod
    def entries(cls, dims: NDArray[np.intp], dimension: int) -> int:
        """The most entries of ``H`` for which a structure of these variables starts an analysis:
        :data:`EARLY_ENTRIES`, or 0 where none runs."""
        return EARLY_ENTRIES if cls._runs(dims, dimension) else 0

    @staticmethod
    def _runs(dims: NDArray[np.intp], dimension: int) -> bool:
        """Whether an analysis can run for these variables: of one dimension, AMD and the C here."""
        return (
            dimension >= 1 and dims.dtype == np.int64 and dims.flags.c_contiguous
            and _patterns._library() is not None and _amd.amd_order_address() is not None
        )  # fmt: skip

    def built(self) -> int | None:
        """Waits for the build (given at construction) and returns its status, or ``None`` in a process
        forked from the one that started it (its arrays are unwritten: build them here)."""
        handle = self._handle
        if handle is None:
            return None
        if self._library.early_built(handle, self._build_status_at) != 0:
            return None
        return int(self._build_status[0])

    def _join(self) -> bool:
        """Wait for the thread (once): whether its statuses were written (not in a forked process, where
        the thread stayed in the parent). Until then, this object keeps every array the thread touches."""
        handle, self._handle = self._handle, None
        return handle is not None and self._library.early_join(handle, self._status_at) == 0

    def __del__(self) -> None:
        self._join()  # never free what the thread may still write

    def result(self) -> Analysis:
        """What the analysis made, once its thread is done (waited for at the first call)."""
        with self._lock:
            if self._result is None:
                self._result = self._read() if self._join() else _NOTHING
            return self._result

    def _read(self) -> Analysis:
        amd, symbolic, triangle = (int(s) for s in self._status)
        if amd not in _amd.SUCCESS:
            return _NOTHING
        order, variables, counts = self._outputs
        made = None
        if triangle == 0:
            cost = (float(self._cost[0]), float(self._cost[1]))
            indptr, rows, gather = self._triangle
            size = int(indptr[-1])  # below the room where the structure was built on the thread
            perm = self._perm.astype(np.intp, copy=False)
            made = Simplicial(cost, self._columns, (indptr, rows[:size], gather[:size]), perm)
        symbolic_ = (variables.astype(np.intp, copy=False), counts) if symbolic == 0 else None
        return Analysis(order.astype(np.intp, copy=False), symbolic_, made, self._dimension)
