"""Preconditioners of the trust region's truncated CG, chosen by name and built once per run.

A preconditioner is a symmetric positive definite operator ``P ≈ H⁻¹`` on
tangent vectors, applied as ``z = P(x, r)``. The named ones come from the
Gauss-Newton matrix ``G = JᵀWJ`` of a :class:`LeastSquaresProblem` at the
current point:

* ``"gauss-newton"``: ``P = G⁻¹`` by a sparse Cholesky factorization, whose
  symbolic analysis is done once per run and whose numeric factorization is
  redone once per outer iteration (the point changes only then);
* ``"block-jacobi"``: ``P = blkdiag(G_vv)⁻¹``, the inverse of each variable's
  diagonal block: no fill-in, for graphs whose factor is dense;
* ``"identity"``: no preconditioning;
* ``"auto"``: for a least-squares problem ``"gauss-newton"``, or ``"block-jacobi"`` where the
  factor of ``G`` would be nearly dense (as its analysis predicts,
  :func:`~manopt_lie.linalg.fill.prefers_iterative`:
  rotation averaging on a well-connected graph, where one factorization costs a second and
  the trust region converges as fast without it); ``"identity"`` otherwise.

The per-point state (the factorization and the point it belongs to) lives in
the object :func:`bind_preconditioner` makes for one run, never in the
optimizer or the problem, so concurrent runs do not share it.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..linalg import CholeskySolver, block_jacobi
from ..linalg.fill import prefers_iterative
from ._values import same_point, snapshot
from .least_squares_problem import LeastSquaresProblem
from .problem import Problem

__all__ = ["PRECONDITIONERS", "Preconditioner", "bind_preconditioner", "check_preconditioner", "from_gauss_newton"]

Preconditioner = Callable[[Any, Any], Any]
"""A preconditioner given as a function ``(x, v) -> P⁻¹v``: at the point ``x``, a tangent
vector ``v`` mapped by a symmetric positive definite approximation of the inverse Hessian."""
PRECONDITIONERS = ("auto", "gauss-newton", "block-jacobi", "identity")
"""The preconditioners ``TrustRegion(preconditioner=…)`` accepts by name; ``"auto"`` picks
Gauss-Newton (a Cholesky factor of ``JᵀJ``) on least-squares problems — block-Jacobi where
that factor would be nearly dense — and identity otherwise."""
_NEED_LEAST_SQUARES = ("gauss-newton", "block-jacobi")


def check_preconditioner(spec: str | Preconditioner, owner: str = "TrustRegion") -> str | Preconditioner:
    """``spec`` if it is one of :data:`PRECONDITIONERS` or a callable ``(x, r) ↦ z``.

    Raises
    ------
    ValueError
        On an unknown name (listing the choices).
    TypeError
        If ``spec`` is neither a string nor callable.
    """
    if isinstance(spec, str):
        if spec not in PRECONDITIONERS:
            raise ValueError(f"{owner}: unknown preconditioner {spec!r}; choose from {', '.join(PRECONDITIONERS)}")
    elif not callable(spec):
        raise TypeError(
            f"{owner}: preconditioner must be one of {', '.join(PRECONDITIONERS)} or a callable (x, r) -> z, "
            f"got {type(spec).__name__}"
        )
    return spec


def bind_preconditioner(
    spec: str | Preconditioner, problem: Problem, owner: str = "TrustRegion"
) -> Preconditioner | None:
    """The preconditioner of one run on ``problem`` (``None``: the identity).

    Raises
    ------
    ValueError
        If a named preconditioner built from ``JᵀWJ`` is asked for on a problem
        that is not a :class:`LeastSquaresProblem`.
    """
    if not isinstance(spec, str):
        return spec
    if spec == "auto":
        if isinstance(problem, LeastSquaresProblem):
            return _Auto(problem)
        spec = "identity"
    if spec == "identity":
        return None
    if not isinstance(problem, LeastSquaresProblem):
        raise ValueError(
            f"{owner}: preconditioner={spec!r} is built from the Gauss-Newton matrix JᵀWJ of a "
            f"LeastSquaresProblem, but the problem is a {type(problem).__name__}; use 'identity', 'auto' "
            "or a callable (x, r) -> z"
        )
    return _GaussNewton(problem) if spec == "gauss-newton" else _BlockJacobi(problem)


def from_gauss_newton(preconditioner: Preconditioner | None) -> bool:
    """Whether a preconditioner bound by :func:`bind_preconditioner` is built from ``G = JᵀWJ``
    (Gauss-Newton or block-Jacobi): its norm ``√(ηᵀP⁻¹η)`` is then in units of the cost's square root."""
    return isinstance(preconditioner, _PerPoint)


class _PerPoint(ABC):
    """Built from ``G = JᵀWJ`` at ``x``, rebuilt when the value of ``x`` changes (a new
    outer iteration; keyed on a private copy, like the problem's own caches)."""

    def __init__(self, problem: LeastSquaresProblem) -> None:
        self._problem = problem
        self._x: Any = None

    def __call__(self, x: Any, r: Any) -> NDArray[np.float64]:
        if self._x is None or not same_point(self._x, x):
            self._x = None  # a failed rebuild leaves nothing stale behind
            self._build(self._problem.linearize(x).hessian)
            self._x = snapshot(x)
        r_ = np.asarray(r)
        return self._apply(r_.reshape(-1)).reshape(r_.shape)

    @abstractmethod
    def _build(self, G: sp.csc_matrix) -> None: ...

    @abstractmethod
    def _apply(self, r: NDArray[np.float64]) -> NDArray[np.float64]: ...


class _GaussNewton(_PerPoint):
    """``z = G⁻¹r``: one numeric factorization per point, the analysis once per run."""

    def __init__(self, problem: LeastSquaresProblem) -> None:
        super().__init__(problem)
        self._solver = CholeskySolver()

    def _analyze(self, G: sp.csc_matrix) -> CholeskySolver:
        """The solver, its analysis of ``G``'s pattern done (once per run)."""
        if self._solver.n_analyses == 0 and self._problem.structure is not None:
            self._solver = self._solver.bind(self._problem.structure)  # its pattern needs no symmetry check
        if not self._solver.matches(G):
            self._solver.analyze(G)
        return self._solver

    def _build(self, G: sp.csc_matrix) -> None:
        self._analyze(G).factorize(G)

    def _apply(self, r: NDArray[np.float64]) -> NDArray[np.float64]:
        return self._solver.solve(r)


class _BlockJacobi(_PerPoint):
    """``z = blkdiag(G_vv)⁻¹ r`` with the variables' blocks of the problem's structure."""

    _M: sp.csr_matrix

    def _build(self, G: sp.csc_matrix) -> None:
        structure = self._problem.structure
        assert structure is not None  # linearize built it
        self._M = block_jacobi(G, structure.dims)

    def _apply(self, r: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(self._M @ r, dtype=np.float64)


class _Auto(_PerPoint):
    """:class:`_GaussNewton`, or :class:`_BlockJacobi` where the analysis of ``G`` predicts a
    nearly dense factor: chosen at the first build."""

    _chosen: _PerPoint | None = None

    def _build(self, G: sp.csc_matrix) -> None:
        if self._chosen is None:
            gauss_newton = _GaussNewton(self._problem)
            cost = gauss_newton._analyze(G).factor_cost
            self._chosen = _BlockJacobi(self._problem) if prefers_iterative(cost, G.nnz) else gauss_newton
        self._chosen._build(G)

    def _apply(self, r: NDArray[np.float64]) -> NDArray[np.float64]:
        assert self._chosen is not None
        return self._chosen._apply(r)
