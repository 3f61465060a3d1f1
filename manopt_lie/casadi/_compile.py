"""One edge type of a symbolic cost or residual, compiled once and mapped over its edges.

A *kind* (:class:`Kind`) says how one point of a manifold enters a CasADi function:
as a flat row of numbers (row-major, as numpy stores it), a symbolic matrix handed to
the user's function, and the coordinates derivatives are taken in —

* a **chart** (Lie groups): the tangent coordinates ``δ`` of ``X ⊕ δ`` at ``δ = 0``,
  so the gradient is the Riemannian one and the Hessian that of the pullback;
* the **ambient** entries (embedded manifolds, and Lie groups inside products): the
  point's own entries, so the gradient is Euclidean and the manifold converts it
  (``egrad2rgrad``, ``ehess2rhess``); the Hessian is taken as Hessian-vector
  products (forward over reverse), never as a matrix.

:class:`Compiled` builds the user's expression for one edge of ``a`` slots, its
derivatives, and ``casadi.Function``\\ s mapped over the ``m`` edges
(``Function.map``), called on C-contiguous ``(m, nnz)`` numpy arrays through
zero-copy buffers (:class:`Batched`).
"""

from __future__ import annotations

import os
import tempfile
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from math import prod
from typing import Any

import casadi as ca
import numpy as np
import scipy.sparse
from numpy.typing import ArrayLike, NDArray

from ..errors import NonFiniteError, ShapeError

__all__ = ["Kind", "Compiled", "Batched", "edges", "edge_data", "expression", "SYMBOLS"]

FloatArray = NDArray[np.float64]
Matrix = Any  # a CasADi SX or MX matrix: casadi's stubs do not type operations across the two
SYMBOLS = ("auto", "SX", "MX")
MX_ABOVE = 100
"""``symbols="auto"`` uses ``MX`` (matrix operations as single nodes) once a point has more
entries than this, ``SX`` (scalar operations, fastest for small points) below."""


@dataclass(frozen=True)
class Kind:
    """How one point of a manifold enters a CasADi function.

    Attributes
    ----------
    label : str
        For messages (``"a SO3 element"``, ``"a point of Sphere(3)"``).
    shape : (rows, cols)
        The symbolic matrix the flat row is reshaped to (row-major, as numpy).
    dim : int
        Derivative coordinates per point: the tangent dimension for a chart, else ``rows·cols``.
    chart : callable ``(X, δ) ↦ X ⊕ δ``, or None
        The retraction in tangent coordinates; ``None``: derivatives in the ambient entries.
    wrap : callable
        The user's argument from the reshaped matrix (e.g. ``SymSO3.from_matrix``).
    """

    label: str
    shape: tuple[int, int]
    dim: int
    chart: Callable[[Matrix, Matrix], Matrix] | None = None
    wrap: Callable[[Matrix], Matrix] = lambda m: m

    @property
    def size(self) -> int:
        return self.shape[0] * self.shape[1]


def reshape_rows(x: Matrix, shape: tuple[int, ...]) -> Matrix:
    """A row-major flattened entry back to a column (``(n,)``, ``(n, 1)``) or a matrix (CasADi is column-major)."""
    return ca.reshape(x, shape[1], shape[0]).T if len(shape) == 2 and shape[1] > 1 else x


def edges(variables: ArrayLike, n: int, name: str) -> NDArray[np.int64]:
    """``variables`` as an ``(m, arity)`` int array indexing ``0..n−1``."""
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


def edge_data(data: Sequence[ArrayLike], m: int, name: str) -> list[FloatArray]:
    """Per-edge data as float arrays ``(m, …)`` with at most two more axes, all finite."""
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


def expression(out: Any, name: str, what: str, sym: type = ca.SX) -> Matrix:
    """The user's result as an expression of the symbols' type ``sym`` (``SX`` or ``MX``)."""
    if isinstance(out, sym):
        return out
    if isinstance(out, (ca.SX, ca.MX)):
        other = type(out).__name__
        raise TypeError(
            f"{name}: the {what} returned an {other} expression; build it from the {sym.__name__} elements it receives"
        )
    if isinstance(out, np.ndarray) and out.dtype == object:
        raise TypeError(
            f"{name}: the {what} returned a numpy array of CasADi objects; combine symbolic elements with "
            "casadi operations (ca.mtimes, ca.dot, ca.sumsqr, ca.vertcat, …) instead of numpy"
        )
    try:
        return sym(ca.DM(np.asarray(out, dtype=np.float64)))
    except (TypeError, ValueError, NotImplementedError, RuntimeError):
        raise TypeError(f"{name}: the {what} must return a CasADi expression, got {type(out).__name__}") from None


def _cse(expr: Any) -> Any:
    """Common subexpressions merged (``casadi.cse``, CasADi ≥ 3.6; 5–10 % fewer instructions)."""
    cse = getattr(ca, "cse", None)
    return cse(expr) if cse is not None and isinstance(expr, ca.SX) else expr


def _fold_constants(outputs: list[Any], inputs: list[Any]) -> list[Any]:
    """``MX`` outputs with their constant subexpressions evaluated once, here (CasADi would
    redo them at every call: reverse mode through ``xᵀAx`` transposes the constant ``A``)."""
    probe = ca.Function("fold", inputs, outputs)
    skip = {ca.OP_INPUT, ca.OP_OUTPUT, ca.OP_CONST, ca.OP_PARAMETER}
    old, new = [], []
    for k in range(probe.n_instructions()):
        if probe.instruction_id(k) in skip:
            continue
        node = probe.instruction_MX(k)
        if not ca.symvar(node):
            old.append(node)
            new.append(ca.MX(ca.evalf(node)))
    return ca.graph_substitute(outputs, old, new) if old else outputs


def _options(jit: bool) -> dict[str, Any]:
    """``casadi.Function`` options: none, or just-in-time compilation by the system's C compiler
    (CasADi's ``"shell"`` compiler; temporary files in the system's temp directory)."""
    if not jit:
        return {}
    flags = {"flags": ["-O2"], "directory": tempfile.gettempdir() + os.sep}
    return {"jit": True, "compiler": "shell", "jit_options": flags}


class Batched:
    """``fn.map(m)`` called on C-contiguous ``(m, nnz)`` numpy arrays through a zero-copy buffer
    (one buffer per function: calls from several threads take turns)."""

    def __init__(self, fn: ca.Function, m: int) -> None:
        self._fn = fn.map(m) if m > 1 else fn
        self._buffer, self._run = self._fn.buffer()
        self._shapes = [(m, fn.nnz_out(i)) for i in range(fn.n_out())]
        self._lock = threading.Lock()

    def __call__(self, *args: FloatArray) -> list[FloatArray]:
        # The buffer reads raw memory: every argument must be a C-contiguous float64 (m, nnz) array.
        # (casadi's stubs list a size argument that its SWIG wrapper takes from the buffer itself)
        outs = [np.empty(s) for s in self._shapes]
        with self._lock:
            for i, a in enumerate(args):
                self._buffer.set_arg(i, a.data)  # type: ignore[call-arg]
            for i, o in enumerate(outs):
                self._buffer.set_res(i, o.data)  # type: ignore[call-arg]
            self._run()
        return outs


def symbol_type(kinds: Sequence[Kind], symbols: str) -> type[Matrix]:
    """``ca.SX`` or ``ca.MX`` for ``symbols`` (``"auto"``: MX above :data:`MX_ABOVE` entries a point)."""
    if symbols not in SYMBOLS:
        raise ValueError(f"symbols must be one of {', '.join(SYMBOLS)}, got {symbols!r}")
    if symbols == "auto":
        return ca.MX if max(k.size for k in kinds) > MX_ABOVE else ca.SX
    return ca.SX if symbols == "SX" else ca.MX


class Compiled:
    """One edge type: symbolic inputs, the user's expression, its mapped functions.

    ``kind="cost"``: ``value → f (1)``, ``gradient → g (Σₛ dₛ)`` and, for charts,
    ``hessian → H ((Σₛ dₛ)², row-major)``, for ambient kinds ``hvp(x, p, u) → ∇²f·u``.
    ``kind="residual"``: ``value → r (k)``, ``jacobian → (r (k), J (k·Σₛ dₛ), row-major)``.
    Chart derivatives are taken at ``δ = 0`` (substituted symbolically, which folds the
    chart's series branches into constants).

    Parameters
    ----------
    kinds : one :class:`Kind` per slot
        All charts or all ambient.
    sources : one int per slot
        Which variable array each slot indexes (several for a product's factors).
    counts : points per variable array
    variables : int array ``(m, a)``
    """

    def __init__(
        self, kinds: Sequence[Kind], sources: Sequence[int], counts: Sequence[int], variables: NDArray[np.int64],
        fn: Callable[..., Any], data: list[FloatArray], kind: str, name: str, *, jit: bool = False,
        symbols: str = "auto",
    ) -> None:  # fmt: skip
        if not callable(fn):
            raise TypeError(f"{name}: the {kind} must be callable, got {type(fn).__name__}")
        self.kinds, self.sources, self.variables, self.name = tuple(kinds), tuple(sources), variables, name
        self.m, arity = variables.shape
        self.chart = kinds[0].chart is not None
        self.sym = sym = symbol_type(kinds, symbols)
        xs = [sym.sym(f"x{s}", k.size) for s, k in enumerate(kinds)]
        ps = [sym.sym(f"p{j}", max(1, prod(a.shape[1:]))) for j, a in enumerate(data)]
        self.data = [np.ascontiguousarray(a.reshape(self.m, -1)) for a in data]
        points = [k.wrap(reshape_rows(x, k.shape)) for k, x in zip(kinds, xs, strict=True)]
        args = [reshape_rows(p, a.shape[1:]) for p, a in zip(ps, data, strict=True)]
        self.offsets = np.cumsum([0, *(k.dim for k in kinds)])
        if self.chart:
            wrt = sym.sym("delta", int(self.offsets[-1]))
            bounds = zip(self.offsets[:-1], self.offsets[1:], strict=True)
            points = [k.chart(x, wrt[int(a) : int(b)]) for k, x, (a, b) in zip(kinds, points, bounds, strict=True)]  # type: ignore[misc]
        else:
            wrt = ca.vertcat(*xs)
        out = expression(fn(*points, *args), name, kind, sym)
        inputs, extra = xs + ps, []
        if kind == "cost":
            if out.shape != (1, 1):
                raise ValueError(
                    f"{name}: the cost must return a scalar (1×1) expression, got {out.shape[0]}×{out.shape[1]}"
                )
            if self.chart:
                hess, grad = ca.hessian(out, wrt)
                outputs = {"value": [out], "gradient": [grad], "hessian": [ca.vec(hess.T)]}
            else:
                grad = ca.gradient(out, wrt)
                us = [sym.sym(f"u{s}", k.size) for s, k in enumerate(kinds)]
                extra = us
                outputs = {"value": [out], "gradient": [grad], "hvp": [ca.jtimes(grad, wrt, ca.vertcat(*us))]}
        else:
            if min(out.shape) != 1 or out.numel() == 0:
                raise ValueError(
                    f"{name}: the residual must return a non-empty vector, got a {out.shape[0]}×{out.shape[1]} matrix"
                )
            out = ca.vec(out)
            outputs = {"value": [out], "jacobian": [out, ca.vec(ca.jacobian(out, wrt).T)]}
        self.k = out.numel()
        self._inputs = {label: inputs + (extra if label == "hvp" else []) for label in outputs}
        self._jit = jit
        if self.chart:
            zero = sym(ca.DM.zeros(wrt.numel()))
            outputs = {
                label: ca.substitute([ca.densify(o) for o in outs], [wrt], [zero]) for label, outs in outputs.items()
            }
        self._outputs = {label: [_cse(ca.densify(o)) for o in outs] for label, outs in outputs.items()}
        if sym is ca.MX:
            self._outputs = {k: _fold_constants(o, self._inputs[k]) for k, o in self._outputs.items()}
        self._functions: dict[str, Batched] = {}
        self.function("value")  # built now, so that free symbols are reported at once
        # Edge e, slot s is point variables[e, s] of array sources[s]: rows scatter-added by
        # S_s (n, m), or nothing to gather or scatter when the edges are the points in order.
        self.in_order = arity == 1 and np.array_equal(variables[:, 0], np.arange(counts[self.sources[0]]))
        self.scatter = [
            scipy.sparse.csr_matrix(
                (np.ones(self.m), (variables[:, s], np.arange(self.m))), shape=(counts[src], self.m)
            )
            for s, src in enumerate(self.sources)
        ]

    def function(self, label: str) -> Batched:
        """The mapped function ``label``, built on first use (the Hessian only if asked for)."""
        if label not in self._functions:
            try:
                fun = ca.Function(f"sym_{label}", self._inputs[label], self._outputs[label], _options(self._jit))
            except RuntimeError as err:
                if "free" in str(err):
                    raise ValueError(
                        f"{self.name}: depends on symbols other than its arguments (free variables): {err}"
                    ) from None
                if self._jit:
                    raise RuntimeError(f"{self.name}: jit=True: compiling with gcc failed: {err}") from None
                raise
            self._functions[label] = Batched(fun, self.m)
        return self._functions[label]

    def gather(self, arrays: Sequence[FloatArray]) -> list[FloatArray]:
        """Each slot's rows ``(m, size)`` from the variable arrays."""
        if self.in_order:
            return [arrays[self.sources[0]]]
        return [np.ascontiguousarray(arrays[src][self.variables[:, s]]) for s, src in enumerate(self.sources)]

    def __call__(self, label: str, arrays: Sequence[FloatArray], *extra: Sequence[FloatArray]) -> list[FloatArray]:
        """The mapped function ``label`` at the points ``arrays`` (one ``(n_i, size_i)`` per array);
        ``extra``: more per-point arrays gathered the same way (the Hessian's directions)."""
        more = [row for e in extra for row in self.gather(e)]
        return self.function(label)(*self.gather(arrays), *self.data, *more)

    def scatter_add(self, rows: FloatArray, into: list[FloatArray]) -> None:
        """Add per-edge rows ``(m, Σₛ dₛ)`` (slot after slot) into the per-array accumulators ``into``."""
        for s, src in enumerate(self.sources):
            block = rows[:, int(self.offsets[s]) : int(self.offsets[s + 1])]
            into[src] += block if self.in_order else self.scatter[s] @ block
