"""AMD, the approximate minimum degree ordering, called directly (:mod:`ctypes`) on NumPy's arrays.

CVXOPT ships AMD as a shared library and loads it for ``cvxopt.amd``, whose interface takes the
pattern as a CVXOPT sparse matrix: built from NumPy's arrays, that costs as much as the ordering
itself (CSAIL's 1,045 variables: 0.08 of 0.17 ms). Called directly, ``amd_order`` reads the
pattern's own 32-bit index arrays. The binding is checked once per process, where it is first
used: the order of a small graph against CVXOPT's. Where the check fails or the library cannot
be found, :func:`amd_order` returns ``None``, and :func:`variable_order` goes through CVXOPT's interface.
"""

from __future__ import annotations

import ctypes
import functools
from ctypes import c_int, c_void_p
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._native import address
from ._cholmod_types import cvxopt_library

__all__ = ["amd_order", "amd_order_address", "variable_order"]

SUCCESS = (0, 1)  # amd.h's statuses of success: AMD_OK, AMD_OK_BUT_JUMBLED


@functools.cache
def _library() -> Any | None:
    """AMD, checked, or ``None``."""
    try:
        from cvxopt import amd, spmatrix  # loads the library this binding calls
    except ImportError:
        return None
    lib = cvxopt_library("amd", {"amd_order": (c_int, [c_int, c_void_p, c_void_p, c_void_p, c_void_p, c_void_p])})
    if lib is None:
        return None
    # A wheel of 7 with a chord: CVXOPT's order of its lower triangle, and ours of both triangles.
    edges = [(k, (k + 1) % 7) for k in range(7)] + [(0, 3), (2, 5)]
    rows = [max(e) for e in edges] + list(range(7))
    cols = [min(e) for e in edges] + list(range(7))
    expected = np.asarray(amd.order(spmatrix(1.0, rows, cols, (7, 7)), "L"), dtype=np.intp).ravel()
    full = np.zeros((7, 7), dtype=bool)
    full[rows, cols] = full[cols, rows] = True
    indptr = np.concatenate([[0], np.cumsum(full.sum(axis=0))]).astype(np.int32)
    indices = np.nonzero(full.T)[1].astype(np.int32)
    got = _order(lib, indptr, indices)
    return lib if got is not None and np.array_equal(got, expected) else None


def _order(lib: Any, indptr: NDArray[np.int32], indices: NDArray[np.int32]) -> NDArray[np.intp] | None:
    n = indptr.size - 1
    order = np.empty(max(n, 1), dtype=np.int32)
    status = lib.amd_order(n, address(indptr), address(indices), address(order), None, None)
    return order[:n].astype(np.intp) if status in SUCCESS else None


@functools.cache
def amd_order_address() -> int | None:
    """The address of the checked ``amd_order`` (for C that calls it, ``early.c: early_start``),
    or ``None``."""
    lib = _library()
    return None if lib is None else ctypes.cast(lib.amd_order, c_void_p).value


def amd_order(indptr: NDArray[np.signedinteger], indices: NDArray[np.signedinteger]) -> NDArray[np.intp] | None:
    """AMD's order of a symmetric pattern (CSC, both triangles stored; the diagonal is ignored), as
    CVXOPT's ``amd.order`` finds it: ``order[k]`` is the ``k``-th node eliminated. ``None`` where AMD
    cannot be called directly here, or the indices are not 32-bit."""
    lib = _library()
    if lib is None or indptr.dtype != np.int32 or indices.dtype != np.int32:
        return None
    return _order(lib, np.ascontiguousarray(indptr), np.ascontiguousarray(indices))


def variable_order(indptr: NDArray[np.signedinteger], indices: NDArray[np.signedinteger]) -> NDArray[np.intp] | None:
    """:func:`amd_order` where it can be called, else CVXOPT's ``amd.order`` of the lower triangle (the
    same order); ``None`` without CVXOPT."""
    order = amd_order(indptr, indices)
    if order is not None:
        return order
    try:
        from cvxopt import amd, matrix, spmatrix
    except ImportError:
        return None
    n = indptr.size - 1
    cols = np.repeat(np.arange(n, dtype=np.int64), np.diff(indptr))
    lower = indices >= cols
    pattern = spmatrix(1.0, matrix(indices[lower].astype(np.int64)), matrix(cols[lower]), (n, n))
    return np.asarray(amd.order(pattern, "L"), dtype=np.intp).reshape(-1)
