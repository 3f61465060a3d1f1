"""Problems and Riemannian optimizers."""

from .conjugate_gradient import ConjugateGradient
from .gradient_descent import GradientDescent
from .optimizer import Optimizer, StoppingCriteria
from .problem import Problem
from .result import History, IterationInfo, OptimizeResult, Status
from .trust_region import TrustRegion

__all__ = [
    "Problem",
    "Optimizer",
    "StoppingCriteria",
    "GradientDescent",
    "ConjugateGradient",
    "TrustRegion",
    "OptimizeResult",
    "Status",
    "History",
    "IterationInfo",
]
