"""Sim(3) kernels on arrays: ``[[s·R, t], [0, 1]]`` as ``(..., 4, 4)``, tangents ``(ρ, θ, σ)`` as ``(..., 7)``.

``hat(ρ, θ, σ) = [[θ^ + σI, ρ], [0, 0]]``, so ``Exp(ρ, θ, σ) = [[e^σ Exp(θ), W(σ, θ) ρ], [0, 1]]``
with ``W(σ, θ) = Σ (θ^ + σI)ⁿ/(n+1)! = ∫₀¹ e^{sσ} Exp(sθ) ds = a I + b θ^ + c θ^²`` in closed
form (``lie._series.sim3_coefficients``; cf. Eade, "Lie groups for computer vision", §6, derived
here without its cancellations). The scale ``s = e^σ`` is read back as the norm of the first
column of ``s·R``. ``|σ| ≤ SIGMA_MAX`` keeps ``e^σ`` and every intermediate finite.
"""

from __future__ import annotations

import numpy as np

from . import _doubling, _matrix, _series, _so3
from ._checks import FloatArray

SIGMA_MAX = 700.0  # e^700 ≈ 1e304: beyond it the element itself is not representable


def _sq(v: FloatArray) -> FloatArray:
    return np.einsum("...i,...i->...", v, v)


def _scalar(x: FloatArray) -> FloatArray:
    return x[..., None, None]


def hat(tau: FloatArray) -> FloatArray:
    """``[[θ^ + σI, ρ], [0, 0]]``."""
    out = np.zeros(tau.shape[:-1] + (4, 4))
    out[..., :3, :3] = _so3.hat(tau[..., 3:6]) + _scalar(tau[..., 6]) * np.eye(3)
    out[..., :3, 3] = tau[..., :3]
    return out


def vee(m: FloatArray) -> FloatArray:
    """``(ρ, θ, σ)``: θ from the skew part, σ = tr/3 of the top-left block."""
    a = m[..., :3, :3]
    sigma = np.trace(a, axis1=-2, axis2=-1) / 3.0
    return np.concatenate([m[..., :3, 3], _so3.vee(a), sigma[..., None]], axis=-1)


def scale(m: FloatArray) -> FloatArray:
    """``s`` of ``[[s·R, t], [0, 1]]``: the norm of the first column of ``s·R``, scaled by its largest
    entry first (``s`` ranges over 1e±304, whose squares would under- or overflow)."""
    col = m[..., :3, 0]
    big = np.abs(col).max(axis=-1)
    safe = np.where(big > 0.0, big, 1.0)
    return big * np.sqrt(_sq(col / safe[..., None]))


def w_unit(sigma: FloatArray, h: FloatArray, s: FloatArray, c: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``(a, bθ, cθ²)`` for huge angles ``θ = 2h`` (``s, c = sin h, cos h``): ``W = a I + bθ [u]× + cθ² [u]×²``.

    With ``1/θ = ½/h``, ``r = t/(σ² + t) = 1/(1 + (σ/θ)²)``, ``t cosc θ = 2 sin²h``,
    ``t sinc3 θ = 1 − sin h cos h/h``, ``t q_coef2 θ = ½ − (sin h/h)²/2``:
    ``bθ = (σ²μ₁ + e^σ(2 sin²h − σ t sinc3)) r/θ``, ``cθ² = (σ²μ₂/2 + e^σ(t sinc3 − σ t q_coef2)) r``.
    """
    es, mu0, mu1, mu2 = _series.sim3_moments(sigma)
    inv = 0.5 / h
    r = 1.0 / (1.0 + (sigma * inv) ** 2)
    ts3 = 1.0 - s * c / h
    tq2 = 0.5 - 0.5 * (s / h) ** 2
    b = (sigma * sigma * mu1 + es * (2.0 * s * s - sigma * ts3)) * inv * r
    cc = (0.5 * sigma * sigma * mu2 + es * (ts3 - sigma * tq2)) * r
    return mu0, b, cc


def _unit_coefficients(theta: FloatArray, sigma: FloatArray) -> tuple[FloatArray, ...]:
    """``(u, a, bθ, cθ²)`` for ``|θ| ≥ _so3.HUGE`` (:func:`w_unit` on the axis and half angle of ``θ``)."""
    u, h, s, c = _so3.polar(theta)
    return (u, *w_unit(sigma, h, s, c))


def _w_apply_huge(theta: FloatArray, v: FloatArray, sigma1: FloatArray) -> FloatArray:
    u, a, b, c = _unit_coefficients(theta, sigma1[..., 0])
    uv = np.cross(u, v)
    return a[..., None] * v + b[..., None] * uv + c[..., None] * np.cross(u, uv)


@_so3.scale_safe(_w_apply_huge)
def w_apply(theta: FloatArray, v: FloatArray, sigma1: FloatArray) -> FloatArray:
    """``W(σ, θ) v = a v + b θ×v + c θ×(θ×v)``, ``σ`` as ``(..., 1)``; huge angles in unit form."""
    a, b, c = _series.sim3_coefficients(sigma1[..., 0], _sq(theta))
    wv = np.cross(theta, v)
    return a[..., None] * v + b[..., None] * wv + c[..., None] * np.cross(theta, wv)


def exp(tau: FloatArray) -> FloatArray:
    """``[[e^σ Exp(θ), a ρ + b θ×ρ + c θ×(θ×ρ)], [0, 1]]``."""
    rho, theta, sigma = tau[..., :3], tau[..., 3:6], tau[..., 6]
    return _matrix.assemble(_so3.exp(theta) * _scalar(np.exp(sigma)), w_apply(theta, rho, tau[..., 6:]))


def _w_inv_matrix_huge(theta: FloatArray, sigma1: FloatArray) -> FloatArray:
    u, a, b, c = _unit_coefficients(theta, sigma1[..., 0])
    al, be, ga = _series.sim3_inverse_coefficients(a, b, c, 1.0)
    k = _so3.hat(u)
    return _scalar(al) * np.eye(3) + _scalar(be) * k + _scalar(ga) * (k @ k)


@_so3.scale_safe(_w_inv_matrix_huge)
def w_inv_matrix(theta: FloatArray, sigma1: FloatArray) -> FloatArray:
    """``W(σ, θ)⁻¹ = α I + β θ^ + γ θ^²`` as a matrix; huge angles in unit form."""
    t = _sq(theta)
    al, be, ga = _series.sim3_inverse_coefficients(*_series.sim3_coefficients(sigma1[..., 0], t), t)
    k2 = theta[..., :, None] * theta[..., None, :] - _scalar(t) * np.eye(3)
    return _scalar(al) * np.eye(3) + _scalar(be) * _so3.hat(theta) + _scalar(ga) * k2


def w_inv_apply(sigma: FloatArray, theta: FloatArray, v: FloatArray) -> FloatArray:
    """``W(σ, θ)⁻¹ v = α v + β θ×v + γ θ×(θ×v)`` (``lie._series.sim3_inverse_coefficients``)."""
    t = _sq(theta)
    al, be, ga = _series.sim3_inverse_coefficients(*_series.sim3_coefficients(sigma, t), t)
    wv = np.cross(theta, v)
    return al[..., None] * v + be[..., None] * wv + ga[..., None] * np.cross(theta, wv)


def log(m: FloatArray) -> FloatArray:
    """``(W(σ, θ)⁻¹ t, θ, σ)`` with ``σ = log s``, ``θ = Log(sR/s)``."""
    sr, t = _matrix.split(m)
    s = scale(m)
    theta = _so3.log(sr / _scalar(s))
    sigma = np.log(s)
    return np.concatenate([w_inv_apply(sigma, theta, t), theta, sigma[..., None]], axis=-1)


def inverse(m: FloatArray) -> FloatArray:
    """``[[(sR)⁻¹, −(sR)⁻¹ t], [0, 1]]`` with ``(sR)⁻¹ = (sR)ᵀ/s²``."""
    sr, t = _matrix.split(m)
    s = _scalar(scale(m))
    mi = np.swapaxes(sr, -1, -2) / s / s
    return _matrix.assemble(mi, -_matrix.rotate_vectors(mi, t))


def adjoint(m: FloatArray) -> FloatArray:
    """``[[sR, [t]× R, −t], [0, R, 0], [0, 0, 1]]``."""
    sr, t = _matrix.split(m)
    r = sr / _scalar(scale(m))
    out = np.zeros(m.shape[:-2] + (7, 7))
    out[..., :3, :3] = sr
    out[..., :3, 3:6] = _so3.hat(t) @ r
    out[..., :3, 6] = -t
    out[..., 3:6, 3:6] = r
    out[..., 6, 6] = 1.0
    return out


def ad(tau: FloatArray) -> FloatArray:
    """``ad_τ = [[θ^ + σI, ρ^, −ρ], [0, θ^, 0], [0, 0, 0]]``, ``ad_τ v = [τ^, v^]^∨``."""
    rho, theta, sigma = tau[..., :3], tau[..., 3:6], tau[..., 6]
    out = np.zeros(tau.shape[:-1] + (7, 7))
    th = _so3.hat(theta)
    out[..., :3, :3] = th + _scalar(sigma) * np.eye(3)
    out[..., :3, 3:6] = _so3.hat(rho)
    out[..., :3, 6] = -rho
    out[..., 3:6, 3:6] = th
    return out


def _double(j: FloatArray, tau: FloatArray) -> FloatArray:
    """``½ (I + Ad_{Exp τ}⁻¹) J`` by 3×3 blocks: with ``Exp(−τ) = (s, R, t)``,
    ``Ad_{Exp(−τ)} = [[sR, [t]×R, −t], [0, R, 0], [0, 0, 1]]`` and ``J = [[D₁, X, y], [0, D₂, 0], [0, 0, 1]]``:
    ``D₁ ← ½(I + sR)D₁``, ``X ← ½((I + sR)X + [t]×R D₂)``, ``y ← ½((I + sR)y − t)``, ``D₂ ← ½(I + R)D₂``."""
    r = _so3.exp(-tau[..., 3:6])
    sr = r * _scalar(np.exp(-tau[..., 6]))
    t = w_apply(-tau[..., 3:6], -tau[..., :3], -tau[..., 6:])
    d1, x, y, d2 = j[..., :3, :3], j[..., :3, 3:6], j[..., :3, 6], j[..., 3:6, 3:6]
    out = np.array(j)
    out[..., :3, :3] = 0.5 * (d1 + sr @ d1)
    out[..., :3, 3:6] = 0.5 * (x + sr @ x + (_so3.hat(t) @ r) @ d2)
    out[..., :3, 6] = 0.5 * (y + _matrix.matvec(sr, y) - t)
    out[..., 3:6, 3:6] = 0.5 * (d2 + r @ d2)
    return out


def jr(tau: FloatArray) -> FloatArray:
    """``Jr(τ) = Σₖ (−ad_τ)ᵏ/(k+1)!``, numerically exact by doubling (``_doubling.jr``), the doubling
    steps by 3×3 blocks (:func:`_double`)."""
    return _doubling.jr(tau, 3, ad, exp, inverse, adjoint, step=_double)


def jr_inv(tau: FloatArray) -> FloatArray:
    """``Jr⁻¹`` by blocks of ``Jr = [[D₁, X, y], [0, D₂, 0], [0, 0, 1]]``:
    ``[[D₁⁻¹, −D₁⁻¹ X D₂⁻¹, −D₁⁻¹ y], [0, D₂⁻¹, 0], [0, 0, 1]]`` with the closed forms
    ``D₁⁻¹ = W(−σ, −θ)⁻¹`` and ``D₂⁻¹ = Jr_SO3(θ)⁻¹``."""
    j = jr(tau)
    theta = tau[..., 3:6]
    d1i = w_inv_matrix(-theta, -tau[..., 6:])
    d2i = _so3.jr_inv(theta)
    out = np.zeros_like(j)
    out[..., :3, :3] = d1i
    out[..., :3, 3:6] = -d1i @ j[..., :3, 3:6] @ d2i
    out[..., :3, 6] = -_matrix.matvec(d1i, j[..., :3, 6])
    out[..., 3:6, 3:6] = d2i
    out[..., 6, 6] = 1.0
    return out


def act_jac(m: FloatArray, p: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``D(X·p)/DX = [sR, −sR[p]×, sR p]``, ``D(X·p)/Dp = sR``."""
    sr = m[..., :3, :3]
    return _matrix.hconcat(sr, -sr @ _so3.hat(p), _matrix.matvec(sr, p)[..., None]), sr
