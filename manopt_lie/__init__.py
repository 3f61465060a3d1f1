"""manopt_lie: optimization on Riemannian manifolds and Lie groups.

Lie groups with exact, batched calculus (CONVENTIONS.md §1–5)::

    from manopt_lie import SO3
    X = SO3.exp(tau)                  # tau: (..., 3)
    Y, J_X, J_tau = X.rplus(d, jac=True)
"""

from .errors import (
    IndefiniteMatrixError,
    NonFiniteError,
    NotInGroupError,
    NotOnManifoldError,
    RangeError,
    ShapeError,
)
from .lie import (
    S3,
    SE2,
    SE3,
    SE23,
    SO2,
    SO3,
    Bundle,
    LieGroup,
    Rn,
    Sim2,
    Sim3,
    angular_distance,
    chordal_distance,
    double_geodesic_distance,
    integrate,
    left_to_right_covariance,
    mean_and_covariance,
    propagate_covariance,
    quaternion_distance,
    right_to_left_covariance,
    sample,
)
from .minimize import minimize

__version__ = "0.2.0"

__all__ = [
    "minimize",
    "LieGroup",
    "SO2",
    "SO3",
    "SE2",
    "SE3",
    "Sim3",
    "Sim2",
    "SE23",
    "S3",
    "Rn",
    "Bundle",
    "angular_distance",
    "chordal_distance",
    "quaternion_distance",
    "double_geodesic_distance",
    "integrate",
    "propagate_covariance",
    "sample",
    "mean_and_covariance",
    "right_to_left_covariance",
    "left_to_right_covariance",
    "ShapeError",
    "NonFiniteError",
    "NotOnManifoldError",
    "NotInGroupError",
    "IndefiniteMatrixError",
    "RangeError",
]
