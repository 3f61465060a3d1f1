"""CasADi twins: symbolic Lie groups and symbolic costs with exact derivatives.

* :mod:`.lie` — ``SymSO2``, ``SymSO3``, ``SymSE2``, ``SymSE3``: ``exp``, ``log``,
  ``compose``, ``inverse``, ``act``, ``rplus``, ``rminus``, … on CasADi matrices,
  agreeing with the numpy kernels to round-off;
* :mod:`.problems` — :func:`problem_from_casadi` and
  :func:`least_squares_from_casadi`: a cost or residual written once with CasADi
  operations becomes a :class:`~manopt_lie.optim.Problem` (exact gradient and
  Hessian) on any manifold of :mod:`manopt_lie.manifolds` — through the chart
  ``X ⊕ δ`` on Lie groups, as Euclidean derivatives converted by the manifold on the
  others — or a :class:`~manopt_lie.optim.LeastSquaresProblem` (right Jacobians),
  evaluated on batches by mapped ``casadi.Function``\\ s (:mod:`._compile`,
  :mod:`._spaces`). These are the only spellings: :mod:`manopt_lie.optim` does not
  import CasADi (casadi builds on optim, never the reverse).
"""

from .lie import Matrix, SymbolicGroup, SymSE2, SymSE3, SymSO2, SymSO3
from .lie_extended import SymS3, SymSE23, SymSim2, SymSim3
from .problems import SymbolicFactor, SymbolicTerm, least_squares_from_casadi, problem_from_casadi
from .twins import symbolic

__all__ = [
    "Matrix",
    "SymbolicGroup",
    "SymSO2",
    "SymSO3",
    "SymSE2",
    "SymSE3",
    "SymSim3",
    "SymSim2",
    "SymSE23",
    "SymS3",
    "symbolic",
    "SymbolicTerm",
    "SymbolicFactor",
    "problem_from_casadi",
    "least_squares_from_casadi",
]
