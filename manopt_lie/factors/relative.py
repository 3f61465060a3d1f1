"""Factors on group-valued variables: between (relative pose), prior, and rotation-only
relative factors, for any :class:`~manopt_lie.lie.LieGroup`.

All residuals are right differences ``Y ⊖ X = Log(X⁻¹Y)`` (CONVENTIONS §3) and all
Jacobians right Jacobians in each slot's tangent coordinates (CONVENTIONS §4), written
from the group's public API only (``between``, ``log``, ``jr_inv``, ``adjoint``), so any
group with that API works: SO(2), SO(3), SE(2), SE(3), Rⁿ, Sim(3), SE₂(3), …
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..lie import LieGroup
from ..optim import Factor
from ._common import Blocks, Loss, as_group, edges, group_measurements, whitened_factor
from ._poses import FUSED_GROUPS, between_kernel
from .noise import NoiseModel, Unit, as_noise_model

__all__ = ["between_factor", "prior_factor", "rotation_factor"]


def _between(xi: LieGroup, xj: LieGroup, z_inv: LieGroup, jac: bool) -> Any:
    """``r = Log(Z⁻¹ X_i⁻¹ X_j)``; ``∂r/∂X_j = Jr⁻¹(r)``, ``∂r/∂X_i = −Jr⁻¹(r) Ad_{(X_i⁻¹X_j)⁻¹}``."""
    y = xi.between(xj)
    r = (z_inv @ y).log()
    if not jac:
        return r
    j_j = type(y).jr_inv(r)
    return r, [-j_j @ y.inverse().adjoint(), j_j]


def between_factor(
    variables: ArrayLike,
    measured: LieGroup,
    noise: NoiseModel | None = None,
    *,
    loss: Loss = None,
    name: str = "between",
    blocks: Blocks = None,
) -> Factor:
    r"""Relative measurements ``Z_e ≈ X_i⁻¹ X_j`` on any Lie group (GTSAM's ``BetweenFactor``).

    .. math::

        r_e = \operatorname{Log}(Z_e^{-1} X_i^{-1} X_j), \qquad
        \frac{\partial r}{\partial X_j} = J_r^{-1}(r), \qquad
        \frac{\partial r}{\partial X_i} = -J_r^{-1}(r)\, \operatorname{Ad}_{(X_i^{-1} X_j)^{-1}}

    — the geodesic pose-graph residual of CONVENTIONS §8 on SE(d) (whitened by
    ``Information(Ω)`` it equals ``problems.costs.geodesic_factor``).

    Parameters
    ----------
    variables : int array ``(m, 2)``
        ``(i, j)`` per edge.
    measured : LieGroup, batch shape ``(m,)`` or ``()`` (shared)
        ``Z_e``; its group is the variables' group. For ``Rn(d)`` the variables may also
        be plain vectors (points of ``Euclidean(d)``).
    noise : NoiseModel, optional
        Of dimension ``G.dim`` in the group's tangent order (translation first on SE(d)).
        ``None``: unit noise.
    loss, name, blocks
        Forwarded to :class:`~manopt_lie.optim.Factor`.

    Returns
    -------
    Factor
        Whitened residuals ``(m, G.dim)`` and Jacobians ``(m, G.dim, G.dim)`` per slot.
    """
    v = edges(variables, 2, name)
    z = group_measurements(measured, len(v), name)
    group, z_inv = type(z), z.inverse()
    if group in FUSED_GROUPS:  # SE(2), SE(3): one fused pass, whitening included (``_poses``)
        model = as_noise_model(noise, len(v), group.dim, name)
        sqrt_info = None
        if not isinstance(model, Unit):  # one matrix for every edge where there is one: one product
            common = model.common_sqrt_information
            sqrt_info = np.ascontiguousarray(model.sqrt_information if common is None else common)
        fused = between_kernel(group, np.ascontiguousarray(z_inv.as_matrix()), sqrt_info)

        def residual(xi: Any, xj: Any, jac: bool = False) -> Any:
            return fused(as_group(xi, group, name), as_group(xj, group, name), jac)

        residual.native_between = fused.native_between  # type: ignore[attr-defined]  # for optim._small_system
        return Factor(v, residual, loss=loss, name=name, blocks=blocks, fresh_jacobians=True,
                      residual_dim=group.dim)

    def kernel(xi: Any, xj: Any, jac: bool = False) -> Any:
        return _between(as_group(xi, group, name), as_group(xj, group, name), z_inv, jac)

    return whitened_factor(v, kernel, group.dim, noise, loss, name, blocks)


def prior_factor(
    variables: ArrayLike,
    measured: LieGroup,
    noise: NoiseModel | None = None,
    *,
    loss: Loss = None,
    name: str = "prior",
    blocks: Blocks = None,
) -> Factor:
    r"""A prior ``X ≈ X̄`` on any Lie group (GTSAM's ``PriorFactor``).

    .. math::

        r_e = X \ominus \bar X = \operatorname{Log}(\bar X^{-1} X), \qquad
        \frac{\partial r}{\partial X} = J_r^{-1}(r)

    Parameters
    ----------
    variables : int array ``(m,)`` or ``(m, 1)``
    measured : LieGroup, batch shape ``(m,)`` or ``()`` (shared)
        ``X̄``. For ``Rn(d)`` the variables may also be plain vectors (``Euclidean(d)``),
        e.g. landmark priors.
    noise : NoiseModel, optional
        Of dimension ``G.dim``, in the tangent order; ``None``: unit noise.
    loss, name, blocks
        Forwarded to :class:`~manopt_lie.optim.Factor`.
    """
    v = edges(variables, 1, name)
    mean = group_measurements(measured, len(v), name)
    group = type(mean)

    def kernel(x: Any, jac: bool = False) -> Any:
        r = as_group(x, group, name).rminus(mean)
        return (r, [group.jr_inv(r)]) if jac else r

    return whitened_factor(v, kernel, group.dim, noise, loss, name, blocks)


def rotation_factor(
    variables: ArrayLike,
    measured: LieGroup,
    noise: NoiseModel | None = None,
    *,
    loss: Loss = None,
    name: str = "rotation",
    blocks: Blocks = None,
) -> Factor:
    r"""Relative rotations ``R̃_e ≈ R_iᵀ R_j`` between rotations or between the rotation parts
    of poses.

    .. math::

        r_e = \operatorname{Log}(\tilde R_e^{-1} R_i^\top R_j), \qquad
        \frac{\partial r}{\partial \theta_j} = J_r^{-1}(r), \qquad
        \frac{\partial r}{\partial \theta_i} = -J_r^{-1}(r)\, R_j^\top R_i

    (``R_jᵀR_i = Ad_{(R_iᵀR_j)⁻¹}``; ``1`` on SO(2)). On SO(d) variables it is
    :func:`between_factor`. On SE(d) poses the Jacobians are on the full pose tangent
    ``(ρ, θ)``: zero on the translation columns, the above on the rotation ones (a right
    perturbation ``X·Exp(ρ, θ)`` turns ``R`` into ``R·Exp(θ)``).
    Which case applies is read from the points' group at each call.

    Parameters
    ----------
    variables : int array ``(m, 2)``
    measured : SO2 or SO3 element, batch shape ``(m,)`` or ``()`` (shared)
    noise : NoiseModel, optional
        Of dimension 1 (2-D) or 3 (3-D); ``None``: unit noise.
    loss, name, blocks
        Forwarded to :class:`~manopt_lie.optim.Factor`.
    """
    v = edges(variables, 2, name)
    z = group_measurements(measured, len(v), name)
    rotations, z_inv = type(z), z.inverse()

    def kernel(xi: Any, xj: Any, jac: bool = False) -> Any:
        if isinstance(xi, rotations):
            return _between(xi, as_group(xj, rotations, name), z_inv, jac)
        if getattr(type(xi), "rotation_group", None) is not rotations or type(xj) is not type(xi):
            raise TypeError(
                f"{name}: expected {rotations.__name__} rotations or poses with {rotations.__name__} rotations, "
                f"got {type(xi).__name__} and {type(xj).__name__}"
            )
        out = _between(xi.rotation(), xj.rotation(), z_inv, jac)  # type: ignore[attr-defined]
        if not jac:
            return out
        r, (j_i, j_j) = out
        pad = np.zeros((len(r), rotations.dim, type(xi).dim - rotations.dim))  # translation columns first
        return r, [np.concatenate([pad, j_i], axis=-1), np.concatenate([pad, j_j], axis=-1)]

    return whitened_factor(v, kernel, rotations.dim, noise, loss, name, blocks)
