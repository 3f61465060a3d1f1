"""A :class:`~manopt_lie.linalg.BlockStructure`'s index arrays built with NumPy, where the compiled
build (``_patterns``, ``patterns.c``) cannot serve: no C compiler, indices past 32 bits, or
scatters too large to keep whole (the 10⁵–10⁶-pose graphs, whose scatters are then made per
chunk). Both builds give the same arrays (``tests/linalg/test_patterns.py``).

Notation (``structure.py``'s): variable ``v`` has dimension ``d_v`` and owns coordinates
``o_v … o_v + d_v − 1``. Block ``k = (a, b)`` holds the rows of variable ``a`` in the columns of
``b``; each column of ``b`` has length ``L[b]`` (the dimensions of the rows of ``b``'s blocks), ``b``'s
columns start at ``base[b]`` of ``H.data``, and block ``k`` starts ``within[k]`` down each of them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ._factors import FactorIndex, HessianScatter, coordinates, exclusive_cumsum, index_dtype

__all__ = ["dense_pattern", "dense_scatters", "edge_coordinates", "factor_scatter", "sparse_pattern"]

IntArray = NDArray[np.intp]
Index = NDArray[np.signedinteger]
# (block pattern (indptr, rows), H's indptr, H's indices, the diagonal's positions)
Pattern = tuple[tuple[Index, Index], Index, Index, Index]
# (L, base, within): the length of each variable's columns, where they start, each block's offset in them
Layout = tuple[IntArray, IntArray, IntArray]


def sparse_pattern(
    dims: IntArray, offsets: IntArray, all_ids: list[IntArray]
) -> tuple[Pattern, list[IntArray], Layout]:
    """Block-CSC pattern of ``H`` and its scalar CSC expansion.

    Returns the pattern; per factor, the block index of every slot pair as an array
    ``(arity, m, arity)`` indexed ``[t, e, s]`` (rows of slot ``s``, columns of slot ``t``); and the
    layout ``(L, base, within)``, which only the factors' scatters read (not kept: a 10⁵-pose
    planar graph's is 4 MB). Block ``k = (a, b)`` puts entry ``(o_a + i, o_b + j)`` at
    ``base[b] + j·L[b] + within[k] + i`` of ``H.data``.
    """
    nv, n = dims.size, int(offsets[-1])
    keys = [np.arange(nv, dtype=np.int64) * (nv + 1)]
    keys += [(ids[:, t, None] * nv + ids).ravel() for ids in all_ids for t in range(ids.shape[1])]
    all_keys = np.concatenate(keys)
    ukeys, inverse = np.unique(all_keys, return_inverse=True)
    bcol, brow = np.divmod(ukeys, nv)
    col_len = np.bincount(bcol, weights=dims[brow], minlength=nv).astype(np.intp)
    base = exclusive_cumsum(col_len * dims)
    stream_start = exclusive_cumsum(col_len)
    within = exclusive_cumsum(dims[brow])[:-1] - stream_start[bcol]

    nnz = int(base[-1])
    itype = index_dtype(max(nnz, n))
    # The variables' graph (block CSC, both triangles): what a fill-reducing ordering reads.
    block_pattern = (exclusive_cumsum(np.bincount(bcol, minlength=nv)).astype(itype), brow.astype(itype))
    var_of_col = np.repeat(np.arange(nv), dims)
    j_local = np.arange(n) - offsets[var_of_col]
    indptr = np.append(base[var_of_col] + j_local * col_len[var_of_col], nnz)
    # Each column of variable b lists the rows of b's blocks in order: the "row stream" segment
    # of b, repeated d_b times. The nnz-sized arrays are built in the index dtype, one at a time
    # (their memory is the structure's peak).
    row_stream = coordinates(offsets, dims, brow)
    per_col = col_len[var_of_col]
    gather = np.repeat((stream_start[var_of_col] - indptr[:-1]).astype(itype), per_col)
    gather += np.arange(nnz, dtype=itype)
    indices = np.take(row_stream.astype(itype), gather)  # take: twice as fast as [] with an int32 index
    del gather
    diagonal = (indptr[:-1] + within[inverse[:nv]][var_of_col] + j_local).astype(itype)
    parts = np.split(inverse[nv:], np.cumsum([ids.size * ids.shape[1] for ids in all_ids])[:-1])
    blocks = [p.reshape(ids.shape[1], *ids.shape) for p, ids in zip(parts, all_ids, strict=True)]
    return (block_pattern, indptr.astype(itype), indices, diagonal), blocks, (col_len, base, within)


def dense_pattern(nv: int, n: int) -> Pattern:
    """:func:`sparse_pattern` for a ``dense`` structure: every entry stored, ``(i, j)`` at ``j·n + i``
    of ``H.data``; the variables' graph complete. For small systems, where the bookkeeping of a
    sparse pattern costs more than the entries it leaves out (:data:`~manopt_lie.linalg.DENSE_MAX`)."""
    itype = index_dtype(n * n)
    block_pattern = (np.arange(0, nv * nv + 1, nv, dtype=itype), np.tile(np.arange(nv, dtype=itype), nv))
    return (block_pattern, np.arange(0, n * n + 1, n, dtype=itype), np.tile(np.arange(n, dtype=itype), n),
            np.arange(0, n * n, n + 1, dtype=itype))  # fmt: skip


def edge_coordinates(offsets: IntArray, f: FactorIndex) -> IntArray:
    """``(m, width)``: the coordinate of every column of each edge's block ``A_e``."""
    slots = [offsets[f.var_ids[:, s], None] + np.arange(ds) for s, ds in enumerate(f.slot_dims)]
    return np.concatenate(slots, 1)


def dense_scatters(factors: list[FactorIndex], offsets: IntArray, n: int) -> tuple[list[HessianScatter], list[Index]]:
    """A dense structure's H and g scatters: entry ``[p, q]`` of ``A_eᵀA_e`` at ``c_p·n + c_q``,
    ``c`` the coordinates of ``A_e``'s columns."""
    itype = index_dtype(n * n)
    columns = [edge_coordinates(offsets, f).astype(itype) for f in factors]
    hessian = [HessianScatter.of_positions((c[:, :, None] * itype(n) + c[:, None, :]).reshape(-1), c.shape[1])
               for c in columns]  # fmt: skip
    return hessian, [c.reshape(-1) for c in columns]


def factor_scatter(
    f: FactorIndex, block: IntArray, layout: Layout, offsets: IntArray, itype: type[np.signedinteger]
) -> tuple[HessianScatter, Index]:
    """Index arrays of one factor type: its H and g scatters (``block``: its block indices from
    :func:`sparse_pattern`; ``itype``: the structure's index dtype)."""
    ids, slot_dims = f.var_ids, f.slot_dims
    colmap = edge_coordinates(offsets, f)
    # A_eᵀA_e is symmetric, so its entry [p, q] may go to H[q, p]: consecutive q then land on
    # consecutive rows of one CSC column, which makes the scatter far more cache-friendly than
    # walking along a row.
    col_len, base, within = (a.astype(itype) for a in layout)
    local = np.concatenate([np.arange(ds, dtype=itype) for ds in slot_dims])  # i within each slot
    # Row j of slot t (variable b) goes to column o_b + j, which starts at base[b] + j·L[b]; its
    # entry q (slot s, row i of that slot's block) then sits at within[block[t, e, s]] + i.
    rows = [col_len[ids[:, t], None] * np.arange(dt, dtype=itype) + base[ids[:, t], None]
            for t, dt in enumerate(slot_dims)]  # fmt: skip
    row_start = np.concatenate(rows, axis=1)  # (m, width)
    offset = np.stack([np.repeat(within[block[t]], slot_dims, axis=1) + local for t in range(len(slot_dims))])
    return HessianScatter(row_start, offset, slot_dims), colmap.astype(itype).reshape(-1)
