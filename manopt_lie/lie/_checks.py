"""Input validation shared by the group kernels."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import NonFiniteError, ShapeError

FloatArray = NDArray[np.float64]


def _fmt(shape: tuple[int, ...]) -> str:
    return "(..., " + ", ".join(map(str, shape)) + ")" if shape else "(...)"


def as_batch(x: ArrayLike, trailing: tuple[int, ...], name: str) -> FloatArray:
    """``x`` as a float64 array of shape ``(..., *trailing)`` holding finite values.

    Raises
    ------
    ShapeError
        If the trailing axes are not ``trailing``.
    NonFiniteError
        If any value is ``nan`` or ``inf``.
    """
    a = np.asarray(x, dtype=np.float64)
    k = len(trailing)
    if a.ndim < k or a.shape[a.ndim - k :] != trailing:
        raise ShapeError(f"{name}: expected shape {_fmt(trailing)}, got {a.shape}")
    check_finite(a, name)
    return a


def check_finite(a: FloatArray, name: str) -> None:
    if not np.isfinite(a).all():
        bad = np.argwhere(~np.isfinite(a))[0]
        raise NonFiniteError(f"{name}: non-finite value at index {tuple(int(i) for i in bad)}")


def broadcast_batch(*shapes: tuple[int, ...]) -> tuple[int, ...]:
    """The broadcast of batch shapes, as a ``ShapeError`` when they do not broadcast."""
    try:
        return np.broadcast_shapes(*shapes)
    except ValueError:
        raise ShapeError(f"batch shapes {', '.join(map(str, shapes))} do not broadcast") from None
