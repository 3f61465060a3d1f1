"""Sparse SPD solver whose ordering and symbolic analysis are computed once per pattern."""

from __future__ import annotations

import functools
import weakref
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from ..errors import ShapeError
from ._analyses import ANALYSES, Key, pattern_key
from ._backends import _PACKAGES, BACKENDS, DENSE_MAX, Backend, _Dense, available_backends
from ._cholmod import cholmod_backend
from ._factors import same_buffer
from ._ldl import available as ldl_available
from ._ldl import ldl_backend
from ._vector import dot, norm
from .errors import SingularSystemError

if TYPE_CHECKING:
    from .structure import BlockStructure

__all__ = ["CholeskySolver", "FactorCost"]

FloatArray = NDArray[np.float64]

_NO_STATS: Mapping[str, float] = MappingProxyType({})
_KINDS = {None: "", True: ":supernodal", False: ":simplicial"}  # in the pool's keys of CHOLMOD's analyses


def _check_square(H: Any) -> sp.csc_matrix:
    if not sp.issparse(H) or H.ndim != 2 or H.shape[0] != H.shape[1]:
        raise ValueError(f"H must be a square scipy.sparse matrix, got {type(H).__name__} {getattr(H, 'shape', '')}")
    return H if H.format == "csc" else H.tocsc()


@functools.lru_cache(maxsize=16)
def _probe(n: int) -> FloatArray:
    """The fixed random probe ``z`` of order ``n`` (read-only, shared: made once per order)."""
    z = np.random.default_rng(0).standard_normal(n)
    z.flags.writeable = False
    return z


@dataclass(frozen=True)
class FactorCost:
    """The size of a Cholesky factor ``L`` and the cost of computing it, from a symbolic analysis.

    Attributes
    ----------
    nnz : float
        ``Σ_j c_j``, ``c_j`` the count of column ``j`` of ``L`` (its diagonal included).
    flops : float
        ``Σ_j c_j²``: CHOLMOD's flop count of a factorization.
    """

    nnz: float
    flops: float


SUPERNODE_DIM = 6
"""A structure whose variables all have at least this dimension is factored by supernodes."""


class CholeskySolver:
    """Solve ``H x = b`` for sparse symmetric positive definite ``H`` of a fixed pattern.

    The fill-reducing ordering and symbolic factorization depend only on the
    pattern of ``H``, so :meth:`analyze` computes them once; each
    :meth:`factorize` then computes ``H = L D Lᵀ`` (or its LU twin) for new
    values and :meth:`solve` applies it. Calling the solver, ``solver(H, b)``,
    analyses on first use or when the pattern changes and factorizes always,
    which suits a Gauss-Newton loop (see :meth:`BlockStructure.add_diagonal`
    for damping without changing the pattern). It is a
    :class:`~manopt_lie.linalg.LinearSolver` (``linear_solver="cholesky"``):
    :meth:`bind` gives each run its own solver and analysis.

    Parameters
    ----------
    backend : {"auto", "cholmod", "ldl", "qdldl", "superlu", "dense"}
        ``"auto"`` (the default) takes the first importable of CHOLMOD (optional
        package ``cvxopt``), QDLDL (optional ``qdldl``) and SciPy's SuperLU; both
        optional ones are 2-8x faster than SuperLU on pose graphs, and CHOLMOD's
        supernodes another 4x on dense 3-D graphs (``benchmarks/bench_linalg.py``).
        A solver of the automatic choice bound to a structure of order ≤ ``DENSE_MAX``
        (128) factors it dense instead (LAPACK's ``potrf``): LM on tinyGrid3D (54
        unknowns) 3.97 → 3.75 ms, a 4×4 grid of planar poses 2.12 → 1.95 ms; from
        ~150 unknowns CHOLMOD is faster (a 10×10 grid, 300: 2.91 against 4.11 ms).
        One bound to a larger structure whose analysis, made on the structure's worker
        thread, found CHOLMOD's simplicial kind (2-D pose graphs) factors with ``"ldl"``,
        the compiled simplicial ``LDLᵀ`` of that analysis (:mod:`~manopt_lie.linalg._ldl`):
        :attr:`backend` then says ``"ldl"``. ``"ldl"`` asked for analyses any pattern itself.
    rtol : float
        Relative residual tolerance of the checks below (default 1e-6).
    supernodal : bool, optional
        CHOLMOD only: ``True`` forces its supernodal ``LLᵀ`` (relaxed supernodes, which
        selected inversion wants), ``False`` its simplicial ``LDLᵀ``; ``None`` (the
        default) lets its analysis choose from the flops per entry of the factor, except
        for a structure (:meth:`bind`) whose variables all have dimension ≥ 6 (3-D
        poses), which gets supernodes: their dense 6×6 blocks make each supernode at
        least six columns wide, and CHOLMOD's rule picked the simplicial kind on mid-size
        3-D graphs where supernodes factor 1.2–1.7× faster (cubes of 10³ and 14³ poses).

    Attributes
    ----------
    backend : str
        The backend in use.
    n_analyses : int
        How many times a pattern was analysed (stays 1 while the pattern is fixed),
        whether anew or taken from the pool below.

    Notes
    -----
    ``H`` must store both triangles (as :class:`BlockStructure` does) and be
    symmetric; only the pattern is checked for that (not for the pattern of the
    structure a solver was bound to, symmetric by construction).

    Analyses are reused across solvers: a solver lends its analysed backend to a
    process-wide pool (:mod:`._analyses`) when it is garbage-collected, and the
    next solver of the same pattern takes it instead of analysing again — so a
    problem solved again, or another problem of the same graph, skips its
    ordering and symbolic factorization (``clear_analysis_cache()`` empties the pool).

    Nothing garbage is ever returned. Every factorization is followed by the
    solve of a fixed random probe ``z``, and every solution ``x`` of
    ``Hx = b`` (probe or not) must be finite, satisfy
    ``‖Hx − b‖ ≤ rtol·‖b‖`` and show positive curvature ``bᵀx > 0``;
    otherwise :class:`SingularSystemError` is raised. A pose graph with an
    unfixed gauge has pivots of rounding size: even when ``b`` lies in the
    range of ``H`` (so that ``H⁻¹b`` looks fine), ``H⁻¹z`` explodes and fails
    the residual check: measured on the shared pose graphs, an unfixed gauge
    leaves a relative probe residual of 1–20, an anchored graph at most 2e-8
    (``parking-garage``, condition number 1e11). The price is that, with the
    default ``rtol``, systems with condition number beyond about 1e12–1e13
    count as singular; loosen ``rtol`` for worse ones. CHOLMOD's pivot signs
    are read after every factorization (its supernodal ``LLᵀ`` fails on them,
    its simplicial ``LDLᵀ`` is checked); QDLDL's and SuperLU's are not (they
    expose them only with a copy of the factor), so with those an indefinite
    but well-conditioned ``H`` — impossible for ``JᵀWJ`` with ``w ≥ 0`` — is
    caught only when ``b`` or the probe meets negative curvature.
    """

    def __init__(self, backend: str = "auto", *, rtol: float = 1e-6, supernodal: bool | None = None) -> None:
        usable = available_backends()
        self._auto = backend == "auto"
        if backend == "auto":
            backend = usable[0]
        elif backend not in BACKENDS:
            raise ValueError(f"unknown backend {backend!r}; choose 'auto' or one of {sorted(BACKENDS)}")
        elif backend not in usable:
            raise ValueError(f"backend {backend!r} needs an optional package: pip install {_PACKAGES[backend]}"
                             + (" (and a C compiler)" if backend == "ldl" else ""))  # fmt: skip
        self.backend = backend
        self._chosen = backend  # the automatic choice before a structure's analysis is seen (analyze)
        self.rtol = float(rtol)
        self.supernodal = supernodal
        self.n_analyses = 0
        self._impl: Backend | None = None
        self._indptr: NDArray[np.signedinteger] | None = None
        self._indices: NDArray[np.signedinteger] | None = None
        self._probe = np.empty(0)
        self._H: sp.csc_matrix | FloatArray | None = None  # the factorized H, for the checks
        self._trusted: tuple[NDArray[np.signedinteger], NDArray[np.signedinteger]] | None = None
        self._lend: weakref.finalize | None = None
        self._structure: BlockStructure | None = None

    @staticmethod
    def available_backends() -> tuple[str, ...]:
        """Names of the backends usable here, fastest first."""
        return available_backends()

    # -- the LinearSolver protocol ---------------------------------------------

    def bind(self, structure: BlockStructure) -> CholeskySolver:
        """A fresh solver with these settings and no analysis, for one run
        (:class:`~manopt_lie.linalg.LinearSolver`); the structure's pattern is
        analysed at the first call (or taken from the pool of analyses)."""
        supernodal, backend = self.supernodal, self._chosen
        if self._auto and supernodal is None and structure.n <= DENSE_MAX:
            backend = "dense"  # a small system: LAPACK on the dense matrix, no sparse machinery
        elif supernodal is None and backend == "cholmod" and structure._lowest >= SUPERNODE_DIM:
            supernodal = True
        solver = CholeskySolver(backend, rtol=self.rtol, supernodal=supernodal)
        solver._auto = self._auto and backend == "cholmod" and supernodal is None  # may take "ldl" (analyze)
        solver._trusted = (structure.indptr, structure.indices)
        solver._structure = structure
        return solver

    @property
    def stats(self) -> Mapping[str, float]:
        """Nothing to report: a direct solve is exact or raises."""
        return _NO_STATS

    # -- phases --------------------------------------------------------------

    def analyze(self, H: sp.spmatrix | sp.sparray) -> None:
        """Compute the ordering and symbolic factorization from the pattern of ``H``.

        The values of ``H`` are ignored: the backend analyses (and factors
        once) a diagonally dominant matrix of the same pattern.

        Raises
        ------
        ValueError
            If ``H`` is not square, its pattern is not symmetric or it misses
            a diagonal entry.
        """
        H = _check_square(H)
        own = self._trusted  # the structure's own pattern: canonical and symmetric by construction
        trusted = own is not None and same_buffer(H.indptr, own[0]) and same_buffer(H.indices, own[1])
        if not trusted and not H.has_canonical_format:
            H = H.copy()
            H.sum_duplicates()
        structure = self._structure if trusted else None
        early = None
        if structure is not None:  # the variables' analysis; an automatic choice makes it where none started
            early = structure._analysis() if self._auto else structure._early_analysis()
        if self._auto:  # CHOLMOD, or the compiled LDLᵀ where the structure's analysis made B's simplicial factor
            simplicial = early is not None and early.simplicial is not None and ldl_available()
            self.backend = "ldl" if simplicial else self._chosen
        key: Key | None = None
        impl: Backend | None = None
        if trusted and self.backend == "dense" and self._structure is not None and self._structure.dense:
            # A dense structure's matrix, every entry stored: nothing to analyse, nothing worth pooling.
            impl = _Dense(H.indptr, H.indices)
        else:
            kind = _KINDS[self.supernodal]  # CHOLMOD's kinds apart
            inputs = self._structure._inputs if trusted and self._structure is not None else None
            key = pattern_key(self.backend + (kind if self.backend == "cholmod" else ""), H.indptr, H.indices, inputs)
            impl = ANALYSES.acquire(key)
        if impl is None:
            if not trusted:
                pattern = sp.csc_matrix((np.ones(H.nnz), H.indices, H.indptr), shape=H.shape)
                if (pattern != pattern.T).nnz:
                    raise ValueError("H must be symmetric with both triangles stored; its pattern is not symmetric")
            if structure is not None and self.backend == "cholmod":
                block_form = (structure.dims, *structure.block_pattern)
                impl = cholmod_backend(H.indptr, H.indices, None, self.supernodal, block_form,
                                       structure.variable_ordering(), early)  # fmt: skip
            elif structure is not None and self.backend == "ldl":
                block_form = (structure.dims, *structure.block_pattern)
                impl = ldl_backend(H.indptr, H.indices, block_form, structure.variable_ordering(), early)
            elif self.backend == "cholmod":
                impl = cholmod_backend(H.indptr, H.indices, None, self.supernodal)
            else:
                impl = BACKENDS[self.backend](H.indptr, H.indices)
        if self._lend is not None:
            self._lend()  # the previous pattern's backend goes back to the pool
        self._lend = None
        if key is not None:
            self._lend = weakref.finalize(self, ANALYSES.release, key, impl)
            self._lend.atexit = False
        self._impl = impl
        self._indptr, self._indices = H.indptr, H.indices
        self._probe = _probe(H.shape[0])
        self._H = None
        self.n_analyses += 1

    @property
    def factor_cost(self) -> FactorCost | None:
        """The analysed pattern's factor size and flops (CHOLMOD's analysis called directly;
        ``None`` before :meth:`analyze` and for the other backends)."""
        cost = getattr(self._impl, "cost", None)
        return None if cost is None else FactorCost(*cost)

    def _own_backend(self) -> Backend:
        """The analysed (and factorized) backend, kept by the caller: it is never lent to the
        pool, whose next borrower would overwrite its factor (e.g. a factor handed out for
        selected inversion)."""
        assert self._impl is not None, "analyze() first"
        if self._lend is not None:  # (a dense structure's backend is never pooled)
            self._lend.detach()
        return self._impl

    def matches(self, H: sp.spmatrix | sp.sparray) -> bool:
        """Whether ``H`` (CSC) has the pattern of the last :meth:`analyze`."""
        if self._indptr is None or self._indices is None or H.format != "csc":
            return False
        if same_buffer(H.indptr, self._indptr) and same_buffer(H.indices, self._indices):
            return True
        return bool(np.array_equal(H.indptr, self._indptr) and np.array_equal(H.indices, self._indices))

    def factorize(self, H: sp.spmatrix | sp.sparray) -> None:
        """Numeric factorization of ``H``, whose pattern must be the analysed one.

        Raises
        ------
        ValueError
            If the pattern differs from the analysed one (call :meth:`analyze`).
        SingularSystemError
            If the factorization fails or the probe solve fails its checks.
        """
        H = _check_square(H)
        if not self.matches(H):
            raise ValueError("H does not have the analysed sparsity pattern; call analyze(H) first")
        assert self._impl is not None
        self._H = None
        self._impl.factorize(np.asarray(H.data, dtype=np.float64))
        dense = getattr(self._impl, "matrix", None)  # the dense backend's H: the same matrix, a faster product
        checked = H if dense is None else dense
        self._check(checked, self._probe, self._impl.solve(self._probe), "the probe solve H⁻¹z after factorization")
        self._H = checked

    def solve(self, b: ArrayLike) -> FloatArray:
        """The solution ``x = H⁻¹b`` with the last factorization, checked.

        Parameters
        ----------
        b : array_like, shape (n,)

        Raises
        ------
        SingularSystemError
            If ``x`` is not finite, ``‖Hx − b‖ > rtol·‖b‖`` or ``bᵀx ≤ 0``.
        """
        if self._H is None or self._impl is None:
            raise RuntimeError("factorize(H) must succeed before solve(b)")
        n = self._H.shape[0]
        b_ = np.asarray(b, dtype=np.float64)
        if b_.shape != (n,):
            raise ShapeError(f"b: expected shape {(n,)}, got {b_.shape}")
        x = self._impl.solve(b_)
        self._check(self._H, b_, x, "the solution of H x = b")
        return x

    def __call__(self, H: sp.spmatrix | sp.sparray, b: ArrayLike) -> FloatArray:
        """``H⁻¹b``: analyse if the pattern is new, factorize, solve."""
        H = _check_square(H)
        if not self.matches(H):
            self.analyze(H)
        if self.backend != "dense":
            self.factorize(H)
            return self.solve(b)
        return self._dense_call(H, b)

    def _dense_call(self, H: sp.csc_matrix, b: ArrayLike) -> FloatArray:
        """:meth:`factorize` and :meth:`solve` of the dense backend in one pass: the probe and
        ``b`` solved together (one ``potrs`` of two columns) and checked with one product —
        the same checks, a third of the calls (a small system's solve is mostly their overhead)."""
        impl = self._impl
        assert isinstance(impl, _Dense)
        self._H = None
        impl.factorize(np.asarray(H.data, dtype=np.float64))
        assert impl.matrix is not None
        n = impl.matrix.shape[0]
        b_ = np.asarray(b, dtype=np.float64)
        if b_.shape != (n,):
            raise ShapeError(f"b: expected shape {(n,)}, got {b_.shape}")
        rhs = np.empty((n, 2), order="F")
        rhs[:, 0], rhs[:, 1] = self._probe, b_
        x = impl.solve(rhs)
        residual = impl.matrix @ x
        residual -= rhs
        # Per column: ‖Hx − b‖², ‖b‖² and bᵀx (diagonals of 2×2 products), tested together; a
        # failure is then named column by column.
        r2, b2, curvature = ((u.T @ v).diagonal() for u, v in ((residual, residual), (rhs, rhs), (rhs, x)))
        if not (np.isfinite(x).all() and (r2 <= self.rtol**2 * b2).all() and ((curvature > 0) | (b2 == 0)).all()):
            for j, what in enumerate(("the probe solve H⁻¹z after factorization", "the solution of H x = b")):
                if not np.isfinite(x[:, j]).all():
                    raise SingularSystemError(f"{what} is not finite")
                self._check_numbers(float(np.sqrt(r2[j])), float(np.sqrt(b2[j])), float(curvature[j]), what)
        self._H = impl.matrix
        return np.ascontiguousarray(x[:, 1])

    # -- checks --------------------------------------------------------------

    def _check(self, H: sp.csc_matrix | FloatArray, b: FloatArray, x: FloatArray, what: str) -> None:
        if not np.isfinite(x).all():
            raise SingularSystemError(f"{what} is not finite")
        self._check_numbers(norm(H @ x - b), norm(b), dot(b, x), what)

    def _check_numbers(self, residual: float, b_norm: float, curvature: float, what: str) -> None:
        """``‖Hx − b‖ ≤ rtol·‖b‖`` and ``bᵀx > 0`` (unless ``b = 0``), from those numbers."""
        if residual > self.rtol * b_norm:
            raise SingularSystemError(
                f"{what} fails the residual check: ‖Hx − b‖ = {residual:.2e} > rtol·‖b‖ = {self.rtol * b_norm:.2e}"
            )
        if b_norm > 0 and curvature <= 0:
            raise SingularSystemError(f"{what} shows non-positive curvature bᵀH⁻¹b = {curvature:.2e}")
