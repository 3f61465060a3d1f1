"""Problems and Riemannian optimizers.

Every optimizer is listed once, in :data:`OPTIMIZERS` (:mod:`.registry`), by
its short name (``"gd"``, ``"cg"``, ``"gn"``, ``"lm"``, ``"tr"``, ``"lbfgs"``, ``"dogleg"``).
"""

from .conjugate_gradient import ConjugateGradient
from .dogleg import Dogleg
from .gradient_descent import GradientDescent
from .lbfgs import LBFGS
from .least_squares_problem import Factor, LeastSquaresProblem, Linearization, SideBySide
from .line_search import Backtracking, LineSearch, LineSearchResult, StrongWolfe
from .marginals import MarginalCovariances, gtsam_tangent_order, marginal_covariances, to_gtsam_order, to_left_frame
from .nonlinear_least_squares import GaussNewton, LevenbergMarquardt, NonlinearLeastSquares
from .optimizer import Optimizer, StoppingCriteria
from .preconditioners import PRECONDITIONERS, Preconditioner
from .problem import Problem
from .registry import OPTIMIZERS, OptimizerEntry, UnknownOptimizerError, get_optimizer, register
from .result import History, IterationInfo, OptimizeResult, Status
from .trust_region import TrustRegion

__all__ = [
    "Problem",
    "LeastSquaresProblem",
    "Factor",
    "Linearization",
    "SideBySide",
    "Optimizer",
    "StoppingCriteria",
    "GradientDescent",
    "ConjugateGradient",
    "TrustRegion",
    "LBFGS",
    "PRECONDITIONERS",
    "Preconditioner",
    "LineSearch",
    "Backtracking",
    "StrongWolfe",
    "LineSearchResult",
    "GaussNewton",
    "LevenbergMarquardt",
    "Dogleg",
    "NonlinearLeastSquares",
    "OPTIMIZERS",
    "OptimizerEntry",
    "UnknownOptimizerError",
    "get_optimizer",
    "register",
    "OptimizeResult",
    "Status",
    "History",
    "IterationInfo",
    "marginal_covariances",
    "MarginalCovariances",
    "to_left_frame",
    "to_gtsam_order",
    "gtsam_tangent_order",
]
