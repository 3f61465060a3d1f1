"""Fixed block-sparsity pattern of a factor graph's Jacobian and normal equations.

A least-squares problem ``½ Σ_k Σ_e w_ke ‖r_ke‖²`` has variables ``x_v`` with
tangent dimension ``d_v`` (stacked in the order of ``dims``; variable ``v``
owns coordinates ``o_v … o_v + d_v − 1`` with ``o = [0, cumsum(dims)]``) and
*factor types* ``k``, each an array of edges ``e`` touching ``arity_k``
variables in slot order. The Jacobian of edge ``e`` w.r.t. its variables,
concatenated in slot order, is the block ``A_e`` of shape ``(r_k, D_k)`` with
``D_k = Σ_s d_s``. Then

    J   = the stack of the rows of every ``A_e`` (factor 0 first),
    H   = JᵀWJ = Σ_e w_e A_eᵀA_e       (scattered into the blocks (v_s, v_t)),
    g   = JᵀWr = Σ_e w_e A_eᵀr_e       (scattered into the variables' rows),

and a Gauss-Newton step solves ``H δ = −g``. The pattern never changes while
a solve runs, so every index array is computed once here and each call only
refills data arrays. The index arrays are built in compiled code (``_patterns``) or,
where it cannot serve, with NumPy (``_patterns_numpy``): the same arrays. ``H`` and ``g``
are summed in compiled code too (``_assembly``), else with NumPy.
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from ..errors import ShapeError
from . import _factors
from ._amd import variable_order
from ._analyses import STRUCTURES, StructureInputs, digest
from ._assembly import gradient_add, hessian_add
from ._early import Analysis, EarlyAnalysis, analyse_here
from ._factors import FactorIndex, HessianScatter, coordinates, exclusive_cumsum, index_dtype, same_buffer
from ._patterns import Pattern, StructureBuild, hessian_pattern
from ._patterns_numpy import dense_pattern, dense_scatters, edge_coordinates, factor_scatter, sparse_pattern

__all__ = ["BlockStructure"]

IntArray = NDArray[np.intp]
FloatArray = NDArray[np.float64]

# (indptr, indices, per-factor gathers into the blocks, per-factor start in J.data)
_JacobianPattern = tuple[NDArray[np.signedinteger], NDArray[np.signedinteger], list[IntArray], IntArray]

CHUNK = 1 << 17
"""Products per chunk of :meth:`BlockStructure.normal_equations` (1 MiB of float64): as fast as
8 MiB chunks from 10⁴ to 10⁵ poses, and 10 MB less resident memory on a 10⁴-pose cube
(``benchmarks/bench_scaling.py``)."""


class BlockStructure:
    """The fixed sparsity of ``J``, ``H = JᵀWJ`` and ``g = JᵀWr`` for a factor graph.

    Parameters
    ----------
    dims : array_like of int, shape (n_vars,)
        Tangent dimension ``d_v ≥ 1`` of every variable.
    factors : sequence of (var_ids, residual_dim)
        One entry per factor type: ``var_ids`` is an integer array
        ``(m, arity)`` of the variables each edge touches, in slot order (all
        variables in one slot share a dimension; an edge touches a variable at
        most once); ``residual_dim`` is the length of each edge's residual.
    dense : bool
        Store every entry of ``H`` (``n²``: for small systems, see
        :data:`~manopt_lie.linalg.DENSE_MAX`) instead of the touched blocks.

    Raises
    ------
    ValueError
        On ids out of range, a slot with mixed dimensions, a repeated variable
        within an edge, or a factor type without edges (naming factor and
        edge), or on no factor types at all.

    Attributes
    ----------
    dims : ndarray of int, shape (n_vars,)
        The variables' tangent dimensions.
    offsets : ndarray of int, shape (n_vars + 1,)
        ``[0, cumsum(dims)]``: variable ``v`` owns coordinates
        ``offsets[v]:offsets[v + 1]`` of ``δ``, ``g`` and ``H``.
    dense : bool
        Whether every entry of ``H`` is stored.

    Notes
    -----
    ``H`` is a canonical CSC matrix (sorted indices, no duplicates) that
    stores every block ``(v_s, v_t)`` some edge touches plus every diagonal
    block, so its ``indptr``/``indices`` arrays are the same objects on every
    call and a symbolic factorization of ``H`` can be reused (also after
    :meth:`add_diagonal`). Several edges on the same pair of variables are
    summed. A ``dense`` structure stores every entry instead: ``H.data`` is then the
    dense matrix itself, column after column (``H.data.reshape(n, n)``, symmetric).
    """

    # Made by the build (which one depends on the structure; on the worker, at _finish).
    _block_pattern: tuple[NDArray[np.signedinteger], NDArray[np.signedinteger]]
    _indptr: NDArray[np.signedinteger]
    _indices: NDArray[np.signedinteger]
    _diag_pos: NDArray[np.signedinteger]

    def __init__(self, dims: ArrayLike, factors: Sequence[tuple[ArrayLike, int]], *, dense: bool = False) -> None:
        self._setup(dims, factors, dense, on_worker=False)

    def _setup(self, dims: ArrayLike, factors: Sequence[tuple[ArrayLike, int]], dense: bool, on_worker: bool) -> None:
        """The constructor's work; ``on_worker``: the compiled build is left to the worker thread where
        it can run there (:meth:`_started`)."""
        d = np.asarray(dims)
        if d.ndim != 1 or d.size == 0 or d.dtype.kind not in "iu" or (lowest := int(d.min())) < 1:  # integers
            raise ValueError(f"dims must be a non-empty 1-D array of positive integers, got {d!r}")
        self.dims: IntArray = d.astype(np.intp)
        if len(factors) == 0:
            raise ValueError("factors must hold at least one factor type")
        ids = [_factors.factor_ids(k, v, r) for k, (v, r) in enumerate(factors)]
        uniform = int(d.max()) == lowest
        self._lowest = lowest  # the smallest dimension (a solver's choice of kind reads it)
        # One dimension: the compiled build checks the edges in its pass over them, NumPy below for
        # the other builds. Several: NumPy checks them here, as it finds the slots' dimensions.
        check = _factors.check_edges
        slots = [(lowest,) * a.shape[1] if uniform else check(k, a, self.dims) for k, a in enumerate(ids)]
        self.dense = bool(dense)
        self._n = d.size * lowest if uniform else int(self.dims.sum())
        self._ordering: IntArray | None = None  # computed at first use
        self._variable_order: IntArray | None = None
        self._digest: bytes | None = None
        self._early: EarlyAnalysis | None = None
        self._here: Analysis | None = None  # made at the first ask where no early analysis was started
        self._build: StructureBuild | None = None  # running on the worker, until _finish
        # Per factor: position in H.data of each entry of every A_eᵀA_e, and coordinate of
        # each column of A_e, in the index dtype (int32 below 2³¹ entries: half the memory).
        self._factors = [FactorIndex(a, int(r), s) for a, s, (_, r) in zip(ids, slots, factors, strict=True)]
        for a in (self.dims, *ids):  # this structure's own copies, its key in the pools (nothing writes to them)
            a.flags.writeable = False
        self._inputs = StructureInputs(self.dims, [(f.var_ids, f.residual_dim) for f in self._factors], self.dense)
        squares = d.size * lowest**2 if uniform else int(np.dot(self.dims, self.dims))
        self._dimension = dimension = lowest if uniform else 0
        entries = EarlyAnalysis.entries(self.dims, dimension) if on_worker else 0  # its arrays cut with the build's
        build = None if dense else hessian_pattern(self.dims, self._n, squares, self._factors, entries, dimension)
        if build is None and uniform:
            for k, a in enumerate(ids):
                check(k, a, self.dims)
        if build is not None and on_worker:  # built, then analysed, on the worker
            self._early = EarlyAnalysis.start_with(self.dims, dimension, build)
            self._build = build if self._early is not None else None
        if build is not None and self._build is None:  # compiled, here
            self._take(build.run())
            # The first solve's ordering and symbolic analysis, on a thread while H is first assembled.
            self._early = EarlyAnalysis.start(self.dims, dimension, self._indptr, *self._block_pattern)
        elif dense:
            self.offsets = exclusive_cumsum(self.dims)
            self._block_pattern, self._indptr, self._indices, self._diag_pos = dense_pattern(self.dims.size, self._n)
            self._hess_scatter, self._grad_scatter = dense_scatters(self._factors, self.offsets, self._n)
            self._diag_pos.flags.writeable = False
        elif build is None:  # NumPy's build: no compiler, 64-bit indices, or scatters made per chunk
            self.offsets = exclusive_cumsum(self.dims)
            pattern, block_ids, layout = sparse_pattern(self.dims, self.offsets, [f.var_ids for f in self._factors])
            self._block_pattern, self._indptr, self._indices, self._diag_pos = pattern
            itype = index_dtype(max(self._indices.size, self._n))
            scatters = [factor_scatter(f, b, layout, self.offsets, itype)
                        for f, b in zip(self._factors, block_ids, strict=True)]  # fmt: skip
            self._hess_scatter = [h for h, _ in scatters]
            self._grad_scatter = [g for _, g in scatters]
            self._diag_pos.flags.writeable = False
        # Workspaces reused by NumPy's normal_equations (one chunk's products and W·A): fresh arrays
        # cost more in page faults than the products written into them. One set per thread,
        # made on first use, so that threads may share the structure.
        self._local = threading.local()
        self._jac: _JacobianPattern | None = None

    def _take(self, built: Pattern) -> None:
        """The compiled build's arrays (:meth:`StructureBuild.result`)."""
        self._block_pattern, self._indptr, self._indices, self._diag_pos, made, self.offsets = built
        pairs = zip(made, self._factors, strict=True)
        self._hess_scatter = [HessianScatter.of_positions(h, f.width) for (h, _), f in pairs]
        self._grad_scatter = [g for _, g in made]
        self._diag_pos.flags.writeable = False

    @classmethod
    def _started(
        cls, dims: NDArray[np.integer], factors: Sequence[tuple[NDArray[np.integer], int]], dense: bool
    ) -> BlockStructure | None:
        """The structure of these inputs, its compiled build and analysis started on the worker thread
        (where they can run there; else built here), for a problem that evaluates its first residuals
        meanwhile and then calls :meth:`_finish` before anything else; ``None`` where the inputs are
        invalid (the constructor raises then)."""
        structure = cls.__new__(cls)
        try:
            structure._setup(dims, factors, dense, on_worker=True)
        except ValueError:
            return None
        return structure

    def _finish(self) -> BlockStructure:
        """This structure, its build on the worker (:meth:`_started`) waited for and taken.

        Raises
        ------
        ValueError
            As the constructor, on edges its checks refuse.
        """
        build, self._build = self._build, None
        if build is not None:
            assert self._early is not None
            status = self._early.built()  # None: forked since; the build is made here
            self._take(build.run() if status is None else build.result(status))
        return self

    @classmethod
    def shared(
        cls, dims: ArrayLike, factors: Sequence[tuple[ArrayLike, int]], *, dense: bool = False
    ) -> BlockStructure:
        """The structure of these inputs from the process's pool: the one built already for the same
        dimensions, edge arrays and residual lengths (by any problem: a graph solved again, another
        cost or other measurements on it), else a new one, then kept. At most
        :data:`~manopt_lie.linalg._analyses.MAX_IDLE` structures are kept;
        :func:`~manopt_lie.linalg.clear_caches` empties the pool.

        Parameters
        ----------
        dims, factors, dense
            As for the constructor: ``dims`` of shape ``(n_vars,)``, per factor type ``var_ids``
            of shape ``(m, arity)`` and its ``residual_dim``.

        Returns
        -------
        BlockStructure
            Shared, not copied: nothing changes a built structure. The pool keys it by its own
            copies of the inputs (:class:`~manopt_lie.linalg._analyses.StructureInputs`).

        Raises
        ------
        ValueError
            As the constructor, for a new structure; nothing is kept then.
        """
        return cls._shared_later(dims, factors, dense, start=False)()

    @classmethod
    def _shared_later(
        cls, dims: ArrayLike, factors: Sequence[tuple[ArrayLike, int]], dense: bool, start: bool = True
    ) -> Callable[[], BlockStructure]:
        """:meth:`shared` in two steps: where the pool lacks the structure, its build and analysis are
        started on the worker thread now (``start``: :meth:`_started`), and the callable returned
        gives :meth:`shared`'s structure (the started one finished, pooled), raising as it would. For
        a problem whose factors declare their residuals' lengths: it evaluates its first residuals
        in between (CSAIL: the build's 0.1 ms off its first linearization)."""
        dims_, pairs = np.asarray(dims), [(np.asarray(ids), int(r)) for ids, r in factors]
        key = StructureInputs(dims_, pairs, dense)  # the caller's arrays: for the look-up only
        started = cls._started(dims_, pairs, dense) if start and key not in STRUCTURES else None

        def build() -> BlockStructure:
            return started._finish() if started is not None else cls(dims_, pairs, dense=dense)

        return lambda: STRUCTURES.get(key, build)

    @functools.cached_property
    def _chunks(self) -> list[int]:
        """Edges per chunk of NumPy's normal_equations: the products of a chunk fill ~CHUNK floats."""
        return [max(1, min(f.m, CHUNK // f.width**2)) for f in self._factors]

    def _workspaces(self) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.signedinteger]]:
        """This thread's workspaces for NumPy's :meth:`normal_equations` (H products, g products, W·A,
        and the positions of a chunk's products where a factor's scatter is made per chunk)."""
        work: tuple[FloatArray, FloatArray, FloatArray, NDArray[np.signedinteger]] | None = getattr(
            self._local, "work", None
        )
        if work is None:
            sizes = [
                (c * f.width**2, c * f.width, c * f.residual_dim * f.width)
                for c, f in zip(self._chunks, self._factors, strict=True)
            ]
            made = [c * s.width**2 for c, s in zip(self._chunks, self._hess_scatter, strict=True) if s.whole is None]
            positions = np.empty(max(made, default=0), dtype=self._hess_scatter[0].dtype)  # one index dtype for all
            work = (np.empty(max(h for h, _, _ in sizes)), np.empty(max(g for _, g, _ in sizes)),
                    np.empty(max(w for _, _, w in sizes)), positions)  # fmt: skip
            self._local.work = work
        return work

    # -- symbolic analysis -------------------------------------------------

    def _jacobian_pattern(self) -> _JacobianPattern:
        """CSR pattern of ``J`` — every row of edge ``e`` holds ``e``'s columns, sorted — and
        the gather of each factor's blocks into its data; built at the first :meth:`jacobian`."""
        if self._jac is not None:
            return self._jac
        cols, gathers = [], []
        for f in self._factors:
            m, r, width = f.m, f.residual_dim, f.width
            colmap = edge_coordinates(self.offsets, f)
            order = np.argsort(colmap, axis=1, kind="stable")
            jac = (np.arange(m) * (r * width))[:, None, None] + (np.arange(r) * width)[:, None] + order[:, None, :]
            gathers.append(jac.ravel())
            cols.append(np.broadcast_to(np.take_along_axis(colmap, order, 1)[:, None, :], (m, r, width)).ravel())
        row_len = np.concatenate([np.full(f.m * f.residual_dim, f.width) for f in self._factors])
        indptr = exclusive_cumsum(row_len)
        itype = index_dtype(max(int(indptr[-1]), self._n))
        start = exclusive_cumsum(np.array([f.m * f.residual_dim * f.width for f in self._factors]))
        self._jac = (indptr.astype(itype), np.concatenate(cols).astype(itype), gathers, start)
        return self._jac

    # -- properties ----------------------------------------------------------

    @property
    def n(self) -> int:
        """Total tangent dimension ``Σ_v d_v`` (columns of ``J``, size of ``H``)."""
        return self._n

    @property
    def n_rows(self) -> int:
        """Number of residual rows ``Σ_k m_k r_k`` (rows of ``J``)."""
        return sum(f.m * f.residual_dim for f in self._factors)

    @property
    def nnz(self) -> int:
        """Number of stored entries of ``H`` (both triangles, all diagonal blocks)."""
        return self._indices.size

    @property
    def indptr(self) -> NDArray[np.signedinteger]:
        """The CSC ``indptr`` of ``H`` (the same array object on every call)."""
        return self._indptr

    @property
    def indices(self) -> NDArray[np.signedinteger]:
        """The CSC row ``indices`` of ``H`` (the same array object on every call)."""
        return self._indices

    @property
    def diagonal_positions(self) -> NDArray[np.signedinteger]:
        """Where each diagonal entry ``H[i, i]`` sits in ``H.data``, shape ``(n,)`` (read-only,
        the same array on every call): e.g. ``H.data[positions[i]] += 1`` adds to ``H[i, i]``."""
        return self._diag_pos

    @property
    def block_pattern(self) -> tuple[NDArray[np.signedinteger], NDArray[np.signedinteger]]:
        """The variables' graph as the block CSC pattern of ``H``: ``indptr`` of shape
        ``(n_vars + 1,)`` and the row variable of every stored block ``(v_s, v_t)``, sorted
        within each column, every diagonal block included (both triangles, like ``H``)."""
        return self._block_pattern

    def variable_ordering(self) -> IntArray | None:
        """A fill-reducing order of the variables: AMD on the variables' graph (called directly,
        else through CVXOPT's ``amd.order``: the same order), as GTSAM orders its variables;
        ``None`` without CVXOPT. Computed once.

        Ordering the ``n_vars`` variables instead of the ``n`` coordinates reads ``d²`` times
        fewer entries (AMD would find the same supervariables), which keeps CHOLMOD's
        analysis small: on a 10⁴-pose 3-D graph its memory drops from ~70 MB to a few.
        """
        if self._variable_order is None:
            early = self._early_analysis()  # the same order, made on a thread at construction
            order = None if early is None else early.order
            self._variable_order = order if order is not None else variable_order(*self._block_pattern)
        return self._variable_order

    def _early_analysis(self) -> Analysis | None:
        """What the analysis started at construction made (:mod:`~manopt_lie.linalg._early`; waited
        for), or ``None`` where none was started."""
        return None if self._early is None else self._early.result()

    def _analysis(self) -> Analysis | None:
        """:meth:`_early_analysis`, else the same made here once
        (:func:`~manopt_lie.linalg._early.analyse_here`: a structure past
        :data:`~manopt_lie.linalg._early.EARLY_ENTRIES`, or of variables of several dimensions);
        ``None`` where neither can be made."""
        if self._early is not None:
            return self._early.result()
        if self._here is None and not self.dense and (order := self.variable_ordering()) is not None:
            # (64-bit patterns: nothing analysed; the compiled steps decline them)
            self._here = analyse_here(self.dims, self._dimension, self._indptr, *self._block_pattern, order)
        return self._here

    def fill_reducing_ordering(self) -> IntArray | None:
        """A fill-reducing permutation of ``H``'s coordinates: the :meth:`variable_ordering`, each
        variable's coordinates kept together and in order; ``None`` without CVXOPT. Computed once."""
        if self._ordering is None:
            order = self.variable_ordering()
            if order is None:
                return None
            self._ordering = coordinates(self.offsets, self.dims, order)
        return self._ordering

    def pattern_digest(self) -> bytes:
        """A digest of ``H``'s pattern through what determines it: the variables' dimensions and
        block pattern (``d²`` times fewer bytes than its coordinates), equal for structures of one
        pattern however their edges were listed. Computed once."""
        if self._digest is None:
            self._digest = digest(self.dims, *self._block_pattern) + b"blocks"
        return self._digest

    # -- numeric assembly ----------------------------------------------------

    def _check_blocks(self, blocks: Sequence[ArrayLike]) -> list[FloatArray]:
        if len(blocks) != len(self._factors):
            raise ValueError(f"expected {len(self._factors)} Jacobian block arrays (one per factor), got {len(blocks)}")
        out = []
        for k, (a, f) in enumerate(zip(blocks, self._factors, strict=True)):
            arr = np.asarray(a, dtype=np.float64)
            if arr.shape != (f.m, f.residual_dim, f.width):
                raise ShapeError(
                    f"blocks[{k}]: expected shape (m, residual_dim, Σ slot dims) = "
                    f"{(f.m, f.residual_dim, f.width)}, got {arr.shape}"
                )
            out.append(arr)
        return out

    def _csc(self, data: FloatArray) -> sp.csc_matrix:
        return sp.csc_matrix((data, self._indices, self._indptr), shape=(self._n, self._n), copy=False)

    def jacobian(self, blocks: Sequence[ArrayLike]) -> sp.csr_matrix:
        """The sparse Jacobian ``J`` (CSR, sorted indices, fixed pattern).

        Parameters
        ----------
        blocks : sequence of array_like, shape (m_k, r_k, D_k)
            Per factor type, each edge's Jacobian ``A_e = [∂r_e/∂x_{v_0} | …]``
            w.r.t. its variables concatenated in slot order.

        Returns
        -------
        scipy.sparse.csr_matrix, shape (n_rows, n)
            Row ``ρ_k + e·r_k + i`` is row ``i`` of edge ``e`` of factor ``k``
            (``ρ_k`` = rows of the factors before ``k``).
        """
        indptr, indices, gathers, starts = self._jacobian_pattern()
        data = np.empty(indices.size)
        for a, gather, start in zip(self._check_blocks(blocks), gathers, starts, strict=False):
            data[start : start + gather.size] = a.ravel()[gather]
        shape = (self.n_rows, self._n)
        return sp.csr_matrix((data, indices, indptr), shape=shape, copy=False)

    def normal_equations(
        self,
        blocks: Sequence[ArrayLike],
        residuals: Sequence[ArrayLike],
        weights: Sequence[ArrayLike | None] | None = None,
    ) -> tuple[sp.csc_matrix, FloatArray]:
        """Gauss-Newton normal equations ``H = JᵀWJ`` and ``g = JᵀWr``.

        With ``A_e`` the block of edge ``e`` and ``w_e`` its weight,

            H = Σ_e w_e A_eᵀ A_e,     g = Σ_e w_e A_eᵀ r_e,

        each edge's ``(D, D)`` product scattered into the blocks of its
        variables (products of edges on the same pair are summed). The
        Gauss-Newton step solves ``H δ = −g``.

        Parameters
        ----------
        blocks : sequence of array_like, shape (m_k, r_k, D_k)
            Per factor type, the edges' Jacobians (see :meth:`jacobian`).
        residuals : sequence of array_like, shape (m_k, r_k)
            Per factor type, the edges' residuals.
        weights : sequence of array_like or None, shape (m_k,), optional
            Per factor type, a scalar weight per edge (e.g. IRLS weights of a
            robust loss), or ``None`` for weights 1; ``None`` (the default) means ``W = I``.

        Returns
        -------
        H : scipy.sparse.csc_matrix, shape (n, n)
            Symmetric, both triangles stored, with :attr:`indptr` and
            :attr:`indices` (the same objects on every call).
        g : ndarray, shape (n,)

        Notes
        -----
        Assembled in compiled code, one pass over the edges (``_assembly``), or by
        NumPy in chunks with workspaces of the structure, one set per thread; either
        way several threads may assemble from one structure at once. ``H`` and ``g``
        are always new arrays.
        """
        blocks_, weights_ = self._check_blocks(blocks), self._check_weights(weights)
        return self._hessian(blocks_, weights_), self._gradient(blocks_, self._check_residuals(residuals), weights_)

    def hessian(
        self, blocks: Sequence[ArrayLike], weights: Sequence[ArrayLike | None] | None = None, *,
        out: sp.csc_matrix | None = None,
    ) -> sp.csc_matrix:
        """``H = JᵀWJ`` alone (see :meth:`normal_equations`): a fresh matrix of the fixed pattern,
        or ``out`` (a matrix of this structure, e.g. the ``H`` of an earlier point) with its
        values overwritten — no new ``nnz`` values to allocate and fault in."""
        if out is not None and not (
            out.format == "csc" and same_buffer(out.indptr, self._indptr) and same_buffer(out.indices, self._indices)
            and out.data.dtype == np.float64 and out.data.flags.c_contiguous and out.data.flags.writeable
        ):  # fmt: skip
            raise ValueError("hessian(out=): out must be an H of this structure (its indptr and indices)")
        return self._hessian(self._check_blocks(blocks), self._check_weights(weights), out)

    def gradient(
        self,
        blocks: Sequence[ArrayLike],
        residuals: Sequence[ArrayLike],
        weights: Sequence[ArrayLike | None] | None = None,
    ) -> FloatArray:
        """``g = JᵀWr`` alone (see :meth:`normal_equations`), shape ``(n,)``: a fraction of the
        cost of ``H`` (one ``(1, r)·(r, D)`` product per edge instead of ``(D, r)·(r, D)``)."""
        blocks_, weights_ = self._check_blocks(blocks), self._check_weights(weights)
        return self._gradient(blocks_, self._check_residuals(residuals), weights_)

    def _check_residuals(self, residuals: Sequence[ArrayLike]) -> list[FloatArray]:
        if len(residuals) != len(self._factors):
            raise ValueError(f"expected {len(self._factors)} residual arrays (one per factor), got {len(residuals)}")
        out = []
        for k, f in enumerate(self._factors):
            r = np.asarray(residuals[k], dtype=np.float64)
            if r.shape != (f.m, f.residual_dim):
                raise ShapeError(f"residuals[{k}]: expected shape {(f.m, f.residual_dim)}, got {r.shape}")
            out.append(r)
        return out

    def _check_weights(self, weights: Sequence[ArrayLike | None] | None) -> list[FloatArray | None]:
        """Per factor, its weights ``(m,)`` or ``None`` (weights 1)."""
        if weights is None:
            return [None] * len(self._factors)
        if len(weights) != len(self._factors):
            raise ValueError(f"expected {len(self._factors)} weight arrays (one per factor), got {len(weights)}")
        out: list[FloatArray | None] = []
        for k, f in enumerate(self._factors):
            w = None if weights[k] is None else np.asarray(weights[k], dtype=np.float64)
            if w is not None and w.shape != (f.m,):
                raise ShapeError(f"weights[{k}]: expected shape {(f.m,)}, got {w.shape}")
            out.append(w)
        return out

    def _hessian(
        self, blocks: list[FloatArray], weights: list[FloatArray | None], out: sp.csc_matrix | None = None
    ) -> sp.csc_matrix:
        """``Σ_e w_e A_eᵀA_e`` scattered into a fresh ``H`` (or into ``out``, zeroed first)."""
        if out is None:
            data = np.zeros(self.nnz)
        else:
            data = out.data
            data.fill(0.0)
        for k, (a, w, f) in enumerate(zip(blocks, weights, self._factors, strict=True)):
            scatter, width = self._hess_scatter[k], f.width
            if scatter.whole is not None and hessian_add(a, w, scatter.whole, data):  # compiled, one pass
                continue
            hess_vals, _, weighted, positions = self._workspaces()
            step = self._chunks[k]
            # Chunks of edges: the products of one chunk stay in cache and in a small workspace,
            # and np.add.at sums them into H (int32 scatters on its fast path). W A_e goes to a
            # workspace even for unit weights: NumPy's matmul of two views of one array takes
            # a slow path (910 edges of 6×12: 0.21 against 0.08 ms with the copy). A scatter made
            # per chunk is summed by the C where it can (the same sums as of the whole scatter).
            for e0 in range(0, f.m, step):
                e1 = min(e0 + step, f.m)
                c, ac = e1 - e0, a[e0:e1]
                at = scatter.chunk(e0, e1, positions)
                if scatter.whole is None and hessian_add(ac, None if w is None else w[e0:e1], at, data):
                    continue
                aw = weighted[: ac.size].reshape(ac.shape)
                if w is None:
                    np.copyto(aw, ac)
                else:
                    np.multiply(ac, w[e0:e1, None, None], out=aw)
                prod = np.matmul(aw.transpose(0, 2, 1), ac, out=hess_vals[: c * width * width].reshape(c, width, width))
                np.add.at(data, at, prod.reshape(-1))
        return self._csc(data) if out is None else out

    def _gradient(
        self, blocks: list[FloatArray], residuals: list[FloatArray], weights: list[FloatArray | None]
    ) -> FloatArray:
        """``Σ_e w_e A_eᵀ r_e`` scattered into a fresh ``g``."""
        g = np.zeros(self._n)
        for k, (a, r, w, f) in enumerate(zip(blocks, residuals, weights, self._factors, strict=True)):
            gs, width = self._grad_scatter[k], f.width
            if gradient_add(a, r, w, gs, g):  # compiled, one pass
                continue
            _, grad_vals, _, _ = self._workspaces()
            step = self._chunks[k]
            rw = r if w is None else r * w[:, None]
            for e0 in range(0, f.m, step):
                e1 = min(e0 + step, f.m)
                gv = np.matmul(rw[e0:e1, None, :], a[e0:e1], out=grad_vals[: (e1 - e0) * width].reshape(-1, 1, width))
                np.add.at(g, gs[e0 * width : e1 * width], gv.reshape(-1))
        return g

    def _check_pattern(self, H: sp.csc_matrix, what: str) -> None:
        if H.shape != (self._n, self._n) or H.nnz != self.nnz or H.format != "csc":
            raise ValueError(f"{what}: H does not have this structure's CSC pattern")

    def add_diagonal(self, H: sp.csc_matrix, values: ArrayLike, *, inplace: bool = False) -> sp.csc_matrix:
        """``H + diag(values)`` with the pattern of ``H`` kept (e.g. Levenberg-Marquardt damping).

        Parameters
        ----------
        H : scipy.sparse.csc_matrix, shape (n, n)
            A matrix returned by :meth:`normal_equations` (or by this method).
        values : array_like, shape (n,) or scalar
            Added to the diagonal, e.g. ``λ·H.diagonal()`` or ``λ``.
        inplace : bool
            Add to ``H.data`` itself and return ``H`` (``O(n)``, no copy) instead of a
            new matrix.

        Returns
        -------
        scipy.sparse.csc_matrix
            A matrix sharing :attr:`indptr` and :attr:`indices`, so a solver's
            symbolic analysis of ``H`` is reused; ``H`` is unchanged unless ``inplace``.
        """
        self._check_pattern(H, "add_diagonal")
        data = H.data if inplace else H.data.copy()
        data[self._diag_pos] += np.broadcast_to(np.asarray(values, dtype=np.float64), (self._n,))
        return H if inplace else self._csc(data)

    @contextmanager
    def shifted_diagonal(self, H: sp.csc_matrix, values: ArrayLike) -> Iterator[sp.csc_matrix]:
        """``H + diag(values)`` in place for the duration of a ``with`` block, ``H`` restored after.

        The diagonal of ``H`` is saved (``n`` numbers), ``values`` added to it, and the
        saved diagonal written back on leaving the block, exceptions included, so ``H``
        is bitwise unchanged afterwards. Damping thus costs ``O(n)``, not a copy of
        ``H``'s ``nnz`` values; ``H`` must not be read elsewhere (another thread) meanwhile.

        Yields
        ------
        scipy.sparse.csc_matrix
            ``H`` itself, damped.
        """
        self._check_pattern(H, "shifted_diagonal")
        pos = self._diag_pos
        saved = H.data[pos]  # fancy indexing: a copy
        H.data[pos] = saved + np.asarray(values, dtype=np.float64)  # a scalar or (n,) (else the assignment raises)
        try:
            yield H
        finally:
            H.data[pos] = saved
