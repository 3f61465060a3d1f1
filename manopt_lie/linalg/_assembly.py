"""The normal equations' numeric assembly in compiled code (``assembly.c``): each edge's ``w_e A_eᵀA_e``
and ``w_e A_eᵀr_e`` formed and added into ``H.data`` and ``g`` in one pass over the edges.

:class:`~manopt_lie.linalg.BlockStructure`'s NumPy path writes a chunk's products to a workspace
(``np.matmul``) and sums them in (``np.add.at``): two passes over the products, and a workspace of a
chunk's products that a cold solve's first assembly brings into its cache. Compiled, CSAIL's ``H``
takes 0.08–0.14 ms instead of 0.13–0.22 and ``g`` 0.03–0.04 instead of 0.06–0.11 (this machine,
alternated); a cold LM solve 7–8 % less on CSAIL, intel and manhattan. The functions
return ``False`` where the C cannot serve — no compiler (``_native.enabled``), a scatter that is
not 32-bit, a factor wider than :data:`MAX_WIDTH`, arrays (weights included) not C-contiguous
float64 — and the caller takes the NumPy path.
"""

from __future__ import annotations

import ctypes
import functools
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import _native

__all__ = ["MAX_WIDTH", "gradient_add", "hessian_add"]

MAX_WIDTH = 32
"""The widest edge block ``A_e`` (``Σ`` of its variables' dimensions) the C assembles."""

FloatArray = NDArray[np.float64]

_P = ctypes.c_void_p
_I = ctypes.c_int64
_SIGNATURES: dict[str, tuple[Any, list[Any]]] = {
    "hessian_add": (ctypes.c_int, [_I, _I, _I, _P, _P, _P, _P]),
    "gradient_add": (ctypes.c_int, [_I, _I, _I, _P, _P, _P, _P, _P]),
}
_at = _native.address


@functools.cache
def _library() -> Any:
    """``assembly.c`` compiled (once per machine, like the kernels), or ``None``."""
    return _native.load_source(__package__, "assembly.c", _SIGNATURES)


def _usable(a: FloatArray, w: FloatArray | None, positions: NDArray[np.signedinteger], out: FloatArray) -> bool:
    """Whether the C can read ``a``, ``w`` and ``positions`` and add into ``out`` as they are."""
    floats = (a, out) if w is None else (a, w, out)
    return (
        positions.dtype == np.int32 and positions.flags.c_contiguous and a.ndim == 3 and a.shape[2] <= MAX_WIDTH
        and all(x.dtype == np.float64 and x.flags.c_contiguous for x in floats) and _library() is not None
    )  # fmt: skip


def hessian_add(a: FloatArray, w: FloatArray | None, positions: NDArray[np.signedinteger], data: FloatArray) -> bool:
    """``data[positions[e, i, j]] += w_e (A_eᵀA_e)_ij`` for every edge of ``a`` (shape ``(m, r, W)``; ``w``
    of shape ``(m,)`` or ``None``: 1), where the C serves; whether it did."""
    if not _usable(a, w, positions, data):
        return False
    m, r, width = a.shape
    if m:
        _library().hessian_add(m, r, width, _at(a), None if w is None else _at(w), _at(positions), _at(data))
    return True


def gradient_add(
    a: FloatArray, residuals: FloatArray, w: FloatArray | None, positions: NDArray[np.signedinteger], g: FloatArray
) -> bool:
    """``g[positions[e, j]] += w_e (A_eᵀr_e)_j`` for every edge of ``a`` (``residuals`` of shape ``(m, r)``),
    where the C serves; whether it did."""
    if not _usable(a, w, positions, g) or not (residuals.dtype == np.float64 and residuals.flags.c_contiguous):
        return False
    m, r, width = a.shape
    if m:
        _library().gradient_add(
            m, r, width, _at(a), _at(residuals), None if w is None else _at(w), _at(positions), _at(g)
        )
    return True
