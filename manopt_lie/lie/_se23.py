"""SE₂(3) kernels (extended poses): ``[[R, p, v], [0, 1, 0], [0, 0, 1]]`` as ``(..., 5, 5)``,
tangents ``(ρ, ν, θ)`` as ``(..., 9)``.

``hat(ρ, ν, θ) = [[θ^, ρ, ν], [0, 0, 0], [0, 0, 0]]``: two translation-like columns
that rotate with ``R``, so every formula is SE(3)'s with its translation block doubled
(Barrau & Bonnabel's group of the IMU state; Solà et al., arXiv:1812.01537, §IV-G):
``Exp = [[Exp(θ), Jl(θ)ρ, Jl(θ)ν], …]``, ``Jr = [[Jr(θ), 0, Q(−ρ, −θ)], [0, Jr(θ), Q(−ν, −θ)],
[0, 0, Jr(θ)]]`` with Barfoot's ``Q`` of ``_se3``.
"""

from __future__ import annotations

import numpy as np

from . import _matrix, _se3, _so3
from ._checks import FloatArray


def assemble(r: FloatArray, p: FloatArray, v: FloatArray) -> FloatArray:
    """``[[R, p, v], [0, 1, 0], [0, 0, 1]]`` broadcast over the batch axes."""
    batch = np.broadcast_shapes(r.shape[:-2], p.shape[:-1], v.shape[:-1])
    out = np.zeros(batch + (5, 5))
    out[..., :3, :3] = r
    out[..., :3, 3] = p
    out[..., :3, 4] = v
    out[..., 3, 3] = out[..., 4, 4] = 1.0
    return out


def split(m: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``(R, p, v)`` views."""
    return m[..., :3, :3], m[..., :3, 3], m[..., :3, 4]


def hat(tau: FloatArray) -> FloatArray:
    """``[[θ^, ρ, ν], [0, 0, 0], [0, 0, 0]]``."""
    out = np.zeros(tau.shape[:-1] + (5, 5))
    out[..., :3, :3] = _so3.hat(tau[..., 6:])
    out[..., :3, 3] = tau[..., :3]
    out[..., :3, 4] = tau[..., 3:6]
    return out


def vee(m: FloatArray) -> FloatArray:
    return np.concatenate([m[..., :3, 3], m[..., :3, 4], _so3.vee(m[..., :3, :3])], axis=-1)


def exp(tau: FloatArray) -> FloatArray:
    """``[[Exp(θ), Jl(θ)ρ, Jl(θ)ν], [0, 1, 0], [0, 0, 1]]``."""
    theta = tau[..., 6:]
    return assemble(_so3.exp(theta), _so3.jl_apply(theta, tau[..., :3]), _so3.jl_apply(theta, tau[..., 3:6]))


def log(m: FloatArray) -> FloatArray:
    """``(Jl(θ)⁻¹ p, Jl(θ)⁻¹ v, θ)`` with ``θ = Log(R)``."""
    r, p, v = split(m)
    theta = _so3.log(r)
    return np.concatenate([_so3.jl_inv_apply(theta, p), _so3.jl_inv_apply(theta, v), theta], axis=-1)


def compose(a: FloatArray, b: FloatArray) -> FloatArray:
    """``[[Ra Rb, Ra pb + pa, Ra vb + va], …]``."""
    ra, pa, va = split(a)
    rb, pb, vb = split(b)
    return assemble(ra @ rb, _matrix.rotate_vectors(ra, pb) + pa, _matrix.rotate_vectors(ra, vb) + va)


def inverse(m: FloatArray) -> FloatArray:
    """``[[Rᵀ, −Rᵀp, −Rᵀv], …]``."""
    r, p, v = split(m)
    rt = np.swapaxes(r, -1, -2)
    return assemble(rt, -_matrix.rotate_vectors(rt, p), -_matrix.rotate_vectors(rt, v))


def act(m: FloatArray, x: FloatArray) -> FloatArray:
    """``R x + p`` (the position acts on points; the velocity does not)."""
    r, p, _ = split(m)
    return _matrix.rotate_vectors(r, x) + p


def act_jac(m: FloatArray, x: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``D(X·x)/DX = [R, 0, −R[x]×]``, ``D(X·x)/Dx = R``."""
    r = m[..., :3, :3]
    zero = np.zeros(r.shape[:-2] + (3, 3))
    return _matrix.hconcat(r, zero, _so3.act_jac_rotation(r, x)), r


def _upper(diagonal: FloatArray, top: FloatArray, middle: FloatArray) -> FloatArray:
    """``[[D, 0, A], [0, D, B], [0, 0, D]]`` from 3×3 blocks."""
    batch = np.broadcast_shapes(diagonal.shape[:-2], top.shape[:-2], middle.shape[:-2])
    out = np.zeros(batch + (9, 9))
    for i in range(3):
        out[..., 3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = diagonal
    out[..., :3, 6:] = top
    out[..., 3:6, 6:] = middle
    return out


def adjoint(m: FloatArray) -> FloatArray:
    """``[[R, 0, [p]× R], [0, R, [v]× R], [0, 0, R]]``."""
    r, p, v = split(m)
    return _upper(r, _so3.hat(p) @ r, _so3.hat(v) @ r)


def ad(tau: FloatArray) -> FloatArray:
    """``ad_τ = [[θ^, 0, ρ^], [0, θ^, ν^], [0, 0, θ^]]``."""
    return _upper(_so3.hat(tau[..., 6:]), _so3.hat(tau[..., :3]), _so3.hat(tau[..., 3:6]))


def jr(tau: FloatArray) -> FloatArray:
    """``[[Jr(θ), 0, Q(−ρ, −θ)], [0, Jr(θ), Q(−ν, −θ)], [0, 0, Jr(θ)]]``."""
    theta = -tau[..., 6:]
    return _upper(_so3.jr(tau[..., 6:]), _se3.q_matrix(-tau[..., :3], theta), _se3.q_matrix(-tau[..., 3:6], theta))


def jr_inv(tau: FloatArray) -> FloatArray:
    """``[[Jr⁻¹, 0, −Jr⁻¹ Q_ρ Jr⁻¹], [0, Jr⁻¹, −Jr⁻¹ Q_ν Jr⁻¹], [0, 0, Jr⁻¹]]``, ``Q_ρ = Q(−ρ, −θ)``."""
    theta = -tau[..., 6:]
    ji = _so3.jr_inv(tau[..., 6:])
    q_rho, q_nu = _se3.q_matrix(-tau[..., :3], theta), _se3.q_matrix(-tau[..., 3:6], theta)
    return _upper(ji, -ji @ q_rho @ ji, -ji @ q_nu @ ji)
