"""Problems from symbolic costs and residuals: exact derivatives by CasADi, evaluated on batches.

A cost or residual is written once, for one *edge* — a tuple of group elements
(and optional numeric data) — with the operations of :mod:`.lie`. CasADi
differentiates it through the tangent-space chart of each argument,

    f̂(δ₁, …, δₐ) = f(X₁ ⊕ δ₁, …, Xₐ ⊕ δₐ),   X ⊕ δ = X·Exp(δ),

at ``δ = 0``, which gives exactly what the Riemannian layer uses (CONVENTIONS §6):

* the Riemannian gradient ``grad f(X) = ∇_δ f̂(0)`` (left-invariant metric, Cartesian coordinates);
* the Hessian of the pullback ``∇²_δ f̂(0)``, what ``LieGroupManifold.ehess2rhess`` returns;
* for residuals, the right Jacobians ``J_s = ∂r̂/∂δ_s (0)`` (CONVENTIONS §4).

Each edge type becomes one ``casadi.Function`` per output set, mapped over its
``m`` edges (``Function.map``) and called on numpy buffers without copies
(``Function.buffer``): element ``i`` enters as the row-major flattening of its
matrix, so a C-contiguous ``(m, k, k)`` stack is passed as it is.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from math import prod
from typing import Any, cast

import casadi as ca
import numpy as np
import scipy.sparse
from numpy.typing import ArrayLike, NDArray

from ..errors import NonFiniteError, ShapeError
from ..lie import LieGroup
from ..manifolds import LieGroupManifold, Power
from ..optim import Factor, LeastSquaresProblem, Problem
from ..optim.losses import RobustLoss, Trivial, parse_loss
from .lie import Matrix, SymbolicGroup, symbolic

__all__ = ["SymbolicTerm", "SymbolicFactor", "problem_from_casadi", "least_squares_from_casadi"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SymbolicTerm:
    """One cost type over ``m`` edges: ``Σ_e cost(X[v_e1], …, X[v_ea], *data_e)``.

    Parameters
    ----------
    variables : int array ``(m, arity)``
        The elements each edge takes (indices into the ``Power``; ``0`` for a
        single element). A 1-D array means arity 1.
    cost : callable
        ``cost(X_1, …, X_arity, *p)`` on symbolic elements (CasADi ``SX``
        matrices) and the edge's data ``p`` (``SX`` of each array's trailing
        shape: ``1×1``, ``a×1`` or ``a×b``); returns a ``1×1`` expression.
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


# ---- the search space ---------------------------------------------------------------------------


@dataclass(frozen=True)
class _Space:
    """The group, the number ``n`` of elements and the chart of a supported manifold."""

    sym: type[SymbolicGroup]
    n: int
    single: bool  # LieGroupManifold(G) itself (points of batch shape ()), not a Power
    geometry: str

    @property
    def size(self) -> int:
        return self.sym.size

    @property
    def dim(self) -> int:
        return self.sym.dim

    def chart(self, x: Matrix, delta: Matrix) -> Matrix:
        """The manifold's retraction: ``X ⊕ δ``, or ``(R ⊕ θ, t + ρ)`` in the product geometry."""
        if self.geometry == "group":
            return self.sym.rplus(x, delta)
        sym = cast(Any, self.sym)
        d = sym.point_dim
        return sym.from_rotation_translation(
            sym.rotation.rplus(sym.rotation_part(x), delta[d:]), sym.translation(x) + delta[:d]
        )

    def flat(self, x: Any) -> FloatArray:
        """The points as a C-contiguous ``(n, k²)`` array of row-major matrices."""
        if not isinstance(x, LieGroup) or type(x) is not self.sym.group:
            raise TypeError(f"expected a {self.sym.group.__name__} element, got {type(x).__name__}")
        a = x.as_matrix()
        if a.shape != (() if self.single else (self.n,)) + (self.size, self.size):
            want = "()" if self.single else f"({self.n},)"
            raise ShapeError(f"expected a {self.sym.group.__name__} element of batch shape {want}, got {x.batch_shape}")
        return np.ascontiguousarray(a.reshape(self.n, self.size * self.size))

    def tangent(self, v: Any) -> FloatArray:
        """A tangent vector as ``(n, d)``."""
        a = np.asarray(v, dtype=np.float64)
        shape = (self.dim,) if self.single else (self.n, self.dim)
        if a.shape != shape:
            raise ShapeError(f"tangent vector: expected shape {shape}, got {a.shape}")
        return a.reshape(self.n, self.dim)

    def shaped(self, t: FloatArray) -> FloatArray:
        """``(n, d)`` back to the manifold's tangent shape."""
        return t.reshape(self.dim) if self.single else t


def _space(manifold: Any, caller: str, *, power_only: bool = False) -> _Space:
    base, n, single = manifold, 1, True
    if isinstance(manifold, Power):
        if len(manifold.shape) != 1:
            raise TypeError(f"{caller}: need Power(LieGroupManifold(G), n) with an integer n, got {manifold!r}")
        base, n, single = manifold.manifold, manifold.shape[0], False
    elif power_only:
        raise TypeError(
            f"{caller}: need Power(LieGroupManifold(G), n) (use n = 1 for a single element), got {manifold!r}"
        )
    if not isinstance(base, LieGroupManifold):
        raise TypeError(
            f"{caller}: need LieGroupManifold(G) or Power(LieGroupManifold(G), n) with G in SO2, SO3, SE2, SE3, "
            f"got {manifold!r}"
        )
    try:
        sym = symbolic(base.group)
    except TypeError as err:
        raise TypeError(f"{caller}: {err}") from None
    return _Space(sym, n, single, base.geometry)


# ---- one edge type, compiled ------------------------------------------------------------------------


def _edges(variables: ArrayLike, n: int, name: str) -> NDArray[np.int64]:
    v = np.asarray(variables)
    if v.ndim == 1:
        v = v[:, None]
    if v.ndim != 2 or v.shape[0] == 0 or v.shape[1] == 0 or not np.issubdtype(v.dtype, np.integer):
        raise ValueError(f"{name}: variables must be a non-empty integer array (m, arity), got shape {v.shape}")
    bad = (v < 0) | (v >= n)
    if bad.any():
        edge = int(np.argwhere(bad)[0, 0])
        raise ValueError(f"{name}: edge {edge} refers to variable {v[edge].tolist()} outside 0..{n - 1}")
    return v.astype(np.int64)


def _data(data: Sequence[ArrayLike], m: int, name: str) -> list[FloatArray]:
    if isinstance(data, np.ndarray):
        raise TypeError(f"{name}: data must be a sequence of arrays (wrap a single array in a tuple)")
    out = []
    for j, d in enumerate(data):
        a = np.asarray(d, dtype=np.float64)
        if a.ndim < 1 or a.ndim > 3 or a.shape[0] != m:
            raise ShapeError(f"{name}: data[{j}] must have shape ({m}, ...) with at most two more axes, got {a.shape}")
        if not np.isfinite(a).all():
            raise NonFiniteError(f"{name}: data[{j}] holds non-finite values")
        out.append(a)
    return out


def _unflatten(p: ca.SX, shape: tuple[int, ...]) -> ca.SX:
    """A row-major flattened data entry back to a scalar, a column or a matrix."""
    return ca.reshape(p, shape[1], shape[0]).T if len(shape) == 2 else p


def _expression(out: Any, name: str, what: str) -> ca.SX:
    """The user's result as an ``SX`` expression."""
    if isinstance(out, ca.SX):
        return out
    if isinstance(out, ca.MX):
        raise TypeError(f"{name}: the {what} returned an MX expression; build it from the SX elements it receives")
    if isinstance(out, np.ndarray) and out.dtype == object:
        raise TypeError(
            f"{name}: the {what} returned a numpy array of CasADi objects; combine symbolic elements with "
            "casadi operations (ca.mtimes, ca.dot, ca.sumsqr, ca.vertcat, …) instead of numpy"
        )
    try:
        return ca.SX(ca.DM(np.asarray(out, dtype=np.float64)))
    except (TypeError, ValueError, NotImplementedError, RuntimeError):
        raise TypeError(f"{name}: the {what} must return a CasADi expression, got {type(out).__name__}") from None


def _cse(expr: ca.SX) -> ca.SX:
    """Common subexpressions merged (``casadi.cse``, CasADi ≥ 3.6; 5–10 % fewer instructions)."""
    cse = getattr(ca, "cse", None)
    return cse(expr) if cse is not None else expr


def _options(jit: bool) -> dict[str, Any]:
    """``casadi.Function`` options: none, or just-in-time compilation by the system's C compiler
    (CasADi's ``"shell"`` compiler; temporary files in the system's temp directory)."""
    if not jit:
        return {}
    flags = {"flags": ["-O2"], "directory": tempfile.gettempdir() + os.sep}
    return {"jit": True, "compiler": "shell", "jit_options": flags}


class _Batched:
    """``fn.map(m)`` called on C-contiguous ``(m, nnz)`` numpy arrays through a zero-copy buffer."""

    def __init__(self, fn: ca.Function, m: int) -> None:
        self._fn = fn.map(m)
        self._buffer, self._run = self._fn.buffer()
        self._shapes = [(m, fn.nnz_out(i)) for i in range(fn.n_out())]

    def __call__(self, *args: FloatArray) -> list[FloatArray]:
        # The buffer reads raw memory: every argument must be a C-contiguous float64 (m, nnz) array.
        # (casadi's stubs list a size argument that its SWIG wrapper takes from the buffer itself)
        for i, a in enumerate(args):
            self._buffer.set_arg(i, a.data)  # type: ignore[call-arg]
        outs = [np.empty(s) for s in self._shapes]
        for i, o in enumerate(outs):
            self._buffer.set_res(i, o.data)  # type: ignore[call-arg]
        self._run()
        return outs


class _Compiled:
    """One edge type: symbolic inputs, the user's expression through the chart, and its mapped functions.

    ``kind="cost"``: ``value → f (1)``, ``gradient → g (a·d)``, ``hessian → H ((a·d)²)``;
    ``kind="residual"``: ``value → r (k)``, ``jacobian → (r (k), J (k·a·d))``; matrices row-major.
    All are taken at ``δ = 0`` (substituted symbolically, which folds the chart's
    series branches into constants).
    """

    def __init__(
        self, space: _Space, variables: NDArray[np.int64], fn: Callable[..., Any], data: list[FloatArray],
        kind: str, name: str, jit: bool = False,
    ) -> None:  # fmt: skip
        if not callable(fn):
            raise TypeError(f"{name}: the {kind} must be callable, got {type(fn).__name__}")
        self.space, self.variables, self.name = space, variables, name
        self.m, arity = variables.shape
        k, d = space.size, space.dim
        xs = [ca.SX.sym(f"x{s}", k * k) for s in range(arity)]
        ps = [ca.SX.sym(f"p{j}", max(1, prod(a.shape[1:]))) for j, a in enumerate(data)]
        self.data = [np.ascontiguousarray(a.reshape(self.m, -1)) for a in data]
        points = [space.sym.from_matrix(ca.reshape(x, k, k).T) for x in xs]
        args = [_unflatten(p, a.shape[1:]) for p, a in zip(ps, data, strict=True)]
        delta = ca.SX.sym("delta", arity * d)
        moved = [space.chart(x, delta[s * d : (s + 1) * d]) for s, x in enumerate(points)]
        out = _expression(fn(*moved, *args), name, kind)
        if kind == "cost":
            if out.shape != (1, 1):
                raise ValueError(
                    f"{name}: the cost must return a scalar (1×1) expression, got {out.shape[0]}×{out.shape[1]}"
                )
            hess, grad = ca.hessian(out, delta)
            outputs = {"value": [out], "gradient": [grad], "hessian": [ca.vec(hess.T)]}
        else:
            if min(out.shape) != 1 or out.numel() == 0:
                raise ValueError(
                    f"{name}: the residual must return a non-empty vector, got a {out.shape[0]}×{out.shape[1]} matrix"
                )
            out = ca.vec(out)
            outputs = {"value": [out], "jacobian": [out, ca.vec(ca.jacobian(out, delta).T)]}
        self.k = out.numel()
        self._symbols, self._jit = xs + ps, jit
        zero = ca.DM.zeros(arity * d)
        self._outputs = {
            label: [_cse(o) for o in ca.substitute([ca.densify(o) for o in outs], [delta], [zero])]
            for label, outs in outputs.items()
        }
        self._functions: dict[str, _Batched] = {}
        self.function("value")  # built now, so that free symbols are reported at once
        # Edge e, slot s is variable variables[e, s]: rows scatter-added by S (n, m·arity), or
        # nothing to gather or scatter when the edges are the variables in order.
        rows = variables.reshape(-1)
        self.in_order = arity == 1 and np.array_equal(rows, np.arange(space.n))
        self.scatter = scipy.sparse.csr_matrix(
            (np.ones(rows.size), (rows, np.arange(rows.size))), shape=(space.n, rows.size)
        )

    def function(self, label: str) -> _Batched:
        """The mapped function ``label``, built on first use (the Hessian only if asked for)."""
        if label not in self._functions:
            try:
                fun = ca.Function(f"sym_{label}", self._symbols, self._outputs[label], _options(self._jit))
            except RuntimeError as err:
                if "free" in str(err):
                    raise ValueError(
                        f"{self.name}: depends on symbols other than its arguments (free variables): {err}"
                    ) from None
                if self._jit:
                    raise RuntimeError(f"{self.name}: jit=True: compiling with gcc failed: {err}") from None
                raise
            self._functions[label] = _Batched(fun, self.m)
        return self._functions[label]

    def __call__(self, label: str, flat: FloatArray) -> list[FloatArray]:
        """The mapped function ``label`` at the points ``flat`` ``(n, k²)``."""
        slots = [flat] if self.in_order else [flat[self.variables[:, s]] for s in range(self.variables.shape[1])]
        return self.function(label)(*slots, *self.data)

    def scatter_add(self, rows: FloatArray) -> FloatArray:
        """``Σ`` of per-edge, per-slot tangent rows ``(m·arity, d)`` into the variables, ``(n, d)``."""
        return rows if self.in_order else self.scatter @ rows


# ---- smooth costs -------------------------------------------------------------------------------


class _CostEvaluator:
    """Cost, Riemannian gradient and pullback-Hessian products of a sum of compiled terms.

    The gradient and the per-edge Hessian blocks at the most recent point are
    remembered (keyed on its identity: points are immutable), so the many
    Hessian-vector products of a trust-region step cost one gather, one batch
    of small matrix products and one sparse scatter each; gradient-only
    optimizers never evaluate the Hessian.
    """

    def __init__(self, space: _Space, terms: list[_Compiled]) -> None:
        self.space, self.terms = space, terms
        self._grad: tuple[Any, FloatArray] | None = None
        self._hess: tuple[Any, list[FloatArray]] | None = None

    def cost(self, x: Any) -> float:
        flat = self.space.flat(x)
        return float(sum(float(np.sum(t("value", flat)[0])) for t in self.terms))

    def grad(self, x: Any) -> FloatArray:
        if self._grad is None or self._grad[0] is not x:
            flat = self.space.flat(x)
            d = self.space.dim
            g = np.zeros((self.space.n, d))
            for t in self.terms:
                g += t.scatter_add(t("gradient", flat)[0].reshape(-1, d))
            self._grad = (x, self.space.shaped(g))
        return self._grad[1].copy()

    def hess(self, x: Any, v: Any) -> FloatArray:
        if self._hess is None or self._hess[0] is not x:
            flat = self.space.flat(x)
            blocks = []
            for t in self.terms:
                ad = t.variables.shape[1] * self.space.dim
                blocks.append(t("hessian", flat)[0].reshape(t.m, ad, ad))
            self._hess = (x, blocks)
        vv = self.space.tangent(v)
        out = np.zeros_like(vv)
        for t, h in zip(self.terms, self._hess[1], strict=True):
            local = (vv if t.in_order else vv[t.variables]).reshape(t.m, -1, 1)  # (m, a·d, 1)
            out += t.scatter_add(np.matmul(h, local).reshape(-1, self.space.dim))
        return self.space.shaped(out)


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


def problem_from_casadi(
    manifold: LieGroupManifold | Power,
    cost: Callable[..., Any] | Sequence[SymbolicTerm],
    *,
    variables: ArrayLike | None = None,
    data: Sequence[ArrayLike] = (),
    name: str = "cost",
    jit: bool = False,
) -> Problem:
    """A :class:`~manopt_lie.optim.Problem` from a symbolic cost, with CasADi's exact
    Riemannian gradient and Hessian.

    The cost is a sum over edges of a function of a few elements,
    ``f(x) = Σ_e cost(X[v_e1], …, X[v_ea], *data_e)``. For each edge, with the
    chart ``f̂(δ) = cost(X₁ ⊕ δ₁, …, Xₐ ⊕ δₐ)`` (the manifold's retraction),

        grad f(x) = Σ_e scatter(∇_δ f̂_e(0)),   Hess f(x)[v] = Σ_e scatter(∇²_δ f̂_e(0) v_e),

    the Hessian being that of the pullback ``δ ↦ f(x ⊕ δ)`` — the same as
    ``LieGroupManifold.ehess2rhess`` (CONVENTIONS §6), exact to second order
    along the retraction.

    Parameters
    ----------
    manifold : LieGroupManifold or Power
        ``LieGroupManifold(G)`` (points: one element) or
        ``Power(LieGroupManifold(G), n)`` (points: batch shape ``(n,)``) with
        ``G`` in ``SO2, SO3, SE2, SE3``, either geometry.
    cost : callable or sequence of SymbolicTerm
        ``cost(X_1, …, X_a, *p)``: symbolic elements (``SX`` matrices) and the
        edge's data in, a ``1×1`` ``SX`` out. Or several edge types, each a
        :class:`SymbolicTerm` (then ``variables`` and ``data`` stay unset).
    variables : int array ``(m, a)``, optional
        The elements of each edge. Default: each element on its own
        (``arange(n)[:, None]``; ``[[0]]`` for a single element), so the cost
        is a function of *one* element summed over the ``n`` — the mapped,
        full-speed path. A function of all ``n`` elements at once is
        ``variables=[range(n)]`` (one edge; its graph grows with ``n``).
    data : sequence of arrays ``(m, …)``
        Numeric data per edge, passed to ``cost`` after the elements. Constants
        shared by every edge can simply be closed over.
    name : str
        For messages.
    jit : bool
        Compile the functions to machine code with ``gcc`` (CasADi's ``"shell"``
        compiler; ``gcc`` must be on the ``PATH``): 2–5x faster evaluations for
        ~0.1–0.5 s of compilation per function.

    Returns
    -------
    Problem
        With ``rgrad`` and ``rhess``; gradients have the manifold's tangent
        shape, ``(d,)`` or ``(n, d)``.

    Raises
    ------
    TypeError
        For an unsupported manifold, a non-callable cost or a result that is
        not a CasADi expression.
    ValueError
        For a non-scalar cost, free symbols, or malformed variables or data
        (``ShapeError``, ``NonFiniteError``).
    """
    space = _space(manifold, "problem_from_casadi")
    if isinstance(cost, SymbolicTerm):
        cost = [cost]
    if callable(cost):
        edges = np.arange(space.n)[:, None] if variables is None else variables
        terms = [SymbolicTerm(edges, cost, data, name)]
    else:
        if variables is not None or len(data):
            raise ValueError("problem_from_casadi: with SymbolicTerms, give variables and data in each term")
        terms = _as_list(cost, SymbolicTerm, "problem_from_casadi")
    compiled = []
    for t in terms:
        v = _edges(t.variables, space.n, t.name)
        compiled.append(_Compiled(space, v, t.cost, _data(t.data, v.shape[0], t.name), "cost", t.name, jit))
    evaluator = _CostEvaluator(space, compiled)
    return Problem(manifold, evaluator.cost, rgrad=evaluator.grad, rhess=evaluator.hess)


# ---- least squares ------------------------------------------------------------------------------


def _factor(space: _Space, f: SymbolicFactor, jit: bool) -> tuple[Factor, _Compiled]:
    v = _edges(f.variables, space.n, f.name)
    c = _Compiled(space, v, f.residual, _data(f.data, v.shape[0], f.name), "residual", f.name, jit)
    m, arity = v.shape
    d = space.dim

    def residual(*points: LieGroup, jac: bool = False) -> Any:
        if len(points) != arity:
            raise TypeError(f"{f.name}: expected {arity} point batches, got {len(points)}")
        flats = []
        for p in points:
            a = p.as_matrix()
            if a.shape != (m, space.size, space.size):
                raise ShapeError(f"{f.name}: expected point batches of shape ({m},), got {p.batch_shape}")
            flats.append(np.ascontiguousarray(a.reshape(m, -1)))
        if not jac:
            return c.function("value")(*flats, *c.data)[0]
        r, j = c.function("jacobian")(*flats, *c.data)
        j = j.reshape(m, c.k, arity * d)
        return r, [j[..., s * d : (s + 1) * d] for s in range(arity)]

    return Factor(v, residual, f.loss, f.name), c


def _fixed_hessian(
    hess: Callable[[Any, Any], FloatArray], fixed: NDArray[np.bool_]
) -> Callable[[Any, Any], FloatArray]:
    """``H`` restricted to the free variables, the identity on the fixed ones (as the Gauss-Newton model)."""

    def product(x: Any, v: Any) -> FloatArray:
        vv = np.where(fixed[:, None], 0.0, v)
        return np.where(fixed[:, None], v, hess(x, vv))

    return product


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
) -> LeastSquaresProblem:
    """A :class:`~manopt_lie.optim.LeastSquaresProblem` from symbolic residuals, with
    CasADi's right Jacobians.

    ``f(x) = ½ Σ_factors Σ_e ρ(‖r_e‖²)`` with, per edge, ``r_e = residual(X[v_e1], …, *data_e)``
    and the right Jacobians ``J_s = ∂/∂δ_s residual(X₁ ⊕ δ₁, …)|_{δ=0}`` (CONVENTIONS §4),
    all edges of a factor type evaluated by one mapped ``casadi.Function``.

    Parameters
    ----------
    manifold : Power
        ``Power(LieGroupManifold(G), n)``, ``G`` in ``SO2, SO3, SE2, SE3``
        (``n = 1`` for a single element).
    variables : int array ``(m, a)``, or sequence of SymbolicFactor
        The elements of each edge; or several factor types (then ``residual``,
        ``data`` and ``loss`` stay unset). Tuples ``(variables, residual, …)``
        are read as ``SymbolicFactor(*tuple)``.
    residual : callable
        ``residual(X_1, …, X_a, *p)``: symbolic elements and the edge's data in,
        a vector ``SX`` of ``k`` residuals out.
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
    jit : bool
        As in :func:`problem_from_casadi`.

    Raises
    ------
    TypeError, ValueError
        As :func:`problem_from_casadi`; also for a residual that is not a
        vector, or ``exact_hessian`` with a robust loss.
    """
    space = _space(manifold, "least_squares_from_casadi", power_only=True)
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
    built = [_factor(space, f, jit) for f in factors]
    hessian = None
    if exact_hessian:
        if any(not isinstance(parse_loss(f.loss), Trivial) for f in factors):
            raise ValueError("least_squares_from_casadi: exact_hessian=True needs plain least squares (no robust loss)")
        terms = [
            _Compiled(space, c.variables, _half_norm2(f.residual), _data(f.data, c.m, f.name), "cost", f.name, jit)
            for f, (_, c) in zip(factors, built, strict=True)
        ]
        keep = np.zeros(space.n, dtype=bool)
        keep[np.asarray(fixed, dtype=np.int64)] = True
        hessian = _fixed_hessian(_CostEvaluator(space, terms).hess, keep)
    return LeastSquaresProblem(manifold, [b[0] for b in built], fixed=fixed, hessian=hessian)


def _half_norm2(residual: Callable[..., Any]) -> Callable[..., Any]:
    def cost(*args: Any) -> Any:
        r = ca.vec(_expression(residual(*args), "residual", "residual"))
        return 0.5 * ca.sumsqr(r)

    return cost
