"""Validation of factor types and the small index helpers behind :class:`BlockStructure`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["FactorIndex", "HessianScatter", "check_edges", "coordinates", "exclusive_cumsum", "factor_ids"]
__all__ += ["index_dtype", "same_buffer"]

IntArray = NDArray[np.intp]

WHOLE_SCATTER_BYTES = 32 << 20
"""A factor's scatter into ``H`` is kept whole up to this size; above it, it is made chunk by
chunk from a quarter of the numbers. On a 10⁵-pose cube that keeps 50 MB off the solve's peak
and costs ~25 ms more per ``H`` (76–82 → 100–105 ms), 1 % of an iteration."""


def index_dtype(maxval: int) -> type[np.signedinteger]:
    """The index dtype SciPy keeps without copying (int32 when it fits)."""
    return np.int32 if maxval < np.iinfo(np.int32).max else np.int64


def same_buffer(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether ``a`` and ``b`` are the same memory seen with the same dtype and length (e.g. a
    pattern's index array and the view of it a SciPy matrix holds)."""
    return a is b or (
        a.dtype == b.dtype and a.shape == b.shape and a.__array_interface__["data"] == b.__array_interface__["data"]
    )


def exclusive_cumsum(a: IntArray) -> IntArray:
    """``[0, a₀, a₀ + a₁, …, Σa]`` (length ``a.size + 1``)."""
    out = np.zeros(a.size + 1, dtype=np.intp)
    np.cumsum(a, out=out[1:])
    return out


def coordinates(offsets: IntArray, dims: IntArray, variables: IntArray) -> IntArray:
    """The coordinates ``o_v … o_v + d_v − 1`` of every variable ``v`` of ``variables``, in that
    order, concatenated (``offsets``: ``[0, cumsum(dims)]``)."""
    if dims.size and dims.min() == dims.max():  # one dimension d: o_v + 0 … d − 1, side by side
        return (offsets[variables][:, None] + np.arange(int(dims[0]))).reshape(-1)
    d = dims[variables]
    return np.repeat(offsets[variables] - exclusive_cumsum(d)[:-1], d) + np.arange(int(d.sum()))


@dataclass(frozen=True)
class FactorIndex:
    """Index arrays of one factor type (``m`` edges, residual ``r``, width ``D``)."""

    var_ids: IntArray  # (m, arity)
    residual_dim: int
    slot_dims: tuple[int, ...]

    @property
    def m(self) -> int:
        return self.var_ids.shape[0]

    @property
    def width(self) -> int:
        return sum(self.slot_dims)


def factor_ids(k: int, var_ids: ArrayLike, residual_dim: int) -> IntArray:
    """Factor ``k``'s ``var_ids`` as a new ``(m, arity)`` array of ``intp``, its shape, dtype and
    ``residual_dim`` checked (its edges are :func:`check_edges`'s)."""
    ids = np.asarray(var_ids)
    if ids.ndim != 2 or ids.dtype.kind not in "iu":  # integers (np.issubdtype: 3 µs in a cold solve)
        raise ValueError(f"factor {k}: var_ids must be an integer array (m, arity), got {ids.dtype} {ids.shape}")
    if int(residual_dim) != residual_dim or residual_dim < 1:
        raise ValueError(f"factor {k}: residual_dim must be a positive integer, got {residual_dim!r}")
    if ids.shape[0] == 0:
        raise ValueError(f"factor {k}: has no edges (leave empty factor types out)")
    return ids.astype(np.intp)


def check_edges(k: int, ids: IntArray, dims: IntArray) -> tuple[int, ...]:
    """The slots' dimensions of factor ``k``, whose edges ``ids`` must name variables in range, none
    twice, and in each slot variables of one dimension (else a ValueError names the edge)."""
    if ids.min() < 0 or ids.max() >= dims.size:
        e, s = np.argwhere((ids < 0) | (ids >= dims.size))[0]
        raise ValueError(f"factor {k}, edge {e}, slot {s}: variable id {ids[e, s]} is outside [0, {dims.size})")
    srt = np.sort(ids, axis=1) if ids.shape[1] > 2 else ids  # two slots: compared as they are
    dup = srt[:, 1:] == srt[:, :-1]
    if dup.any():
        e = np.argwhere(dup)[0, 0]
        raise ValueError(f"factor {k}, edge {e}: touches variable {srt[e][1:][dup[e]][0]} in two slots")
    if dims.min() == dims.max():
        return (int(dims[0]),) * ids.shape[1]
    slot_dims = dims[ids]
    mixed = slot_dims != slot_dims[0]
    if mixed.any():
        e, s = np.argwhere(mixed)[0]
        raise ValueError(
            f"factor {k}, slot {s}: variables of dimension {slot_dims[0, s]} (edge 0) and "
            f"{slot_dims[e, s]} (edge {e}, variable {ids[e, s]}); every slot needs one dimension"
        )
    return tuple(int(d) for d in slot_dims[0])


class HessianScatter:
    """Where each entry of every edge's ``A_eᵀA_e`` (``W × W``) goes in ``H.data``.

    Entry ``[p, q]`` of edge ``e`` goes to ``row_start[e, p] + offset[t(p), e, q]``, ``t(p)`` the
    slot of row ``p``: the rows of one slot share their offsets. Those ``W + arity·W`` numbers
    per edge are kept; the ``W²`` positions themselves are kept too when they fit in
    :data:`WHOLE_SCATTER_BYTES`, else made per chunk of edges by :meth:`chunk`.

    Parameters
    ----------
    row_start : ndarray of int, shape (m, W)
    offset : ndarray of int, shape (arity, m, W)
    slot_dims : tuple of int
        The slots' dimensions (summing to ``W``).
    """

    def __init__(self, row_start: NDArray[np.signedinteger], offset: NDArray[np.signedinteger],
                 slot_dims: tuple[int, ...]) -> None:  # fmt: skip
        self._row_start, self._offset = row_start, offset
        self._starts = np.cumsum((0, *slot_dims)).tolist()
        m, self.width = row_start.shape
        self.dtype = row_start.dtype
        self.whole: NDArray[np.signedinteger] | None = None
        """The positions of every edge's entries, flat (``None``: made per chunk)."""
        if m * self.width**2 * self.dtype.itemsize <= WHOLE_SCATTER_BYTES:
            self.whole = self._fill(0, m, np.empty(m * self.width**2, dtype=self.dtype))
            del self._row_start, self._offset

    @classmethod
    def of_positions(cls, positions: NDArray[np.signedinteger], width: int) -> HessianScatter:
        """The scatter of the given positions (every edge's ``W²``, flat): for a dense structure,
        whose positions are one product of coordinates."""
        scatter = cls.__new__(cls)
        scatter.width, scatter.dtype, scatter.whole = width, positions.dtype, positions
        return scatter

    def _fill(self, e0: int, e1: int, out: NDArray[np.signedinteger]) -> NDArray[np.signedinteger]:
        width = self.width
        block = out[: (e1 - e0) * width * width].reshape(e1 - e0, width, width)
        for t, (s0, s1) in enumerate(zip(self._starts, self._starts[1:], strict=False)):
            np.add(self._row_start[e0:e1, s0:s1, None], self._offset[t, e0:e1, None, :], out=block[:, s0:s1, :])
        return block.reshape(-1)

    def chunk(self, e0: int, e1: int, work: NDArray[np.signedinteger]) -> NDArray[np.signedinteger]:
        """The positions of edges ``e0:e1``'s entries, flat: a slice of the whole scatter, or
        made in ``work`` (at least ``(e1 − e0)·W²`` entries of the index dtype)."""
        if self.whole is not None:
            return self.whole[e0 * self.width**2 : e1 * self.width**2]
        return self._fill(e0, e1, work)
