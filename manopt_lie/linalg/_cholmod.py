"""CHOLMOD called directly (:mod:`ctypes`) on NumPy's arrays, the matrix handed over in the
factor's own order.

CVXOPT ships CHOLMOD (3.0) as a shared library and loads it with ``cvxopt.cholmod``. Its Python
interface copies the matrix into CHOLMOD's form at every call (values and 64-bit row indices),
and CHOLMOD itself, given any ordering but the natural one, factors a permuted transpose of the
matrix that it makes anew at every factorization. Called directly:

- the analysis of a structure's ``H`` runs on the variables' graph (``d²`` times fewer
  entries): CHOLMOD analyses it in the structure's AMD order of the variables and postorders
  it; where every variable has one dimension, ``B``'s symbolic factor (below) is made from the
  variables' one — the column counts, or the supernodes expanded to their coordinates — and
  nothing is analysed at the scale of coordinates (:meth:`Cholmod._analyze_blocks`); otherwise
  CHOLMOD analyses ``B``'s triangle as it is, in the natural order. Any other pattern is
  analysed as it is (its lower triangle, ``stype = −1``), in the given ordering or CHOLMOD's
  choice, postordered;
- the matrix factored is one triangle of ``B = P H Pᵀ`` in the factor's final order ``P``
  (:func:`~manopt_lie.linalg._triangles.permuted_block_triangle`, 32-bit indices), its values
  gathered from ``H.data`` at each factorization into an array released after it; the factor
  is then told that its ordering is the natural one (its permutation the identity), and
  ``cholmod_factorize`` reads ``B`` as it is: the lower triangle for supernodal ``LLᵀ``, the
  upper one for simplicial ``LDLᵀ``;
- solves permute the right-hand sides (``b[P]``) and the solutions back.

Against CVXOPT's interface (parking-garage, this machine): the analysis 10 → 4.6 ms, each
factorization 6.8 → 4.2 ms; CSAIL 0.48 → 0.34 and 0.45 → 0.27 ms. Through the variables' graph
(2026-12-06) the analysis of CSAIL's ``H`` (the permuted triangle included) takes 0.19 ms
instead of 1.0.

The binding is checked once per process before it is used: the library's version (3.0.x), the
defaults ``cholmod_start`` writes where the fields' offsets say, the supernodal fields of a factor
(consistent where they are read), and the solutions of two small systems by both kinds of factor
against NumPy's, one of them made from its variables' analysis. Where a check fails, the library cannot be
found, ``H``'s indices are not 32-bit, or ``MANOPT_LIE_CHOLMOD=cvxopt`` is set, CVXOPT's
interface is used (:class:`~manopt_lie.linalg._backends._CHOLMOD`).
"""

from __future__ import annotations

import ctypes
import functools
import itertools
import os
import weakref
from ctypes import byref, c_int, c_void_p
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from .. import _native
from . import _patterns
from ._backends import _CHOLMOD, supernodal_setting
from ._cholmod_types import (
    _AMD,
    _COMMON_BYTES,
    _DEFAULTS,
    _DOUBLE,
    _GIVEN,
    _INT,
    _NATURAL,
    _NOT_POSDEF,
    _PATTERN,
    _REAL,
    _SIGNATURES,
    _SIMPLICIAL,
    _SOLVE_A,
    _SUPERNODAL,
    _array,
    _Common,
    _Dense,
    _Factor,
    _Sparse,
    cvxopt_library,
)
from ._early import Analysis, coordinates_cost
from ._factors import coordinates, exclusive_cumsum
from ._memory import TRIM_ENTRIES, release_freed_memory
from ._triangles import check_diagonal, columns, permuted_block_triangle
from .errors import SingularSystemError

__all__ = ["Cholmod", "available", "cholmod_backend"]

FloatArray = NDArray[np.float64]
IndexArray = NDArray[np.signedinteger]
Triangle = tuple[NDArray[np.int32], NDArray[np.int32], NDArray[np.signedinteger]]  # indptr, indices, gather

@functools.cache
def _library() -> Any | None:
    """CHOLMOD, checked (see the module's notes), or ``None``."""
    try:
        import cvxopt.cholmod  # noqa: F401  (loads the library this binding calls)
    except ImportError:
        return None
    lib = cvxopt_library("cholmod", _SIGNATURES)
    if lib is None:
        return None
    return lib if _works(lib) else None


def _works(lib: Any) -> bool:
    """Whether ``lib`` is CHOLMOD 3.0 laid out as :class:`_Common` says, and solves right."""
    version = (c_int * 3)()
    lib.cholmod_version(version)
    if list(version)[:2] != [3, 0]:
        return False
    buffer = ctypes.create_string_buffer(_COMMON_BYTES)
    if not lib.cholmod_start(buffer):
        return False
    common = _Common.from_buffer(buffer)
    laid_out = all(getattr(common, name) == value for name, value in _DEFAULTS.items()) and (
        [common.method[k].ordering for k in range(3)] == [_GIVEN, _AMD, 3] and list(common.nrelax) == [4, 16, 48]
    )
    lib.cholmod_finish(buffer)
    if not laid_out:
        return False
    rng = np.random.default_rng(0)
    a = rng.standard_normal((6, 6))
    dense = a @ a.T + 6.0 * np.eye(6)
    b = rng.standard_normal((6, 2))
    order = np.array([3, 1, 0, 5, 2, 4])
    # The same as 6 variables of 2 coordinates, every entry of every block nonzero: a factor made
    # from the variables'.
    big = np.kron(dense, [[1.0, 0.3], [0.3, 1.0]])
    blocks = (np.full(6, 2), np.arange(0, 37, 6, dtype=np.int32), np.tile(np.arange(6, dtype=np.int32), 6))
    coordinates_ = np.ravel([2 * order, 2 * order + 1], "F")
    cases = [(sp.csc_matrix(dense), order, None), (sp.csc_matrix(big), coordinates_, blocks)]
    try:
        for (M, ordering, form), supernodal in itertools.product(cases, (True, False)):
            M.indptr, M.indices = M.indptr.astype(np.int32), M.indices.astype(np.int32)
            variables = None if form is None else order
            factor = Cholmod(M.indptr, M.indices, ordering, supernodal, form, variables=variables, lib=lib)
            f = factor._factor()
            if f.is_super:  # the supernodal fields where _Factor says: their ends agree
                ends = [_array(getattr(f, name), np.int32, f.nsuper + 1)[-1] for name in ("super", "pi", "px")]
                if ends != [f.n, f.ssize, f.xsize]:
                    return False
            factor.factorize(M.data)
            rhs = np.tile(b, (M.shape[0] // 6, 1))
            if not np.allclose(factor.solve(rhs), np.linalg.solve(M.toarray(), rhs), rtol=1e-10, atol=1e-12):
                return False
    except (RuntimeError, SingularSystemError, ValueError):
        return False
    return True


def available() -> bool:
    """Whether CHOLMOD is called directly here (else through CVXOPT's interface)."""
    return os.environ.get("MANOPT_LIE_CHOLMOD", "").lower() != "cvxopt" and _library() is not None


def cholmod_backend(
    indptr: IndexArray, indices: IndexArray, ordering: NDArray[np.intp] | None = None,
    supernodal: bool | None = None, blocks: tuple[IndexArray, IndexArray, IndexArray] | None = None,
    variables: NDArray[np.intp] | None = None, early: Analysis | None = None,
) -> Cholmod | _CHOLMOD:
    """CHOLMOD's factorization of the pattern, called directly where it can be, else through CVXOPT.
    With ``blocks``, ``variables`` (the variables' fill-reducing order) stands for ``ordering``:
    CVXOPT's interface gets it expanded to the coordinates. ``early``: what a structure's early
    analysis made (:class:`Cholmod`)."""
    if indptr.dtype == np.int32 and indices.dtype == np.int32 and available():
        return Cholmod(indptr, indices, ordering, supernodal, blocks, variables=variables, early=early)
    if ordering is None and blocks is not None and variables is not None:
        ordering = _coordinates(blocks[0], variables)
    return _CHOLMOD(indptr, indices, ordering, supernodal, blocks)


def _coordinates(dims: IndexArray, order: NDArray[np.intp]) -> NDArray[np.intp]:
    """The coordinates of the variables in ``order``, each variable's kept together and in order."""
    return coordinates(exclusive_cumsum(dims.astype(np.intp)), dims, order)


def _permuted_triangle(
    indptr: IndexArray, indices: IndexArray, perm: NDArray[np.intp], upper: bool
) -> tuple[NDArray[np.int32], NDArray[np.int32], NDArray[np.intp]]:
    """:func:`permuted_block_triangle` for any pattern and permutation (SciPy's indexing: slower)."""
    n = indptr.size - 1
    tagged = sp.csc_matrix((np.arange(1.0, indices.size + 1.0), indices, indptr), shape=(n, n))
    triangle = (sp.triu if upper else sp.tril)(tagged[perm][:, perm], format="csc")
    triangle.sort_indices()
    return triangle.indptr.astype(np.int32), triangle.indices.astype(np.int32), triangle.data.astype(np.intp) - 1


def _block_triangle(indptr: IndexArray, dims: IndexArray, block_indptr: IndexArray, block_rows: IndexArray,
                    order: NDArray[np.intp], upper: bool) -> tuple[Triangle, NDArray[np.intp]]:  # fmt: skip
    """:func:`permuted_block_triangle` and ``P`` (the coordinates of the variables in ``order``), built
    in compiled code where it can be (``_patterns``)."""
    args = (indptr, dims, block_indptr, block_rows, order, upper)
    compiled = _patterns.permuted_block_triangle(*args)
    if compiled is not None:
        return compiled
    return permuted_block_triangle(*args), _coordinates(dims, order)


def _release(lib: Any, common: Any, factor: Any) -> None:
    lib.cholmod_free_factor(byref(factor), common)
    lib.cholmod_finish(common)


class Cholmod:
    """CHOLMOD's supernodal ``LLᵀ`` or simplicial ``LDLᵀ`` of ``H`` (as its analysis chooses, or
    ``supernodal`` forces), called directly: the backend ``cholmod`` where :func:`available`.

    ``ordering``: the fill-reducing ordering to follow (``None``: CHOLMOD's own choice);
    ``blocks``: the pattern's block form ``(dims, block indptr, block rows)``, from which the
    permuted triangle is built fast (trusted; without it, through SciPy); ``variables``: with
    ``blocks``, the variables' fill-reducing order, which then stands for ``ordering`` (trusted):
    the analysis runs on the variables' graph (:meth:`_analyze_blocks`), and takes from ``early``
    (a structure's early analysis, :mod:`~manopt_lie.linalg._early`, where its order is
    ``variables``) what it made. Without both, the pattern is analysed as it is.
    """

    def __init__(
        self, indptr: IndexArray, indices: IndexArray, ordering: NDArray[np.intp] | None = None,
        supernodal: bool | None = None, blocks: tuple[IndexArray, IndexArray, IndexArray] | None = None,
        *, variables: NDArray[np.intp] | None = None, early: Analysis | None = None, lib: Any = None,
    ) -> None:
        lib = lib if lib is not None else _library()
        if lib is None:
            raise RuntimeError("CHOLMOD cannot be called directly here")
        n = indptr.size - 1
        if blocks is None:  # an untrusted pattern (a structure's has every diagonal block)
            cols = columns(indptr)
            check_diagonal(cols, indices == cols)
        self._lib, self._n = lib, n
        self._common = ctypes.create_string_buffer(_COMMON_BYTES)
        if not lib.cholmod_start(self._common):
            raise RuntimeError("cholmod_start failed")
        common = self._settings = _Common.from_buffer(self._common)
        common.print = 0  # failures are raised here, not printed
        common.supernodal = supernodal_setting(supernodal)
        self._handle = c_void_p()  # the factor (a cholmod_factor*), freed with the Common
        self._release = weakref.finalize(self, _release, lib, self._common, self._handle)
        if blocks is not None and variables is not None:
            self._perm, (self._indptr, self._indices, gather) = self._analyze_blocks(indptr, blocks, variables, early)
        else:
            self._perm = self._analyze_pattern(indptr, indices, ordering)
            triangle = _permuted_triangle(indptr, indices, self._perm, not self.supernodal)
            self._indptr, self._indices, gather = triangle
        upper = not self.supernodal  # the triangle each kind factors in place in the natural order
        self._gather = gather
        # Its values are gathered at each factorization into a fresh array, not kept between
        # them: a 10⁵-pose cube's (50 MB) would otherwise stay resident through the solve's peak.
        at = _native.address
        self._matrix = _Sparse(n, n, gather.size, at(self._indptr), at(self._indices), None, None, None,
                               1 if upper else -1, _INT, _REAL, _DOUBLE, 1, 1)  # fmt: skip
        self.pivots: FloatArray | None = None
        """``D`` of the last factorization if it is an ``LDLᵀ`` (in the factor's order), else ``None``."""
        if gather.size >= TRIM_ENTRIES:
            release_freed_memory()  # the analysis's transients, kept by malloc, would stay resident

    def _analyze(self, indptr: IndexArray, indices: IndexArray, stype: int = -1,
                 given: NDArray[np.intp] | None = None, natural: bool = False) -> _Factor:  # fmt: skip
        """CHOLMOD's analysis of a pattern (``stype``: the triangle it reads, −1 lower, 1 upper): in
        the ``given`` order, else in the natural order as it is (``natural``), else in CHOLMOD's
        choice; postordered except in the natural order. It becomes the factor, whose cost and kind
        are read from it."""
        n, common = indptr.size - 1, self._settings
        indptr32, indices32 = np.asarray(indptr, dtype=np.int32), np.asarray(indices, dtype=np.int32)
        pattern = _Sparse(n, n, indices32.size, indptr32.ctypes.data, indices32.ctypes.data, None, None, None,
                          stype, _INT, _PATTERN, _DOUBLE, 1, 1)  # fmt: skip
        common.nmethods = 1 if given is not None or natural else 0  # 0: CHOLMOD's default choice
        if given is not None or natural:
            common.method[0].ordering = _GIVEN if given is not None else _NATURAL
        common.postorder = int(not natural)
        perm = None if given is None else np.ascontiguousarray(given, dtype=np.int32)
        analysed = self._lib.cholmod_analyze_p(byref(pattern), None if perm is None else perm.ctypes.data, None, 0,
                                               self._common)  # fmt: skip
        if self._handle.value:
            self._lib.cholmod_free_factor(byref(self._handle), self._common)
        self._handle.value = ctypes.cast(analysed, c_void_p).value
        factor = self._factor()
        if factor.n != n or factor.itype != _INT or factor.xtype != _PATTERN:
            raise RuntimeError(f"CHOLMOD analysis failed (status {common.status})")
        method = common.method[common.selected]
        self.cost = (float(method.lnz), float(method.fl))
        """``(Σ_j c_j, Σ_j c_j²)`` of the factor's column counts ``c_j``: its entries and CHOLMOD's
        flop count of a factorization, from the analysis."""
        self.supernodal = bool(factor.is_super)
        """Whether the factor is supernodal ``LLᵀ`` (else simplicial ``LDLᵀ``)."""
        return factor

    def _analyze_pattern(self, indptr: IndexArray, indices: IndexArray, ordering: NDArray[np.intp] | None
                         ) -> NDArray[np.intp]:  # fmt: skip
        """Analyse ``H``'s pattern as it is (its lower triangle) in ``ordering`` (``None``: CHOLMOD's
        choice), postordered. Returns the factor's final order ``P``; CHOLMOD's own is then made
        the natural one (it factors ``B = P H Pᵀ`` as it is)."""
        factor = self._analyze(indptr, indices, given=ordering)
        cholmod_perm = _array(factor.Perm, np.int32, self._n)
        perm = cholmod_perm.astype(np.intp)
        cholmod_perm[:] = np.arange(self._n, dtype=np.int32)
        factor.ordering = _NATURAL
        return perm

    def _analyze_blocks(self, indptr: IndexArray, blocks: tuple[IndexArray, IndexArray, IndexArray],
                        order: NDArray[np.intp], early: Analysis | None = None
                        ) -> tuple[NDArray[np.intp], Triangle]:  # fmt: skip
        """Analyse a structure's ``H`` in the variables' ``order`` through the variables' graph
        (``d²`` times fewer entries). Returns ``P`` and the triangle of ``B = P H Pᵀ`` to factor.

        The variables' graph is analysed first, in ``order`` and postordered, which gives the
        variables' final order (the postorder of the variables expands to the coordinates' one):
        simplicial by ``patterns.c: block_symbolic`` (0.03 ms on CSAIL against CHOLMOD's 0.10),
        supernodal, or where ``L`` fills in too much for that, by CHOLMOD. Where every variable has
        one dimension ``d``, ``B``'s symbolic factor follows from the variables' one
        (:meth:`_expand`) and nothing is analysed at the scale of coordinates; CHOLMOD's own choice
        of kind (supernodes where its flops per entry of ``L`` reach 40) is made on ``B``'s exact
        cost. Otherwise ``B``'s triangle is analysed in the natural order, as it is: CHOLMOD permutes
        nothing and postorders nothing (CSAIL: 0.53 → 0.32 ms, sphere2500: 11 → 6 ms against the
        analysis of ``H`` in the coordinates' order)."""
        dims, block_indptr, block_rows = blocks
        wanted = self._settings.supernodal
        known = 0 if early is None else early.dimension  # an early analysis: variables of one dimension
        d = known or int(dims.min())
        uniform = (known > 0 or int(dims.max()) == d) and _patterns._library() is not None
        block: _Factor | None = None
        counts: NDArray[np.int64] | None = None
        made: tuple[Triangle, NDArray[np.intp]] | None = None
        if early is not None and early.order is not order:
            early = None  # made for another order
        found = None
        if uniform and wanted != _SUPERNODAL:
            found = early.symbolic if early and early.symbolic else _patterns.block_symbolic(*blocks[1:], order)
        if found is not None:
            variables, counts = found
        else:
            kind = _SUPERNODAL if uniform and wanted == _SUPERNODAL else _SIMPLICIAL
            block = self._analyze_variables(block_indptr, block_rows, order, kind, d)
            variables = _array(block.Perm, np.int32, dims.size).astype(np.intp)
            if not block.is_super:
                counts = _array(block.ColCount, np.int32, dims.size).astype(np.int64)
        # B's simplicial factor made early from this symbolic (early.c: early_run, the same sums)
        simplicial = early.simplicial if early and found is not None and found is early.symbolic else None
        if uniform:
            if simplicial is not None:
                lnz, fl = simplicial.cost
            else:
                lnz_b, fl_b = self.cost if counts is None else (float(counts.sum()), float(np.dot(counts, counts)))
                lnz, fl = coordinates_cost(lnz_b, fl_b, dims.size, d)  # c_j = d·c − a (see _expand)
            switch = self._settings.supernodal_switch
            supernodal = wanted == _SUPERNODAL or (wanted != _SIMPLICIAL and fl >= switch * lnz)
            if supernodal and (block is None or not block.is_super):
                block = self._analyze_variables(block_indptr, block_rows, order, _SUPERNODAL, d)
                variables = _array(block.Perm, np.int32, dims.size).astype(np.intp)  # the supernodes' order
            early_made = None if supernodal or simplicial is None else (simplicial.triangle, simplicial.perm)
            source = block if supernodal else counts if simplicial is None else simplicial.column_counts
            assert source is not None  # a simplicial analysis has its counts
            if self._expand(d, source):
                self.cost = (float(lnz), float(fl))
                made = early_made or _block_triangle(indptr, dims, block_indptr, block_rows, variables, not supernodal)
        if made is None:  # B's triangle analysed as it is
            upper = wanted == _SIMPLICIAL  # the triangle each kind factors in place in the natural order
            made = _block_triangle(indptr, dims, block_indptr, block_rows, variables, upper)
            self._analyze(*made[0][:2], 1 if upper else -1, natural=True)
            if upper == self.supernodal:  # CHOLMOD chose the other kind: it factors the other triangle
                made = _block_triangle(indptr, dims, block_indptr, block_rows, variables, not upper)
        triangle, perm = made
        return perm, triangle

    def _analyze_variables(self, block_indptr: IndexArray, block_rows: IndexArray, order: NDArray[np.intp],
                           kind: int, d: int) -> _Factor:  # fmt: skip
        """CHOLMOD's analysis of the variables' graph in ``order``, postordered: simplicial, or (``kind``
        :data:`_SUPERNODAL`) supernodal with the amalgamation's bounds (in columns) read in variables of ``d``
        (rounded down: on parking-garage, sphere2500 and a 10⁴-pose cube the factor stores 0–0.1 %
        more entries than CHOLMOD's analysis of the coordinates makes, against 5–14 % rounded up,
        and factors as fast)."""
        common = self._settings
        wanted, relax = common.supernodal, list(common.nrelax)
        supernodal = kind == _SUPERNODAL  # else simplicial: only the order and the counts are read
        common.supernodal = _SUPERNODAL if supernodal else _SIMPLICIAL
        if supernodal:  # rounded down: the factor as large as an analysis of the coordinates would make it
            common.nrelax[:] = [columns_ // d for columns_ in relax]
        try:
            return self._analyze(block_indptr, block_rows, given=order)
        finally:
            common.supernodal, common.nrelax[:] = wanted, relax

    def _expand(self, d: int, variables_factor: _Factor | NDArray[np.int64] | NDArray[np.int32]) -> bool:
        """Make the symbolic factor of ``B`` (natural order) from the variables' one, every variable of
        dimension ``d``: their supernodal factor (CHOLMOD's), or their simplicial one, its column
        counts in blocks (64-bit) or already expanded (32-bit: ``B``'s, made early); ``False`` (nothing
        changed) where an index passes 32 bits.

        The blocks are dense, so the column of coordinate ``a`` of a variable whose column of ``L``
        holds ``c`` blocks holds ``d·c − a`` entries, below the rows of the variable's own ones.
        A simplicial factor is its column counts (CHOLMOD's numeric factorization finds each
        column's rows), exactly those of an analysis of ``B``. A supernodal one is the variables'
        supernodes expanded to their coordinates (``patterns.c: expand_supernodes``), amalgamated as
        CHOLMOD would (:meth:`_analyze_variables`). The arrays are allocated by CHOLMOD, as its
        analysis would allocate them."""
        lib, n, nv = self._lib, self._n, self._n // d
        address = lib.cholmod_allocate_factor(n, self._common)  # natural order, simplicial, no rows
        if not address:
            raise MemoryError("CHOLMOD could not allocate a factor")
        handle, factor = c_void_p(address), _Factor.from_address(address)
        try:
            if isinstance(variables_factor, _Factor):
                supernodal, made = True, self._expand_supernodes(variables_factor, factor, d)
            else:
                if variables_factor.dtype == np.int32:  # B's own counts (early): copied as they are
                    ctypes.memmove(factor.ColCount, _native.address(variables_factor), 4 * n)
                else:
                    counts = _array(factor.ColCount, np.int32, n)
                    block_counts = (d * variables_factor).astype(np.int32)[:, None]
                    np.subtract(block_counts, np.arange(d, dtype=np.int32), out=counts.reshape(nv, d))
                factor.is_ll, supernodal, made = 0, False, True
        except BaseException:
            lib.cholmod_free_factor(byref(handle), self._common)
            raise
        if not made:
            lib.cholmod_free_factor(byref(handle), self._common)
            return False
        factor.ordering = _NATURAL
        if self._handle.value:
            lib.cholmod_free_factor(byref(self._handle), self._common)
        self._handle.value = address
        self.supernodal = supernodal
        return True

    def _expand_supernodes(self, block: _Factor, factor: _Factor, d: int) -> bool:
        """Fill ``factor`` (just allocated) with ``block``'s supernodes expanded (see :meth:`_expand`)."""
        nsuper, ssize = int(block.nsuper), int(block.ssize) * d
        factor.nsuper, factor.ssize, factor.is_super = nsuper, ssize, 1  # what cholmod_free_factor frees
        for name, size in (("super", nsuper + 1), ("pi", nsuper + 1), ("px", nsuper + 1), ("s", ssize)):
            address = self._lib.cholmod_malloc(size, ctypes.sizeof(c_int), self._common)
            if not address:
                raise MemoryError("CHOLMOD could not allocate a supernodal factor")
            setattr(factor, name, address)
        sizes = np.zeros(3, dtype=np.int64)  # xsize, maxcsize, maxesize
        dims = np.full(int(block.n), d, dtype=np.int64)
        arrays = (block.super, block.pi, block.s, factor.super, factor.pi, factor.px, factor.s, factor.ColCount)
        if _patterns._library().expand_supernodes(nsuper, dims.ctypes.data, *arrays, sizes.ctypes.data) < 0:
            return False
        factor.xsize, factor.maxcsize, factor.maxesize = (int(v) for v in sizes)
        factor.is_ll, factor.is_monotonic = 1, 1
        return True

    def _factor(self) -> _Factor:
        if not self._handle.value:
            raise RuntimeError(f"CHOLMOD analysis failed (status {self._settings.status})")
        return _Factor.from_address(self._handle.value)

    def factorize(self, data: FloatArray) -> None:
        values = np.take(np.asarray(data, dtype=np.float64), self._gather, mode="clip")
        self._matrix.x = values.ctypes.data
        try:
            ok = self._lib.cholmod_factorize(byref(self._matrix), self._handle, self._common)
        finally:
            self._matrix.x = None
        factor, status = self._factor(), self._settings.status
        if not ok or status < 0:
            raise SingularSystemError(f"CHOLMOD factorization failed (status {status})")
        if status == _NOT_POSDEF or factor.minor < self._n:
            raise SingularSystemError(f"CHOLMOD factorization failed: not positive definite (column {factor.minor})")
        if factor.is_ll:
            self.pivots = None
            return
        # LDLᵀ: D heads every column of the simplicial factor; CHOLMOD does not stop at D ≤ 0.
        d = _array(factor.x, np.float64, factor.nzmax)[_array(factor.p, np.int32, self._n)]
        if not (np.isfinite(d).all() and (d > 0.0).all()):
            raise SingularSystemError(
                f"CHOLMOD factorization: not positive definite ({int(np.sum(~(d > 0.0)))} pivots of LDLᵀ ≤ 0 or nan)"
            )
        self.pivots = None if (d == 1.0).all() else d

    def solve(self, b: FloatArray) -> FloatArray:
        """``H⁻¹b`` for ``b`` of shape ``(n,)`` or ``(n, k)``: ``Pᵀ B⁻¹ P b``."""
        b = np.asarray(b, dtype=np.float64)
        rhs = np.asfortranarray(b[self._perm])
        k = 1 if b.ndim == 1 else b.shape[1]
        dense = _Dense(self._n, k, self._n * k, self._n, rhs.ctypes.data, None, _REAL, _DOUBLE)
        x = self._lib.cholmod_solve(_SOLVE_A, self._handle, byref(dense), self._common)
        if not x:
            raise SingularSystemError(f"CHOLMOD solve failed (status {self._settings.status})")
        try:
            solution = _array(x.contents.x, np.float64, self._n * k).reshape(b.shape, order="F")
            out = np.empty_like(b)
            out[self._perm] = solution
        finally:
            self._lib.cholmod_free_dense(byref(x), self._common)
        return out

    def permutation(self) -> NDArray[np.intp]:
        """The factor's order in ``H``'s coordinates: ``P H Pᵀ = L D Lᵀ`` with
        ``(P H Pᵀ)[i, j] = H[perm[i], perm[j]]``."""
        return self._perm.copy()

    def factor_csc(self) -> tuple[FloatArray, NDArray[np.int32], NDArray[np.int32]]:
        """``(data, indices, indptr)`` of the last factorization's ``L`` (``LDLᵀ``: ``D`` on its
        diagonal), in the factor's order; the factor itself stays as it is."""
        copy = self._lib.cholmod_copy_factor(self._handle, self._common)
        if not copy:
            raise MemoryError("CHOLMOD could not copy its factor")
        try:
            lower = self._lib.cholmod_factor_to_sparse(copy, self._common)
            if not lower:
                raise MemoryError("CHOLMOD could not convert its factor")
            try:
                m = lower.contents
                indptr = _array(m.p, np.int32, self._n + 1).copy()
                nnz = int(indptr[-1])
                return _array(m.x, np.float64, nnz).copy(), _array(m.i, np.int32, nnz).copy(), indptr
            finally:
                self._lib.cholmod_free_sparse(byref(lower), self._common)
        finally:
            self._lib.cholmod_free_factor(byref(copy), self._common)
