"""SE(3) kernels on arrays: homogeneous ``(..., 4, 4)``, tangents ``(ρ, θ)`` as ``(..., 6)``.

Formulas: Solà et al. (arXiv:1812.01537), Appendix D, with ``Jr`` from eqs. 179–180;
Barfoot, "State Estimation for Robotics", §7.1.5 for ``Q``.
"""

from __future__ import annotations

import numpy as np

from . import _formulas, _matrix, _one, _series, _so3
from ._checks import FloatArray


def hat(tau: FloatArray) -> FloatArray:
    """``[[θ^, ρ], [0, 0]]``."""
    out = np.zeros(tau.shape[:-1] + (4, 4))
    out[..., :3, :3] = _so3.hat(tau[..., 3:])
    out[..., :3, 3] = tau[..., :3]
    return out


def vee(m: FloatArray) -> FloatArray:
    return np.concatenate([m[..., :3, 3], _so3.vee(m[..., :3, :3])], axis=-1)


@_one.fast(_one.se3_exp, 1, small=_one.SMALL_JACOBIAN)
def exp(tau: FloatArray) -> FloatArray:
    """``[[Exp(θ), Jl(θ) ρ], [0, 1]]``."""
    rho, theta = tau[..., :3], tau[..., 3:]
    return _matrix.assemble(_so3.exp(theta), _so3.jl_apply(theta, rho))


@_one.fast(_one.se3_log, 2, small=_one.SMALL_JACOBIAN)
def log(m: FloatArray) -> FloatArray:
    """``(Jl(θ)⁻¹ t, θ)`` with ``θ = Log(R)``."""
    r, t = _matrix.split(m)
    theta = _so3.log(r)
    return np.concatenate([_so3.jl_inv_apply(theta, t), theta], axis=-1)


def _q_sum(
    rho: FloatArray, v: FloatArray, k: tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]
) -> FloatArray:
    """``k₀ρ^ + k₁v^ + k₂(vρᵀ + ρvᵀ) + k₃(v wᵀ − w vᵀ) − k₄ vvᵀ + k₅ I`` with ``w = v × ρ``
    (:func:`_formulas.q_entries`, entry by entry)."""
    r = (rho[..., 0], rho[..., 1], rho[..., 2])
    return _formulas.stack(_formulas.q_entries(r, (v[..., 0], v[..., 1], v[..., 2]), k), 3, 3)


def _q_matrix_huge(rho: FloatArray, theta: FloatArray) -> FloatArray:
    """:func:`q_matrix` for ``|θ| ≥ HUGE``, with ``θ = 2h·u`` and the scaled coefficients
    ``C₁ = c₁θ² = 1 − sin h cos h/h``, ``c₁θ = C₁/(2h)``, ``C₂ = c₂θ² = ½ − (sin h/h)²/2``,
    ``C₃ = c₃θ³ = (2 + cos θ)/(4h) − ¾ (sin h/h)(cos h/h)``, ``d_u = u·ρ``."""
    u, h, s, c = _so3.polar(theta)
    c1 = 1.0 - s * c / h
    c1h = c1 / (2.0 * h)
    c2 = 0.5 - 0.5 * (s / h) ** 2
    c3 = 0.25 * (2.0 + c * c - s * s) / h - 0.75 * (s / h) * (c / h)
    du = _dot(u, rho)
    return _q_sum(rho, u, (0.5 - 2.0 * c2, (3.0 * c2 - c1) * du, c1h, c2, 2.0 * c3 * du, 2.0 * (c3 - c1h) * du))


def _dot(a: FloatArray, b: FloatArray) -> FloatArray:
    return _formulas.dot3(a[..., 0], a[..., 1], a[..., 2], b[..., 0], b[..., 1], b[..., 2])


@_one.fast(_one.q_matrix, 1, 1, small=_one.SMALL_JACOBIAN)
@_so3.scale_safe(_q_matrix_huge, angle=1)
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

    Angles beyond ``_so3.HUGE`` use the same sum with ``θ`` replaced by its axis and the
    coefficients scaled accordingly (:func:`_q_matrix_huge`).
    """
    s = _so3.sq(theta)
    d = _dot(theta, rho)
    angle = np.sqrt(s)
    c1, c2, c3 = _series.sinc3(angle, s), _series.q_coef2(angle, s), _series.q_coef3(angle, s)
    return _q_sum(rho, theta, _formulas.q_coefficients(c1, c2, c3, s, d))


def _block_upper(diagonal: FloatArray, corner: FloatArray) -> FloatArray:
    """``[[D, C], [0, D]]`` from 3×3 blocks."""
    shape = diagonal.shape if diagonal.shape == corner.shape else np.broadcast_shapes(diagonal.shape, corner.shape)
    out = np.zeros(shape[:-2] + (6, 6))
    out[..., :3, :3] = diagonal
    out[..., 3:, 3:] = diagonal
    out[..., :3, 3:] = corner
    return out


def _jr_blocks(tau: FloatArray, inverse: bool = False) -> FloatArray:
    """:func:`jr` (:func:`jr_inv`) through the scale-safe kernels ``_so3.jr`` and :func:`q_matrix`: huge angles."""
    rho, theta = tau[..., :3], tau[..., 3:]
    if not inverse:
        return _block_upper(_so3.jr(theta), q_matrix(-rho, -theta))
    ji = _so3.jr_inv(theta)
    return _block_upper(ji, -ji @ q_matrix(-rho, -theta) @ ji)


def _jacobian(tau: FloatArray, inverse: bool) -> FloatArray:
    """:func:`_formulas.se3_jacobian` on the components of ``tau``."""
    rho = (tau[..., 0], tau[..., 1], tau[..., 2])
    theta = (tau[..., 3], tau[..., 4], tau[..., 5])
    t = _formulas.sq3(*theta)
    ab = _so3.jr_coefficients(t, inverse)
    angle = np.sqrt(t)
    c1 = ab[1] if not inverse else _series.sinc3(angle, t)  # (θ − sin θ)/θ³, as in Jr(θ)
    c = (c1, _series.q_coef2(angle, t), _series.q_coef3(angle, t))
    diagonal, corner = _formulas.se3_jacobian(rho, theta, t, ab, c, inverse)
    return _block_upper(_formulas.stack(diagonal, 3, 3), _formulas.stack(corner, 3, 3))


@_one.fast(_one.se3_jr, 1, small=_one.SMALL_JACOBIAN)
@_so3.scale_safe(_jr_blocks, part=slice(3, 6))
def jr(tau: FloatArray) -> FloatArray:
    """``Jr(ρ, θ) = [[Jr(θ), Q(−ρ, −θ)], [0, Jr(θ)]]`` (eq. 179), entry by entry."""
    return _jacobian(tau, False)


@_one.fast(_one.se3_jr_inv, 1, small=_one.SMALL_JACOBIAN)
@_so3.scale_safe(lambda tau: _jr_blocks(tau, True), part=slice(3, 6))
def jr_inv(tau: FloatArray) -> FloatArray:
    """``Jr⁻¹ = [[Jr(θ)⁻¹, −Jr(θ)⁻¹ Q Jr(θ)⁻¹], [0, Jr(θ)⁻¹]]`` with ``Q = Q(−ρ, −θ)``, entry by entry."""
    return _jacobian(tau, True)


def adjoint(m: FloatArray) -> FloatArray:
    """``[[R, [t]× R], [0, R]]``."""
    r, t = _matrix.split(m)
    return _block_upper(r, _so3.hat(t) @ r)


def act_jac(m: FloatArray, p: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``D(T·p)/DT = [R, −R[p]×]``, ``D(T·p)/Dp = R``."""
    r, _ = _matrix.split(m)
    j_x = _matrix.hconcat(r, _so3.act_jac_rotation(r, p))
    return j_x, r
