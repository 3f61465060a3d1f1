"""Marginal covariances of the variables of a least-squares problem at its solution.

The Laplace approximation of the posterior at a solution ``x̂`` of ``½ Σ ρ(‖r‖²)`` is
Gaussian in the right tangent at ``x̂``, ``x = x̂ ⊕ τ``, ``τ ~ N(0, Σ)``, with
``Σ = H⁻¹`` and ``H = JᵀWJ`` the Gauss-Newton matrix at ``x̂`` (CONVENTIONS §4, the
tangent ordering of §2: translation first). Variables held fixed (the gauge) are
conditioned on: ``H`` restricted to the free variables is inverted, so the fixed ones
are left out (their rows in ``H`` are identity blocks decoupled from the rest). With a
robust loss ``H`` carries the IRLS weights ``w = ρ'(‖r‖²)`` (as GTSAM's ``Marginals`` on
a robust noise model does); the ``ρ''`` term of the exact Hessian is not included.

The blocks are read from the sparse Cholesky factor of ``H``, never from a dense inverse:

- ``method="selected"``: the Takahashi recursion (:class:`~manopt_lie.linalg.SelectedInverse`)
  gives ``H⁻¹`` on the factor's filled pattern — every variable's diagonal block and the
  cross block of every pair of variables sharing a factor — at about the cost of one
  more factorization, restricted to the requested variables' supernodes and their
  ancestors. Pairs off the pattern fall back to solves.
- ``method="solve"``: columns of ``H⁻¹`` by multi-right-hand-side solves, in chunks.
  Costs ``O(nnz(L))`` per requested tangent coordinate, so it suits a few variables.
- ``method="auto"`` (default): solves for at most :data:`SOLVE_COLUMNS` requested
  coordinates, the recursion above that (``benchmarks/bench_marginals.py``).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import NonFiniteError, ShapeError
from ..lie import SE2, SE3, SO2, SO3
from ..lie.base import LieGroup
from ..lie.rn import RnGroup
from ..linalg import SelectedInverse, cholesky_factor
from ..manifolds import Blocks
from .least_squares_problem import LeastSquaresProblem

__all__ = ["SOLVE_COLUMNS", "MarginalCovariances", "gtsam_tangent_order", "marginal_covariances", "to_gtsam_order",
           "to_left_frame"]  # fmt: skip

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
Key = int | tuple[str, int]

SOLVE_COLUMNS = 16
"""``method="auto"`` uses solves up to this many requested tangent coordinates (the
coordinates of the variables and of the pairs' second members), selected inversion above."""

_CHUNK_BYTES = 64 * 2**20  # right-hand sides of one solve


class _Names:
    """Variables by global index ``0..N−1`` (block after block) and by ``(block, index)``."""

    def __init__(self, problem: LeastSquaresProblem) -> None:
        m = problem.manifold
        if isinstance(m, Blocks):
            self.names, self.sizes, self.dims = m.names, m.sizes, m.block_dims
        else:
            self.names, self.sizes, self.dims = ("",), (len(problem.dims),), (int(problem.dims[0]),)
        self.starts = np.cumsum((0, *self.sizes))
        self.blocked = isinstance(m, Blocks)

    def block(self, name: str | None) -> int:
        if not self.blocked:
            if name is None:
                return 0
            raise KeyError(f"no block named {name!r}: variables of a power manifold are named by index only")
        if name not in self.names:
            raise KeyError(f"no block named {name!r}; blocks: {', '.join(self.names)}")
        return self.names.index(name)

    def block_of(self, g: ArrayLike) -> IntArray:
        return np.searchsorted(self.starts, g, side="right") - 1  # type: ignore[no-any-return]

    def check(self, g: ArrayLike, what: str) -> IntArray:
        out = np.asarray(g)
        if out.size and not np.issubdtype(out.dtype, np.integer):
            raise TypeError(f"{what}: variables are integers (global indices) or (block, index) pairs")
        out = out.astype(np.int64)
        bad = (out < 0) | (out >= self.starts[-1])
        if bad.any():
            raise ValueError(f"{what}: variable {out[bad][0]} outside 0..{self.starts[-1] - 1}")
        return out

    def key(self, key: Any, what: str = "variable") -> int:
        """Global index of ``i`` or ``(block, i)``."""
        if isinstance(key, tuple) and len(key) == 2 and isinstance(key[0], str):
            b, i = self.block(key[0]), int(key[1])
            if not 0 <= i < self.sizes[b]:
                raise ValueError(f"{what}: index {i} outside block {key[0]!r} 0..{self.sizes[b] - 1}")
            return int(self.starts[b] + i)
        if isinstance(key, (int, np.integer)) and not isinstance(key, bool):
            return int(self.check(np.int64(key), what))
        raise TypeError(f"{what}: expected a global index or (block, index), got {key!r}")

    def variables(self, spec: Any, free: NDArray[np.bool_]) -> IntArray:
        """Sorted unique global indices of the requested variables."""
        if spec is None:
            return np.flatnonzero(free).astype(np.int64)
        if isinstance(spec, str):
            b = self.block(spec)
            g = np.arange(self.starts[b], self.starts[b + 1])
            return g[free[g]].astype(np.int64)
        if isinstance(spec, Mapping):
            parts = [self.starts[self.block(name)] + self.local(name, idx) for name, idx in spec.items()]
            return np.unique(np.concatenate([np.zeros(0, np.int64), *parts]))
        if isinstance(spec, Sequence) and any(isinstance(k, tuple) for k in spec):
            return np.unique([self.key(k) for k in spec]).astype(np.int64)
        return np.unique(self.check(np.reshape(spec, -1), "variables"))

    def local(self, name: str, idx: ArrayLike) -> IntArray:
        b = self.block(name)
        out = np.asarray(idx, dtype=np.int64).reshape(-1)
        if out.size and (out.min() < 0 or out.max() >= self.sizes[b]):
            raise ValueError(f"variables: indices of block {name!r} must lie in 0..{self.sizes[b] - 1}")
        return out

    def pairs(self, spec: Any) -> IntArray:
        """``(p, 2)`` global indices of the requested pairs, in request order."""
        if isinstance(spec, Mapping):
            parts = []
            for (bu, bv), idx in spec.items():
                loc = np.asarray(idx, dtype=np.int64).reshape(-1, 2)
                parts.append(np.c_[self.starts[self.block(bu)] + self.local(bu, loc[:, 0]),
                                   self.starts[self.block(bv)] + self.local(bv, loc[:, 1])])  # fmt: skip
            return np.concatenate([np.zeros((0, 2), np.int64), *parts])
        if isinstance(spec, Sequence) and any(
            isinstance(k, tuple) and any(isinstance(a, tuple) for a in k) for k in spec
        ):
            return np.array([[self.key(u, "pairs"), self.key(v, "pairs")] for u, v in spec], dtype=np.int64)
        if not np.size(spec):
            return np.zeros((0, 2), np.int64)
        shape = np.shape(spec)
        if shape != (2,) and (len(shape) != 2 or shape[1] != 2):
            raise ShapeError(f"pairs: expected (p, 2) global indices, got shape {shape}")
        return self.check(spec, "pairs").reshape(-1, 2)


class MarginalCovariances:
    """Covariance blocks of chosen variables (and cross blocks of chosen pairs), from
    :func:`marginal_covariances`.

    ``cov[v]`` is the ``(d, d)`` block ``Σ_vv = E[τ_v τ_vᵀ]`` of variable ``v`` (a global
    index, or ``(block, i)`` on :class:`~manopt_lie.manifolds.Blocks`), ``cov.cross(u, v)``
    the ``(d_u, d_v)`` block ``E[τ_u τ_vᵀ]`` of a requested pair (either order),
    ``cov.stacked(block)`` the ``(k, d, d)`` array of the block's requested variables,
    whose local indices are ``cov.indices(block)``. Right (local) tangent, CONVENTIONS
    ordering; :meth:`left` and :func:`to_gtsam_order` convert.

    Attributes
    ----------
    variables : int array
        Global indices of the variables, sorted.
    pairs : int array ``(p, 2)``
        Global indices of the pairs, in request order.
    fixed : int array
        Requested variables (and pair members) held fixed: their blocks are zero (they
        are conditioned on, CONVENTIONS §4).
    method, backend : str
        How the blocks were computed.
    """

    def __init__(self, names: _Names, variables: IntArray, blocks: list[FloatArray], pairs: IntArray,
                 cross: dict[tuple[str, str], tuple[IntArray, FloatArray]], fixed: IntArray, method: str,
                 backend: str) -> None:  # fmt: skip
        self._names = names
        self.variables, self.pairs, self.fixed = variables, pairs, fixed
        self.method, self.backend = method, backend
        of = names.block_of(variables)
        self._stacked = {names.names[b]: (variables[of == b] - names.starts[b], blocks[b]) for b in range(len(blocks))}
        self._cross = cross  # (block_u, block_v) → (positions in pairs, blocks)
        # Where pair i lives: its group and its row there; pairs sorted by key for lookups.
        self._group, self._slot = np.zeros(len(pairs), np.int64), np.zeros(len(pairs), np.int64)
        self._groups = list(cross)
        for g, (positions, _) in enumerate(cross.values()):  # over (block, block) groups
            self._group[positions], self._slot[positions] = g, np.arange(positions.size)
        key = pairs[:, 0] * names.starts[-1] + pairs[:, 1]
        self._pair_order = np.argsort(key, kind="stable")
        self._pair_keys = key[self._pair_order]

    def __len__(self) -> int:
        return int(self.variables.size)

    def __repr__(self) -> str:
        return (f"MarginalCovariances({len(self)} variables, {len(self.pairs)} pairs, {self.fixed.size} fixed, "
                f"method={self.method!r}, backend={self.backend!r})")  # fmt: skip

    def __iter__(self) -> Iterator[Key]:
        """The requested variables' keys: global indices, or ``(block, i)`` on ``Blocks``."""
        if not self._names.blocked:
            yield from self.variables.tolist()
            return
        for name, (local, _) in self._stacked.items():
            yield from ((name, i) for i in local.tolist())

    def items(self) -> Iterator[tuple[Key, FloatArray]]:
        """``(key, block)`` for every requested variable (:meth:`stacked` is the fast way)."""
        if not self._names.blocked:
            yield from zip(self.variables.tolist(), self._stacked[""][1], strict=True)
            return
        for name, (local, blocks) in self._stacked.items():
            yield from (((name, i), b) for i, b in zip(local.tolist(), blocks, strict=True))

    def __contains__(self, key: Any) -> bool:
        g = self._names.key(key)
        i = np.searchsorted(self.variables, g)
        return bool(i < self.variables.size and self.variables[i] == g)

    def __getitem__(self, key: Key) -> FloatArray:
        g = self._names.key(key)
        if g not in self:
            raise KeyError(f"variable {key!r} was not requested")
        b = int(self._names.block_of(np.int64(g)))
        local, blocks = self._stacked[self._names.names[b]]
        return blocks[np.searchsorted(local, g - self._names.starts[b])]  # type: ignore[no-any-return]

    def indices(self, block: str | None = None) -> IntArray:
        """Local indices (within ``block``; global on a power manifold) of :meth:`stacked`'s rows."""
        return self._stacked[self._names.names[self._names.block(block)]][0]

    def stacked(self, block: str | None = None) -> FloatArray:
        """The ``(k, d, d)`` covariances of ``block``'s requested variables (``block`` is
        omitted on a power manifold), in the order of :meth:`indices`."""
        return self._stacked[self._names.names[self._names.block(block)]][1]

    def cross(self, u: Key, v: Key) -> FloatArray:
        """``E[τ_u τ_vᵀ]``, ``(d_u, d_v)``, of a requested pair (or its reverse, transposed)."""
        gu, gv = self._names.key(u), self._names.key(v)
        n = self._names.starts[-1]
        for key, transpose in ((gu * n + gv, False), (gv * n + gu, True)):
            i = np.searchsorted(self._pair_keys, key)
            if i < self._pair_keys.size and self._pair_keys[i] == key:
                j = self._pair_order[i]
                block = self._cross[self._groups[self._group[j]]][1][self._slot[j]]
                return block.T if transpose else block  # type: ignore[no-any-return]
        raise KeyError(f"pair ({u!r}, {v!r}) was not requested")

    def joint(self, u: Key, v: Key) -> FloatArray:
        """The joint covariance ``[[Σ_uu, Σ_uv], [Σ_vu, Σ_vv]]`` of a requested pair whose
        variables were requested too."""
        c = self.cross(u, v)
        return np.block([[self[u], c], [c.T, self[v]]])

    def stacked_cross(self, block_u: str | None = None, block_v: str | None = None) -> tuple[IntArray, FloatArray]:
        """The requested pairs from ``block_u`` to ``block_v`` (omitted on a power manifold):
        their local indices ``(q, 2)`` and cross blocks ``(q, d_u, d_v)``, in request order."""
        bu, bv = (self._names.names[self._names.block(b)] for b in (block_u, block_v))
        if (bu, bv) not in self._cross:
            return np.zeros((0, 2), np.int64), np.zeros(
                (0, *(self._names.dims[self._names.block(b)] for b in (bu, bv)))
            )
        positions, blocks = self._cross[bu, bv]
        starts = self._names.starts[[self._names.block(bu), self._names.block(bv)]]
        return self.pairs[positions] - starts, blocks

    def left(self, x: Any, block: str | None = None) -> FloatArray:
        """:meth:`stacked` in the left (global) frame, ``Ad_X Σ Ad_Xᵀ`` (:func:`to_left_frame`),
        with ``X`` the block's points of ``x`` (the solution) at :meth:`indices`."""
        points = x[self._names.names[self._names.block(block)]] if self._names.blocked else x
        return to_left_frame(points[self.indices(block)], self.stacked(block))


def to_left_frame(points: Any, cov: ArrayLike, points_v: Any = None) -> FloatArray:
    """Right-tangent covariances ``(k, d, d)`` in the left (global) frame: ``Ad_X Σ Ad_Xᵀ``
    (``X·Exp(τ) = Exp(Ad_X τ)·X``), batched over ``points`` (group elements of
    batch ``(k,)``; arrays of a vector space are returned unchanged). With ``points_v`` the
    cross blocks of pairs: ``Ad_{X_u} Σ_uv Ad_{X_v}ᵀ``."""
    c = np.asarray(cov, dtype=np.float64)
    ad_u = points.adjoint() if isinstance(points, LieGroup) else None
    other = points if points_v is None else points_v
    ad_v = other.adjoint() if isinstance(other, LieGroup) else None
    if ad_u is not None:
        c = ad_u @ c
    if ad_v is not None:
        c = c @ np.swapaxes(ad_v, -1, -2)
    return c


_GTSAM_ORDER = {SE3: np.r_[3:6, 0:3], SE2: np.arange(3), SO3: np.arange(3), SO2: np.arange(1)}


def gtsam_tangent_order(group: type[LieGroup]) -> IntArray:
    """``p`` with ``τ_gtsam = τ[p]``: GTSAM's ``Pose3`` tangent is ``(ω, v)``, rotation first
    (``p = [3, 4, 5, 0, 1, 2]``); ``Pose2`` is ``(x, y, θ)`` like ours; rotations and
    vectors need no permutation."""
    if group in _GTSAM_ORDER:
        return _GTSAM_ORDER[group]
    if isinstance(group, type) and issubclass(group, RnGroup):
        return np.arange(group.dim)
    raise ValueError(f"no GTSAM tangent ordering known for {getattr(group, '__name__', group)!r}")


def to_gtsam_order(cov: ArrayLike, group: type[LieGroup], group_v: type[LieGroup] | None = None) -> FloatArray:
    """Covariances ``(..., d, d)`` (or cross blocks ``(..., d_u, d_v)`` with ``group_v``) in
    GTSAM's tangent ordering: ``Σ[..., p, :][..., :, q]`` with :func:`gtsam_tangent_order`."""
    p, q = gtsam_tangent_order(group), gtsam_tangent_order(group if group_v is None else group_v)
    c = np.asarray(cov, dtype=np.float64)
    return c[..., p, :][..., :, q]


class _Request(NamedTuple):
    """Blocks ``H⁻¹[u, v]`` of one shape ``(du, dv)``: row variables ``u``, column variables ``v``."""

    u: IntArray
    v: IntArray
    du: int
    dv: int


def _coordinates(offsets: IntArray, r: _Request, mine: Any = slice(None)) -> tuple[IntArray, IntArray]:
    """Scalar rows ``(q, du, 1)`` and columns ``(q, 1, dv)`` of the requested blocks."""
    rows = offsets[r.u[mine]][:, None, None] + np.arange(r.du)[:, None]
    return rows, offsets[r.v[mine]][:, None, None] + np.arange(r.dv)


def _scalar(offsets: IntArray, dims: IntArray, variables: IntArray) -> tuple[IntArray, IntArray]:
    """The scalar coordinates of ``variables`` (concatenated) and where each variable's start."""
    width = dims[variables]
    first = np.cumsum(width) - width
    return np.repeat(offsets[variables] - first, width) + np.arange(int(width.sum())), first


def _solve_blocks(factor: Any, offsets: IntArray, dims: IntArray, requests: list[_Request]) -> list[FloatArray]:
    """The blocks from the columns ``X = H⁻¹ E_v`` of every column variable ``v``, solved in
    chunks of at most :data:`_CHUNK_BYTES` of right-hand sides."""
    columns = np.unique(np.concatenate([np.zeros(0, np.int64)] + [r.v for r in requests]))
    out = [np.zeros((r.u.size, r.du, r.dv)) for r in requests]
    n = factor.n
    per_chunk = max(1, _CHUNK_BYTES // (8 * n * int(dims.max())))
    for lo in range(0, columns.size, per_chunk):  # over chunks of columns, one multi-RHS solve each
        chunk = columns[lo : lo + per_chunk]
        coords, first = _scalar(offsets, dims, chunk)
        E = np.zeros((n, coords.size))
        E[coords, np.arange(coords.size)] = 1.0
        X = factor.solve(E)
        for r, block in zip(requests, out, strict=True):
            mine = np.isin(r.v, chunk)
            if mine.any():
                rows, cols = _coordinates(offsets, r, mine)
                shift = first[np.searchsorted(chunk, r.v[mine])] - offsets[r.v[mine]]
                block[mine] = X[rows, cols + shift[:, None, None]]
    return out


def _selected_blocks(
    factor: Any, offsets: IntArray, dims: IntArray, requests: list[_Request], n_free: int
) -> list[FloatArray]:
    """The blocks from the selected inverse on the factor's pattern, restricted to the
    supernodes of the requested variables (unless they are all ``n_free`` free ones) and
    their ancestors; blocks off the pattern from solves."""
    involved = np.unique(np.concatenate([np.zeros(0, np.int64)] + [a for r in requests for a in (r.u, r.v)]))
    inverse = SelectedInverse(factor, None if involved.size == n_free else _scalar(offsets, dims, involved)[0])
    out, missing = [], []
    for r in requests:
        values, found = inverse.entries(*_coordinates(offsets, r))
        out.append(values)
        missing.append(~found.all(axis=(1, 2)))
    if any(m.any() for m in missing):
        rest = [r._replace(u=r.u[m], v=r.v[m]) for r, m in zip(requests, missing, strict=True)]
        for values, m, solved in zip(out, missing, _solve_blocks(factor, offsets, dims, rest), strict=True):
            values[m] = solved
    return out


def marginal_covariances(
    problem: LeastSquaresProblem,
    x: Any,
    variables: Any = None,
    pairs: Any = (),
    *,
    method: str = "auto",
    backend: str = "auto",
) -> MarginalCovariances:
    """Marginal covariances ``Σ = H⁻¹`` (blocks) of chosen variables at a solution ``x``.

    The Laplace approximation (module doc): ``x = x̂ ⊕ τ``, ``τ ~ N(0, H⁻¹)`` with the
    Gauss-Newton matrix ``H = JᵀWJ`` at ``x`` (IRLS weights under a robust loss), in the
    right tangent of CONVENTIONS §4, translation first; fixed variables are held fixed
    (conditioned on). Computed from the sparse Cholesky factor ``P H Pᵀ = L Lᵀ``, never
    from a dense inverse.

    Parameters
    ----------
    problem : LeastSquaresProblem
    x : point
        The solution (a point of ``problem.manifold``).
    variables : optional
        ``None`` (default): every free variable. Global indices (block after block), a block
        name (every free variable of that block), ``(block, i)`` pairs, or a mapping
        ``{"landmarks": [...]}``. Requested fixed variables get zero blocks and are listed
        in :attr:`MarginalCovariances.fixed`.
    pairs : optional
        Pairs ``(u, v)`` whose cross blocks ``E[τ_u τ_vᵀ]`` are wanted: ``(p, 2)`` global
        indices, a sequence of ``(key_u, key_v)`` or a mapping ``{("poses", "landmarks"): (p, 2)}``
        of local indices.
    method : {"auto", "selected", "solve"}
        Selected inversion, column solves, or the cheaper one for the request (module doc).
    backend : {"auto", "cholmod", "ldl", "qdldl", "superlu"}
        The factorization (:class:`~manopt_lie.linalg.CholeskySolver`'s backends).

    Returns
    -------
    MarginalCovariances

    Raises
    ------
    NonFiniteError
        If ``H`` is not finite at ``x``.
    SingularSystemError
        If ``H`` is not positive definite (an unobservable direction, e.g. an unfixed gauge).
    """
    if method not in ("auto", "selected", "solve"):
        raise ValueError(f"method must be 'auto', 'selected' or 'solve', got {method!r}")
    names = _Names(problem)
    free = ~problem.fixed
    var = names.variables(variables, free)
    pr = names.pairs(pairs)
    lin = problem.linearize(x)
    if not lin.is_finite():
        raise NonFiniteError("marginal_covariances: the Gauss-Newton matrix is not finite at x")
    dims = problem.dims
    offsets = np.cumsum(dims) - dims
    factor = cholesky_factor(lin.hessian, backend)
    free_pairs = free[pr].all(axis=1) if pr.size else np.zeros(0, dtype=bool)
    # One request per block of variables and per (block, block) of pairs: uniform shapes.
    of, pair_of = names.block_of(var), names.block_of(pr)
    nb, bd = len(names.names), names.dims
    requests = [_Request(var[(of == b) & free[var]], var[(of == b) & free[var]], bd[b], bd[b]) for b in range(nb)]
    groups = [(bu, bv) for bu in range(nb) for bv in range(nb)]
    in_group = [np.flatnonzero((pair_of[:, 0] == bu) & (pair_of[:, 1] == bv) & free_pairs) for bu, bv in groups]
    requests += [_Request(pr[i, 0], pr[i, 1], bd[bu], bd[bv]) for i, (bu, bv) in zip(in_group, groups, strict=True)]
    columns = var[free[var]]  # sorted, unique
    if free_pairs.any():
        columns = np.union1d(columns, pr[free_pairs, 1])
    if method == "auto":
        method = "solve" if dims[columns].sum() <= SOLVE_COLUMNS else "selected"
    if not columns.size:
        values = [np.zeros((0, r.du, r.dv)) for r in requests]
    elif method == "solve":
        values = _solve_blocks(factor, offsets, dims, requests)
    else:
        values = _selected_blocks(factor, offsets, dims, requests, int(np.count_nonzero(free)))
    blocks = []
    for b in range(nb):
        out = np.zeros((int(np.count_nonzero(of == b)), bd[b], bd[b]))
        out[free[var[of == b]]] = 0.5 * (values[b] + values[b].swapaxes(1, 2))  # exact already when selected
        blocks.append(out)
    cross = {}
    for (bu, bv), i, part in zip(groups, in_group, values[nb:], strict=True):
        mine = np.flatnonzero((pair_of[:, 0] == bu) & (pair_of[:, 1] == bv))
        if mine.size:
            out = np.zeros((mine.size, bd[bu], bd[bv]))
            out[np.searchsorted(mine, i)] = part
            cross[names.names[bu], names.names[bv]] = (mine, out)
    involved = np.unique(np.concatenate([var, pr.reshape(-1)]))
    return MarginalCovariances(names, var, blocks, pr, cross, involved[~free[involved]], method, factor.backend)
