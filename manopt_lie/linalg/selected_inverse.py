"""Entries of ``H⁻¹`` on the pattern of a sparse Cholesky factor, without the dense inverse.

With a fill-reducing permutation ``P`` and the factor ``P H Pᵀ = L Lᵀ``, the inverse
``Z = (P H Pᵀ)⁻¹ = L⁻ᵀL⁻¹`` satisfies ``Lᵀ Z = L⁻¹``, a lower-triangular right-hand
side whose diagonal blocks are known (``L_JJ⁻¹``) and whose upper part is zero. Split the
columns of ``L`` into *supernodes*: runs ``J`` of consecutive columns sharing one row
structure, ``J`` itself then the rows ``R`` below (dense blocks ``L_JJ`` lower triangular
and ``L_RJ``). Reading ``Lᵀ Z = L⁻¹`` in the block rows ``J`` and the columns ``J`` and
``R`` gives the *Takahashi recursion* (Takahashi, Fagan, Chen 1973; Erisman and Tinney 1975)

    B     = L_RJ L_JJ⁻¹
    Z_RJ  = −Z_RR B
    Z_JJ  = L_JJ⁻ᵀ L_JJ⁻¹ + Bᵀ Z_RR B

run from the last supernode to the first. It needs ``Z_RR`` only where the filled pattern
of ``L + Lᵀ`` is (``R`` is a clique of it: ``R`` lies in the row structure of ``J``'s parent
supernode, whose own block ``Z[rows, rows]`` — its *front* — is complete when ``J`` is
reached), so ``Z`` is computed on that pattern only, at about the cost of the factorization
(``Σ |R|²|J|`` flops). The loop runs over supernodes, not columns; everything else
(structure, panels, the batched inverses ``L_JJ⁻¹``) is vectorized. Asking for a few
columns restricts the loop to their supernodes and the supernodes' ancestors.

:func:`cholesky_factor` obtains ``(L, P)`` from any :class:`CholeskySolver` backend
(CHOLMOD's supernodal factor, QDLDL's, SuperLU's or the compiled ``ldl``'s ``LDLᵀ`` scaled to
``LLᵀ``; CHOLMOD's simplicial ``LDLᵀ`` too, though this function asks for supernodes);
:class:`SelectedInverse` runs the recursion and reads entries of ``H⁻¹`` by original
index; :meth:`CholeskyFactor.solve` is the alternative for a few columns of ``H⁻¹``,
multi-right-hand-side triangular solves.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike, NDArray

from ._factors import exclusive_cumsum
from .cholesky import CholeskySolver, _check_square
from .errors import SingularSystemError

__all__ = ["CholeskyFactor", "SelectedInverse", "Supernodes", "cholesky_factor"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


class CholeskyFactor:
    """``P H Pᵀ = L Lᵀ``: ``L`` lower triangular (CSC, sorted, diagonal first in each column)
    and ``perm`` with ``(P H Pᵀ)[i, j] = H[perm[i], perm[j]]``; made by :func:`cholesky_factor`.

    Attributes
    ----------
    perm : int array, shape (n,)
    backend : str
        The backend that factorized ``H``.
    exact : bool
        Whether ``L`` stores its whole symbolic pattern, structural zeros included
        (CHOLMOD, QDLDL; see :class:`Supernodes`).
    """

    def __init__(
        self,
        perm: IntArray,
        backend: str,
        lower: Callable[[], sp.csc_matrix],
        solve: Callable[[FloatArray], FloatArray] | None = None,
        *,
        exact: bool = False,
    ) -> None:
        self.perm, self.backend, self.exact = perm, backend, exact
        self._lower, self._solve = lower, solve
        self._L: sp.csc_matrix | None = None

    @property
    def n(self) -> int:
        """The order of the factored matrix (the length of the fill-reducing permutation)."""
        return int(self.perm.size)

    @property
    def L(self) -> sp.csc_matrix:
        """The factor ``L`` (extracted from the backend at the first use)."""
        if self._L is None:
            self._L = self._lower()
        return self._L

    def solve(self, B: ArrayLike) -> FloatArray:
        """``H⁻¹ B`` for a dense ``B`` of shape ``(n, k)``: the backend's multi-right-hand-side
        solve where it has one (CHOLMOD, SuperLU), else the two triangular solves with ``L``,
        ``x = Pᵀ L⁻ᵀ L⁻¹ P b``."""
        b = np.asarray(B, dtype=np.float64)
        if self._solve is not None:
            return np.asarray(self._solve(b), dtype=np.float64)
        y = spla.spsolve_triangular(self.L, b[self.perm], lower=True)
        x = np.empty_like(b)
        x[self.perm] = spla.spsolve_triangular(self.L.T.tocsr(), y, lower=False)
        return x


def _cholmod_factor(impl: Any, H: sp.csc_matrix, name: str = "cholmod") -> CholeskyFactor:
    """The factor of CHOLMOD (called directly: ``LLᵀ`` or ``LDLᵀ``) or of the compiled ``LDLᵀ``, which
    share their interface (``factor_csc``, ``pivots``, ``permutation``, ``solve``)."""
    n = H.shape[0]

    def lower() -> sp.csc_matrix:
        pivots = impl.pivots
        arrays = list(impl.factor_csc())  # (values, row indices, column pointers)
        if pivots is None:  # LLᵀ
            return sp.csc_matrix(tuple(arrays), shape=(n, n))
        # LDLᵀ, packed: D on the diagonal (the head of each sorted column), L₁ below it.
        arrays[0][arrays[2][:-1]] = 1.0
        return _scaled(sp.csc_matrix(tuple(arrays), shape=(n, n)), pivots, name)

    def solve(b: FloatArray) -> FloatArray:
        return np.asarray(impl.solve(b), dtype=np.float64)

    return CholeskyFactor(impl.permutation(), name, lower, solve, exact=True)


def _scaled(unit: sp.spmatrix, d: FloatArray, name: str, *, diagonal: bool = True) -> sp.csc_matrix:
    """``L = L₁ D^½`` from a unit lower-triangular ``L₁`` (its diagonal stored, or with
    ``diagonal=False`` left implicit) and the pivots ``D`` of ``LDLᵀ``. The pattern is kept
    as stored, structural zeros included (SciPy's sparse sums and products would drop them)."""
    if not (np.isfinite(d).all() and (d > 0).all()):
        raise SingularSystemError(f"{name}: H is not positive definite (a pivot is not positive)")
    m = sp.csc_matrix(unit)
    m.sort_indices()
    n, root = m.shape[0], np.sqrt(d)
    indptr, indices, data = m.indptr.astype(np.intp), m.indices.astype(np.intp), m.data.astype(np.float64)
    if not diagonal:  # insert the unit diagonal at the head of every column
        count = np.diff(indptr) + 1
        head = exclusive_cumsum(count)
        at = np.ones(head[-1], dtype=bool)
        at[head[:-1]] = False
        indices_, data_ = np.empty(head[-1], dtype=np.intp), np.ones(head[-1])
        indices_[head[:-1]], indices_[at], data_[at] = np.arange(n), indices, data
        indptr, indices, data = head, indices_, data_
    data = data * root[np.repeat(np.arange(n), np.diff(indptr))]
    return sp.csc_matrix((data, indices, indptr), shape=(n, n))


def _qdldl_factor(impl: Any, H: sp.csc_matrix) -> CholeskyFactor:
    strict, d, p = impl._solver.factors()  # H = P (I + L) D (I + L)ᵀ Pᵀ with P[p, arange] = 1
    L = _scaled(strict, np.asarray(d, dtype=np.float64), "QDLDL", diagonal=False)
    return CholeskyFactor(np.asarray(p, dtype=np.intp), "qdldl", lambda: L, exact=True)


def _superlu_factor(impl: Any, H: sp.csc_matrix) -> CholeskyFactor:
    lu = impl._lu
    # Symmetric mode without pivoting on H[order][:, order]: U = D L₁ᵀ.
    L = _scaled(lu.L, lu.U.diagonal(), "SuperLU")
    return CholeskyFactor(impl._order.astype(np.intp), "superlu", lambda: L, impl.solve)


_FACTORS: dict[str, Callable[[Any, sp.csc_matrix], CholeskyFactor]] = {
    "cholmod": _cholmod_factor, "ldl": functools.partial(_cholmod_factor, name="ldl"), "qdldl": _qdldl_factor,
    "superlu": _superlu_factor,
}


def cholesky_factor(H: sp.spmatrix | sp.sparray, backend: str = "auto", *, rtol: float = 1e-6) -> CholeskyFactor:
    """The sparse Cholesky factor ``P H Pᵀ = L Lᵀ`` of a symmetric positive definite ``H``.

    Parameters
    ----------
    H : scipy.sparse matrix, shape (n, n)
        Both triangles stored (as :class:`BlockStructure` builds it).
    backend : {"auto", "cholmod", "ldl", "qdldl", "superlu"}
        A :class:`~manopt_lie.linalg.CholeskySolver` backend (its ordering, analysis and
        checks); ``"auto"`` takes the first available. CHOLMOD's factor is supernodal
        (relaxed supernodes, explicit zeros included), which keeps the recursion's loop short.
    rtol : float
        The solver's probe-residual tolerance: ``H`` with a condition number beyond about
        ``0.1/rtol`` counts as singular (:class:`~manopt_lie.linalg.CholeskySolver`).

    Raises
    ------
    SingularSystemError
        If ``H`` is not numerically positive definite (e.g. a pose graph without a fixed gauge).
    """
    if backend != "auto" and backend not in _FACTORS:
        raise ValueError(f"selected inversion: unknown backend {backend!r}; choose 'auto' or one of {sorted(_FACTORS)}")
    solver = CholeskySolver(backend, rtol=rtol, supernodal=True)  # relaxed supernodes: a short loop
    H = _check_square(H)
    if not H.has_canonical_format:
        H = H.copy()
        H.sum_duplicates()
    solver.analyze(H)
    solver.factorize(H)  # the probe solve: no factor of a singular H is handed out
    return _FACTORS[solver.backend](solver._own_backend(), H)


class Supernodes:
    """The supernodes of a lower-triangular CSC pattern and where each entry lives.

    Supernode ``s`` owns the columns ``start[s] … start[s] + width[s] − 1`` of ``L``,
    which share the row list ``rows[row_start[s]:row_start[s + 1]]`` (its own columns
    first, then ``R_s``); its *panel* is the dense ``(nrows, width)`` block of ``L`` (or
    of ``Z``) on those rows, stored row-major at ``panel_start[s]`` of a flat buffer. A
    column joins the previous one's supernode when it is that column's elimination-tree
    parent with the same rows below it (a fundamental supernode; CHOLMOD's relaxed
    supernodes arrive padded with zeros and are found whole).

    The recursion needs an elimination pattern: ``R_s`` inside the rows of the parent
    supernode (the owner of ``R_s``'s first row). A factor whose numerically zero entries
    were dropped (SciPy's copy of SuperLU's ``L``) is not one; its rows are then completed
    by the symbolic factorization ``rows_p ← rows_p ∪ R_s`` (a loop over supernodes in
    elimination order), which restores the structural zeros.

    Parameters
    ----------
    L : scipy.sparse.csc_matrix
        Lower triangular, sorted, the diagonal stored first in every column.
    exact : bool
        Whether ``L`` has an exact (or CHOLMOD's relaxed) symbolic pattern, as CHOLMOD's and
        QDLDL's factors have: then two columns with nested structure and equal counts have
        equal rows, and that is not checked entry by entry (one pass over ``L`` less).
    """

    def __init__(self, L: sp.csc_matrix, *, exact: bool = False) -> None:
        n, indptr, indices = L.shape[0], L.indptr.astype(np.intp), L.indices.astype(np.intp)
        count = np.diff(indptr)
        if (count < 1).any() or (indices[indptr[:-1]] != np.arange(n)).any():
            raise ValueError("L must store its diagonal first in every column")
        self.n = n
        # Column c + 1 continues c's supernode if it is c's first row below the diagonal
        # with one entry less; unless the pattern is exact, the rows below c + 1 must be c's
        # too: each entry of c + 1 is compared with the entry count[c + 1] places before it.
        below = np.where(count > 1, indices[np.minimum(indptr[:-1] + 1, indices.size - 1)], -1)
        joins = (below[:-1] == np.arange(1, n)) & (count[:-1] == count[1:] + 1)
        if not exact:
            back = np.maximum(np.arange(indices.size) - np.repeat(count, count), 0)
            differs = np.repeat(np.r_[False, joins], count) & (indices != indices[back])
            joins[np.searchsorted(indptr, np.flatnonzero(differs), side="right") - 2] = False
        self.start: IntArray = np.flatnonzero(np.r_[True, ~joins])
        self.width: IntArray = np.diff(np.r_[self.start, n])
        self.owner: IntArray = np.repeat(np.arange(self.start.size), self.width)
        counts = count[self.start]
        first = exclusive_cumsum(counts)
        of = np.repeat(np.arange(self.start.size), counts)
        rows = indices[indptr[self.start][of] + np.arange(first[-1]) - first[of]]
        closed = self._index(rows, counts)
        if not closed:
            self._index(*self._completed(rows, first))
        self.completed = not closed  # whether rows had to be added
        self.panel_start: IntArray = exclusive_cumsum(self.nrows * self.width)
        if closed:
            # Column k of a supernode holds its rows k, k + 1, …: its entry q goes to panel
            # row k + q, at panel_start + k·(w + 1) + q·w (per-column constants, repeated).
            k = np.arange(n) - self.start[self.owner]
            w = self.width[self.owner]
            q = np.arange(indices.size) - np.repeat(indptr[:-1], count)
            self._scatter = np.repeat(self.panel_start[self.owner] + k * (w + 1), count) + q * np.repeat(w, count)
        else:
            self._scatter, found = self.locate(indices, np.repeat(np.arange(n), count))
            assert found.all(), "completed rows hold every entry of L"

    def _index(self, rows: IntArray, counts: IntArray) -> bool:
        """Set up the row lists, parents and relative positions; ``False`` if the pattern is
        not an elimination pattern."""
        ns = self.start.size
        self.rows, self.nrows = rows, counts
        self.row_start: IntArray = exclusive_cumsum(counts)
        of = np.repeat(np.arange(ns), counts)
        self._keys = of.astype(np.int64) * self.n + rows  # sorted: by supernode, then row
        has = counts > self.width
        self.parent: IntArray = np.full(ns, -1, dtype=np.intp)
        self.parent[has] = self.owner[rows[self.row_start[:-1][has] + self.width[has]]]
        in_r = np.arange(rows.size) - self.row_start[of] >= self.width[of]
        pos, found = self._find(self.parent[of[in_r]], rows[in_r])
        self.rel: IntArray = pos - self.row_start[self.parent[of[in_r]]]
        self.rel_start: IntArray = exclusive_cumsum(counts - self.width)
        return bool(found.all())

    def _completed(self, rows: IntArray, first: IntArray) -> tuple[IntArray, IntArray]:
        """Row lists closed under elimination: ``rows_p ← rows_p ∪ R_s`` for every
        supernode ``s`` in order, ``p`` the owner of ``R_s``'s first row."""
        lists = np.split(rows, first[1:-1])
        for s, w in enumerate(self.width.tolist()):  # in order: a parent after its children
            r = lists[s]
            if r.size > w:
                p = int(self.owner[r[w]])
                lists[p] = np.union1d(lists[p], r[w:])
        return np.concatenate(lists), np.array([r.size for r in lists], dtype=np.intp)

    def _find(self, s: IntArray, r: IntArray) -> tuple[IntArray, NDArray[np.bool_]]:
        """Position in :attr:`rows` of row ``r`` of supernode ``s`` (vectorized), and whether it is there."""
        key = s.astype(np.int64) * self.n + r
        pos = np.minimum(np.searchsorted(self._keys, key), self._keys.size - 1)
        return pos, self._keys[pos] == key

    def panels(self, data: ArrayLike) -> FloatArray:
        """The flat panel buffer of the values ``data`` of ``L`` (CSC order); zero elsewhere."""
        out = np.zeros(int(self.panel_start[-1]))
        out[self._scatter] = data
        return out

    def locate(self, rows: ArrayLike, cols: ArrayLike) -> tuple[IntArray, NDArray[np.bool_]]:
        """Flat panel index of the entries ``(rows, cols)`` of the permuted matrix (either
        triangle; the lower one is read), and whether each lies on the pattern."""
        r, c = np.asarray(rows, dtype=np.intp), np.asarray(cols, dtype=np.intp)
        r, c = np.maximum(r, c), np.minimum(r, c)
        s = self.owner[c]
        pos, found = self._find(s, r)
        return self.panel_start[s] + (pos - self.row_start[s]) * self.width[s] + (c - self.start[s]), found

    def ancestors(self, supernodes: ArrayLike) -> NDArray[np.bool_]:
        """Mask of the given supernodes and all their ancestors (one vectorized step per tree level)."""
        mask = np.zeros(self.start.size, dtype=bool)
        frontier = np.unique(np.asarray(supernodes, dtype=np.intp))
        while frontier.size:
            mask[frontier] = True
            up = self.parent[frontier]
            frontier = np.unique(up[up >= 0])
            frontier = frontier[~mask[frontier]]
        return mask


def _lower_inverses(L: FloatArray) -> FloatArray:
    """``L⁻¹`` of a batch ``(k, w, w)`` of lower-triangular matrices by forward substitution,
    ``X[i] = (e_i − L[i, :i] X[:i]) / L[i, i]``: ``w`` steps, each vectorized over the batch
    (cheaper than ``np.linalg.inv``'s one LU per matrix)."""
    w = L.shape[-1]
    X = np.zeros_like(L)
    scale = 1.0 / np.diagonal(L, axis1=1, axis2=2)
    for i in range(w):  # over the rows of one width, not over supernodes
        row = -np.einsum("kj,kjl->kl", L[:, i, :i], X[:, :i, :])
        row[:, i] += 1.0
        X[:, i, :] = row * scale[:, i, None]
    return X


def _diagonal_inverses(nodes: Supernodes, panels: FloatArray, todo: IntArray, z: FloatArray) -> dict[int, FloatArray]:
    """``L_JJ⁻¹`` of the supernodes ``todo``, batched over supernodes of equal width, and
    ``L_JJ⁻ᵀ L_JJ⁻¹`` written into the diagonal blocks of ``z``."""
    out: dict[int, FloatArray] = {}
    for w in np.unique(nodes.width[todo]).tolist():  # a few distinct widths
        group = todo[nodes.width[todo] == w]
        at = nodes.panel_start[group][:, None] + np.arange(w * w)  # the first w rows of each panel
        inverse = _lower_inverses(panels[at].reshape(-1, w, w))
        z[at] = (np.swapaxes(inverse, 1, 2) @ inverse).reshape(-1, w * w)
        out.update(zip(group.tolist(), inverse, strict=True))
    return out


class SelectedInverse:
    """``H⁻¹`` on the filled pattern of its Cholesky factor, read by original index.

    Parameters
    ----------
    factor : CholeskyFactor
    columns : int array, optional
        Original indices of the columns whose entries will be read: the recursion then
        covers only their supernodes and those supernodes' ancestors. Default: all.

    Notes
    -----
    An entry ``(i, j)`` of ``H⁻¹`` is available when ``(P i, P j)`` lies on the pattern of
    ``L + Lᵀ`` (true for every pair of coordinates of variables that share a factor, and
    within one variable) and the supernode of the earlier of the two was computed (always
    when ``i`` and ``j`` are both among ``columns``).
    """

    def __init__(self, factor: CholeskyFactor, columns: ArrayLike | None = None) -> None:
        self.factor = factor
        self.nodes = nodes = Supernodes(factor.L, exact=factor.exact)
        self._iperm = np.empty(factor.n, dtype=np.intp)
        self._iperm[factor.perm] = np.arange(factor.n)
        if columns is None:
            self.computed = np.ones(nodes.start.size, dtype=bool)
        else:
            cols = self._iperm[np.asarray(columns, dtype=np.intp).reshape(-1)]
            self.computed = nodes.ancestors(nodes.owner[cols])
        self.z = self._recursion(nodes.panels(factor.L.data))

    def _recursion(self, panels: FloatArray) -> FloatArray:
        """``Z`` on the panels of the computed supernodes (module doc), one step per supernode."""
        nodes = self.nodes
        todo = np.flatnonzero(self.computed)
        z = np.zeros_like(panels)
        inverses = _diagonal_inverses(nodes, panels, todo, z)
        rel = nodes.rel
        children = np.bincount(nodes.parent[todo][nodes.parent[todo] >= 0], minlength=nodes.parent.size)
        # Python ints for the loop (numpy scalars cost more to index with).
        parent, width, nrows, start, rel_start, pending = (
            a.tolist() for a in (nodes.parent, nodes.width, nodes.nrows, nodes.panel_start, nodes.rel_start, children)
        )  # fmt: skip
        fronts: dict[int, FloatArray] = {}  # Z[rows_s, rows_s] of supernodes whose children are pending
        # The recursion, parents before children; a childless supernode with no rows below is done.
        for s in todo[(nodes.nrows[todo] > nodes.width[todo]) | (children[todo] > 0)][::-1].tolist():
            w, nr = width[s], nrows[s]
            out = z[start[s] : start[s + 1]].reshape(nr, w)
            z_rr = None
            if nr > w:
                p = parent[s]
                r = rel[rel_start[s] : rel_start[s + 1]]
                z_rr = fronts[p].take(r, 0).take(r, 1)
                pending[p] -= 1
                if not pending[p]:
                    del fronts[p]
                b = panels[start[s] + w * w : start[s + 1]].reshape(nr - w, w) @ inverses[s]
                zb = z_rr @ b
                out[:w] += b.T @ zb
                np.negative(zb, out=out[w:])
            if pending[s]:
                front = np.empty((nr, nr))
                front[:, :w] = out
                front[:w, w:] = out[w:].T
                if z_rr is not None:
                    front[w:, w:] = z_rr
                fronts[s] = front
        return z

    def entries(self, rows: ArrayLike, cols: ArrayLike) -> tuple[FloatArray, NDArray[np.bool_]]:
        """``H⁻¹[rows, cols]`` elementwise (original indices, any broadcastable shapes), and
        whether each entry was available (see the class notes); unavailable entries read 0."""
        r, c = np.broadcast_arrays(np.asarray(rows, dtype=np.intp), np.asarray(cols, dtype=np.intp))
        rp, cp = self._iperm[r], self._iperm[c]
        index, found = self.nodes.locate(rp, cp)
        found &= self.computed[self.nodes.owner[np.minimum(rp, cp)]]
        return np.where(found, self.z[np.where(found, index, 0)], 0.0), found
