"""Sparse linear algebra for Gauss-Newton and Levenberg-Marquardt on factor graphs.

:class:`BlockStructure` turns arrays of edges (one array per factor type) into
the fixed sparsity of ``J``, ``H = JᵀWJ`` and ``g = JᵀWr``, computed once;
:class:`CholeskySolver` solves ``H δ = −g`` reusing its symbolic analysis;
:func:`pcg_solve` is the iterative fallback for very large systems::

    structure = BlockStructure(dims, [(odometry_ids, 6), (loop_ids, 6)])
    solver = CholeskySolver()
    H, g = structure.normal_equations(blocks, residuals)
    delta = -solver(structure.add_diagonal(H, lam * H.diagonal()), g)
"""

from .cholesky import CholeskySolver
from .errors import SingularSystemError
from .pcg import PCGResult, block_jacobi, pcg_solve
from .structure import BlockStructure

__all__ = ["BlockStructure", "CholeskySolver", "SingularSystemError", "PCGResult", "block_jacobi", "pcg_solve"]
