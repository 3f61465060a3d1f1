"""Private helpers on the values optimizers handle.

* the *structure* of a callback's result (its shape, or a tuple of shapes for a
  product manifold's vectors) and whether it is finite, for the checks made once
  per run at ``x₀``;
* value *snapshots* of points, so that caches key on a point's value, never on
  its identity (an array point may be mutated in place between two calls);
* an overflow- and underflow-safe norm: ``√Σv²`` loses everything when the
  squares underflow (a cost scaled by 1e-300) or overflow.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import NonFiniteError, ShapeError
from ..lie import LieGroup
from ..manifolds.base import Manifold

__all__ = ["all_finite", "check_result", "max_abs", "safe_norm", "same_point", "snapshot", "structure"]

# ‖v‖² outside this range is recomputed from v / max|v| (no under- or overflow).
_SQ_LOW, _SQ_HIGH = 1e-250, 1e250


def structure(v: Any) -> Any:
    """The shape of ``v``, or the tuple of its parts' structures for a tuple (product vectors)."""
    if isinstance(v, tuple):
        return tuple(structure(p) for p in v)
    return np.shape(v)


def all_finite(v: Any) -> bool:
    """Whether every entry of ``v`` (an array, a number or a tuple of them) is finite."""
    if isinstance(v, tuple):
        return all(all_finite(p) for p in v)
    return bool(np.all(np.isfinite(v)))


def max_abs(v: Any) -> float:
    """``max |vᵢ|`` over every entry (``nan`` if any is ``nan``)."""
    if isinstance(v, tuple):
        return max((max_abs(p) for p in v), default=0.0)
    a = np.abs(np.asarray(v, dtype=np.float64))
    return float(np.max(a)) if a.size else 0.0


def safe_norm(manifold: Manifold, x: Any, v: Any) -> float:
    """``‖v‖_x = √⟨v, v⟩_x`` summed over any batch, computed as ``a·‖v/a‖`` with
    ``a = max|vᵢ|`` when ``⟨v, v⟩`` is outside ``[1e-250, 1e250]`` (the metric is
    bilinear, so the rescaling is exact).

    The common case is one :meth:`~manopt_lie.manifolds.Manifold.total_inner` (a single
    ``np.vdot`` on most manifolds) and a range test; only a norm outside the range pays
    for the second pass.
    """
    with np.errstate(over="ignore", under="ignore"):  # recomputed below if so
        sq = manifold.total_inner(x, v, v)
    if _SQ_LOW < sq < _SQ_HIGH:
        return math.sqrt(sq)
    if math.isnan(sq):
        return math.nan
    a = max_abs(v)
    if not (0.0 < a < math.inf):
        return a  # 0, inf or nan
    w = v / a
    return a * math.sqrt(manifold.total_inner(x, w, w))


def check_result(owner: str, name: str, value: Any, expected: Any, what: str) -> None:
    """Raise unless the result ``value`` of the callback ``name`` has the structure
    ``expected`` and is finite and real.

    Raises
    ------
    ShapeError
        Naming the callback, the expected and the actual shape.
    TypeError
        For a complex or non-numeric result.
    NonFiniteError
        For a result holding ``nan`` or ``inf``.
    """
    actual = structure(value)
    if actual != expected:
        raise ShapeError(f"{owner}: {name} returned shape {actual} at x0; {what} has shape {expected}")
    parts = value if isinstance(value, tuple) else (value,)
    for p in parts:
        a = np.asarray(p)
        if a.dtype.kind not in "fiub":  # float, int, unsigned, bool
            raise TypeError(f"{owner}: {name} returned {a.dtype} values at x0; it must return real numbers")
    if not all_finite(value):
        raise NonFiniteError(f"{owner}: {name} returned non-finite values (nan or inf) at x0")


class _Element:
    """A snapshot of a group element: its class and a private copy of its array."""

    __slots__ = ("cls", "data")

    def __init__(self, x: LieGroup) -> None:
        self.cls, self.data = type(x), np.array(x.data, copy=True)


def snapshot(x: Any) -> Any:
    """A private copy of the point ``x``'s value, for :func:`same_point`.

    Arrays and group elements are copied (an element's array can be made writeable
    and changed in place, so not even its identity proves its value); tuples
    (product points) are snapshot part by part.
    """
    if isinstance(x, LieGroup):
        return _Element(x)
    if isinstance(x, tuple):
        return tuple(snapshot(p) for p in x)
    return np.array(x, copy=True)


def same_point(snap: Any, x: Any) -> bool:
    """Whether ``x`` has the value recorded in ``snap`` (by :func:`snapshot`): one
    ``np.array_equal`` per array, cheap beside any evaluation it saves."""
    if type(snap) is _Element:  # (one comparison, as for arrays below: np.array_equal costs twice that)
        if type(x) is not snap.cls:
            return False
        data = x.data
        return data.shape == snap.data.shape and bool((data == snap.data).all())
    if isinstance(snap, tuple):
        return isinstance(x, tuple) and len(x) == len(snap) and all(map(same_point, snap, x))
    if type(x) is np.ndarray:  # the hot path: one comparison, no conversions
        return x.shape == snap.shape and bool((x == snap).all())
    if isinstance(x, (LieGroup, tuple)):
        return False
    return np.shape(x) == snap.shape and bool(np.array_equal(x, snap))
