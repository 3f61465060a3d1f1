"""SO(2) kernels on arrays: rotation matrices ``(..., 2, 2)``, tangents ``θ`` as ``(..., 1)``.

SO(2) is commutative: ``Ad = Jr = Jl = 1``.
"""

from __future__ import annotations

import numpy as np

from . import _matrix
from ._checks import FloatArray


def hat(tau: FloatArray) -> FloatArray:
    """``θ J = [[0, −θ], [θ, 0]]``."""
    out = np.zeros(tau.shape[:-1] + (2, 2))
    out[..., 0, 1], out[..., 1, 0] = -tau[..., 0], tau[..., 0]
    return out


def vee(m: FloatArray) -> FloatArray:
    return 0.5 * (m[..., 1, 0] - m[..., 0, 1])[..., None]


def exp(tau: FloatArray) -> FloatArray:
    return _matrix.rotation2(tau[..., 0])


def log(m: FloatArray) -> FloatArray:
    """``θ = atan2(R₁₀, R₀₀) ∈ (−π, π]``."""
    return _matrix.angle2(m)[..., None]


def ones(tau_or_m: FloatArray, batch_ndim: int) -> FloatArray:
    """The ``1×1`` identity over the batch axes (``Jr``, ``Jl``, ``Ad`` of SO(2))."""
    return np.ones(tau_or_m.shape[:batch_ndim] + (1, 1))


def act_jac(m: FloatArray, p: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``D(R·p)/DR = R J p``, ``D(R·p)/Dp = R``."""
    return _matrix.rotate_vectors(m, _matrix.skew2(p))[..., None], m
