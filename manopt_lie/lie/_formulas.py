"""Formulas on components, written once for two evaluators: Python floats and NumPy arrays.

The single-element twins of ``_one`` call these with Python floats, the array kernels with
arrays holding one component of every batch element; both get the same operations in the same
order, hence the same roundings. Augmented assignments (``t += …``) apply only to fresh results:
in place on arrays, rebinding on floats.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

# ``Any``: a Python float, or an array of one component over the batch.
C = Any


def stack(entries: Sequence[np.ndarray], *trailing: int) -> np.ndarray:
    """Entries (equal or broadcastable batch shapes) as the trailing axes ``trailing`` of one array.

    ``np.array`` of the list, then its first axis moved last as a view: about 6× faster than
    ``np.stack(…, axis=-1)`` on 10⁴ elements, 4× on a few. The result is not C-contiguous.
    """
    shapes = {np.shape(e) for e in entries}
    if len(shapes) > 1:
        entries = np.broadcast_arrays(*entries)
    a = np.array(entries)
    batch = a.shape[1:]
    return a.reshape(len(entries), -1).T.reshape(batch + trailing)


def sq3(x: C, y: C, z: C) -> C:
    """``(x² + y²) + z²``."""
    t = x * x
    t += y * y
    t += z * z
    return t


def dot3(a0: C, a1: C, a2: C, b0: C, b1: C, b2: C) -> C:
    """``(a₀b₀ + a₁b₁) + a₂b₂``."""
    d = a0 * b0
    d += a1 * b1
    d += a2 * b2
    return d


def cross3(a0: C, a1: C, a2: C, b0: C, b1: C, b2: C) -> tuple[C, C, C]:
    """``a × b``."""
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


def rodrigues(r: C, c: C, x: C, y: C, z: C, t: C) -> list[C]:
    """The nine entries of ``Exp(w) = cos θ I + (1 − cos θ)/θ² w wᵀ + sin θ/θ [w]×`` from ``r = sin(θ/2)/θ``,
    ``c = cos(θ/2)`` and ``t = θ²``: ``sin θ/θ = 2rc``, ``(1 − cos θ)/θ² = 2r²``, ``cos θ = 1 − 2r²t``."""
    r2 = r + r
    a = r2 * c
    b = r2 * r
    cd = 1.0 - b * t
    bx, by, bz = b * x, b * y, b * z
    ax, ay, az = a * x, a * y, a * z
    bxy, bxz, byz = bx * y, bx * z, by * z
    return [cd + bx * x, bxy - az, bxz + ay, bxy + az, cd + by * y, byz - ax, bxz - ay, byz + ax, cd + bz * z]


def i_plus(a: C, b: C, x: C, y: C, z: C, t: C) -> list[C]:
    """The nine entries (row-major) of ``I + a [w]× + b [w]×²``, ``[w]×² = w wᵀ − t I``, ``t = |w|²``."""
    xy, xz, yz = x * y, x * z, y * z
    return [
        1.0 + b * (x * x - t), a * -z + b * xy, a * y + b * xz,
        a * z + b * xy, 1.0 + b * (y * y - t), a * -x + b * yz,
        a * -y + b * xz, a * x + b * yz, 1.0 + b * (z * z - t),
    ]  # fmt: skip


def q_coefficients(c1: C, c2: C, c3: C, s: C, d: C) -> tuple[C, C, C, C, C, C]:
    """``(k₀, …, k₅)`` of :func:`q_entries` for Barfoot's ``Q(ρ, θ)`` (``_se3.q_matrix``), from
    ``c₁, c₂, c₃``, ``s = |θ|²`` and ``d = θ·ρ``."""
    return 0.5 - 2.0 * c2 * s, (3.0 * c2 - c1) * d, c1, c2, 2.0 * c3 * d, 2.0 * d * (c3 * s - c1)


def q_entries(r: tuple[C, C, C], v: tuple[C, C, C], k: tuple[C, C, C, C, C, C]) -> list[C]:
    """The nine entries of ``k₀ρ^ + k₁v^ + k₂(vρᵀ + ρvᵀ) + k₃(v wᵀ − w vᵀ) − k₄ vvᵀ + k₅ I``, ``w = v × ρ``.

    Summed left to right; the terms that vanish identically (the diagonals of ``ρ^``, ``v^`` and of the
    antisymmetric ``v wᵀ − w vᵀ``, the off-diagonal of ``I``) are left out.
    """
    r0, r1, r2 = r
    v0, v1, v2 = v
    k0, k1, k2, k3, k4, k5 = k
    w0, w1, w2 = cross3(v0, v1, v2, r0, r1, r2)
    s01, s02, s12 = v0 * r1 + v1 * r0, v0 * r2 + v2 * r0, v1 * r2 + v2 * r1
    a01, a02, a12 = v0 * w1 - w0 * v1, v0 * w2 - w0 * v2, v1 * w2 - w1 * v2
    p01, p02, p12 = v0 * v1, v0 * v2, v1 * v2
    return [
        k2 * (v0 * r0 + v0 * r0) - k4 * (v0 * v0) + k5,
        k0 * -r2 + k1 * -v2 + k2 * s01 + k3 * a01 - k4 * p01,
        k0 * r1 + k1 * v1 + k2 * s02 + k3 * a02 - k4 * p02,
        k0 * r2 + k1 * v2 + k2 * s01 + k3 * -a01 - k4 * p01,
        k2 * (v1 * r1 + v1 * r1) - k4 * (v1 * v1) + k5,
        k0 * -r0 + k1 * -v0 + k2 * s12 + k3 * a12 - k4 * p12,
        k0 * -r1 + k1 * -v1 + k2 * s02 + k3 * -a02 - k4 * p02,
        k0 * r0 + k1 * v0 + k2 * s12 + k3 * -a12 - k4 * p12,
        k2 * (v2 * r2 + v2 * r2) - k4 * (v2 * v2) + k5,
    ]


def mat3(a: list[C], b: list[C]) -> list[C]:
    """The nine entries of the product of 3×3 matrices given by their row-major entries, each summed
    left to right (no fused multiply-adds: the same on floats and arrays)."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = a
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = b
    return [
        a0 * b0 + a1 * b3 + a2 * b6, a0 * b1 + a1 * b4 + a2 * b7, a0 * b2 + a1 * b5 + a2 * b8,
        a3 * b0 + a4 * b3 + a5 * b6, a3 * b1 + a4 * b4 + a5 * b7, a3 * b2 + a4 * b5 + a5 * b8,
        a6 * b0 + a7 * b3 + a8 * b6, a6 * b1 + a7 * b4 + a8 * b7, a6 * b2 + a7 * b5 + a8 * b8,
    ]  # fmt: skip


def neg(a: list[C]) -> list[C]:
    return [-e for e in a]


def se3_jacobian(
    rho: tuple[C, C, C], theta: tuple[C, C, C], t: C, ab: tuple[C, C], c: tuple[C, C, C], inverse: bool
) -> tuple[list[C], list[C]]:
    """The diagonal and corner blocks (entries) of SE(3)'s ``Jr = [[Jr(θ), Q(−ρ, −θ)], [0, Jr(θ)]]`` or of
    ``Jr⁻¹ = [[Jr(θ)⁻¹, −Jr(θ)⁻¹ Q Jr(θ)⁻¹], [0, Jr(θ)⁻¹]]``, from ``t = |θ|²``, the coefficients ``ab`` of
    :func:`i_plus` for ``Jr(θ)`` or ``Jr(θ)⁻¹`` and ``c = (c₁, c₂, c₃)`` of ``Q`` (``_se3.q_matrix``)."""
    d = dot3(*theta, *rho)  # (−θ)·(−ρ), exactly
    j = i_plus(ab[0], ab[1], *theta, t)
    q = q_entries((-rho[0], -rho[1], -rho[2]), (-theta[0], -theta[1], -theta[2]), q_coefficients(*c, t, d))
    return (j, neg(mat3(mat3(j, q), j))) if inverse else (j, q)
