"""The predicted cost of a sparse Cholesky factorization, and the choice it makes between a
direct and an iterative solve.

The factor ``L`` of ``H`` fills in where eliminating a variable connects its neighbours.
Along a trajectory (a pose graph's odometry with loop closures) the fill stays within a
few times ``nnz(H)``; on a well-connected graph — rotation averaging with many random
relative measurements, an expander — ``L`` is nearly dense, and a factorization costs
``O(n³)`` where a product with ``H`` costs ``O(nnz(H))``. Such graphs are also well
conditioned, so conjugate gradients preconditioned by the diagonal blocks converge in a few
dozen products. Measured (``benchmarks/bench_pose_graph.py`` and ``manopt-lie bench --suite
full``): on ``rotations-2000`` (6,000 unknowns, 2.3·10⁵ entries of ``H``) one factorization
takes 1.1 s and PCG 18–24 products of 0.3 ms; on every SE-Sync dataset the factorization is
the faster, by far on the ill-conditioned pose graphs (condition 10⁸–10¹¹).

:func:`factor_cost` predicts ``Σ_j c_j`` (``nnz(L)``) and ``Σ_j c_j²`` (the factorization's
flops, CHOLMOD's measure), ``c_j`` the count of column ``j``, from CHOLMOD's column counts of
the variables' graph in the structure's fill-reducing order: for variable ``k`` of dimension
``d_k`` whose column of ``L`` holds ``C_k`` blocks, ``c = d_k − i + (C_k − 1)·d̄`` for its
coordinates ``i = 0 … d_k − 1`` (``d̄`` the mean dimension; exact when all are equal).
:class:`AutoSolver` — the least-squares optimizers' default linear solver — factors unless the
flops reach :data:`ITERATIVE_FLOPS_PER_ENTRY` per entry of ``H``; then it runs PCG first,
capped at a quarter of a factorization's predicted time, and falls back to the factorization
for the rest of the run if PCG does not converge within the cap.
"""

from __future__ import annotations

import weakref
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ._cholmod import _block_order, block_column_counts
from ._triangles import ranges
from ._vector import norm
from .cholesky import CholeskySolver
from .errors import SingularSystemError
from .pcg import PCGSolver

if TYPE_CHECKING:
    from .structure import BlockStructure

__all__ = ["AutoSolver", "FactorCost", "factor_cost", "prefers_iterative"]

FloatArray = NDArray[np.float64]

ITERATIVE_FLOPS_PER_ENTRY = 5000.0
"""PCG is tried first where the factorization's predicted flops ``Σ c_j²`` reach this many per
stored entry of ``H``: rotations-2000 5.7·10⁴; the SE-Sync datasets 8 (CSAIL) to 860
(sphere2500), torus-20x100 842."""

FLOPS_PER_PRODUCT = 100.0
"""A product with ``H`` (one PCG iteration) costs about as much time as ``FLOPS_PER_PRODUCT``
flops of the factorization per entry of ``H`` (this machine: CHOLMOD's supernodal
factorization ~1.2·10¹⁰ of ``Σ c_j²`` per second, a product ~4 ns per entry); the PCG cap is a
quarter of a factorization in these units."""

_COSTS: weakref.WeakKeyDictionary[BlockStructure, FactorCost | None] = weakref.WeakKeyDictionary()


@dataclass(frozen=True)
class FactorCost:
    """The predicted size of ``L`` and cost of computing it.

    Attributes
    ----------
    nnz : float
        ``Σ_j c_j``: the entries of ``L`` (its diagonal included).
    flops : float
        ``Σ_j c_j²``: CHOLMOD's flop count of the factorization.
    """

    nnz: float
    flops: float


def factor_cost(structure: BlockStructure) -> FactorCost | None:
    """The predicted cost of factoring ``H`` of ``structure`` in its fill-reducing order;
    ``None`` where it cannot be predicted (no fill-reducing ordering or CHOLMOD not called
    directly). Computed once per structure."""
    if structure in _COSTS:
        return _COSTS[structure]
    cost = None
    ordering = structure.fill_reducing_ordering()
    order = None if ordering is None else _block_order(ordering, structure.dims)
    counts = None if order is None else block_column_counts(*structure.block_pattern, order)
    if counts is not None:
        variables, blocks = counts
        dims = structure.dims[variables]
        below = (blocks - 1) * float(structure.dims.mean())  # the rows under each diagonal block
        column = np.repeat(dims + below, dims) - ranges(dims)  # c of coordinate i of each variable: d − i + below
        cost = FactorCost(float(column.sum()), float(np.dot(column, column)))
    _COSTS[structure] = cost
    return cost


def prefers_iterative(structure: BlockStructure) -> bool:
    """Whether ``H`` of ``structure`` fills in so much that PCG is worth trying first (see the
    module's notes): a sparse structure whose predicted flops reach
    :data:`ITERATIVE_FLOPS_PER_ENTRY` per entry of ``H``."""
    cost = None if structure.dense else factor_cost(structure)
    return cost is not None and cost.flops >= ITERATIVE_FLOPS_PER_ENTRY * structure.nnz


class AutoSolver:
    """The linear solver a structure's fill calls for (``linear_solver="auto"``, the default of
    the least-squares optimizers): :class:`CholeskySolver`, unless the factor is predicted to be
    nearly dense (:func:`prefers_iterative`); then :class:`PCGSolver` first, capped at a quarter
    of a factorization's predicted time, and the factorization for the rest of the run after
    the first solve PCG does not finish within the cap (or finds ``H`` not positive definite).

    ``stats`` always holds ``linear_iterations``, ``linear_residual`` (``‖b − Hx‖/‖b‖``) and
    ``linear_converged`` where PCG is tried: a direct solve counts the iterations its failed
    PCG attempt took (0 once the run has fallen back) and is converged.

    Parameters
    ----------
    tol : float
        PCG's relative residual (see :class:`PCGSolver`).
    """

    def __init__(self, *, tol: float = 1e-6) -> None:
        self.tol = tol
        self._structure: BlockStructure | None = None
        self._iterative: PCGSolver | None = None
        self._direct: CholeskySolver | None = None
        self._stats: Mapping[str, float] = MappingProxyType({})

    def __repr__(self) -> str:
        return f"AutoSolver(tol={self.tol!r})"

    def bind(self, structure: BlockStructure) -> CholeskySolver | AutoSolver:
        """A :class:`CholeskySolver` bound to ``structure``, or, where the fill calls for PCG,
        a fresh :class:`AutoSolver` that tries it first."""
        if not prefers_iterative(structure):
            return CholeskySolver().bind(structure)
        cost = factor_cost(structure)
        assert cost is not None
        cap = int(min(structure.n, max(50.0, cost.flops / (4.0 * FLOPS_PER_PRODUCT * structure.nnz))))
        solver = AutoSolver(tol=self.tol)
        solver._structure = structure
        solver._iterative = PCGSolver(tol=self.tol, maxiter=cap).bind(structure)
        return solver

    @property
    def iterative(self) -> bool:
        """Whether the next solve tries PCG (bound, and not fallen back to the factorization)."""
        return self._iterative is not None

    def __call__(self, H: sp.csc_matrix, b: FloatArray) -> FloatArray:
        """``x ≈ H⁻¹b``: PCG's where it converges, else the factorization's."""
        if self._structure is None:
            raise RuntimeError("AutoSolver: bind(structure) before solving")
        attempted = 0.0
        if self._iterative is not None:
            try:
                x = self._iterative(H, b)
                if self._iterative.stats["linear_converged"]:
                    self._stats = self._iterative.stats
                    return x
                attempted = self._iterative.stats["linear_iterations"]
            except SingularSystemError:  # non-positive curvature: let the factorization judge H
                pass
            self._iterative = None  # PCG did not do: the factorization from now on
        if self._direct is None:
            self._direct = CholeskySolver().bind(self._structure)
        x = self._direct(H, b)
        residual = norm(H @ x - b) / max(norm(b), np.finfo(float).tiny)
        self._stats = MappingProxyType(
            {"linear_iterations": attempted, "linear_residual": residual, "linear_converged": 1.0}
        )
        return x

    @property
    def stats(self) -> Mapping[str, float]:
        """The numbers of the last solve (see the class notes); empty before the first."""
        return self._stats
