"""Lie groups: SO(2), SO(3), SE(2), SE(3), Sim(3), SE₂(3), Rⁿ and their products, batched, with exact Jacobians."""

from .base import LieGroup
from .bundle import Bundle, BundleGroup
from .calculus import angular_distance, chordal_distance, double_geodesic_distance, integrate, quaternion_distance
from .extended import SE23, Sim2, Sim3
from .groups import SE2, SE3, SO2, SO3
from .quaternion import S3
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
    "Sim2",
    "SE23",
    "S3",
    "Rn",
    "RnGroup",
    "Bundle",
    "BundleGroup",
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
]
