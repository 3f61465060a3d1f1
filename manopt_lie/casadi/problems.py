"""Problems from symbolic costs and residuals: exact derivatives by CasADi, evaluated on batches.

A cost or residual is written once, for one *edge* — a tuple of points (and optional
numeric data) — with CasADi operations and those of :mod:`.lie`, and summed over the
edges. How a point enters depends on its manifold (:mod:`._spaces`):

* on a **Lie group** (``LieGroupManifold(G)``, ``Power(LieGroupManifold(G), n)``) it is
  the element matrix, and CasADi differentiates through the tangent-space chart of
  each argument, ``f̂(δ₁, …, δₐ) = f(X₁ ⊕ δ₁, …, Xₐ ⊕ δₐ)`` at ``δ = 0``: the
  Riemannian gradient ``∇_δ f̂(0)`` (left-invariant metric, Cartesian coordinates) and
  the pullback Hessian ``∇²_δ f̂(0)``, what ``LieGroupManifold.ehess2rhess`` returns
  (CONVENTIONS §6); for residuals, the right Jacobians ``∂r̂/∂δ_s (0)`` (CONVENTIONS §4);
* on an **embedded manifold** (``Euclidean``, ``Sphere``, ``Stiefel``, ``Grassmann``,
  ``SpecialOrthogonal(n)``, a ``Power`` of one, a ``Product`` of single manifolds) it is
  the point's array, an ``n×1`` column or an ``n×p`` matrix, and CasADi gives the
  Euclidean gradient ``∇f̄(x)`` and Hessian-vector products ``∇²f̄(x)[u]`` of the
  expression as a function of the array's entries; the manifold converts them
  (``egrad2rgrad``, ``ehess2rhess``), as for a hand-written :class:`~manopt_lie.optim.Problem`.

Each edge type becomes one ``casadi.Function`` per output set, mapped over its ``m``
edges (``Function.map``) and called on numpy buffers without copies: point ``i`` enters
as the row-major flattening of its array or matrix, so a C-contiguous stack is passed
as it is.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, cast

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..manifolds import Euclidean, LieGroupManifold, Power
from ..manifolds.base import Manifold
from ..optim import Factor, LeastSquaresProblem, Problem
from ..optim.losses import RobustLoss, Trivial, parse_loss
from ._compile import Compiled, edge_data, edges, expression
from ._spaces import Space, space_of

__all__ = ["SymbolicTerm", "SymbolicFactor", "problem_from_casadi", "least_squares_from_casadi"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SymbolicTerm:
    """One cost type over ``m`` edges: ``Σ_e cost(X[v_e1], …, X[v_ea], *data_e)``.

    Parameters
    ----------
    variables : int array ``(m, arity)``
        The points each edge takes (indices into the ``Power``; ``0`` for a single
        point). A 1-D array means arity 1.
    cost : callable
        ``cost(X_1, …, X_arity, *p)`` on symbolic points (CasADi matrices) and the
        edge's data ``p`` (of each array's trailing shape: ``1×1``, ``a×1`` or
        ``a×b``); returns a ``1×1`` expression.
    data : sequence of arrays ``(m, …)``
        Numeric data per edge (at most two trailing axes).
    name : str
        For messages.
    """

    variables: ArrayLike
    cost: Callable[..., Any]
    data: Sequence[ArrayLike] = ()
    name: str = "term"


@dataclass(frozen=True)
class SymbolicFactor:
    """One residual type over ``m`` edges, as :class:`SymbolicTerm` but ``residual(X_1, …, *p)``
    returns a vector of ``k`` residuals; ``loss`` as in :class:`~manopt_lie.optim.Factor`."""

    variables: ArrayLike
    residual: Callable[..., Any]
    data: Sequence[ArrayLike] = ()
    loss: RobustLoss | str | None = field(default_factory=Trivial)
    name: str = "factor"


def _compile(space: Space, variables: ArrayLike, fn: Any, data: Sequence[ArrayLike], kind: str, name: str,
             jit: bool, symbols: str) -> Compiled:  # fmt: skip
    if space.product:
        k = len(space.parts)
        return Compiled(
            [p.kind for p in space.parts], range(k), [1] * k, np.zeros((1, k), dtype=np.int64), fn,
            edge_data(data, 1, name), kind, name, jit=jit, symbols=symbols,
        )  # fmt: skip
    v = edges(variables, space.n, name)
    part = space.parts[0]
    return Compiled(
        [part.kind] * v.shape[1], [0] * v.shape[1], [space.n], v, fn, edge_data(data, v.shape[0], name),
        kind, name, jit=jit, symbols=symbols,
    )  # fmt: skip


# ---- smooth costs -------------------------------------------------------------------------------


class _ChartEvaluator:
    """Cost, Riemannian gradient and pullback-Hessian products of compiled chart terms.

    The gradient and the per-edge Hessian blocks at the most recent point are
    remembered (keyed on its identity: group elements are immutable), so the many
    Hessian-vector products of a trust-region step cost one gather, one batch of
    small matrix products and one sparse scatter each; gradient-only optimizers
    never evaluate the Hessian.
    """

    def __init__(self, space: Space, terms: list[Compiled]) -> None:
        self.space, self.terms = space, terms
        self._grad: tuple[Any, Any] | None = None
        self._hess: tuple[Any, list[FloatArray]] | None = None

    def cost(self, x: Any) -> float:
        flats = self.space.flats(x)
        return float(sum(float(np.sum(t("value", flats)[0])) for t in self.terms))

    def grad(self, x: Any) -> FloatArray:
        memo = self._grad  # read once: another thread may replace it
        if memo is None or memo[0] is not x:
            flats, acc = self.space.flats(x), self.space.zeros()
            for t in self.terms:
                t.scatter_add(t("gradient", flats)[0], acc)
            memo = self._grad = (x, self.space.shaped(acc))
        return cast(FloatArray, memo[1]).copy()

    def hess(self, x: Any, v: Any) -> FloatArray:
        memo = self._hess
        if memo is None or memo[0] is not x:
            flats = self.space.flats(x)
            blocks = []
            for t in self.terms:
                ad = int(t.offsets[-1])
                blocks.append(t("hessian", flats)[0].reshape(t.m, ad, ad))
            memo = self._hess = (x, blocks)
        rows, acc = self.space.rows(v, "tangent vector"), self.space.zeros()
        for t, h in zip(self.terms, memo[1], strict=True):
            local = np.concatenate(t.gather(rows), axis=1)[:, :, None]  # (m, a·d, 1)
            t.scatter_add(np.matmul(h, local)[:, :, 0], acc)
        return cast(FloatArray, self.space.shaped(acc))


class _AmbientEvaluator:
    """Cost, Euclidean gradient and Euclidean Hessian-vector products of compiled ambient terms
    (the :class:`~manopt_lie.optim.Problem` remembers the gradient of the last point)."""

    def __init__(self, space: Space, terms: list[Compiled]) -> None:
        self.space, self.terms = space, terms

    def cost(self, x: Any) -> float:
        flats = self.space.flats(x)
        return float(sum(float(np.sum(t("value", flats)[0])) for t in self.terms))

    def egrad(self, x: Any) -> Any:
        flats, acc = self.space.flats(x), self.space.zeros()
        for t in self.terms:
            t.scatter_add(t("gradient", flats)[0], acc)
        return self.space.shaped(acc)

    def ehess(self, x: Any, u: Any) -> Any:
        flats, rows, acc = self.space.flats(x), self.space.rows(u, "ambient direction"), self.space.zeros()
        for t in self.terms:
            t.scatter_add(t("hvp", flats, rows)[0], acc)
        return self.space.shaped(acc)


def _as_list(items: Any, kind: type, caller: str) -> list[Any]:
    if not isinstance(items, (list, tuple)):
        what = "cost" if kind is SymbolicTerm else "residual"
        raise TypeError(
            f"{caller}: the {what} must be callable or a list of {kind.__name__}s, got {type(items).__name__}"
        )
    out = []
    for item in items:
        if isinstance(item, kind):
            out.append(item)
        elif isinstance(item, tuple):
            out.append(kind(*item))
        else:
            raise TypeError(f"{caller}: expected {kind.__name__} instances or tuples, got {type(item).__name__}")
    if not out:
        raise ValueError(f"{caller}: no {kind.__name__}s given")
    return out


def _terms(space: Space, cost: Any, variables: Any, data: Sequence[ArrayLike], name: str) -> list[SymbolicTerm]:
    if isinstance(cost, SymbolicTerm):
        cost = [cost]
    if callable(cost):
        if space.product and variables is not None:
            raise ValueError("problem_from_casadi: on a Product the cost takes one argument per factor; no variables")
        edges_ = np.zeros((1, 1), dtype=np.int64) if space.product else np.arange(space.n)[:, None]
        return [SymbolicTerm(edges_ if variables is None else variables, cost, data, name)]
    if variables is not None or len(data):
        raise ValueError("problem_from_casadi: with SymbolicTerms, give variables and data in each term")
    if space.product:
        raise TypeError("problem_from_casadi: on a Product, give one cost function of all factors")
    return _as_list(cost, SymbolicTerm, "problem_from_casadi")


def problem_from_casadi(
    manifold: Manifold,
    cost: Callable[..., Any] | Sequence[SymbolicTerm],
    *,
    variables: ArrayLike | None = None,
    data: Sequence[ArrayLike] = (),
    name: str = "cost",
    jit: bool = False,
    symbols: str = "auto",
) -> Problem:
    """A :class:`~manopt_lie.optim.Problem` from a symbolic cost, with CasADi's exact
    gradient and Hessian, on any manifold of the library.

    The cost is a sum over edges of a function of a few points,
    ``f(x) = Σ_e cost(X[v_e1], …, X[v_ea], *data_e)`` (on one point, or on a
    product, a single edge). The function receives each point as a CasADi matrix:

    ============================================  =========================================
    manifold                                      argument
    ============================================  =========================================
    ``Euclidean(n)``, ``Sphere(n)``               ``n×1`` column
    ``Euclidean(m, n)``, ``Stiefel(n, p)``,       ``m×n`` / ``n×p`` matrix
    ``Grassmann(n, p)``, ``SpecialOrthogonal(n)``
    ``LieGroupManifold(G)``                       the element matrix (``Rn(n)``: ``n×1``)
    ``Product(M₁, M₂, …)``                        one argument per factor, as above
    ``Power(M, n)``                               the points of an edge, each as for ``M``
    ============================================  =========================================

    On a Lie group (alone or a ``Power`` of it) the derivatives are those of the chart
    ``f̂_e(δ) = cost(X₁ ⊕ δ₁, …, Xₐ ⊕ δₐ)``::

        grad f(x) = Σ_e scatter(∇_δ f̂_e(0)),   Hess f(x)[v] = Σ_e scatter(∇²_δ f̂_e(0) v_e),

    the Hessian being that of the pullback ``δ ↦ f(x ⊕ δ)`` (CONVENTIONS §6). On the
    others the expression is differentiated in the point's entries, ``G = ∇f̄(x)`` and
    ``∇²f̄(x)[u]`` (forward over reverse, never a matrix), and the manifold converts them:
    ``grad f(x) = egrad2rgrad(x, G)``, ``Hess f(x)[v] = ehess2rhess(x, G, ∇²f̄(x)[v], v)``
    (a product's Lie-group factors through their matrix embedding).

    Parameters
    ----------
    manifold : Manifold
        One of the table above; ``Power(M, n)`` with an integer ``n``.
    cost : callable or sequence of SymbolicTerm
        ``cost(X_1, …, X_a, *p)``: symbolic points and the edge's data in, a ``1×1``
        expression out. Or several edge types, each a :class:`SymbolicTerm` (then
        ``variables`` and ``data`` stay unset; not on a ``Product``).
    variables : int array ``(m, a)``, optional
        The points of each edge of a ``Power``. Default: each point on its own
        (``arange(n)[:, None]``), so the cost is a function of *one* point summed over
        the ``n`` — the mapped, full-speed path. A function of all ``n`` points at once
        is ``variables=[range(n)]`` (one edge of ``n`` arguments; its graph grows with ``n``).
    data : sequence of arrays ``(m, …)``
        Numeric data per edge, passed to ``cost`` after the points (first axis 1 on a
        single point or a product). Constants shared by every edge can simply be closed over.
    name : str
        For messages.
    jit : bool
        Compile the functions to machine code with ``gcc`` (CasADi's ``"shell"``
        compiler; ``gcc`` must be on the ``PATH``): 2–5x faster evaluations for
        ~0.1–0.5 s of compilation per function.
    symbols : {"auto", "SX", "MX"}
        CasADi's scalar (``SX``) or matrix (``MX``) symbols. ``"auto"``: ``MX`` once a
        point has more than 100 entries (a dense ``A @ x`` stays one operation), ``SX``
        otherwise (fastest for small points).

    Returns
    -------
    Problem
        With ``rgrad`` and ``rhess`` (Lie groups; gradients of shape ``(d,)`` or
        ``(n, d)``), or with ``egrad`` and ``ehess`` (the others).

    Raises
    ------
    TypeError
        For an unsupported manifold, a non-callable cost or a result that is not a
        CasADi expression (a numeric function applied to symbols raises what it raises).
    ValueError
        For a non-scalar cost, free symbols, or malformed variables or data
        (``ShapeError``, ``NonFiniteError``).
    """
    space = space_of(manifold, "problem_from_casadi")
    terms = _terms(space, cost, variables, data, name)
    compiled = [_compile(space, t.variables, t.cost, t.data, "cost", t.name, jit, symbols) for t in terms]
    if space.chart:
        chart = _ChartEvaluator(space, compiled)
        return Problem(manifold, chart.cost, rgrad=chart.grad, rhess=chart.hess)
    ambient = _AmbientEvaluator(space, compiled)
    return Problem(manifold, ambient.cost, egrad=ambient.egrad, ehess=ambient.ehess)


# ---- least squares ------------------------------------------------------------------------------


def _factor(space: Space, f: SymbolicFactor, jit: bool, symbols: str) -> tuple[Factor, Compiled]:
    c = _compile(space, f.variables, f.residual, f.data, "residual", f.name, jit, symbols)
    m, arity = c.variables.shape
    part, d = space.parts[0], space.parts[0].kind.dim

    def residual(*points: Any, jac: bool = False) -> Any:
        if len(points) != arity:
            raise TypeError(f"{f.name}: expected {arity} point batches, got {len(points)}")
        flats = [part.flat(p, f"{f.name}: point batch", (m,)) for p in points]
        if not jac:
            return c.function("value")(*flats, *c.data)[0]
        r, j = c.function("jacobian")(*flats, *c.data)
        j = j.reshape(m, c.k, arity * d)
        return r, [j[..., s * d : (s + 1) * d] for s in range(arity)]

    return Factor(c.variables, residual, f.loss, f.name), c


def _fixed_hessian(
    hess: Callable[[Any, Any], FloatArray], fixed: NDArray[np.bool_]
) -> Callable[[Any, Any], FloatArray]:
    """``H`` restricted to the free variables, the identity on the fixed ones (as the Gauss-Newton model)."""

    def product(x: Any, v: Any) -> FloatArray:
        vv = np.where(fixed[:, None], 0.0, v)
        return np.where(fixed[:, None], v, hess(x, vv))

    return product


def _least_squares_space(manifold: Any) -> Space:
    caller = "least_squares_from_casadi"
    if not isinstance(manifold, Power):
        raise TypeError(
            f"{caller}: need Power(LieGroupManifold(G), n) or Power(Euclidean(d), n) "
            f"(use n = 1 for a single element), got {manifold!r}"
        )
    space = space_of(manifold, caller)
    base = space.parts[0].base
    vector = isinstance(base, Euclidean) and len(base.point_shape) == 1
    if not (space.chart or vector or isinstance(base, LieGroupManifold)):
        raise TypeError(
            f"{caller}: least squares need tangent coordinates: Power(LieGroupManifold(G), n) or "
            f"Power(Euclidean(d), n), got {manifold!r} (use problem_from_casadi with ½‖r‖² as the cost)"
        )
    return space


def least_squares_from_casadi(
    manifold: Power,
    variables: ArrayLike | Sequence[SymbolicFactor],
    residual: Callable[..., Any] | None = None,
    *,
    data: Sequence[ArrayLike] = (),
    loss: RobustLoss | str | None = None,
    fixed: Sequence[int] | NDArray[Any] = (),
    exact_hessian: bool = False,
    name: str = "factor",
    jit: bool = False,
    symbols: str = "auto",
) -> LeastSquaresProblem:
    """A :class:`~manopt_lie.optim.LeastSquaresProblem` from symbolic residuals, with
    CasADi's right Jacobians.

    ``f(x) = ½ Σ_factors Σ_e ρ(‖r_e‖²)`` with, per edge, ``r_e = residual(X[v_e1], …, *data_e)``
    and the right Jacobians ``J_s = ∂/∂δ_s residual(X₁ ⊕ δ₁, …)|_{δ=0}`` (CONVENTIONS §4;
    on ``Euclidean(d)`` the ordinary Jacobians), all edges of a factor type evaluated by
    one mapped ``casadi.Function``.

    Parameters
    ----------
    manifold : Power
        ``Power(LieGroupManifold(G), n)``, ``G`` a group with a symbolic twin or
        ``Rn(d)``, or ``Power(Euclidean(d), n)`` (``n = 1`` for a single point).
    variables : int array ``(m, a)``, or sequence of SymbolicFactor
        The points of each edge; or several factor types (then ``residual``,
        ``data`` and ``loss`` stay unset). Tuples ``(variables, residual, …)``
        are read as ``SymbolicFactor(*tuple)``.
    residual : callable
        ``residual(X_1, …, X_a, *p)``: symbolic points and the edge's data in,
        a vector of ``k`` residuals out.
    data : sequence of arrays ``(m, …)``
        Numeric data per edge.
    loss : RobustLoss, str or None
        Robust loss of the factor (plain least squares by default).
    fixed : int array
        Variables held constant (passed to ``LeastSquaresProblem``).
    exact_hessian : bool
        Give :meth:`~manopt_lie.optim.Problem.hess` the exact pullback Hessian
        of the cost (CasADi's, including the residuals' curvature) instead of
        the Gauss-Newton model ``JᵀJ``; for the trust region on problems with
        large residuals. Plain least squares only.
    name : str
        For messages.
    jit, symbols
        As in :func:`problem_from_casadi`.

    Raises
    ------
    TypeError, ValueError
        As :func:`problem_from_casadi`; also for a residual that is not a
        vector, a manifold without vector tangents, or ``exact_hessian`` with a robust loss.
    """
    space = _least_squares_space(manifold)
    if isinstance(variables, SymbolicFactor):
        variables = [variables]
    if residual is not None:
        factors = [SymbolicFactor(cast(ArrayLike, variables), residual, data, loss, name)]
    else:
        if len(data) or loss is not None:
            raise ValueError("least_squares_from_casadi: with SymbolicFactors, give data and loss in each factor")
        if isinstance(variables, np.ndarray):
            raise TypeError("least_squares_from_casadi: give the residual function after the variables")
        factors = _as_list(variables, SymbolicFactor, "least_squares_from_casadi")
    built = [_factor(space, f, jit, symbols) for f in factors]
    hessian = None
    if exact_hessian:
        if any(not isinstance(parse_loss(f.loss), Trivial) for f in factors):
            raise ValueError("least_squares_from_casadi: exact_hessian=True needs plain least squares (no robust loss)")
        terms = [
            _compile(space, c.variables, _half_norm2(f.residual, c.sym), f.data, "cost", f.name, jit, symbols)
            for f, (_, c) in zip(factors, built, strict=True)
        ]
        keep = np.zeros(space.n, dtype=bool)
        keep[np.asarray(fixed, dtype=np.int64)] = True
        hess = _ChartEvaluator(space, terms).hess if space.chart else _AmbientEvaluator(space, terms).ehess
        hessian = _fixed_hessian(hess, keep)
    return LeastSquaresProblem(manifold, [b[0] for b in built], fixed=fixed, hessian=hessian)


def _half_norm2(residual: Callable[..., Any], sym: type) -> Callable[..., Any]:
    def cost(*args: Any) -> Any:
        r = ca.vec(expression(residual(*args), "residual", "residual", sym))
        return 0.5 * ca.sumsqr(r)

    return cost
