"""Problems and Riemannian optimizers."""

from .conjugate_gradient import ConjugateGradient
from .gradient_descent import GradientDescent
from .least_squares_problem import Factor, LeastSquaresProblem, Linearization
from .line_search import Backtracking, LineSearch, LineSearchResult, StrongWolfe
from .nonlinear_least_squares import GaussNewton, LevenbergMarquardt, NonlinearLeastSquares
from .optimizer import Optimizer, StoppingCriteria
from .problem import Problem
from .result import History, IterationInfo, OptimizeResult, Status
from .trust_region import TrustRegion

__all__ = [
    "Problem",
    "LeastSquaresProblem",
    "Factor",
    "Linearization",
    "Optimizer",
    "StoppingCriteria",
    "GradientDescent",
    "ConjugateGradient",
    "TrustRegion",
    "LineSearch",
    "Backtracking",
    "StrongWolfe",
    "LineSearchResult",
    "GaussNewton",
    "LevenbergMarquardt",
    "NonlinearLeastSquares",
    "OptimizeResult",
    "Status",
    "History",
    "IterationInfo",
]
