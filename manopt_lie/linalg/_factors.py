"""Validation of factor types and the small index helpers behind :class:`BlockStructure`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["FactorIndex", "check_factor", "exclusive_cumsum", "index_dtype", "same_buffer"]

IntArray = NDArray[np.intp]


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


def check_factor(k: int, var_ids: ArrayLike, residual_dim: int, dims: IntArray) -> tuple[IntArray, tuple[int, ...]]:
    """Validated ``var_ids`` and slot dimensions of factor ``k``."""
    ids = np.asarray(var_ids)
    if ids.ndim != 2 or not np.issubdtype(ids.dtype, np.integer):
        raise ValueError(f"factor {k}: var_ids must be an integer array (m, arity), got {ids.dtype} {ids.shape}")
    if int(residual_dim) != residual_dim or residual_dim < 1:
        raise ValueError(f"factor {k}: residual_dim must be a positive integer, got {residual_dim!r}")
    if ids.shape[0] == 0:
        raise ValueError(f"factor {k}: has no edges (leave empty factor types out)")
    ids = ids.astype(np.intp)
    bad = (ids < 0) | (ids >= dims.size)
    if bad.any():
        e, s = np.argwhere(bad)[0]
        raise ValueError(f"factor {k}, edge {e}, slot {s}: variable id {ids[e, s]} is outside [0, {dims.size})")
    srt = np.sort(ids, axis=1)
    dup = srt[:, 1:] == srt[:, :-1]
    if dup.any():
        e = np.argwhere(dup)[0, 0]
        raise ValueError(f"factor {k}, edge {e}: touches variable {srt[e][1:][dup[e]][0]} in two slots")
    slot_dims = dims[ids]
    mixed = slot_dims != slot_dims[0]
    if mixed.any():
        e, s = np.argwhere(mixed)[0]
        raise ValueError(
            f"factor {k}, slot {s}: variables of dimension {slot_dims[0, s]} (edge 0) and "
            f"{slot_dims[e, s]} (edge {e}, variable {ids[e, s]}); every slot needs one dimension"
        )
    return ids, tuple(int(d) for d in slot_dims[0])
