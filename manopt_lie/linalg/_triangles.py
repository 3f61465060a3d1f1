"""CHOLMOD's copy of one triangle of ``H`` (the lower, or with ``upper=True`` the upper one),
built as a CVXOPT sparse matrix of ones (the symbolic analysis reads only the pattern), with
the positions in ``H.data`` of its entries.

CVXOPT makes sparse matrices from triplets, whose constructor scans a column's entries for
every entry it inserts (``k²`` per column of ``k``; 20–80 ns per entry), from sparse
products (~30 ns per entry of the product), or by joining blocks (``cvxopt.sparse``,
~7 ns per entry, one linear pass). Two builds:

- :func:`triangle`: any canonical CSC pattern, from triplets, in column ranges of
  :data:`CHUNK` entries joined (64-bit transients of a few MiB).
- :func:`coordinate_major_triangle`: a pattern given by its blocks (a :class:`BlockStructure`),
  reordered so that it *is* a grid of copies of the variables' graph, joined: first
  coordinate 0 of every variable, then coordinate 1 of those with ``d_v > 1``, and so on.
  In that order the entries of coordinates ``(a, b)`` form the block pattern ``S`` itself
  (restricted to the variables that have those coordinates), so the lower triangle is
  ``S`` below the diagonal blocks ``a > b`` and ``tril(S)`` on them (the upper one: ``S``
  above them, ``triu(S)`` on them), and CVXOPT only joins
  copies of two or a few small matrices; CHOLMOD factors the reordered matrix with the
  reordered fill-reducing ordering, which is the same matrix in the same elimination order.
"""

from __future__ import annotations

import ctypes
from functools import cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._factors import exclusive_cumsum

__all__ = ["CHUNK", "check_diagonal", "columns", "coordinate_major_triangle", "permuted_block_triangle", "triangle"]
__all__ += ["values_view"]

IndexArray = NDArray[np.signedinteger]
Blocks = slice | NDArray[np.intp]  # the stored blocks in a coordinate pair's matrix (a slice: all)

CHUNK = 1 << 16
"""Entries of ``H`` per piece of :func:`triangle`."""


def columns(indptr: IndexArray) -> NDArray[np.signedinteger]:
    """Column of every stored entry of a CSC matrix (in the index dtype: half the memory of intp
    for int32 patterns)."""
    return np.repeat(np.arange(indptr.size - 1, dtype=indptr.dtype), np.diff(indptr))


def check_diagonal(
    cols: NDArray[np.signedinteger], diag: NDArray[np.bool_], c0: int = 0, c1: int | None = None
) -> None:
    """Raise if some column of ``c0 … c1 − 1`` (all of ``cols`` by default) stores no diagonal
    entry (``cols``: the column of each stored entry; ``diag``: entries on the diagonal)."""
    if c1 is None:
        c1 = int(cols[-1]) + 1 if cols.size else 0
    if np.count_nonzero(diag) != c1 - c0:
        missing = np.setdiff1d(np.arange(c0, c1), cols[diag])[0]
        raise ValueError(f"H stores no diagonal entry in column {missing}: it cannot be positive definite")


def triangle(
    cvxopt: Any, indptr: IndexArray, indices: IndexArray, upper: bool = False
) -> tuple[Any, NDArray[np.signedinteger]]:
    """The lower (``upper``: the upper) triangle of the pattern (in ``H``'s order) and the
    positions of its entries among ``H``'s (in the index dtype), built column range by column
    range and joined.

    CVXOPT's triplets go through 64-bit row and column indices and a sorting workspace, each
    as large as the matrix; in pieces of :data:`CHUNK` entries of ``H`` these transients stay a
    few MiB and in cache, and ``cvxopt.sparse`` joins the pieces' columns in one pass.

    Raises
    ------
    ValueError
        If a column stores no diagonal entry, or the pattern is not canonical CSC (unsorted
        indices or duplicates in a column), which CVXOPT would silently reorder.
    """
    n = indptr.size - 1
    bounds = np.unique(np.concatenate([np.searchsorted(indptr, np.arange(0, int(indptr[-1]), CHUNK)), [n]]))
    pieces, positions = [], []
    for c0, c1 in zip(bounds[:-1].tolist(), bounds[1:].tolist(), strict=True):
        start, stop = int(indptr[c0]), int(indptr[c1])
        cols = np.repeat(np.arange(c0, c1, dtype=np.int64), np.diff(indptr[c0 : c1 + 1]))
        rows = indices[start:stop]
        check_diagonal(cols, rows == cols, c0, c1)
        keep = rows <= cols if upper else rows >= cols
        rows, cols = rows[keep].astype(np.int64), cols[keep] - c0
        piece = cvxopt.spmatrix(1.0, cvxopt.matrix(rows), cvxopt.matrix(cols), (n, c1 - c0))
        same = np.array_equal(np.asarray(piece.I).ravel(), rows) and np.array_equal(np.asarray(piece.J).ravel(), cols)
        if not same:
            raise ValueError("CHOLMOD backend: H must be canonical CSC (sorted indices, no duplicates)")
        pieces.append([piece])
        positions.append((start + np.flatnonzero(keep)).astype(indices.dtype))
    joined = pieces[0][0] if len(pieces) == 1 else cvxopt.sparse(pieces)
    return joined, np.concatenate(positions)


def _block_starts(
    indptr: IndexArray, dims: IndexArray, block_indptr: IndexArray, block_rows: IndexArray
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]:
    """Per block ``k = (w, v)`` of the pattern: its column ``v``, its row ``w`` and ``s_k``, the
    position in ``H.data`` of its entry ``(o_w, o_v)``; and per variable ``ℓ_v``, the length of
    each of its columns (entry ``(o_w + a, o_v + b)`` of block ``k`` sits at ``s_k + b·ℓ_v + a``)."""
    offsets = exclusive_cumsum(dims)
    block_cols = columns(block_indptr).astype(np.intp)
    rows = block_rows.astype(np.intp)
    first = indptr[offsets[:-1]].astype(np.intp)
    length = (indptr[offsets[1:]].astype(np.intp) - first) // dims
    rho = exclusive_cumsum(dims[rows])  # ρ_k: how far down its column block k begins
    start = first[block_cols] + rho[:-1] - rho[block_indptr[block_cols]]
    return block_cols, rows, start, length


def coordinate_major_triangle(
    cvxopt: Any, indptr: IndexArray, dims: IndexArray, block_indptr: IndexArray, block_rows: IndexArray,
    upper: bool = False,
) -> tuple[Any, NDArray[np.signedinteger], NDArray[np.intp]]:
    """The lower (``upper``: the upper) triangle of ``P H Pᵀ`` in the coordinate-major order ``P``, the position in
    ``H.data`` of each of its entries (CVXOPT's column-major order, ``H``'s index dtype), and
    ``coords``: the coordinate of ``H`` at each row of ``P H Pᵀ``.

    ``H`` (CSC ``indptr``) is the scalar expansion of the block pattern (``dims``,
    ``block_indptr``, ``block_rows``: both triangles, every diagonal block, rows sorted), as
    :class:`~manopt_lie.linalg.BlockStructure` builds it; its column ``o_v + b`` starts at
    ``indptr[o_v] + b·ℓ_v`` (every column of ``v`` stores the same ``ℓ_v`` rows), where block
    ``k = (w, v)`` begins ``ρ_k`` rows down, so entry ``(o_w + a, o_v + b)`` sits at
    ``indptr[o_v] + b·ℓ_v + ρ_k + a``. Trusted: the pattern is not checked.
    """
    nv, d_max = dims.size, int(dims.max())
    offsets = exclusive_cumsum(dims)
    block_cols, rows, start, length = _block_starts(indptr, dims, block_indptr, block_rows)
    step = length[block_cols]  # from column o_v + b to o_v + b + 1

    # Coordinate a exists for the variables with d_v > a; their rank among those numbers them.
    has = dims[None, :] > np.arange(d_max)[:, None]
    count = has.sum(axis=1)
    base = exclusive_cumsum(count)
    rank = np.cumsum(has, axis=1) - 1
    coords = np.concatenate([offsets[:-1][has[a]] + a for a in range(d_max)])

    # On the diagonal coordinate pairs a == b, the blocks of the triangle.
    triangle_blocks = rows <= block_cols if upper else rows >= block_cols
    grid = []
    gather = np.empty((int(indptr[-1]) + int(offsets[-1])) // 2, dtype=indptr.dtype)  # (nnz + n) / 2
    done = 0
    shared: dict[tuple[int, int, bool], tuple[Any, Blocks, NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]] = {}
    for b in range(d_max):
        # Column coordinate b holds row coordinates a ≥ b (lower) or a ≤ b (upper); zeros elsewhere.
        above, below = (0, int(base[-1] - base[b + 1])) if upper else (int(base[b]), 0)
        column = [cvxopt.spmatrix([], [], [], (above, int(count[b])))] if above else []
        segments = []
        for a in range(b + 1) if upper else range(b, d_max):
            # Coordinates a and b are shared by the same variables as a' and b' when the counts
            # agree (has[a] ⊇ has[a + 1]): one matrix, one set of block indices.
            key = (int(count[a]), int(count[b]), a == b)
            if key not in shared:
                keep = has[a][rows] & has[b][block_cols] & (triangle_blocks if a == b else True)
                blocks: Blocks = slice(None) if keep.all() else np.flatnonzero(keep)
                cols = block_cols[blocks]
                per_column = np.bincount(cols, minlength=nv)
                within = np.arange(cols.size) - exclusive_cumsum(per_column)[cols]
                matrix = cvxopt.spmatrix(1.0, cvxopt.matrix(rank[a][rows[blocks]].astype(np.int64)),
                                         cvxopt.matrix(rank[b][cols].astype(np.int64)),
                                         (int(count[a]), int(count[b])))  # fmt: skip
                shared[key] = (matrix, blocks, cols, per_column, within)
            column.append(shared[key][0])
            segments.append((a, *shared[key][1:]))
        if below:
            column.append(cvxopt.spmatrix([], [], [], (below, int(count[b]))))
        grid.append(column)
        # Column o_v + b of P H Pᵀ lists coordinate b's blocks, then coordinate b + 1's, …
        total = np.sum([per_column for *_, per_column, _ in segments], axis=0)
        head = exclusive_cumsum(total)[:-1]
        out = gather[done : done + int(total.sum())]
        done += out.size
        at_b = start + b * step
        for a, blocks, cols, per_column, within in segments:
            out[head[cols] + within] = at_b[blocks] + a
            head += per_column
    return cvxopt.sparse(grid), gather, coords


def ranges(counts: NDArray[np.intp]) -> NDArray[np.intp]:
    """``0 … c − 1`` for every ``c`` of ``counts``, concatenated."""
    return np.arange(int(counts.sum())) - np.repeat(exclusive_cumsum(counts)[:-1], counts)


def permuted_block_triangle(
    indptr: IndexArray, dims: IndexArray, block_indptr: IndexArray, block_rows: IndexArray, order: NDArray[np.intp],
    upper: bool = False,
) -> tuple[NDArray[np.int32], NDArray[np.int32], NDArray[np.signedinteger]]:
    """The lower (``upper``: the upper) triangle of ``B = P H Pᵀ``, ``P`` the permutation that
    puts variable ``order[k]`` k-th (its coordinates kept together and in order), as 32-bit CSC
    arrays ``(indptr, indices)`` with sorted rows, and the position in ``H.data`` of each entry
    (``H``'s index dtype).

    ``H`` (CSC ``indptr``) is the scalar expansion of the block pattern (``dims``,
    ``block_indptr``, ``block_rows``: both triangles, every diagonal block, rows sorted), as
    :class:`~manopt_lie.linalg.BlockStructure` builds it: entry ``(o_w + a, o_v + b)`` of block
    ``k = (w, v)`` sits at ``s_k + b·ℓ_v + a`` (``ℓ_v`` the length of each of ``v``'s columns).
    Column ``c`` of ``B`` (variable ``v = order[c]``, coordinate ``b``) holds the rows ``a ≥ b`` of
    ``v``'s diagonal block, then the off-diagonal blocks below it in ``B``'s order (the upper
    triangle: the blocks above, then the rows ``a ≤ b``). Everything is built at the level of
    blocks and expanded once (sorting scalars would cost 10–15 ms on parking-garage). Trusted:
    the pattern is not checked.
    """
    nv = dims.size
    rank = np.empty(nv, dtype=np.intp)
    rank[order] = np.arange(nv)
    new_dims = dims[order].astype(np.intp)
    new_offsets = exclusive_cumsum(new_dims)
    block_cols, rows, start, length = _block_starts(indptr, dims, block_indptr, block_rows)
    new_col, new_row = rank[block_cols], rank[rows]
    diagonal = np.empty(nv, dtype=np.intp)
    diagonal[new_col[new_col == new_row]] = np.flatnonzero(new_col == new_row)  # v's block, by v's rank
    off = np.flatnonzero(new_row < new_col if upper else new_row > new_col)
    off = off[np.argsort(new_col[off] * nv + new_row[off], kind="stable")]  # B's block order

    # The off-diagonal rows of each of B's block columns ("stream"), at coordinate b = 0.
    widths = dims[rows[off]].astype(np.intp)
    stream_len = np.bincount(new_col[off], weights=widths, minlength=nv).astype(np.intp)
    within = ranges(widths)
    stream_row = (np.repeat(new_offsets[new_row[off]], widths) + within).astype(np.int32)
    stream_pos = (np.repeat(start[off], widths) + within).astype(indptr.dtype)
    stream_start = exclusive_cumsum(stream_len)

    # Scalar column j: block column c, coordinate b; its diagonal rows a ≥ b (upper: a ≤ b).
    c = np.repeat(np.arange(nv), new_dims)
    b = np.arange(int(new_offsets[-1])) - new_offsets[c]
    n_diag = b + 1 if upper else new_dims[c] - b
    step = b * length[order[c]]  # from coordinate 0 to b in H's columns of the variable
    count = stream_len[c]
    out_ptr = exclusive_cumsum(n_diag + count)

    # Column j copies its block column's stream (positions shifted by its step): in the output's
    # order, the stream entries are contiguous pieces of the stream arrays.
    pieces = exclusive_cumsum(count)
    source = np.repeat((stream_start[c] - pieces[:-1]).astype(indptr.dtype), count)
    source += np.arange(int(pieces[-1]), dtype=indptr.dtype)
    stream_rows, stream_at = np.take(stream_row, source), np.take(stream_pos, source)
    stream_at += np.repeat(step.astype(indptr.dtype), count)
    del source

    # The diagonal entries (n (d + 1) / 2 of them) go where the streams leave room.
    a = ranges(n_diag) + (0 if upper else np.repeat(b, n_diag))
    jd = np.repeat(np.arange(b.size), n_diag)
    at = out_ptr[jd] + (count[jd] if upper else 0) + (a if upper else a - b[jd])
    is_diagonal = np.zeros(int(out_ptr[-1]), dtype=bool)
    is_diagonal[at] = True
    out_rows = np.empty(is_diagonal.size, dtype=np.int32)
    gather = np.empty(is_diagonal.size, dtype=indptr.dtype)
    out_rows[at], gather[at] = new_offsets[c[jd]] + a, start[diagonal[c[jd]]] + step[jd] + a
    is_stream = ~is_diagonal
    out_rows[is_stream], gather[is_stream] = stream_rows, stream_at
    return out_ptr.astype(np.int32), out_rows, gather


_POINTER = ctypes.sizeof(ctypes.c_void_p)


def _values_address(matrix: Any) -> int:
    """The address of a CVXOPT sparse matrix's values: its object holds, after the Python object
    header, a pointer to its ``ccs`` struct, whose first member points to the values."""
    ccs = ctypes.c_void_p.from_address(id(matrix) + object.__basicsize__).value
    return int(ctypes.c_void_p.from_address(ccs).value or 0) if ccs else 0


def _view(matrix: Any, size: int) -> NDArray[np.float64] | None:
    address = _values_address(matrix)
    return np.ctypeslib.as_array((ctypes.c_double * size).from_address(address)) if address else None


@cache
def _layout_checked(cvxopt: Any) -> bool:
    """Whether :func:`values_view` reads this CVXOPT's sparse matrices right: checked once, on a
    small matrix, by writing through the view and reading back through CVXOPT's own ``V``."""
    probe = cvxopt.spmatrix([1.0, 2.0, 3.0], [0, 1, 1], [0, 0, 1], (2, 2))
    if type(probe).__basicsize__ != object.__basicsize__ + _POINTER:  # not a header and one pointer
        return False
    view = _view(probe, 3)
    if view is None or view.tolist() != [1.0, 2.0, 3.0]:
        return False
    view[:] = (4.0, 5.0, 6.0)
    return bool(np.asarray(probe.V).ravel().tolist() == [4.0, 5.0, 6.0])


def values_view(cvxopt: Any, matrix: Any, size: int) -> NDArray[np.float64] | None:
    """A writable NumPy view of the ``size`` values of the real CVXOPT sparse matrix ``matrix``
    (``None`` where its layout is not the one :func:`_layout_checked` confirmed).

    CVXOPT hands its values out only as copies (``matrix.V``) and takes new ones only as a
    CVXOPT matrix, which costs two copies of every value per factorization (parking-garage:
    0.85 ms of a 6.2 ms factorization); through the view, new values are written in place.
    The view does not keep ``matrix`` alive: its owner must hold both, and never resize the
    matrix.
    """
    if matrix.typecode != "d" or not _layout_checked(cvxopt):
        return None
    return _view(matrix, size)
