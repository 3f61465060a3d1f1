"""Input validation shared by the group kernels.

Validation runs once, at the public boundary, on what the user passed; arrays the library made
itself are not validated again. It is cheap on small inputs: a float64 array is taken as it is,
and finiteness is read off the sum of the entries (a sum is finite iff every entry is, unless it
overflows, in which case the entries are checked one by one).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import NonFiniteError, ShapeError

FloatArray = NDArray[np.float64]
_F64 = np.dtype(np.float64)
# Up to this many entries, finiteness is checked on Python floats (cheaper than a ufunc call).
_SMALL = 64


def _fmt(shape: tuple[int, ...]) -> str:
    return "(..., " + ", ".join(map(str, shape)) + ")" if shape else "(...)"


def as_batch(x: ArrayLike, trailing: tuple[int, ...], name: str) -> FloatArray:
    """``x`` as a float64 array of shape ``(..., *trailing)`` holding finite values.

    A float64 array is returned as it is (not copied).

    Raises
    ------
    ShapeError
        If the trailing axes are not ``trailing``.
    NonFiniteError
        If any value is ``nan`` or ``inf``.
    """
    a = x if type(x) is np.ndarray and x.dtype is _F64 else np.asarray(x, dtype=np.float64)
    k = len(trailing)
    if a.shape[a.ndim - k :] != trailing or a.ndim < k:
        raise ShapeError(f"{name}: expected shape {_fmt(trailing)}, got {a.shape}")
    check_finite(a, name)
    return a


def check_finite(a: FloatArray, name: str) -> None:
    """Raise :class:`NonFiniteError` naming the first ``nan``/``inf`` entry of ``a``."""
    if a.size <= _SMALL:
        total = sum(a.ravel().tolist())
    else:
        with np.errstate(over="ignore", invalid="ignore"):  # inf − inf: nan, as wanted
            total = float(a.sum())
    if math.isfinite(total) or np.isfinite(a).all():  # an overflowing sum of finite entries: look closer
        return
    bad = np.argwhere(~np.isfinite(a))[0]
    raise NonFiniteError(f"{name}: non-finite value at index {tuple(int(i) for i in bad)}")


def broadcast_batch(*shapes: tuple[int, ...]) -> tuple[int, ...]:
    """The broadcast of batch shapes, as a ``ShapeError`` when they do not broadcast."""
    if len(shapes) == 2 and shapes[0] == shapes[1]:
        return shapes[0]
    try:
        return np.broadcast_shapes(*shapes)
    except ValueError:
        raise ShapeError(f"batch shapes {', '.join(map(str, shapes))} do not broadcast") from None
