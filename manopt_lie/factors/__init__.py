"""A library of factors with closed-form right Jacobians, for
:class:`~manopt_lie.optim.LeastSquaresProblem` on ``Power(M, n)`` or named
:class:`~manopt_lie.manifolds.Blocks`.

Each constructor returns one :class:`~manopt_lie.optim.Factor`: one residual type over all
of its ``m`` edges, evaluated in one vectorized call, whitened by a noise model
(:mod:`.noise`), with an optional robust ``loss``, a ``name`` and the ``blocks`` of its
slots. Residuals and Jacobians follow CONVENTIONS §3–4: right differences, right
Jacobians in each slot's tangent coordinates (translation first on SE(d)).

=========================  ==================================================  ===========
factor                     residual                                            slots
=========================  ==================================================  ===========
``between_factor``         ``Log(Z⁻¹ X_i⁻¹ X_j)``                              G, G
``prior_factor``           ``Log(X̄⁻¹ X)``                                      G
``rotation_factor``        ``Log(R̃⁻¹ R_iᵀ R_j)``                               SO/SE, SO/SE
``relative_point_factor``  ``(X S)⁻¹ l − z``                                   SE(d), Rᵈ
``range_factor``           ``‖p‖ − ρ``, ``p = (X S)⁻¹ l``                      SE(d), Rᵈ
``bearing_factor``         ``wrap(∠p − β)`` (2-D), ``Bᵀ Log_z(p̂)`` (3-D)        SE(d), Rᵈ
``range_bearing_factor``   ``(‖p‖ − ρ, bearing)``                              SE(d), Rᵈ
``pose_range_factor``      ``‖t_j − t_i‖ − ρ``                                 SE(d), SE(d)
=========================  ==================================================  ===========

See ``docs/factors.md`` for the formulas and an example.
"""

from .landmarks import bearing_factor, pose_range_factor, range_bearing_factor, range_factor, relative_point_factor
from .noise import (
    Covariance,
    Diagonal,
    Gaussian,
    IndefiniteNoiseError,
    Information,
    Isotropic,
    NoiseModel,
    NoiseModelError,
    NoiseShapeError,
    NonFiniteNoiseError,
    Unit,
)
from .relative import between_factor, prior_factor, rotation_factor

__all__ = [
    "between_factor",
    "prior_factor",
    "rotation_factor",
    "relative_point_factor",
    "range_factor",
    "bearing_factor",
    "range_bearing_factor",
    "pose_range_factor",
    "NoiseModel",
    "Gaussian",
    "Information",
    "Covariance",
    "Diagonal",
    "Isotropic",
    "Unit",
    "NoiseModelError",
    "NoiseShapeError",
    "NonFiniteNoiseError",
    "IndefiniteNoiseError",
]
