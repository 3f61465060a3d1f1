"""SE(2) kernels on arrays: homogeneous ``(..., 3, 3)``, tangents ``(ρx, ρy, θ)``.

Formulas: Solà et al. (arXiv:1812.01537), Appendix C.

Angles of any finite size are accepted: ``sin``/``cos`` of a huge angle are finite (NumPy
reduces the argument exactly, though an angle whose ulp exceeds 2π, ``|θ| ≳ 1e16``, has no
physical meaning), and ``θ²``, ``θ³`` overflowing inside the coefficients only drives terms
that are ``O(1/θ)`` to ``0`` — hence the ``errstate(over="ignore")`` on the kernels that
take an angle from a tangent.
"""

from __future__ import annotations

import numpy as np

from . import _matrix, _one, _series
from ._checks import FloatArray


def hat(tau: FloatArray) -> FloatArray:
    """``[[0, −θ, ρx], [θ, 0, ρy], [0, 0, 0]]``."""
    out = np.zeros(tau.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 1, 0] = -tau[..., 2], tau[..., 2]
    out[..., :2, 2] = tau[..., :2]
    return out


def vee(m: FloatArray) -> FloatArray:
    return np.stack([m[..., 0, 2], m[..., 1, 2], 0.5 * (m[..., 1, 0] - m[..., 0, 1])], axis=-1)


def _v_coefficients(theta: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``(sin θ/θ, (1 − cos θ)/θ)``: ``V(θ) = [[a, −b], [b, a]]``."""
    ang = np.abs(theta)  # contiguous: ``theta`` is often a strided view of the tangents
    return _series.sinc(ang), theta * _series.cosc(ang)


def _v_inverse_coefficients(theta: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``((θ/2) cot(θ/2), θ/2)``: ``V(θ)⁻¹ = [[a, b], [−b, a]]``."""
    return _series.half_cot(np.abs(theta)), 0.5 * theta


_quiet = np.errstate(over="ignore")


@_one.fast(_one.se2_exp, 1)
@_quiet
def exp(tau: FloatArray) -> FloatArray:
    """``[[R(θ), V(θ) ρ], [0, 1]]``."""
    theta = tau[..., 2]
    a, b = _v_coefficients(theta)
    rho = tau[..., :2]
    return _matrix.assemble(_matrix.rotation2(theta), a[..., None] * rho + b[..., None] * _matrix.skew2(rho))


@_one.fast(_one.se2_log, 2)
def log(m: FloatArray) -> FloatArray:
    """``(V(θ)⁻¹ t, θ)`` with ``θ = atan2(R₁₀, R₀₀) ∈ (−π, π]``."""
    theta = _matrix.angle2(m[..., :2, :2])
    a, b = _v_inverse_coefficients(theta)
    t = m[..., :2, 2]
    rho = a[..., None] * t - b[..., None] * _matrix.skew2(t)
    return np.concatenate([rho, theta[..., None]], axis=-1)


def adjoint(m: FloatArray) -> FloatArray:
    """``[[R, (t_y, −t_x)ᵀ], [0, 1]]``."""
    out = m.copy()
    out[..., 0, 2], out[..., 1, 2] = m[..., 1, 2], -m[..., 0, 2]
    return out


@_one.fast(_one.se2_jr, 1, small=_one.SMALL_JACOBIAN)
@_quiet
def jr(tau: FloatArray) -> FloatArray:
    """Right Jacobian::

    [[ sin θ/θ,        (1−cos θ)/θ, ρx (θ−sin θ)/θ² − ρy (1−cos θ)/θ²],
     [−(1−cos θ)/θ,    sin θ/θ,     ρx (1−cos θ)/θ² + ρy (θ−sin θ)/θ²],
     [ 0,              0,           1                                 ]]
    """
    rho_x, rho_y, theta = tau[..., 0], tau[..., 1], tau[..., 2]
    ang = np.abs(theta)
    a, b = _v_coefficients(theta)
    c = _series.cosc(ang)
    d = theta * _series.sinc3(ang)
    out = np.zeros(tau.shape[:-1] + (3, 3))
    out[..., 0, 0], out[..., 0, 1], out[..., 0, 2] = a, b, rho_x * d - rho_y * c
    out[..., 1, 0], out[..., 1, 1], out[..., 1, 2] = -b, a, rho_x * c + rho_y * d
    out[..., 2, 2] = 1.0
    return out


@_one.fast(_one.se2_jr_inv, 1, small=_one.SMALL_JACOBIAN)
@_quiet
def jr_inv(tau: FloatArray) -> FloatArray:
    """``Jr⁻¹ = [[M⁻¹, −M⁻¹ w], [0, 1]]`` of ``Jr = [[M, w], [0, 1]]``, with
    ``M⁻¹ = [[(θ/2)cot(θ/2), −θ/2], [θ/2, (θ/2)cot(θ/2)]]``."""
    j = jr(tau)
    a, b = _v_inverse_coefficients(tau[..., 2])
    out = np.zeros_like(j)
    out[..., 0, 0], out[..., 0, 1] = a, -b
    out[..., 1, 0], out[..., 1, 1] = b, a
    w0, w1 = j[..., 0, 2], j[..., 1, 2]
    out[..., 0, 2] = -(a * w0 + -b * w1)
    out[..., 1, 2] = -(b * w0 + a * w1)
    out[..., 2, 2] = 1.0
    return out


def act_jac(m: FloatArray, p: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``D(T·p)/DT = [R, R J p]`` with ``J = [[0, −1], [1, 0]]``, ``D(T·p)/Dp = R``."""
    r = m[..., :2, :2]
    rjp = _matrix.rotate_vectors(r, _matrix.skew2(p))
    return _matrix.hconcat(r, rjp[..., None]), r
