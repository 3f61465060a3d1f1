"""Sparse linear algebra for Gauss-Newton and Levenberg-Marquardt on factor graphs.

:class:`BlockStructure` turns arrays of edges (one array per factor type) into
the fixed sparsity of ``J``, ``H = JᵀWJ`` and ``g = JᵀWr``, computed once;
:class:`CholeskySolver` solves ``H δ = −g`` reusing its symbolic analysis;
:class:`PCGSolver` (over :func:`pcg_solve`) is the iterative alternative for
systems whose factor fills in; :class:`AutoSolver` chooses between them by the fill the
analysis predicts (:attr:`CholeskySolver.factor_cost`). All are :class:`LinearSolver`\\ s, the protocol the
least-squares optimizers take (``linear_solver="auto"``, ``"cholesky"`` or ``"pcg"``)::

    structure = BlockStructure(dims, [(odometry_ids, 6), (loop_ids, 6)])
    solver = get_linear_solver("cholesky").bind(structure)   # one per run
    H, g = structure.normal_equations(blocks, residuals)
    delta = -solver(structure.add_diagonal(H, lam * H.diagonal()), g)

Analyses and structures are pooled by pattern across solvers and problems (a graph solved again
skips both); :func:`clear_caches` forgets them.
"""

from ._analyses import clear_caches
from ._backends import DENSE_MAX
from .cholesky import CholeskySolver, FactorCost
from .errors import SingularSystemError
from .fill import AutoSolver
from .linear_solver import LINEAR_SOLVERS, LinearSolver, get_linear_solver
from .pcg import PCGResult, PCGSolver, block_jacobi, pcg_solve
from .selected_inverse import CholeskyFactor, SelectedInverse, Supernodes, cholesky_factor
from .structure import BlockStructure

__all__ = [
    "BlockStructure",
    "DENSE_MAX",
    "CholeskySolver",
    "PCGSolver",
    "AutoSolver",
    "FactorCost",
    "LinearSolver",
    "LINEAR_SOLVERS",
    "get_linear_solver",
    "SingularSystemError",
    "PCGResult",
    "block_jacobi",
    "pcg_solve",
    "CholeskyFactor",
    "SelectedInverse",
    "Supernodes",
    "cholesky_factor",
    "clear_caches",
]
