"""A new structure's analysis, run on a thread of its own while its first linearization goes on.

The first solve of a pattern orders the variables (AMD), analyses the variables' graph in that
order (``patterns.c: block_symbolic``), expands that to the symbolic factor of ``B = P H Pᵀ`` and
builds the triangle of ``B`` that the simplicial ``LDLᵀ`` factors (``permuted_triangle``): the
compiled one (:mod:`~manopt_lie.linalg._ldl`) or CHOLMOD's. None of it reads the values of ``H``,
only the block pattern, which :class:`~manopt_lie.linalg.BlockStructure` has as soon as it is
built, before the first linearization assembles ``H`` and ``g`` (CSAIL: 0.3 ms, about what the
analysis takes). So the structure starts these steps in C (``early.c: early_start``) on a worker
thread, which needs no GIL, and the first analysis takes what they made
(:meth:`EarlyAnalysis.result`) instead of making it. A structure whose build can wait (a problem's,
its residuals' lengths declared) has the thread build it first, while the problem evaluates its
first residuals (:meth:`EarlyAnalysis.start_with`): the build and the analysis are planned and
started in one call (:class:`~manopt_lie.linalg._patterns.Plan`).

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
from ._factors import exclusive_cumsum
from ._patterns import Int32, Plan, StructureBuild, Triangle

__all__ = ["EARLY_ENTRIES", "Analysis", "EarlyAnalysis", "Simplicial", "analyse_here", "coordinates_cost"]

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


def coordinates_cost(lnz_b: float, fl_b: float, nv: int, d: int) -> tuple[float, float]:
    """``(Σ_j c_j, Σ_j c_j²)`` over ``B``'s columns from ``Σ c`` and ``Σ c²`` over the variables'
    columns of ``L`` (``c`` blocks each, ``nv`` variables of dimension ``d``): column ``a`` of a
    variable holds ``d·c − a`` entries (``early.c: early_run`` sums the same)."""
    lnz = d * d * lnz_b - nv * d * (d - 1) / 2
    fl = d**3 * fl_b - d * d * (d - 1) * lnz_b + nv * (d - 1) * d * (2 * d - 1) / 6
    return lnz, fl


def analyse_here(
    dims: NDArray[np.intp], dimension: int, indptr: Int32, block_indptr: Int32, block_rows: Int32,
    order: NDArray[np.intp], simplicial_always: bool = False,
) -> Analysis:  # fmt: skip
    """What an early analysis makes in ``order`` (AMD's, given), made here by the same compiled steps:
    for a structure that started none — past :data:`EARLY_ENTRIES`, or of variables of several
    dimensions (``dimension`` 0: each block then counts its rows, and :attr:`Analysis.symbolic`
    is left out) — which a solver of the automatic choice analyses. ``B``'s simplicial factor is made
    where CHOLMOD's default choice of kind is simplicial, as on the thread; with
    ``simplicial_always`` (the backend ``ldl`` asked for), whatever its fill."""
    weights = None if dimension else dims
    symbolic = _patterns.block_symbolic(block_indptr, block_rows, order, not simplicial_always, weights)
    if symbolic is None:
        return Analysis(order, None, None, dimension)
    variables, counts = symbolic
    if dimension:  # column a of a variable whose column of L holds c blocks: d·c − a rows
        lnz, fl = coordinates_cost(float(counts.sum()), float(np.dot(counts, counts)), counts.size, dimension)
        column_counts = ((dimension * counts)[:, None] - np.arange(dimension)).reshape(-1)
    else:  # c rows in its first column, one fewer in each next
        d = dims[variables]
        column_counts = np.repeat(counts, d) - (np.arange(int(d.sum())) - np.repeat(exclusive_cumsum(d)[:-1], d))
        lnz, fl = float(column_counts.sum()), float(np.dot(column_counts.astype(np.float64), column_counts))
    simplicial = None
    if simplicial_always or fl < _DEFAULTS["supernodal_switch"] * lnz:
        made = _patterns.permuted_block_triangle(indptr, dims, block_indptr, block_rows, variables, upper=True)
        if made is not None:
            simplicial = Simplicial((lnz, fl), column_counts.astype(np.int32), made[0], made[1])
    return Analysis(order, symbolic if dimension else None, simplicial, dimension)


class EarlyAnalysis:
    """The analysis of a block pattern, started on a thread (see the module): by :meth:`start` for a
    structure built already, or with its build (:meth:`start_with`).

    Parameters
    ----------
    plan : Plan
        Where the analysis's arrays are and its handle (``early.c: plan_structure``), which the
        plan keeps, with every array the thread reads or writes, until it is joined.
    nv, n : int
        The variables and coordinates.
    dimension : int
        Every variable's dimension.
    """

    def __init__(self, plan: Plan, nv: int, n: int, dimension: int) -> None:
        self._plan, self._nv, self._n, self._dimension = plan, nv, n, dimension
        self._lock = threading.Lock()
        self._result: Analysis | None = None

    @classmethod
    def start(
        cls, dims: NDArray[np.intp], dimension: int, indptr: NDArray[np.signedinteger],
        block_indptr: NDArray[np.signedinteger], block_rows: NDArray[np.signedinteger],
    ) -> EarlyAnalysis | None:  # fmt: skip
        """An analysis started for this pattern of variables of one ``dimension`` (0: of several), or
        ``None`` where none is: more than :data:`EARLY_ENTRIES` entries, variables of several
        dimensions, indices that are not 32-bit, or no compiled library or AMD here. The arrays must
        not change until :meth:`result` (a structure's never do)."""
        entries = int(indptr[-1])
        if entries > EARLY_ENTRIES or not all(a.dtype == np.int32 for a in (indptr, block_indptr, block_rows)):
            return None
        if not cls._runs(dims, dimension):
            return None
        nv, n = dims.size, indptr.size - 1
        flags = _patterns.PLAN_ANALYSIS | _patterns.PLAN_START
        plan = _patterns.Plan(nv, n, entries, flags, dims, indptr, block_pattern=(block_indptr, block_rows),
                              dimension=dimension)  # fmt: skip
        return cls(plan, nv, n, dimension)

    @classmethod
    def start_with(cls, dims: NDArray[np.intp], dimension: int, build: StructureBuild) -> EarlyAnalysis | None:
        """The analysis ``build`` planned and started after it on the thread (where it was given a
        ``dimension``: :meth:`entries`), else ``None``."""
        if build.plan.handle is None:
            return None
        return cls(build.plan, dims.size, build.indptr.size - 1, dimension)

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
        """Waits for the build (planned with the analysis) and returns its status, or ``None`` in a
        process forked from the one that started it (its arrays are unwritten: build them here)."""
        return self._plan.built()

    def result(self) -> Analysis:
        """What the analysis made, once its thread is done (waited for at the first call)."""
        with self._lock:
            if self._result is None:
                self._result = self._read() if self._plan.join() else _NOTHING
            return self._result

    def _read(self) -> Analysis:
        plan, nv, n = self._plan, self._nv, self._n
        amd, symbolic, triangle = plan.int64(_patterns.STATUS, 3).tolist()
        if amd not in _amd.SUCCESS:
            return _NOTHING
        made = None
        if triangle == 0:
            cost = plan.int64(_patterns.COST, 2).view(np.float64).tolist()
            indptr = plan.int32(_patterns.TRI_INDPTR, n + 1)
            size = int(indptr[-1])  # below the room where the structure was built on the thread
            triangle_ = (indptr, plan.int32(_patterns.TRI_ROWS, size), plan.int32(_patterns.TRI_GATHER, size))
            perm = plan.int64(_patterns.PERM, n).astype(np.intp, copy=False)
            made = Simplicial((cost[0], cost[1]), plan.int32(_patterns.COLCOUNT, n), triangle_, perm)
        symbolic_ = None
        if symbolic == 0:
            variables = plan.int64(_patterns.VARIABLES, nv).astype(np.intp, copy=False)
            symbolic_ = (variables, plan.int64(_patterns.COUNTS, nv))
        order = plan.int64(_patterns.ORDER, nv).astype(np.intp, copy=False)
        return Analysis(order, symbolic_, made, self._dimension)
