"""Rⁿ under addition, as a Lie group: stored as vectors ``(..., n)``.

``Rn(n)`` returns the group class for one ``n`` (the same class on every call),
so ``Rn(3).exp(tau)`` and ``isinstance(x, Rn(3))`` work as for the other groups.
Everything is trivial (``Exp = Log = id``, ``Ad = Jr = Jl = I``), which makes
Rⁿ factors mix with rotations and poses in products of groups.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..errors import NotInGroupError
from ._checks import FloatArray, as_batch
from .base import LieGroup

__all__ = ["Rn", "RnGroup"]


def _eye_over(x: FloatArray, n: int) -> FloatArray:
    return np.array(np.broadcast_to(np.eye(n), x.shape[:-1] + (n, n)))


class RnGroup(LieGroup):
    """Base of the ``Rn(n)`` classes; use :func:`Rn` to get one."""

    __slots__ = ()

    @staticmethod
    def _exp(tau: FloatArray) -> FloatArray:
        return tau.copy()

    _log = _exp

    @staticmethod
    def _compose(a: FloatArray, b: FloatArray) -> FloatArray:
        return a + b

    @staticmethod
    def _inverse(a: FloatArray) -> FloatArray:
        return -a

    _act = _compose

    @classmethod
    def _act_jac(cls, a: FloatArray, p: FloatArray) -> tuple[FloatArray, FloatArray]:
        eye = _eye_over(np.broadcast_to(a, np.broadcast_shapes(a.shape, p.shape)), cls.dim)
        return eye, eye.copy()

    @classmethod
    def _adjoint(cls, a: FloatArray) -> FloatArray:
        return _eye_over(a, cls.dim)

    @classmethod
    def _jr(cls, tau: FloatArray) -> FloatArray:
        return _eye_over(tau, cls.dim)

    _jr_inv = _jr

    @classmethod
    def _hat(cls, tau: FloatArray) -> FloatArray:
        """``[[0, τ], [0, 0]]``, ``(..., n+1, n+1)``."""
        out = np.zeros(tau.shape[:-1] + (cls.dim + 1, cls.dim + 1))
        out[..., : cls.dim, cls.dim] = tau
        return out

    @classmethod
    def _vee(cls, m: FloatArray) -> FloatArray:
        return m[..., : cls.dim, cls.dim].copy()

    @classmethod
    def _identity(cls, batch: tuple[int, ...]) -> FloatArray:
        return np.zeros(batch + (cls.dim,))

    @classmethod
    def _random(cls, rng: np.random.Generator, batch: tuple[int, ...]) -> FloatArray:
        return rng.standard_normal(batch + (cls.dim,))

    @classmethod
    def _validated(cls, a: FloatArray, tol: float, name: str) -> FloatArray:
        return a

    @classmethod
    def _project(cls, a: FloatArray) -> FloatArray:
        return a

    @classmethod
    def _matrix_to_data(cls, m: ArrayLike) -> FloatArray:
        """The translation column of ``[[I, v], [0, 1]]``, checking the other entries."""
        n = cls.dim
        mat = as_batch(m, (n + 1, n + 1), "from_matrix")
        target = np.eye(n + 1)
        target[:n, n] = 0.0
        rest = mat.copy()
        rest[..., :n, n] = 0.0
        if np.abs(rest - target).max(initial=0.0) > 1e-12:
            raise NotInGroupError(f"from_matrix: not a translation matrix [[I, v], [0, 1]] of R^{n}")
        return mat[..., :n, n]

    def as_matrix(self) -> FloatArray:
        """``[[I, v], [0, 1]]``, shape ``(..., n+1, n+1)``."""
        n = self.dim
        out = np.array(np.broadcast_to(np.eye(n + 1), self.batch_shape + (n + 1, n + 1)))
        out[..., :n, n] = self._data
        return out

    def __reduce__(self) -> tuple[Any, ...]:
        return (_rebuild, (self.dim, np.array(self._data)))


def Rn(n: int) -> type[RnGroup]:
    """The group ``(Rⁿ, +)`` as a :class:`LieGroup` class with ``dim = n``
    (one class per ``n``: ``Rn(3) is Rn(3)``)."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"Rn: n must be a positive integer, got {n!r}")
    return _rn_class(int(n))


@cache
def _rn_class(n: int) -> type[RnGroup]:
    attrs = {"__slots__": (), "dim": n, "point_dim": n, "storage_shape": (n,), "__module__": __name__}
    return type(f"R{n}", (RnGroup,), attrs)


def _rebuild(n: int, data: FloatArray) -> RnGroup:
    return Rn(n)._wrap(data)
