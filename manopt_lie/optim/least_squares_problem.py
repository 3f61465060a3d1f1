"""Nonlinear least squares over variables of one or several kinds, from factor types given
as arrays of edges.

The variables are a point of ``Power(M, n)`` (``n`` poses, rotations, …; tangent vectors
``(n, d)``) or of :class:`~manopt_lie.manifolds.Blocks` — named blocks of several kinds,
poses *and* landmarks, each a ``Power(M_k, n_k)``, with one flat tangent of
``Σ n_k d_k`` coordinates. Each :class:`Factor` is one residual *type* over a tuple of
blocks (unary, binary, …), evaluated for all of its ``m`` edges in one vectorized call;
its Jacobians are right Jacobians in tangent coordinates. The cost is

    f(x) = ½ Σ_factors Σ_edges ρ(‖r_e(x)‖²)

with ``ρ`` the factor's robust loss (plain least squares by default), the
gradient ``Σ w Jᵀr`` and the Gauss-Newton Hessian ``Σ w JᵀJ`` with IRLS weights
``w = ρ'(‖r‖²)``, assembled as a sparse matrix with a fixed pattern.
"""

from __future__ import annotations

import functools
import itertools
import math
import numbers
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np
import scipy.sparse
from numpy.typing import NDArray

from ..errors import NonFiniteError, ShapeError
from ..linalg import DENSE_MAX, BlockStructure
from ..manifolds import Blocks, Power
from ._values import check_result, same_point, snapshot
from .losses import RobustLoss, Trivial, parse_loss
from .problem import Problem

FloatArray = NDArray[np.float64]
Residual = Callable[..., Any]
_Evaluation = tuple[float, list[FloatArray], list[FloatArray], list[FloatArray]]
"""``(cost, residuals, Jacobian blocks, IRLS weights)`` of every factor at one point."""


@dataclass(frozen=True)
class Factor:
    """One residual type over ``m`` edges.

    Parameters
    ----------
    variables : int array ``(m, arity)``
        The variables each edge connects: indices into the power manifold, or into the
        block of each slot (``blocks``).
    residual : callable
        ``residual(*points, jac)`` gets, for each slot ``s``, the points
        ``x[variables[:, s]]`` (batch shape ``(m,)``) and returns the residuals
        ``(m, k)``; with ``jac=True`` it returns ``(r, [J_1, …, J_arity])``,
        ``J_s`` of shape ``(m, k, d)``: right Jacobians in tangent coordinates
        (a unary factor may return its ``J_1`` bare).
    loss : RobustLoss, str or None
        Applied to ``‖r‖²`` per edge (IRLS): an instance, ``"huber:1.0"``-style
        text (see :func:`~manopt_lie.optim.losses.parse_loss`) or ``None`` for
        plain least squares.
    name : str
        For messages.
    blocks : tuple of str, optional
        On :class:`~manopt_lie.manifolds.Blocks`: the block of each slot, e.g.
        ``("poses", "landmarks")``; a single name applies to every slot. Ignored on ``Power``.
    fresh_jacobians : bool
        The residual returns new Jacobian arrays at every call, which the problem may
        overwrite (zeroing the columns of fixed variables in place). Jacobians returned as
        a :class:`SideBySide` (slices of one array) are then read as that array without
        concatenating them (the library's fused pose factors return them so).
    residual_dim : int, optional
        ``k``, the length of every edge's residual, where it is known before the first
        evaluation (the library's factors declare it): residuals of another length are then a
        :class:`~manopt_lie.errors.ShapeError`, and the problem builds its sparsity structure on
        a worker thread while its first residuals are evaluated.
    """

    variables: NDArray[np.int64]
    residual: Residual
    loss: RobustLoss | str | None = field(default_factory=Trivial)
    name: str = "factor"
    blocks: tuple[str, ...] | str | None = None
    fresh_jacobians: bool = False
    residual_dim: int | None = None

    def __post_init__(self) -> None:
        v = np.asarray(self.variables)
        if v.ndim == 1:
            v = v[:, None]
        if v.ndim != 2 or v.shape[0] == 0 or not np.issubdtype(v.dtype, np.integer):
            raise ValueError(f"{self.name}: variables must be a non-empty integer array (m, arity), got {v.shape}")
        object.__setattr__(self, "variables", v.astype(np.int64))
        object.__setattr__(self, "loss", parse_loss(self.loss))
        r = self.residual_dim
        if r is not None and (isinstance(r, bool) or not isinstance(r, numbers.Integral) or r < 1):
            raise ValueError(f"{self.name}: residual_dim must be a positive integer or None, got {r!r}")
        if isinstance(self.blocks, str):
            object.__setattr__(self, "blocks", (self.blocks,) * v.shape[1])
        elif self.blocks is not None:
            blocks = tuple(self.blocks)
            if len(blocks) != v.shape[1]:
                raise ValueError(f"{self.name}: {len(blocks)} blocks for {v.shape[1]} slots")
            object.__setattr__(self, "blocks", blocks)

    @property
    def robust_loss(self) -> RobustLoss:
        """The loss as a :class:`RobustLoss` (``loss`` after parsing)."""
        return cast(RobustLoss, self.loss)


class Linearization:
    """Everything Gauss-Newton needs at one point: cost, gradient, ``H = JᵀWJ``.

    Parameters
    ----------
    cost : float
    grad : ndarray, the tangent shape
    hessian : scipy.sparse.csc_matrix, or a callable returning it
        A callable is called at the first use of :attr:`hessian` (and then forgotten):
        a run that stops at a point, or a solver that needs only gradients, never
        assembles ``H``. After :meth:`recycle` it is called with ``out=``, the matrix
        to overwrite.
    residuals, weights : list of ndarray
        Per factor, the whitened residuals ``(m, k)`` and IRLS weights ``(m,)``.
    jacobians : list of ndarray, optional
        The Jacobian blocks ``H`` is assembled from: :meth:`is_finite` checks them while
        ``H`` is not assembled.
    """

    __slots__ = ("_hessian", "_jacobians", "cost", "grad", "residuals", "weights")

    def __init__(
        self,
        cost: float,
        grad: FloatArray,
        hessian: scipy.sparse.csc_matrix | Callable[..., scipy.sparse.csc_matrix],
        residuals: list[FloatArray],
        weights: list[FloatArray],
        *,
        jacobians: list[FloatArray] | None = None,
    ) -> None:
        self.cost, self.grad, self.residuals, self.weights = cost, grad, residuals, weights
        self._hessian, self._jacobians = hessian, jacobians

    @property
    def hessian(self) -> scipy.sparse.csc_matrix:
        """``H = JᵀWJ`` (CSC, both triangles), assembled at the first access."""
        if callable(self._hessian):
            self._hessian, self._jacobians = self._hessian(), None
        return self._hessian

    def hessian_product(self, v: FloatArray) -> FloatArray:
        """``H v`` for a flat ``v`` of shape ``(n,)`` (``n`` the tangent dimension), shape ``(n,)``.

        A small system's ``H``, which stores every entry (a dense structure's), is multiplied as
        the dense matrix its data is, without sparse machinery; any other through SciPy."""
        h = self.hessian
        n = h.shape[0]
        if h.nnz == n * n and h.has_canonical_format:  # every entry once, column after column (H = Hᵀ)
            return h.data.reshape(n, n) @ v
        return h @ v

    def recycle(self, old: Linearization) -> None:
        """Assemble ``H``, at its first use, into the arrays of ``old``'s (assembled) ``H``, which
        is given up: ``old.hessian`` raises from now on.

        For an optimizer moving from ``old``'s point to this one: the new ``H`` is written over
        the old one instead of beside it (a pose graph of 10⁵ poses: 23 MB less at the solve's
        peak). Anything else still holding the old matrix (a linear solver) sees the new
        values. Nothing happens if ``old`` never assembled ``H`` or this one already did.
        The deferred assembly must take ``out=`` (:meth:`LeastSquaresProblem.linearize`'s does).
        """
        if old is self or not callable(self._hessian) or callable(old._hessian):
            return
        self._hessian, old._hessian = functools.partial(self._hessian, out=old._hessian), _recycled

    def is_finite(self) -> bool:
        """Whether the cost, the gradient and ``H`` (while it is not assembled: the Jacobians
        it is made of) are all finite."""
        if not (math.isfinite(self.cost) and np.isfinite(self.grad).all()):
            return False
        if callable(self._hessian) and self._jacobians is not None:
            return all(bool(np.isfinite(j).all()) for j in self._jacobians)
        return bool(np.isfinite(self.hessian.data).all())

    def __repr__(self) -> str:
        assembled = ("recycled" if self._hessian is _recycled else
                     "not assembled" if callable(self._hessian) else "assembled")  # fmt: skip
        return f"Linearization(cost={self.cost!r}, grad shape {np.shape(self.grad)}, H {assembled})"


def _recycled(out: Any = None) -> scipy.sparse.csc_matrix:
    """The ``H`` of a linearization whose matrix a later one took over."""
    raise RuntimeError("this linearization's H was recycled by a later one (Linearization.recycle)")


class SideBySide(list):  # type: ignore[type-arg]
    """The Jacobians of a factor's slots, in slot order, declared to be the consecutive
    last-axis slices of one ``(m, k, Σd)`` array, :attr:`block` (the library's fused pose
    factors return them so): a :class:`LeastSquaresProblem` then reads ``block`` whole instead of
    concatenating the slices. A plain list to everyone else.

    Parameters
    ----------
    block : ndarray, shape (m, k, Σd)
        The Jacobians of all slots side by side: ``[J_1 | J_2 | …]``.
    widths : sequence of int
        ``d_s``, the width of each slot's Jacobian (their sum is ``block``'s last axis).

    Raises
    ------
    ShapeError
        If ``block`` is not 3-D or its last axis is not ``Σ d_s``.
    """

    __slots__ = ("block",)

    def __init__(self, block: FloatArray, widths: Sequence[int]) -> None:
        starts = list(itertools.accumulate(widths, initial=0))
        if block.ndim != 3 or block.shape[2] != starts[-1]:
            raise ShapeError(f"SideBySide: a block of shape {block.shape} for slots of widths {tuple(widths)}")
        super().__init__([block[:, :, a:b] for a, b in itertools.pairwise(starts)])
        self.block = block


def _read_only(a: FloatArray) -> FloatArray:
    a.flags.writeable = False
    return a


class _Layout:
    """Where the variables are: one ``Power(M, n)`` (tangents ``(n, d)``) or the named blocks
    of :class:`~manopt_lie.manifolds.Blocks` (tangents flat), as global variable indices
    ``0..N−1`` with their tangent dimensions (the normal equations' block layout)."""

    def __init__(self, manifold: Power | Blocks) -> None:
        if isinstance(manifold, Blocks):
            self.blocks: Blocks | None = manifold
            self.dims = manifold.dims
            self.sizes = dict(zip(manifold.names, manifold.sizes, strict=True))
            self.block_dims = dict(zip(manifold.names, manifold.block_dims, strict=True))
            self.offsets = manifold.offsets
            self.tangent_shape: tuple[int, ...] = (manifold.size,)
        elif isinstance(manifold, Power) and len(manifold.shape) == 1 and manifold.manifold.tangent_ndim == 1:
            self.blocks = None
            n, d = manifold.shape[0], manifold.manifold.dim
            self.dims = np.full(n, d, dtype=np.int64)
            self.sizes, self.block_dims, self.offsets = {"": n}, {"": d}, {"": 0}
            self.tangent_shape = (n, d)
        else:
            raise TypeError(f"LeastSquaresProblem: need Power(M, n) with vector tangents or Blocks, got {manifold!r}")
        self.n = len(self.dims)

    def slots(self, f: Factor) -> tuple[str, ...]:
        """The block of each of ``f``'s slots (``""`` for the one block of a power)."""
        arity = f.variables.shape[1]
        if self.blocks is None:
            return ("",) * arity
        if f.blocks is None:
            if len(self.sizes) == 1:
                return (self.blocks.names[0],) * arity
            raise ValueError(f"{f.name}: say which block each slot refers to (blocks=…); blocks: {self.blocks.names}")
        unknown = [b for b in f.blocks if b not in self.sizes]
        if unknown:
            raise ValueError(f"{f.name}: unknown blocks {unknown}; blocks: {self.blocks.names}")
        return f.blocks  # type: ignore[return-value]

    def global_variables(self, f: Factor) -> NDArray[np.int64]:
        """``(m, arity)`` global variable indices of ``f``'s edges, range-checked per slot."""
        out = np.empty_like(f.variables)
        for s, block in enumerate(self.slots(f)):
            local, size = f.variables[:, s], self.sizes[block]
            if local.min() < 0 or local.max() >= size:
                edge = int(np.argmax((local < 0) | (local >= size)))
                where = f"block {block!r} " if block else ""
                raise ValueError(
                    f"{f.name}: edge {edge} refers to variable {f.variables[edge].tolist()} "
                    f"outside {where}0..{size - 1}"
                )
            out[:, s] = local + self.offsets[block]
        return out

    def points(self, x: Any, f: Factor, slots: tuple[str, ...]) -> list[Any]:
        if self.blocks is None:
            return [x[f.variables[:, s]] for s in range(len(slots))]
        return [x[block][f.variables[:, s]] for s, block in enumerate(slots)]

    def fixed_mask(self, fixed: Any) -> NDArray[np.bool_]:
        """Global mask of the fixed variables from indices (global) or, on blocks, a mapping
        ``name → indices``."""
        mask = np.zeros(self.n, dtype=bool)
        if isinstance(fixed, Mapping):
            if self.blocks is None:
                raise TypeError("LeastSquaresProblem: fixed={block: indices} needs Blocks")
            for block, local in fixed.items():
                if block not in self.sizes:
                    raise ValueError(f"fixed: unknown block {block!r}; blocks: {self.blocks.names}")
                local = np.asarray(local, dtype=np.int64).reshape(-1)
                if local.size and (local.min() < 0 or local.max() >= self.sizes[block]):
                    raise ValueError(f"fixed: indices of block {block!r} must lie in 0..{self.sizes[block] - 1}")
                mask[self.offsets[block] + local] = True
            return mask
        index = np.asarray(fixed, dtype=np.int64).reshape(-1)
        if index.size and (index.min() < 0 or index.max() >= self.n):
            raise ValueError(f"fixed: variable indices must lie in 0..{self.n - 1}")
        mask[index] = True
        return mask


class LeastSquaresProblem(Problem):
    """``½ Σ ρ(‖r‖²)`` over factor types on ``Power(M, n)`` or on named :class:`Blocks`; also
    a :class:`Problem` whose Hessian is the Gauss-Newton model, so every optimizer runs on it.

    Parameters
    ----------
    manifold : Power or Blocks
        ``Power(M, n)`` with vector tangents (tangents ``(n, d)``), or
        ``Blocks({"poses": Power(SE3, n), "landmarks": Power(R3, L)})`` (tangents flat,
        ``Σ n_k d_k``; each factor names the block of each slot).
    factors : sequence of Factor
    fixed : int array or mapping, optional
        Variables held constant (e.g. the first pose, fixing the gauge): their
        Jacobian columns are dropped, so steps never move them. Indices (global:
        block after block), or on blocks ``{"poses": [0]}``.
    hessian : callable ``(x, v) ↦ Hess f(x)[v]``, optional
        The exact Riemannian Hessian-vector product, for optimizers that use
        :meth:`hess` (the trust region) instead of the Gauss-Newton model.

    Notes
    -----
    One problem may be solved from several threads at once: the last
    linearization is remembered per thread, keyed on the point's value (a
    private copy compared with ``np.array_equal``), and the structure's
    workspaces are per thread too. The residual functions must then be
    thread-safe themselves (pure functions of their arguments are).
    """

    __slots__ = (
        "_build_lock", "_exact_hessian", "_factors", "_fixed", "_fixed_columns", "_fixed_coordinates", "_layout",
        "_residual_dims", "_slots", "_started", "_structure", "_unit_weights", "_variables",
    )  # fmt: skip

    def __init__(
        self,
        manifold: Power | Blocks,
        factors: Sequence[Factor],
        *,
        fixed: Sequence[int] | NDArray[Any] | Mapping[str, Any] = (),
        hessian: Callable[[Any, FloatArray], FloatArray] | None = None,
    ) -> None:
        self._layout = _Layout(manifold)
        if not factors:
            raise ValueError("LeastSquaresProblem: no factors")
        self._factors = tuple(factors)
        self._slots = tuple(self._layout.slots(f) for f in self._factors)
        self._variables = tuple(self._layout.global_variables(f) for f in self._factors)
        self._fixed = self._layout.fixed_mask(fixed)
        # Where the fixed variables sit, found once: per factor the (edges, first column, end
        # column) of their Jacobian columns, and the 1s they get on the diagonal of H.
        self._fixed_columns = tuple(self._fixed_slots(k) for k in range(len(self._factors)))
        self._fixed_coordinates = np.flatnonzero(np.repeat(self._fixed, self._layout.dims))
        self._unit_weights = tuple(_read_only(np.ones(len(v))) for v in self._variables)
        self._structure: BlockStructure | None = None
        declared = [f.residual_dim for f in self._factors]  # else known at the first evaluation
        self._residual_dims = None if None in declared else tuple(int(r) for r in cast(list[int], declared))
        self._started: Callable[[], BlockStructure] | None = None  # the structure, being built
        self._build_lock = threading.Lock()
        self._exact_hessian = hessian
        rhess = hessian if hessian is not None else self._gauss_newton_product
        super().__init__(manifold, self._evaluate_cost, rgrad=self._evaluate_grad, rhess=rhess)

    @property
    def factors(self) -> tuple[Factor, ...]:
        """The factor types of the cost ``½ Σ_f Σ_e ρ_f(‖r_f,e‖²)``, in the order given."""
        return self._factors

    @property
    def fixed(self) -> NDArray[np.bool_]:
        """Mask of the fixed variables, by global index (block after block)."""
        return self._fixed.copy()

    @property
    def dims(self) -> NDArray[np.int64]:
        """The tangent dimension of each variable, by global index."""
        return self._layout.dims.copy()

    def _points(self, x: Any, k: int) -> list[Any]:
        return self._layout.points(x, self._factors[k], self._slots[k])

    def _check_residual(self, k: int, r: Any, jac: bool) -> None:
        """Shapes only (no pass over the data): ``(m, residual_dim)``."""
        f = self._factors[k]
        dims = self._residual_dims
        shape = np.shape(r)
        if len(shape) != 2 or shape[0] != f.variables.shape[0] or (dims is not None and shape[1] != dims[k]):
            expected = f"({f.variables.shape[0]}, {dims[k] if dims is not None else 'k'})"
            raise ShapeError(
                f"{f.name}: residual(jac={jac}) returned residuals of shape {shape}; expected (m, k) = {expected}"
            )

    def _loss(self, k: int, r: FloatArray) -> tuple[float, FloatArray]:
        """``½ Σ_e ρ(‖r_e‖²)`` of factor ``k``'s residuals and the IRLS weights ``ρ'(‖r_e‖²)``:
        for plain least squares ``½ Σ r²`` in one product and weights 1 (an array kept once)."""
        loss = self._factors[k].robust_loss
        if type(loss) is Trivial:
            flat = r.reshape(-1)
            # Large: einsum, on one core, where BLAS's threaded ddot may stall; small (OpenBLAS's ddot
            # stays on one thread up to 10⁴ entries): np.dot, without einsum's parsing.
            square = np.dot(flat, flat) if flat.size <= 10_000 else np.einsum("i,i->", flat, flat)
            return 0.5 * float(square), self._unit_weights[k]
        s = np.einsum("...i,...i->...", r, r)
        return 0.5 * float(np.sum(loss.rho(s))), loss.weight(s)

    def _evaluate_cost(self, x: Any) -> float:
        total = 0.0
        for k, f in enumerate(self._factors):
            r = f.residual(*self._points(x, k), jac=False)
            self._check_residual(k, r, False)
            total += self._loss(k, r)[0]
        return total

    def linearize(self, x: Any) -> Linearization:
        """Residuals, IRLS weights, cost, gradient and Gauss-Newton Hessian at ``x``.

        The last one is remembered per thread, keyed on the value of ``x`` (a
        private copy of it), so asking again at the same point costs a comparison;
        after :meth:`trial_cost` at the same point only ``g`` is assembled. ``H`` is
        assembled at its first use (:attr:`Linearization.hessian`).

        Raises
        ------
        ShapeError
            If a factor's residuals or Jacobians do not have the shapes
            ``(m, k)`` and ``(m, k, d)`` (naming the factor).
        """
        memo: tuple[Any, Linearization] | None = getattr(self._local, "linearization", None)
        if memo is not None and same_point(memo[0], x):
            return memo[1]
        kept = self._kept(x)
        if kept is None and self._structure is None and self._residual_dims is not None:
            self._start_structure()  # its build overlaps the first evaluation
        key, evaluation = kept if kept is not None else (snapshot(x), self._evaluate(x))
        cost, residuals, blocks, weights = evaluation
        structure = self._structure or self._build_structure(residuals)
        # Plain least squares weighs every edge by 1: the assembly skips the product.
        scaling = [None if type(f.robust_loss) is Trivial else w for f, w in zip(self._factors, weights, strict=True)]
        # The structure's unchecked assembly: _evaluate checked every shape, and out (a recycled
        # H) is one of this structure's (a small system's linearization is mostly such checks).
        g = structure._gradient(blocks, residuals, scaling)
        fixed = self._fixed_coordinates

        def hessian(out: scipy.sparse.csc_matrix | None = None) -> scipy.sparse.csc_matrix:
            h = structure._hessian(blocks, scaling, out)
            if fixed.size:  # H is its own (fresh or recycled): 1 on the fixed variables' diagonal, in place
                h.data[structure.diagonal_positions[fixed]] += 1.0
            return h

        lin = Linearization(cost, g.reshape(self._layout.tangent_shape), hessian, residuals, weights, jacobians=blocks)
        self._local.linearization = (key, lin)
        return lin

    def trial_cost(self, x: Any) -> float:
        """The cost at a trial point ``x``, its residuals and Jacobians kept (per thread) for
        a :meth:`linearize` at ``x`` that may follow, which then only assembles ``H`` and ``g``.

        For optimizers that linearize where a trial is accepted: one evaluation of the
        residuals instead of two, for the Jacobians' work wasted on a rejected trial. The
        trial kept before is dropped first, so at most one set of Jacobians is held.
        """
        self._local.kept = None
        evaluation = self._evaluate(x)
        self._local.kept = (snapshot(x), evaluation)
        return evaluation[0]

    def discard_trial(self) -> None:
        """Drop what :meth:`trial_cost` kept: after a rejected trial its Jacobians would stay
        resident through the next damped factorizations (the solve's peak; on a 10⁶-pose
        grid 158 MB) until the next trial."""
        self._local.kept = None

    def kept_at(self, x: Any) -> bool:
        """Whether the residuals and Jacobians of :meth:`trial_cost` at ``x`` are kept (so
        that :meth:`linearize` at ``x`` evaluates no residual)."""
        kept = getattr(self._local, "kept", None)
        return kept is not None and same_point(kept[0], x)

    def _kept(self, x: Any) -> tuple[Any, _Evaluation] | None:
        """What :meth:`trial_cost` kept if it was at ``x`` (taken: it is used once), else ``None``."""
        kept = self._local.kept if self.kept_at(x) else None
        self._local.kept = None
        return kept

    def _evaluate(self, x: Any) -> _Evaluation:
        """``(cost, residuals, Jacobian blocks, IRLS weights)`` of every factor at ``x``, shapes checked."""
        residuals, blocks, weights, cost = [], [], [], 0.0
        for k, f in enumerate(self._factors):
            r, jacobians = f.residual(*self._points(x, k), jac=True)
            self._check_residual(k, r, True)
            m, arity, rdim = f.variables.shape[0], f.variables.shape[1], np.shape(r)[1]
            if arity == 1 and np.ndim(jacobians) == 3:  # a unary factor's one Jacobian, given bare
                jacobians = [jacobians]
            expected = [(m, rdim, self._layout.block_dims[b]) for b in self._slots[k]]
            if len(jacobians) != arity or [np.shape(j) for j in jacobians] != expected:
                raise ShapeError(
                    f"{f.name}: residual(jac=True) returned Jacobians of shapes "
                    f"{[np.shape(j) for j in jacobians]}; expected (m, k, d) = {expected}"
                )
            part, w = self._loss(k, r)
            cost += part
            blocks.append(self._jacobian_block(k, jacobians))
            residuals.append(r)
            weights.append(w)
        return cost, residuals, blocks, weights

    def _fixed_slots(self, k: int) -> list[tuple[NDArray[np.intp], int, int]]:
        """Per slot of factor ``k`` holding fixed variables: those edges and the slot's column range in
        the factor's block."""
        fixed = self._fixed[self._variables[k]]
        starts = list(itertools.accumulate((self._layout.block_dims[b] for b in self._slots[k]), initial=0))
        return [(np.flatnonzero(fixed[:, t]), starts[t], starts[t + 1]) for t in np.flatnonzero(fixed.any(axis=0))]

    def _jacobian_block(self, k: int, jacobians: Sequence[FloatArray]) -> FloatArray:
        """Factor ``k``'s Jacobians side by side, ``(m, r, Σd)``, with zero columns for the
        fixed variables (so their update is exactly zero): the factor's own array when its
        fresh Jacobians are slices of one, else a concatenation."""
        if self._factors[k].fresh_jacobians and type(jacobians) is SideBySide:
            block = jacobians.block
        else:
            block = np.concatenate(jacobians, axis=-1)
        for edges, start, stop in self._fixed_columns[k]:
            block[edges, :, start:stop] = 0.0
        return block

    def _shared_structure(self, residual_dims: Sequence[int], start: bool) -> Callable[[], BlockStructure]:
        """The structure from the pool, or built (``start``: its build started now on the worker):
        another problem of the same graph (a repeated solve, other measurements) built it already."""
        dims = self._layout.dims  # a small system is stored dense: less bookkeeping than it saves
        shapes = list(zip(self._variables, residual_dims, strict=True))
        return BlockStructure._shared_later(dims, shapes, int(dims.sum()) <= DENSE_MAX, start)

    def _start_structure(self) -> None:
        """Start building the structure of the declared residual lengths (finished by :meth:`_build_structure`)."""
        with self._build_lock:
            if self._structure is None and self._started is None and self._residual_dims is not None:
                self._started = self._shared_structure(self._residual_dims, start=True)

    def _build_structure(self, residuals: list[FloatArray]) -> BlockStructure:
        """The sparsity pattern, built once (under a lock: every thread must share one
        structure, whose ``H`` patterns a solver's symbolic analysis recognizes). The residuals
        have their declared lengths where they are (:meth:`_check_residual`)."""
        with self._build_lock:
            if self._structure is None:
                residual_dims = tuple(int(r.shape[-1]) for r in residuals)
                started, self._started = self._started, None
                self._structure = (started or self._shared_structure(residual_dims, start=False))()
                self._residual_dims = residual_dims
            return self._structure

    def validate(self, x: Any, *, hessian: bool = False) -> tuple[float, FloatArray]:
        """The cost and gradient at ``x`` (one linearization), checked: every factor's
        residuals and Jacobians of the right shapes and finite, and with ``hessian=True``
        an exact ``hessian=`` product of the tangent shape (see :meth:`Problem.validate`).

        Raises
        ------
        ShapeError, NonFiniteError
            Naming the factor (and, for a non-finite residual, the edge).
        """
        owner = type(self).__name__
        lin = self.linearize(x)
        for f, r in zip(self._factors, lin.residuals, strict=True):
            bad = ~np.isfinite(r).all(axis=-1)
            if bad.any():
                e = int(np.argmax(bad))
                raise NonFiniteError(
                    f"{owner}: factor {f.name!r} has a non-finite residual at x0 (edge {e}, variables "
                    f"{f.variables[e].tolist()}: {r[e]})"
                )
        if not lin.is_finite():
            what = "cost" if not math.isfinite(lin.cost) else "gradient or Gauss-Newton matrix (a Jacobian)"
            raise NonFiniteError(f"{owner}: the {what} is not finite at x0 although every residual is")
        if hessian and self._exact_hessian is not None:
            check_result(owner, "hessian", self._exact_hessian(x, lin.grad), self._layout.tangent_shape,
                         f"a tangent vector of {self.manifold!r}")  # fmt: skip
        return lin.cost, lin.grad

    def _evaluate_grad(self, x: Any) -> FloatArray:
        return self.linearize(x).grad

    def _gauss_newton_product(self, x: Any, v: FloatArray) -> FloatArray:
        """``JᵀWJ v`` (fixed variables: ``v`` itself, which no step ever excites)."""
        flat = np.asarray(v, dtype=np.float64).reshape(-1)
        return self.linearize(x).hessian_product(flat).reshape(self._layout.tangent_shape)

    @property
    def structure(self) -> BlockStructure | None:
        """The sparsity structure (built at the first linearization)."""
        return self._structure
