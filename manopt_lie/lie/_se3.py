"""SE(3) kernels on arrays: homogeneous ``(..., 4, 4)``, tangents ``(ρ, θ)`` as ``(..., 6)``.

Formulas: Solà et al. (arXiv:1812.01537), Appendix D, with ``Jr`` from eqs. 179–180;
Barfoot, "State Estimation for Robotics", §7.1.5 for ``Q``.
"""

from __future__ import annotations

import numpy as np

from . import _matrix, _series, _so3
from ._checks import FloatArray


def hat(tau: FloatArray) -> FloatArray:
    """``[[θ^, ρ], [0, 0]]``."""
    out = np.zeros(tau.shape[:-1] + (4, 4))
    out[..., :3, :3] = _so3.hat(tau[..., 3:])
    out[..., :3, 3] = tau[..., :3]
    return out


def vee(m: FloatArray) -> FloatArray:
    return np.concatenate([m[..., :3, 3], _so3.vee(m[..., :3, :3])], axis=-1)


def exp(tau: FloatArray) -> FloatArray:
    """``[[Exp(θ), Jl(θ) ρ], [0, 1]]``."""
    rho, theta = tau[..., :3], tau[..., 3:]
    return _matrix.assemble(_so3.exp(theta), _so3.jl_apply(theta, rho))


def log(m: FloatArray) -> FloatArray:
    """``(Jl(θ)⁻¹ t, θ)`` with ``θ = Log(R)``."""
    r, t = _matrix.split(m)
    theta = _so3.log(r)
    return np.concatenate([_so3.jl_inv_apply(theta, t), theta], axis=-1)


def q_matrix(rho: FloatArray, theta: FloatArray) -> FloatArray:
    """Barfoot's ``Q(ρ, θ)``, the top-right block of ``Jl(ρ, θ)`` (Solà eq. 180)::

        Q = ½ρ^ + c₁(θ^ρ^ + ρ^θ^ + θ^ρ^θ^) + c₂(θ^²ρ^ + ρ^θ^² − 3θ^ρ^θ^)
              + c₃(θ^ρ^θ^² + θ^²ρ^θ^)

    with ``c₁ = (θ − sin θ)/θ³``, ``c₂ = (θ² + 2cos θ − 2)/(2θ⁴)``,
    ``c₃ = (2θ − 3 sin θ + θ cos θ)/(2θ⁵)``. Evaluated without matrix products
    through ``a^b^ = b aᵀ − (a·b) I`` and ``a^b^a^ = −(a·b) a^``, which give,
    with ``d = θ·ρ``, ``s = |θ|²`` and ``u = θ × ρ``::

        Q = (½ − 2c₂s) ρ^ + (3c₂ − c₁) d θ^ + c₁(ρθᵀ + θρᵀ) + c₂(θuᵀ − uθᵀ)
              − 2c₃ d θθᵀ + 2d (c₃s − c₁) I
    """
    s = np.einsum("...i,...i->...", theta, theta)
    d = np.einsum("...i,...i->...", theta, rho)
    angle = np.sqrt(s)
    c1, c2, c3 = _series.sinc3(angle), _series.q_coef2(angle), _series.q_coef3(angle)
    u = np.cross(theta, rho)

    def outer(a: FloatArray, b: FloatArray) -> FloatArray:
        return a[..., :, None] * b[..., None, :]

    def scalar(x: FloatArray) -> FloatArray:
        return x[..., None, None]

    tr = outer(theta, rho)
    return (
        scalar(0.5 - 2.0 * c2 * s) * _so3.hat(rho)
        + scalar((3.0 * c2 - c1) * d) * _so3.hat(theta)
        + scalar(c1) * (tr + np.swapaxes(tr, -1, -2))
        + scalar(c2) * (outer(theta, u) - outer(u, theta))
        - scalar(2.0 * c3 * d) * outer(theta, theta)
        + scalar(2.0 * d * (c3 * s - c1)) * np.eye(3)
    )


def _block_upper(diagonal: FloatArray, corner: FloatArray) -> FloatArray:
    """``[[D, C], [0, D]]`` from 3×3 blocks."""
    out = np.zeros(np.broadcast_shapes(diagonal.shape, corner.shape)[:-2] + (6, 6))
    out[..., :3, :3] = diagonal
    out[..., 3:, 3:] = diagonal
    out[..., :3, 3:] = corner
    return out


def jr(tau: FloatArray) -> FloatArray:
    """``Jr(ρ, θ) = [[Jr(θ), Q(−ρ, −θ)], [0, Jr(θ)]]`` (eq. 179)."""
    rho, theta = tau[..., :3], tau[..., 3:]
    return _block_upper(_so3.jr(theta), q_matrix(-rho, -theta))


def jr_inv(tau: FloatArray) -> FloatArray:
    """``Jr⁻¹ = [[Jr(θ)⁻¹, −Jr(θ)⁻¹ Q Jr(θ)⁻¹], [0, Jr(θ)⁻¹]]`` with ``Q = Q(−ρ, −θ)``."""
    rho, theta = tau[..., :3], tau[..., 3:]
    ji = _so3.jr_inv(theta)
    return _block_upper(ji, -ji @ q_matrix(-rho, -theta) @ ji)


def adjoint(m: FloatArray) -> FloatArray:
    """``[[R, [t]× R], [0, R]]``."""
    r, t = _matrix.split(m)
    return _block_upper(r, _so3.hat(t) @ r)


def act_jac(m: FloatArray, p: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``D(T·p)/DT = [R, −R[p]×]``, ``D(T·p)/Dp = R``."""
    r, _ = _matrix.split(m)
    j_x = _matrix.hconcat(r, _so3.act_jac_rotation(r, p))
    return j_x, r
