"""Sim(2) kernels on arrays: ``[[s·R, t], [0, 1]]`` as ``(..., 3, 3)``, tangents ``(ρx, ρy, θ, σ)`` as ``(..., 4)``.

``hat = [[θJ + σI, ρ], [0, 0]]`` (``J`` the quarter turn). ``σI + θJ`` acts on the plane as the
complex number ``z = σ + iθ``, so ``W(σ, θ) = ∫₀¹ e^{sσ} R(sθ) ds = A I + B J`` with
``A + iB = (e^z − 1)/z``: from Sim(3)'s coefficients (``lie._series.sim3_coefficients``) on the
plane normal to the axis, where ``[u]× = J`` and ``[u]×² = −I``, ``A = a − c θ²``, ``B = b θ``.
``W⁻¹ = (A I − B J)/(A² + B²)``. ``Jr`` by doubling (``_doubling``), ``Jr⁻¹`` by blocks.
"""

from __future__ import annotations

import numpy as np

from . import _doubling, _matrix, _series, _sim3, _so3
from ._checks import FloatArray

SIGMA_MAX = 700.0


def _scalar(x: FloatArray) -> FloatArray:
    return x[..., None, None]


def hat(tau: FloatArray) -> FloatArray:
    """``[[σ, −θ, ρx], [θ, σ, ρy], [0, 0, 0]]``."""
    out = np.zeros(tau.shape[:-1] + (3, 3))
    out[..., 0, 0] = out[..., 1, 1] = tau[..., 3]
    out[..., 0, 1], out[..., 1, 0] = -tau[..., 2], tau[..., 2]
    out[..., :2, 2] = tau[..., :2]
    return out


def vee(m: FloatArray) -> FloatArray:
    a = m[..., :2, :2]
    theta = 0.5 * (a[..., 1, 0] - a[..., 0, 1])
    sigma = 0.5 * (a[..., 0, 0] + a[..., 1, 1])
    return np.stack([m[..., 0, 2], m[..., 1, 2], theta, sigma], axis=-1)


def scale(m: FloatArray) -> FloatArray:
    """``s``: the norm of the first column of ``s·R``, scaled by its largest entry first."""
    col = m[..., :2, 0]
    big = np.abs(col).max(axis=-1)
    safe = np.where(big > 0.0, big, 1.0)
    return big * np.hypot(col[..., 0] / safe, col[..., 1] / safe)


def w_coefficients(sigma: FloatArray, theta: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``(A, B)`` with ``W(σ, θ) = A I + B J``: ``A = a − c θ²``, ``B = b θ`` of ``sim3_coefficients``;
    angles beyond ``_so3.HUGE`` (whose θ² would overflow) through ``_sim3.w_unit`` of ``θ/2``."""
    big = ~(np.abs(theta) < _so3.HUGE)
    th = np.where(big, 0.0, theta) if big.any() else theta
    t = th * th
    a, b, c = _series.sim3_coefficients(sigma, t)
    aa, bb = np.array(a - c * t), np.array(b * th)  # writable, also for 0-d
    if big.any():  # the rare rows of huge angles, on their own
        h = 0.5 * np.abs(theta[big])
        a_h, b_h, c_h = _sim3.w_unit(np.broadcast_to(sigma, big.shape)[big], h, np.sin(h), np.cos(h))
        aa[big], bb[big] = a_h - c_h, np.sign(theta[big]) * b_h
    return aa, bb


def exp(tau: FloatArray) -> FloatArray:
    """``[[e^σ R(θ), W(σ, θ) ρ], [0, 1]]``."""
    rho, theta, sigma = tau[..., :2], tau[..., 2], tau[..., 3]
    a, b = w_coefficients(sigma, theta)
    trans = a[..., None] * rho + b[..., None] * _matrix.skew2(rho)
    return _matrix.assemble(_matrix.rotation2(theta) * _scalar(np.exp(sigma)), trans)


def log(m: FloatArray) -> FloatArray:
    """``(W⁻¹ t, θ, σ)``, ``θ = atan2`` of ``s·R``'s first column, ``σ = log s``;
    ``W⁻¹ = (A I − B J)/(A² + B²)`` with ``A² + B²`` formed as ``hypot(A, B)²`` (no overflow)."""
    theta = np.arctan2(m[..., 1, 0], m[..., 0, 0])
    sigma = np.log(scale(m))
    a, b = w_coefficients(sigma, theta)
    t = m[..., :2, 2]
    r = np.hypot(a, b)  # |A + iB|, without overflow for large σ
    rho = (a / r / r)[..., None] * t - (b / r / r)[..., None] * _matrix.skew2(t)
    return np.concatenate([rho, theta[..., None], sigma[..., None]], axis=-1)


def inverse(m: FloatArray) -> FloatArray:
    """``[[(sR)ᵀ/s², −(sR)ᵀ t/s²], [0, 1]]``."""
    s = _scalar(scale(m))
    mi = np.swapaxes(m[..., :2, :2], -1, -2) / s / s
    return _matrix.assemble(mi, -_matrix.rotate_vectors(mi, m[..., :2, 2]))


def adjoint(m: FloatArray) -> FloatArray:
    """``[[sR, (t_y, −t_x)ᵀ, −t], [0, 1, 0], [0, 0, 1]]``."""
    out = np.zeros(m.shape[:-2] + (4, 4))
    out[..., :2, :2] = m[..., :2, :2]
    out[..., 0, 2], out[..., 1, 2] = m[..., 1, 2], -m[..., 0, 2]
    out[..., :2, 3] = -m[..., :2, 2]
    out[..., 2, 2] = out[..., 3, 3] = 1.0
    return out


def ad(tau: FloatArray) -> FloatArray:
    """``ad_τ = [[σI + θJ, −Jρ, −ρ], [0, 0, 0], [0, 0, 0]]``."""
    out = np.zeros(tau.shape[:-1] + (4, 4))
    out[..., :2, :2] = hat(tau)[..., :2, :2]
    out[..., :2, 2] = -_matrix.skew2(tau[..., :2])
    out[..., :2, 3] = -tau[..., :2]
    return out


def jr(tau: FloatArray) -> FloatArray:
    """``Jr(τ) = Σₖ (−ad_τ)ᵏ/(k+1)!`` by doubling (``_doubling.jr``)."""
    return _doubling.jr(tau, 2, ad, exp, inverse, adjoint)


def jr_inv(tau: FloatArray) -> FloatArray:
    """``Jr = [[D, Y], [0, I]]`` → ``[[D⁻¹, −D⁻¹ Y], [0, I]]``, ``D = W(−σ, −θ)``, ``D⁻¹ = (A I − B J)/(A² + B²)``."""
    j = jr(tau)
    a, b = w_coefficients(-tau[..., 3], -tau[..., 2])
    r = np.hypot(a, b)
    di = np.zeros(tau.shape[:-1] + (2, 2))
    di[..., 0, 0] = di[..., 1, 1] = a / r / r
    di[..., 0, 1], di[..., 1, 0] = b / r / r, -b / r / r
    out = np.zeros_like(j)
    out[..., :2, :2] = di
    out[..., :2, 2:] = -di @ j[..., :2, 2:]
    out[..., 2, 2] = out[..., 3, 3] = 1.0
    return out


def act_jac(m: FloatArray, p: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``D(X·p)/DX = [sR, sR J p, sR p]``, ``D(X·p)/Dp = sR``."""
    sr = m[..., :2, :2]
    rjp = _matrix.rotate_vectors(sr, _matrix.skew2(p))
    return _matrix.hconcat(sr, rjp[..., None], _matrix.rotate_vectors(sr, p)[..., None]), sr
