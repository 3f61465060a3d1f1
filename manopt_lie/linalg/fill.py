"""The choice between a direct and an iterative solve, by the fill of the Cholesky factor.

The factor ``L`` of ``H`` fills in where eliminating a variable connects its neighbours.
Along a trajectory (a pose graph's odometry with loop closures) the fill stays within a
few times ``nnz(H)``; on a well-connected graph — rotation averaging with many random
relative measurements, an expander — ``L`` is nearly dense, and a factorization costs
``O(n³)`` where a product with ``H`` costs ``O(nnz(H))``. Such graphs are also well
conditioned, so conjugate gradients preconditioned by the diagonal blocks converge in a few
dozen products. Measured (``manopt-lie bench --suite full``): on ``rotations-2000`` (6,000
unknowns, 2.3·10⁵ entries of ``H``) one factorization takes 1.1 s and PCG 18–24 products of
0.3 ms; on every SE-Sync dataset the factorization is the faster, by far on the
ill-conditioned pose graphs (condition 10⁸–10¹¹).

The symbolic analysis a factorization needs anyway predicts its cost
(:attr:`CholeskySolver.factor_cost`: ``Σ_j c_j²`` over the column counts ``c_j``, CHOLMOD's
flop count), so the choice costs nothing where the factorization is kept. :class:`AutoSolver`
— the least-squares optimizers' default linear solver — factors unless those flops reach
:data:`ITERATIVE_FLOPS_PER_ENTRY` per entry of ``H``; then it runs PCG, capped at a quarter of
a factorization's predicted time, and factors for the rest of the run after the first solve
PCG does not finish within the cap.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ._vector import norm
from .cholesky import CholeskySolver, FactorCost
from .errors import SingularSystemError
from .pcg import PCGSolver

if TYPE_CHECKING:
    from .structure import BlockStructure

__all__ = ["AutoSolver", "prefers_iterative"]

FloatArray = NDArray[np.float64]

ITERATIVE_FLOPS_PER_ENTRY = 5000.0
"""PCG is taken where the factorization's flops ``Σ c_j²`` reach this many per stored entry of
``H``: rotations-2000 5.7·10⁴; the SE-Sync datasets 8 (CSAIL) to 860 (sphere2500), torus-20x100
842, a 10⁵-pose cube 2.0·10³."""

FLOPS_PER_PRODUCT = 100.0
"""A product with ``H`` (one PCG iteration) takes about as long as ``FLOPS_PER_PRODUCT`` flops of
the factorization per entry of ``H`` (this machine: CHOLMOD's supernodal factorization
~1.2·10¹⁰ of ``Σ c_j²`` per second, a product ~4 ns per entry); PCG's cap is a quarter of a
factorization in these units."""


def prefers_iterative(cost: FactorCost | None, nnz: int) -> bool:
    """Whether a factor of this ``cost`` for ``H`` with ``nnz`` stored entries is so nearly dense
    that PCG is worth trying instead (``None``, an unknown cost: no)."""
    return cost is not None and cost.flops >= ITERATIVE_FLOPS_PER_ENTRY * nnz


def pcg_cap(cost: FactorCost, structure: BlockStructure) -> int:
    """PCG's iterations in a quarter of the factorization's predicted time (50 to ``n``)."""
    return int(min(structure.n, max(50.0, cost.flops / (4.0 * FLOPS_PER_PRODUCT * structure.nnz))))


class AutoSolver:
    """The linear solver a structure's fill calls for (``linear_solver="auto"``, the default of
    the least-squares optimizers): :class:`CholeskySolver`, whose analysis at the first solve
    predicts the factorization's cost; where the factor would be nearly dense
    (:func:`prefers_iterative`), :class:`PCGSolver` instead, capped at a quarter of a
    factorization's predicted time, and the factorization for the rest of the run after a solve
    PCG does not finish within the cap (or in which it finds ``H`` not positive definite).

    ``stats`` are empty where only the factorization is used; where PCG is taken they hold
    ``linear_iterations``, ``linear_residual`` (``‖b − Hx‖/‖b‖``) and ``linear_converged``
    after every solve: a solve by the factorization counts the iterations its failed PCG
    attempt took (0 once the run has fallen back) and is converged.

    Parameters
    ----------
    tol : float
        PCG's relative residual (see :class:`PCGSolver`).
    """

    def __init__(self, *, tol: float = 1e-6) -> None:
        self.tol = PCGSolver(tol=tol).tol  # checked now (ValueError), not at the first PCG solve
        self._structure: BlockStructure | None = None
        self._direct: CholeskySolver | None = None
        self._iterative: PCGSolver | None = None
        self._stats: Mapping[str, float] = MappingProxyType({})

    def __repr__(self) -> str:
        return f"AutoSolver(tol={self.tol!r})"

    def bind(self, structure: BlockStructure) -> CholeskySolver | AutoSolver:
        """A fresh solver for one run: a bound :class:`CholeskySolver` for a dense (small)
        structure, else an :class:`AutoSolver` that chooses at its first solve."""
        if structure.dense:
            return CholeskySolver().bind(structure)
        solver = AutoSolver(tol=self.tol)
        solver._structure = structure
        return solver

    @property
    def iterative(self) -> bool:
        """Whether the next solve runs PCG (chosen, and not fallen back to the factorization)."""
        return self._iterative is not None

    def _choose(self, H: sp.csc_matrix) -> CholeskySolver:
        """At the first solve: the factorization's solver, analysed, and PCG if its cost says so."""
        assert self._structure is not None
        direct = self._direct = CholeskySolver().bind(self._structure)
        direct.analyze(H)
        cost = direct.factor_cost
        if cost is not None and prefers_iterative(cost, self._structure.nnz):
            self._iterative = PCGSolver(tol=self.tol, maxiter=pcg_cap(cost, self._structure)).bind(self._structure)
        return direct

    def __call__(self, H: sp.csc_matrix, b: FloatArray) -> FloatArray:
        """``x ≈ H⁻¹b``: PCG's where it is chosen and converges, else the factorization's."""
        if self._structure is None:
            raise RuntimeError("AutoSolver: bind(structure) before solving")
        direct = self._direct or self._choose(H)
        pcg = self._iterative
        if pcg is None and not self._stats:  # the factorization only
            return direct(H, b)
        attempted = 0.0
        if pcg is not None:
            try:
                x = pcg(H, b)
                if pcg.stats["linear_converged"]:
                    self._stats = pcg.stats
                    return x
                attempted = pcg.stats["linear_iterations"]
            except SingularSystemError:  # non-positive curvature: let the factorization judge H
                pass
            self._iterative = None  # PCG did not do: the factorization from now on
        x = direct(H, b)
        residual = norm(H @ x - b) / max(norm(b), np.finfo(float).tiny)
        self._stats = MappingProxyType(
            {"linear_iterations": attempted, "linear_residual": residual, "linear_converged": 1.0}
        )
        return x

    @property
    def stats(self) -> Mapping[str, float]:
        """The numbers of the last solve (see the class notes)."""
        return self._stats
