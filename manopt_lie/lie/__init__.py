"""Lie groups: SO(2), SO(3), SE(2), SE(3), Sim(3), SE₂(3), Rⁿ and their products, batched, with exact Jacobians."""

from .base import LieGroup
from .extended import SE23, Sim3
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
    "Sim3",
    "SE23",
    "Rn",
    "RnGroup",
    "propagate_covariance",
    "sample",
    "mean_and_covariance",
    "right_to_left_covariance",
    "left_to_right_covariance",
]
