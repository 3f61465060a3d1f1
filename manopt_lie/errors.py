"""Exceptions raised on bad input (all are ``ValueError`` subclasses, CONVENTIONS §7)."""

from __future__ import annotations

__all__ = [
    "ShapeError",
    "NonFiniteError",
    "NotOnManifoldError",
    "NotInGroupError",
    "IndefiniteMatrixError",
    "RangeError",
]


class ShapeError(ValueError):
    """An array does not have the shape an operation needs.

    The message names the argument, the expected shape (``...`` for any batch
    axes) and the actual shape.
    """


class NonFiniteError(ValueError):
    """An input holds ``nan`` or ``inf``."""


class NotOnManifoldError(ValueError):
    """A point violates a manifold's constraint (``‖x‖ = 1``, ``XᵀX = I``, …)."""


class NotInGroupError(NotOnManifoldError):
    """A matrix is not an element of the group (not orthonormal, a reflection,
    or a homogeneous matrix whose last row is not ``[0, ..., 0, 1]``)."""


class IndefiniteMatrixError(ValueError):
    """A covariance or information matrix is not symmetric positive (semi)definite."""


class RangeError(ValueError):
    """A finite input whose result is not representable in float64 (e.g. a Sim(3) log-scale
    σ beyond ±700, whose scale e^σ overflows or underflows)."""
