"""Factors between poses ``X = (R, t) ∈ SE(d)`` and points ``l ∈ Rᵈ`` (d = 2, 3): the point
seen in the pose's (or a sensor's) frame, its range, its bearing, both; and the range
between two poses.

Every observation factor is a function of the point in the sensor frame

    p = (X S)⁻¹ l = R_Sᵀ(Rᵀ(l − t) − t_S),

``S = (R_S, t_S) ∈ SE(d)`` a fixed sensor offset per edge (g2o's ``PARAMS_SE3OFFSET``;
``S = I`` by default), so its right Jacobians are ``∂r/∂p · ∂p/∂X`` and ``∂r/∂p · ∂p/∂l``
with ``∂p/∂X = R_Sᵀ[−I, [q]×]`` (``q = Rᵀ(l − t)``; in 2-D ``[−I, (q_y, −q_x)ᵀ]``) and
``∂p/∂l = R_SᵀRᵀ``. The pose tangent is ``(ρ, θ)``, translation first. Points are given
as arrays (``Euclidean(d)`` blocks) or ``Rn(d)`` elements (``LieGroupManifold(Rn(d))``
blocks); the pose slot comes first.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..errors import ShapeError
from ..lie import LieGroup
from ..optim import Factor
from . import _geometry as geo
from ._common import (
    POSE_GROUPS,
    Blocks,
    FloatArray,
    Loss,
    edges,
    group_measurements,
    measurements,
    pose_parts,
    vectors,
    whitened_factor,
)
from .noise import NoiseModel

__all__ = ["relative_point_factor", "range_factor", "bearing_factor", "range_bearing_factor", "pose_range_factor"]

# p (m, d), jac -> r (m, k) | (r, ∂r/∂p (m, k, d))
Part = Callable[[FloatArray, bool], Any]

MIN_RANGE = 1e-9


def _offset(offset: LieGroup | None, m: int, d: int | None, name: str) -> tuple[int | None, Any]:
    """The dimension the offset fixes (or ``d``) and its ``(R_S, t_S)`` arrays."""
    if offset is None:
        return d, None
    s = group_measurements(offset, m, name, "offset")
    sd = getattr(type(s), "point_dim", None)
    if sd is None or POSE_GROUPS.get(sd) is not type(s) or (d is not None and sd != d):
        want = POSE_GROUPS[d].__name__ if d is not None else "SE2 or SE3"
        raise TypeError(f"{name}: the offset must be a {want} element, got {type(s).__name__}")
    return sd, pose_parts(s, sd, name)


def _min_range(value: float, name: str) -> float:
    if not (np.isfinite(value) and value >= 0):
        raise ValueError(f"{name}: min_range must be finite and non-negative, got {value!r}")
    return float(value)


def _observation_factor(
    variables: ArrayLike,
    parts: list[Part],
    dim: int,
    d: int | None,
    offset: LieGroup | None,
    noise: NoiseModel | None,
    loss: Loss,
    name: str,
    blocks: Blocks,
) -> Factor:
    """A pose–point factor whose residual stacks ``part(p)`` for the point ``p`` in the sensor
    frame; ``d = None`` takes the dimension from the poses at each call."""
    v = edges(variables, 2, name)
    d, sensor = _offset(offset, len(v), d, name)

    def kernel(x: Any, landmark: Any, jac: bool = False) -> Any:
        dd = d if d is not None else getattr(type(x), "point_dim", 0)
        if dd not in POSE_GROUPS:
            raise TypeError(f"{name}: expected SE2 or SE3 poses in the first slot, got {type(x).__name__}")
        rotation, translation = pose_parts(x, dd, name)
        p, j_x, j_l = geo.in_sensor_frame(rotation, translation, vectors(landmark, dd, name), sensor, jac)
        outs = [part(p, jac) for part in parts]
        if not jac:
            return np.concatenate(outs, axis=-1)
        d_p = np.concatenate([o[1] for o in outs], axis=1)
        return np.concatenate([o[0] for o in outs], axis=-1), [d_p @ j_x, d_p @ j_l]  # type: ignore[operator]

    return whitened_factor(v, kernel, dim, noise, loss, name, blocks)


def _range(measured: FloatArray) -> Part:
    def part(p: FloatArray, jac: bool) -> Any:
        r, d_p = geo.range_part(p, measured)
        return (r, d_p) if jac else r

    return part


def _bearing(measured: FloatArray, name: str, min_range: float) -> tuple[Part, int, int]:
    """The bearing part for angles ``(m,)`` (2-D) or directions ``(m, 3)`` (3-D), its residual
    dimension and the space dimension."""
    if measured.ndim == 1:
        cos_sin = np.stack([np.cos(measured), np.sin(measured)], axis=-1)

        def angle(p: FloatArray, jac: bool) -> Any:
            return geo.angle_part(p, cos_sin, min_range, jac)

        return angle, 1, 2
    n = geo.norm(measured)
    if not (n > 0).all():
        raise ValueError(f"{name}: zero bearing direction at edge {int(np.argmax(~(n > 0)))}")
    z = measured / n[:, None]
    basis = geo.tangent_basis(z)

    def direction(p: FloatArray, jac: bool) -> Any:
        return geo.direction_part(p, z, basis, min_range, jac)

    return direction, 2, 3


def _bearings(bearings: ArrayLike, m: int, name: str) -> FloatArray:
    a = np.asarray(bearings, dtype=np.float64)
    if a.ndim > 2 or (a.ndim == 2 and a.shape[1] != 3):
        raise ShapeError(f"{name}: bearings must be angles (m,) or directions (m, 3), got {a.shape}")
    return measurements(a, (3,) if a.ndim == 2 else (), m, name, "bearings")


def relative_point_factor(
    variables: ArrayLike,
    measured: ArrayLike,
    noise: NoiseModel | None = None,
    *,
    offset: LieGroup | None = None,
    loss: Loss = None,
    name: str = "relative_point",
    blocks: Blocks = None,
) -> Factor:
    r"""A point ``z_e`` observed in the frame of a pose (or of its sensor): ``z ≈ (X S)⁻¹ l``.

    .. math::

        r_e = (X S)^{-1} l - z_e = R_S^\top\big(R^\top(l - t) - t_S\big) - z_e, \qquad
        \frac{\partial r}{\partial X} = R_S^\top [-I,\ [q]_\times], \qquad
        \frac{\partial r}{\partial l} = R_S^\top R^\top

    with ``q = Rᵀ(l − t)`` (in 2-D ``[q]×`` is the column ``(q_y, −q_x)ᵀ``). g2o's
    ``EDGE_SE3_TRACKXYZ`` / ``EDGE_SE2_XY``.

    Parameters
    ----------
    variables : int array ``(m, 2)``
        ``(pose, point)`` per edge.
    measured : array ``(m, d)``, d = 2 or 3
        The points in the sensor frame.
    noise : NoiseModel, optional
        Of dimension ``d``; ``None``: unit noise.
    offset : SE2 or SE3 element, batch ``(m,)`` or ``()``, optional
        The sensor's pose in the body frame ``S``; ``None``: the identity.
    loss, name, blocks
        Forwarded to :class:`~manopt_lie.optim.Factor` (``blocks=("poses", "landmarks")``).
    """
    v = edges(variables, 2, name)
    z = np.asarray(measured, dtype=np.float64)
    d = z.shape[-1] if z.ndim == 2 else 0
    if d not in POSE_GROUPS:
        raise ShapeError(f"{name}: measured must be points of shape (m, 2) or (m, 3), got {z.shape}")
    z = measurements(z, (d,), len(v), name, "measured points")
    eye = np.eye(d)

    def point(p: FloatArray, jac: bool) -> Any:
        return (p - z, np.broadcast_to(eye, p.shape + (d,))) if jac else p - z

    return _observation_factor(v, [point], d, d, offset, noise, loss, name, blocks)


def range_factor(
    variables: ArrayLike,
    measured: ArrayLike,
    noise: NoiseModel | None = None,
    *,
    offset: LieGroup | None = None,
    loss: Loss = None,
    name: str = "range",
    blocks: Blocks = None,
) -> Factor:
    r"""The distance ``ρ_e`` from a pose (or its sensor) to a point (GTSAM's ``RangeFactor``).

    .. math::

        r_e = \|p\| - \rho_e = \|l - t_{XS}\| - \rho_e, \qquad
        \frac{\partial r}{\partial p} = \hat p^\top = p^\top / \|p\|

    times ``∂p/∂X``, ``∂p/∂l`` (without an offset ``∂r/∂X = [−p̂ᵀ, 0]``: turning the sensor
    does not change the distance; ``t_{XS}`` is the sensor's position). At
    ``p = 0`` (the point on the sensor) the residual is ``−ρ`` and the derivative ``0`` (a
    subgradient of ``‖·‖``). The dimension (2-D or 3-D) is the poses'.

    Parameters
    ----------
    variables : int array ``(m, 2)``
        ``(pose, point)`` per edge.
    measured : array ``(m,)``
        Ranges.
    noise : NoiseModel, optional
        Of dimension 1; ``None``: unit noise.
    offset, loss, name, blocks
        As for :func:`relative_point_factor`.
    """
    v = edges(variables, 2, name)
    rho = measurements(measured, (), len(v), name, "ranges")
    return _observation_factor(v, [_range(rho)], 1, None, offset, noise, loss, name, blocks)


def bearing_factor(
    variables: ArrayLike,
    measured: ArrayLike,
    noise: NoiseModel | None = None,
    *,
    offset: LieGroup | None = None,
    min_range: float = MIN_RANGE,
    loss: Loss = None,
    name: str = "bearing",
    blocks: Blocks = None,
) -> Factor:
    r"""The direction of a point seen from a pose (or its sensor) (GTSAM's ``BearingFactor``).

    - **2-D**, ``measured`` angles ``β_e`` ``(m,)``: one residual, the angle from the
      measured to the predicted bearing wrapped to ``(−π, π]``,

      .. math::

          r_e = \operatorname{wrap}(\operatorname{atan2}(p_y, p_x) - \beta_e), \qquad
          \frac{\partial r}{\partial p} = (-p_y,\ p_x) / \|p\|^2

      computed as ``atan2`` of the cross and dot products of ``p`` with
      ``(cos β, sin β)`` (exact for any ``β``, no subtraction of angles).
    - **3-D**, ``measured`` directions ``z_e`` ``(m, 3)`` (normalized here): two residuals,
      the sphere's log of the predicted direction ``p̂ = p/‖p‖`` at ``z`` in an orthonormal
      basis ``B`` of ``z^⊥`` fixed per edge at construction,

      .. math::

          r_e = B^\top \operatorname{Log}_z(\hat p) = \frac{\theta}{\sin\theta} B^\top \hat p,
          \qquad \theta = \angle(\hat p, z) = \operatorname{atan2}(\|B^\top \hat p\|,\ z^\top \hat p)

      so ``‖r‖`` is the angle between the directions (GTSAM's ``Unit3::localCoordinates``,
      up to the choice of ``B``). Unlike the projection ``Bᵀp̂``, it has no false minimum at
      ``p̂ = −z``; there ``‖r‖ = π`` (a point behind the sensor costs the most).

    Near-degenerate cases, all finite (no ``nan`` or ``inf``): within ``min_range`` of the
    sensor (``‖p‖ ≤ min_range``) the residual is that of the direction of ``p`` (the
    sensor's x axis at ``p = 0`` exactly: angle 0, direction ``(1, 0, 0)``) and the
    Jacobians are zero — the bearing of a point on the sensor is undefined and its
    derivative ``∝ 1/‖p‖`` unbounded (GTSAM does the same below ``1e-5``). At the
    antipode of ``z`` (3-D) the direction of ``r`` is undefined: ``r = (π, 0)``.

    Parameters
    ----------
    variables : int array ``(m, 2)``
        ``(pose, point)`` per edge.
    measured : array ``(m,)`` (angles, 2-D) or ``(m, 3)`` (directions, 3-D)
    noise : NoiseModel, optional
        Of dimension 1 (2-D) or 2 (3-D, in the basis ``B``: isotropic noise is the natural
        choice); ``None``: unit noise.
    offset : optional
        As for :func:`relative_point_factor`.
    min_range : float
        Distance below which the Jacobians are zero (``1e-9``; in the points' unit).
    loss, name, blocks
        Forwarded to :class:`~manopt_lie.optim.Factor`.
    """
    v = edges(variables, 2, name)
    part, k, d = _bearing(_bearings(measured, len(v), name), name, _min_range(min_range, name))
    return _observation_factor(v, [part], k, d, offset, noise, loss, name, blocks)


def range_bearing_factor(
    variables: ArrayLike,
    ranges: ArrayLike,
    bearings: ArrayLike,
    noise: NoiseModel | None = None,
    *,
    offset: LieGroup | None = None,
    min_range: float = MIN_RANGE,
    loss: Loss = None,
    name: str = "range_bearing",
    blocks: Blocks = None,
) -> Factor:
    r"""Range and bearing of a point seen from a pose (GTSAM's ``BearingRangeFactor``, whose
    residual lists the bearing first; here the range comes first).

    .. math::

        r_e = \big(\|p\| - \rho_e,\ r_{\text{bearing}}(p)\big)

    with the bearing residual of :func:`bearing_factor`: ``(range, angle)`` in 2-D (2
    entries), ``(range, direction)`` in 3-D (3 entries).

    Parameters
    ----------
    variables : int array ``(m, 2)``
        ``(pose, point)`` per edge.
    ranges : array ``(m,)``
    bearings : array ``(m,)`` (angles, 2-D) or ``(m, 3)`` (directions, 3-D)
    noise : NoiseModel, optional
        Of dimension 2 (2-D) or 3 (3-D), range first; e.g. ``Diagonal([σ_ρ, σ_β])``.
    offset, min_range, loss, name, blocks
        As for :func:`bearing_factor`.
    """
    v = edges(variables, 2, name)
    rho = measurements(ranges, (), len(v), name, "ranges")
    part, k, d = _bearing(_bearings(bearings, len(v), name), name, _min_range(min_range, name))
    return _observation_factor(v, [_range(rho), part], 1 + k, d, offset, noise, loss, name, blocks)


def pose_range_factor(
    variables: ArrayLike,
    measured: ArrayLike,
    noise: NoiseModel | None = None,
    *,
    loss: Loss = None,
    name: str = "pose_range",
    blocks: Blocks = None,
) -> Factor:
    r"""The distance between the positions of two poses (GTSAM's ``RangeFactor<Pose, Pose>``).

    .. math::

        r_e = \|t_j - t_i\| - \rho_e, \qquad
        \frac{\partial r}{\partial X_j} = [\hat u^\top R_j,\ 0], \qquad
        \frac{\partial r}{\partial X_i} = [-\hat u^\top R_i,\ 0]

    with ``û = (t_j − t_i)/‖t_j − t_i‖`` (``0`` where the positions coincide); the
    rotation columns are zero (``X·Exp(ρ, θ)`` moves ``t`` by ``Rρ`` to first order).

    Parameters
    ----------
    variables : int array ``(m, 2)``
    measured : array ``(m,)``
    noise : NoiseModel, optional
        Of dimension 1; ``None``: unit noise.
    loss, name, blocks
        Forwarded to :class:`~manopt_lie.optim.Factor`.
    """
    v = edges(variables, 2, name)
    rho = measurements(measured, (), len(v), name, "ranges")

    def kernel(xi: Any, xj: Any, jac: bool = False) -> Any:
        d = getattr(type(xi), "point_dim", 0)
        if d not in POSE_GROUPS:
            raise TypeError(f"{name}: expected SE2 or SE3 poses, got {type(xi).__name__}")
        (r_i, t_i), (r_j, t_j) = pose_parts(xi, d, name), pose_parts(xj, d, name)
        r, u = geo.range_part(t_j - t_i, rho)
        if not jac:
            return r
        zeros = np.zeros((len(r), 1, xi.dim - d))
        return r, [np.concatenate([-u @ r_i, zeros], axis=-1), np.concatenate([u @ r_j, zeros], axis=-1)]

    return whitened_factor(v, kernel, 1, noise, loss, name, blocks)
