"""Lie groups: SO(2), SO(3), SE(2), SE(3) and Rⁿ, batched, with exact Jacobians."""

from .base import LieGroup
from .groups import SE2, SE3, SO2, SO3
from .rn import Rn, RnGroup
from .uncertainty import (
    left_to_right_covariance,
    mean_and_covariance,
    propagate_covariance,
    right_to_left_covariance,
    sample,
)

__all__ = [
    "LieGroup",
    "SO2",
    "SO3",
    "SE2",
    "SE3",
    "Rn",
    "RnGroup",
    "propagate_covariance",
    "sample",
    "mean_and_covariance",
    "right_to_left_covariance",
    "left_to_right_covariance",
]
