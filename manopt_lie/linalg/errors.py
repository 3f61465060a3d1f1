"""Exceptions of the sparse linear algebra (``ValueError`` subclasses, like the package's others)."""

from __future__ import annotations

__all__ = ["SingularSystemError"]

_ADVICE = (
    "The normal equations are singular or indefinite: if this is a pose graph or another "
    "problem with a gauge freedom, fix the gauge (anchor one pose or add a prior factor). "
    "No step was returned: the solvers never return a garbage step."
)


class SingularSystemError(ValueError):
    """The linear system ``H x = b`` is singular, indefinite or numerically so.

    Raised when the factorization fails, when a random probe ``H⁻¹z`` or the
    solution itself fails the residual check ``‖Hx − b‖ ≤ rtol·‖b‖``, is not
    finite, or shows non-positive curvature (``bᵀx ≤ 0``), and by PCG on
    ``pᵀHp ≤ 0`` or a non-positive-definite diagonal block. The message says
    what was detected and how to fix the usual cause: an unfixed gauge.
    """

    def __init__(self, detail: str) -> None:
        super().__init__(f"{detail}. {_ADVICE}")
