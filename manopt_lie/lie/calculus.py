"""Distances between rotations and poses, and motion integration with covariance propagation.

Distances follow the VNAV lecture notes (§2.8, eqs. 2.67–2.86; Huynh 2009; Hartley et al.
2013): with ``θ`` the angle of ``R_Aᵀ R_B``,

* geodesic (angular) ``d_θ = |Log(R_Aᵀ R_B)|`` (2.67–2.68), bi-invariant;
* chordal ``d_c = ‖R_A − R_B‖_F = 2√2 |sin(θ/2)|`` (2.70–2.74), ``≈ √2 d_θ`` for small θ;
* quaternion ``d_q = min_± ‖q_A ∓ q_B‖ = 2 sin(θ/4)`` (2.79), a pseudo-metric on quaternions,
  with ``θ/π ≤ d_q ≤ θ/2``;
* SE(3) double geodesic ``d_dg = √(d_θ² + w²‖t_B − t_A‖²)`` (2.81, weight ``w`` in 1/m), the
  product metric of SO(3) × R³, left-invariant: ``d_dg(T_C T_A, T_C T_B) = d_dg(T_A, T_B)``
  (2.83); the geodesic ``|Log(T_A⁻¹ T_B)|`` is ``X.dist(Y)`` (2.80) and the chordal
  ``‖T_A − T_B‖_F = √(d_c(R)² + ‖Δt‖²)`` is ``X.chordal_dist(Y)`` (2.84–2.85).
"""

from __future__ import annotations

from typing import Literal, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from ..errors import ShapeError
from ._checks import FloatArray, as_batch, broadcast_batch
from .base import LieGroup
from .groups import SE2, SE3, SO2, SO3

G = TypeVar("G", bound=LieGroup)

__all__ = [
    "angular_distance",
    "chordal_distance",
    "quaternion_distance",
    "double_geodesic_distance",
    "integrate",
]


def _rotations(x: LieGroup, name: str) -> LieGroup:
    if isinstance(x, (SO2, SO3)):
        return x
    if isinstance(x, (SE2, SE3)):
        return x.rotation()
    rotation = getattr(x, "rotation", None)
    if rotation is None:
        raise TypeError(f"{name}: expected an element with a rotation (SO2, SO3, SE2, SE3, Sim3, SE23), got {x!r}")
    return rotation()


def angular_distance(a: LieGroup, b: LieGroup) -> FloatArray:
    """``d_θ = |Log(R_Aᵀ R_B)|`` of the rotation parts, in ``[0, π]`` (VNAV eq. 2.67–2.68)."""
    ra, rb = _rotations(a, "a"), _rotations(b, "b")
    return np.abs(rb.rminus(ra))[..., 0] if isinstance(ra, SO2) else np.linalg.norm(rb.rminus(ra), axis=-1)


def chordal_distance(a: LieGroup, b: LieGroup) -> FloatArray:
    """``d_c = ‖R_A − R_B‖_F`` of the rotation parts ``= 2√2 |sin(d_θ/2)|`` (VNAV eq. 2.70–2.74)."""
    return _rotations(a, "a").chordal_dist(_rotations(b, "b"))


def quaternion_distance(qa: ArrayLike | SO3, qb: ArrayLike | SO3) -> FloatArray:
    """``d_q = min_{s=±1} ‖q_A − s q_B‖ = √(2 − 2|q_A·q_B|)`` of unit quaternions ``(x, y, z, w)`` or
    SO(3) elements (VNAV eq. 2.79): ``q`` and ``−q`` are one rotation, so the sign is minimized
    over; ``= 2 sin(θ/4)`` for the relative angle θ. Written ``‖q_A − s q_B‖`` with
    ``s = sign(q_A·q_B)`` (no cancellation for nearby rotations)."""
    a = qa.as_quaternion() if isinstance(qa, SO3) else as_batch(qa, (4,), "qa")
    b = qb.as_quaternion() if isinstance(qb, SO3) else as_batch(qb, (4,), "qb")
    broadcast_batch(a.shape[:-1], b.shape[:-1])
    s = np.where(np.einsum("...i,...i->...", a, b) < 0.0, -1.0, 1.0)
    return np.linalg.norm(a - s[..., None] * b, axis=-1)


def double_geodesic_distance(a: LieGroup, b: LieGroup, weight: float = 1.0) -> FloatArray:
    """``d_dg = √(d_θ(R_A, R_B)² + w² ‖t_B − t_A‖²)`` for SE(2)/SE(3) poses (VNAV eq. 2.81): SE(n) as
    the product SO(n) × Rⁿ; ``weight`` (1/m) makes the translation commensurate with radians."""
    if not (isinstance(a, (SE2, SE3)) and type(a) is type(b)):
        raise TypeError(f"double_geodesic_distance: expected two SE2 or two SE3 elements, got {a!r}, {b!r}")
    dt = b.translation() - a.translation()
    return np.hypot(angular_distance(a, b), weight * np.linalg.norm(dt, axis=-1))


def integrate(
    x0: G,
    increments: ArrayLike,
    covariances: ArrayLike | None = None,
    *,
    frame: Literal["right", "left"] = "right",
    initial_covariance: ArrayLike | None = None,
) -> G | tuple[G, FloatArray]:
    """The trajectory ``X_k = X_{k−1} ⊕ u_k`` (``frame="left"``: ``u_k ⊕ X_{k−1} = Exp(u_k)·X_{k−1}``).

    Parameters
    ----------
    x0
        The start, batch shape ``B``.
    increments
        ``u_1 … u_n``, shape ``(n, *B', dim)`` with ``B'`` broadcasting against ``B``.
    covariances
        ``Q_k`` of the increments, ``(n, *B'', dim, dim)`` or ``(dim, dim)`` for all steps; with it,
        the covariances of ``X_k`` are propagated to first order in the right (local) tangent
        (Solà et al. §IV-B, eqs. 171–173): ``P_k = F P_{k−1} Fᵀ + G Q_k Gᵀ`` with, for
        ``frame="right"``, ``F = Ad_{Exp u_k}⁻¹`` and ``G = Jr(u_k)`` (the Jacobians of ``X ⊕ u``);
        for ``frame="left"``, ``F = I``, ``G = Ad_{X_k}⁻¹ Jl(u_k)``.
    initial_covariance
        ``P_0`` (default 0).

    Returns
    -------
    trajectory
        ``X_0 … X_n`` stacked on a new leading axis, batch shape ``(n + 1, *broadcast(B, B'))``.
    covariances
        With ``covariances``: ``P_0 … P_n``, ``(n + 1, …, dim, dim)``.

    Notes
    -----
    The products ``U_1·…·U_k`` (``U_k = Exp u_k``) are a prefix product, computed by
    pointer doubling in ``⌈log₂ n⌉`` batched compositions (Hillis–Steele scan). The
    covariance recursion is sequential; it loops over the ``n`` steps (batched over the rest).
    """
    if frame not in ("right", "left"):
        raise ValueError(f"frame must be 'right' or 'left', got {frame!r}")
    group = type(x0)
    u = as_batch(increments, (group.dim,), "increments")
    if u.ndim < 2:
        raise ShapeError(f"increments: expected shape (n, ..., {group.dim}), got {u.shape}")
    n = u.shape[0]
    prefix = group.exp(u)
    step = 1
    while step < n:  # prefix[k] ← prefix[k − step]·prefix[k] (right) or prefix[k]·prefix[k − step] (left)
        head, tail = prefix[: n - step], prefix[step:]
        joined = head @ tail if frame == "right" else tail @ head
        prefix = group.concatenate([prefix[:step].broadcast_to((step,) + joined.batch_shape[1:]), joined])
        step *= 2
    xs = x0 @ prefix if frame == "right" else prefix @ x0
    start = x0.broadcast_to(xs.batch_shape[1:])
    trajectory = group.concatenate([group.stack([start]), xs])
    if covariances is None:
        return trajectory
    q = as_batch(covariances, (group.dim, group.dim), "covariances")
    q = np.broadcast_to(q, (n,) + q.shape[-2:]) if q.ndim == 2 else q
    batch = trajectory.batch_shape[1:]
    p0 = np.zeros((group.dim, group.dim)) if initial_covariance is None else initial_covariance
    p = np.array(np.broadcast_to(as_batch(p0, (group.dim, group.dim), "initial_covariance"), batch + q.shape[-2:]))
    out = [p]
    for k in range(n):
        if frame == "right":
            f = group.exp(u[k]).inverse().adjoint()
            g = group.jr(u[k])
        else:
            f = np.eye(group.dim)
            g = trajectory[k + 1].inverse().adjoint() @ group.jl(u[k])
        p = f @ p @ np.swapaxes(f, -1, -2) + g @ q[k] @ np.swapaxes(g, -1, -2)
        out.append(p)
    return trajectory, np.stack(np.broadcast_arrays(*out))
