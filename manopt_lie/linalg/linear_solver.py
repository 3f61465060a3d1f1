"""The protocol of the linear solvers behind Gauss-Newton and Levenberg-Marquardt, and their names.

A least-squares step solves the normal equations ``H δ = −g`` with
``H = JᵀWJ (+ λD)`` sparse, symmetric positive definite and of a pattern fixed
by the problem's :class:`BlockStructure`. A :class:`LinearSolver` is configured
once (a *template*, e.g. ``PCGSolver(tol=1e-8)``) and :meth:`LinearSolver.bind`
makes a fresh solver for one run on one structure, so the state a solver keeps
between the solves of a run (a symbolic factorization, block sizes, the numbers
of its last solve) never leaks into another run::

    template = get_linear_solver("pcg")      # or "cholesky", or an instance
    solver = template.bind(structure)        # once per run
    delta = solver(H, -g)                    # every iteration
    history_extras = dict(solver.stats)      # e.g. {"linear_iterations": 12.0, ...}
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from .cholesky import CholeskySolver
from .fill import AutoSolver
from .pcg import PCGSolver

if TYPE_CHECKING:
    from .structure import BlockStructure

__all__ = ["LINEAR_SOLVERS", "LinearSolver", "get_linear_solver"]

FloatArray = NDArray[np.float64]


@runtime_checkable
class LinearSolver(Protocol):
    """Solves ``H x = b`` for the sparse SPD normal equations of one least-squares run.

    Three members:

    * ``bind(structure) -> LinearSolver``: a fresh solver, with no state from
      earlier runs, for systems of this :class:`BlockStructure` (its
      ``dims`` are the variables' block sizes, e.g. for a block-Jacobi
      preconditioner). Called once per ``solve`` run; the template is not modified.
    * ``solver(H, b) -> x``: ``x ≈ H⁻¹b``, shape ``(n,)``, for a
      ``scipy.sparse.csc_matrix`` ``H`` of the structure's pattern. A solver that
      cannot return a usable ``x`` (a singular or indefinite ``H``) raises
      :class:`~manopt_lie.linalg.SingularSystemError`; an iterative one may
      return an inexact ``x`` and say so in ``stats``.
    * ``stats``: numbers about the last call (``str → float``), recorded in the
      optimizer's history (empty for a direct solver).

    :class:`CholeskySolver`, :class:`PCGSolver` and :class:`AutoSolver` implement it.
    """

    def bind(self, structure: BlockStructure) -> LinearSolver:
        """A fresh solver for systems of ``structure``'s pattern (the template is left unchanged)."""
        ...

    def __call__(self, H: sp.csc_matrix, b: FloatArray) -> FloatArray: ...

    @property
    def stats(self) -> Mapping[str, float]:
        """Numbers about the last solve (e.g. PCG's iterations and residual), empty for a direct solver."""
        ...


LINEAR_SOLVERS: dict[str, Callable[[], LinearSolver]] = {
    "auto": AutoSolver,  # Cholesky, or PCG first where the factor would be nearly dense (the default)
    "cholesky": CholeskySolver,  # sparse Cholesky, symbolic analysis reused
    "pcg": PCGSolver,  # conjugate gradients preconditioned by the variables' diagonal blocks
}
"""The linear solvers by name, as ``linear_solver="auto" | "cholesky" | "pcg"`` selects them in
``GaussNewton``/``LevenbergMarquardt`` (see :func:`get_linear_solver`)."""


def get_linear_solver(spec: str | LinearSolver | None = None) -> LinearSolver:
    """The linear-solver template ``spec`` names.

    Parameters
    ----------
    spec : {"auto", "cholesky", "pcg"}, LinearSolver or None
        A name of :data:`LINEAR_SOLVERS` (with its default settings), an
        instance used as the template, or ``None`` for ``"auto"``.

    Raises
    ------
    ValueError
        On an unknown name (listing the choices).
    TypeError
        If ``spec`` is neither a name nor a :class:`LinearSolver`.
    """
    if spec is None:
        spec = "auto"
    if isinstance(spec, str):
        if spec not in LINEAR_SOLVERS:
            raise ValueError(f"unknown linear solver {spec!r}; choose from {', '.join(LINEAR_SOLVERS)}")
        return LINEAR_SOLVERS[spec]()
    if isinstance(spec, type):  # a class passes the structural check, but bind() needs an instance
        raise TypeError(f"linear_solver: pass an instance, e.g. {spec.__name__}(), not the class")
    if not isinstance(spec, LinearSolver):
        raise TypeError(
            f"linear_solver must be one of {', '.join(LINEAR_SOLVERS)} or an object with bind(structure), "
            f"__call__(H, b) and stats (see manopt_lie.linalg.LinearSolver), got {type(spec).__name__}"
        )
    return spec
