"""Array kernels of the landmark factors: a point in a sensor's frame with its right
Jacobians, and the range, planar angle and spatial direction of that point with their
derivatives — all vectorized over edges, all finite for every finite input."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..lie import SO3

FloatArray = NDArray[np.float64]

# Below this angle from the measured direction, ψ(θ) of the sphere log's Jacobian is its series.
_SERIES_ANGLE = 1e-3
# Near the antipode of the measured direction, sin of the distance to it is clamped here.
_ANTIPODAL_SIN = 1e-12
# 1/‖p‖ stays finite above this, whatever min_range a caller asks for.
_MIN_RANGE_FLOOR = 1e-300


def matvec(m: FloatArray, v: FloatArray) -> FloatArray:
    return np.einsum("...ij,...j->...i", m, v)


def matvec_t(m: FloatArray, v: FloatArray) -> FloatArray:
    """``Mᵀ v``."""
    return np.einsum("...ji,...j->...i", m, v)


def norm(p: FloatArray) -> FloatArray:
    """``‖p‖`` over the last axis, scale-safe (no overflow or underflow of the squares)."""
    scale = np.max(np.abs(p), axis=-1)
    safe = np.where(scale > 0, scale, 1.0)
    return scale * np.sqrt(np.einsum("...i,...i->...", p / safe[..., None], p / safe[..., None]))


def unit(p: FloatArray, n: FloatArray) -> FloatArray:
    """``p / ‖p‖``, ``0`` where ``p = 0`` (no overflow: ``|p_i| ≤ ‖p‖``)."""
    return p / np.where(n > 0, n, 1.0)[..., None]


def in_sensor_frame(
    rotation: FloatArray,
    translation: FloatArray,
    landmark: FloatArray,
    offset: tuple[FloatArray, FloatArray] | None,
    jac: bool = True,
) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
    """``p = (X S)⁻¹ l = R_Sᵀ(Rᵀ(l − t) − t_S)`` and its right Jacobians.

    With ``q = Rᵀ(l − t)``: ``X·Exp(ρ, θ)`` moves ``q`` to ``Exp(−(ρ, θ))·q ≈ q − ρ + [q]×θ``,
    so ``∂q/∂X = [−I, [q]×]`` (3-D) or ``[−I, (q_y, −q_x)ᵀ]`` (2-D), ``∂q/∂l = Rᵀ``; the
    fixed offset ``S = (R_S, t_S)`` multiplies both by ``R_Sᵀ``.

    Returns
    -------
    p : ``(m, d)``; J_X : ``(m, d, dim SE(d))``; J_l : ``(m, d, d)`` (``None`` unless ``jac``)
    """
    m, d = landmark.shape
    q = matvec_t(rotation, landmark - translation)
    if not jac:
        return (q if offset is None else matvec_t(offset[0], q - offset[1])), None, None
    if d == 3:
        j_theta = SO3.hat(q)
    else:
        j_theta = np.stack([q[:, 1], -q[:, 0]], axis=-1)[..., None]
    j_x = np.concatenate([np.broadcast_to(-np.eye(d), (m, d, d)), j_theta], axis=-1)
    j_l = np.swapaxes(rotation, -1, -2)
    if offset is None:
        return q, j_x, j_l
    r_s, t_s = offset
    r_st = np.swapaxes(r_s, -1, -2)
    return matvec(r_st, q - t_s), r_st @ j_x, r_st @ j_l


def range_part(p: FloatArray, measured: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``‖p‖ − ρ`` and its derivative ``p̂ᵀ`` (``0`` at ``p = 0``, a subgradient): ``(m, 1)``,
    ``(m, 1, d)``."""
    n = norm(p)
    return (n - measured)[:, None], unit(p, n)[:, None, :]


def predicted_direction(p: FloatArray, min_range: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``p̂ = p/‖p‖`` (the sensor's x axis at ``p = 0``), ``‖p‖`` and ``∂p̂/∂p = (I − p̂p̂ᵀ)/‖p‖``,
    zero where ``‖p‖ ≤ min_range``: within ``min_range`` of the sensor a bearing has no
    trustworthy derivative (GTSAM zeroes it below 1e-5 too)."""
    d = p.shape[1]
    n = norm(p)
    zero = n == 0
    u = np.where(zero[:, None], np.eye(d)[0], unit(p, n))
    far = n > max(min_range, _MIN_RANGE_FLOOR)
    scale = np.where(far, 1.0 / np.where(far, n, 1.0), 0.0)
    j = (np.eye(d) - u[:, :, None] * u[:, None, :]) * scale[:, None, None]
    return u, n, j


def angle_part(p: FloatArray, cos_sin: FloatArray, min_range: float, jac: bool = True) -> Any:
    """``wrap(atan2(p_y, p_x) − β)`` in ``(−π, π]``, computed as the angle from the measured
    direction ``(cos β, sin β)`` to ``p`` (``atan2(cross, dot)``, no subtraction of angles),
    and (with ``jac``) its derivative ``(−p_y, p_x)/‖p‖²`` (zero within ``min_range``): ``(m, 1)``,
    ``(m, 1, 2)``."""
    u, _, j = predicted_direction(p, min_range)
    c, s = cos_sin[:, 0], cos_sin[:, 1]
    angle = np.arctan2(c * u[:, 1] - s * u[:, 0], c * u[:, 0] + s * u[:, 1])
    angle = np.where(angle <= -np.pi, np.pi, angle)  # atan2 gives −π for (−0, −1): (−π, π] wants π
    if not jac:
        return angle[:, None]
    perp = np.stack([-u[:, 1], u[:, 0]], axis=-1)  # ∂angle/∂p̂ on the circle
    return angle[:, None], matvec_t(j, perp)[:, None, :]  # j is symmetric: perpᵀ j


def tangent_basis(z: FloatArray) -> FloatArray:
    """An orthonormal basis ``B = [b₁ b₂]`` of ``z^⊥`` for unit vectors ``z`` ``(m, 3)``:
    ``b₁ ∝ e_k − z_k z`` for the axis ``e_k`` least aligned with ``z``, ``b₂ = z × b₁``.
    Returns ``(m, 3, 2)``."""
    e = np.eye(3)[np.argmin(np.abs(z), axis=-1)]
    b1 = e - np.einsum("ei,ei->e", e, z)[:, None] * z
    b1 = b1 / np.linalg.norm(b1, axis=-1, keepdims=True)
    return np.stack([b1, np.cross(z, b1)], axis=-1)


def direction_part(p: FloatArray, z: FloatArray, basis: FloatArray, min_range: float, jac: bool = True) -> Any:
    """The sphere's log ``r = Bᵀ Log_z(p̂)`` of the predicted direction ``p̂`` at the measured
    one ``z`` in the basis ``B`` of ``z^⊥``, and (with ``jac``) ``∂r/∂p``: ``(m, 2)``, ``(m, 2, 3)``.

    With ``w = Bᵀp̂``, ``s = ‖w‖``, ``c = zᵀp̂`` and the angle ``θ = atan2(s, c)``:
    ``r = (θ/s) w``, so ``‖r‖ = θ = ∠(p, z)``, and

        ∂r/∂p̂ = (φ I + ψ w wᵀ) Bᵀ − w zᵀ,   φ = θ/s,   ψ = (cs − θ)/s³,

    (``φ → 1``, ``ψ = −2/3 − θ²/5 − 17θ⁴/420 + …`` near ``z``), then ``∂p̂/∂p``. At the
    antipode (``θ → π``) the direction is undefined: ``s`` is clamped at ``1e-12`` in ``φ, ψ``
    (large but finite derivatives) and ``r = (π, 0)`` where ``s = 0``.
    """
    u, _, j = predicted_direction(p, min_range)
    w = matvec_t(basis, u)
    c = np.einsum("ei,ei->e", z, u)
    s = norm(w)
    theta = np.arctan2(s, c)
    direction = np.where((s == 0)[:, None], np.array([1.0, 0.0]), unit(w, s))
    r = theta[:, None] * direction
    if not jac:
        return r
    behind = c < 0
    s_eff = np.where(behind, np.maximum(s, _ANTIPODAL_SIN), s)
    near = (~behind) & (theta < _SERIES_ANGLE)
    safe = np.where(near, 1.0, s_eff)
    t2 = theta * theta
    phi = np.where(near, 1.0 + t2 / 6.0 + 7.0 * t2 * t2 / 360.0, theta / safe)
    psi = np.where(near, -2.0 / 3.0 - t2 / 5.0 - 17.0 * t2 * t2 / 420.0, (c * s_eff - theta) / safe**3)
    d_w = phi[:, None, None] * np.eye(2) + psi[:, None, None] * w[:, :, None] * w[:, None, :]
    d_u = d_w @ np.swapaxes(basis, -1, -2) - w[:, :, None] * z[:, None, :]
    return r, d_u @ j
