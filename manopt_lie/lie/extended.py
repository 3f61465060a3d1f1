"""Sim(3), Sim(2) and SE₂(3): similarities and extended poses, on the kernels of ``_sim3``/``_sim2``/``_se23``.

Storage and tangent ordering follow CONVENTIONS §2: ``Sim3`` as ``(..., 4, 4)`` matrices
``[[s·R, t], [0, 1]]`` with tangent ``(ρ, θ, σ)``; ``SE23`` as ``(..., 5, 5)`` matrices
``[[R, p, v], [0, 1, 0], [0, 0, 1]]`` with tangent ``(ρ, ν, θ)``.
"""

from __future__ import annotations

from typing import Any, Self

import numpy as np
from numpy.typing import ArrayLike

from ..errors import NotInGroupError, RangeError
from . import _matrix, _se23, _sim2, _sim3
from ._checks import FloatArray, as_batch
from .base import LieGroup
from .groups import SO2, SO3

__all__ = ["Sim3", "Sim2", "SE23"]


def _first(bad: np.ndarray | np.bool_) -> tuple[int, ...]:
    return tuple(int(i) for i in np.argwhere(bad)[0]) if bad.ndim else ()


def _project_similarity(a: FloatArray) -> FloatArray:
    """Nearest ``sR`` in Frobenius norm (Sim3 and Sim2): ``R`` the nearest rotation, ``s = ⟨R, M⟩_F / d``."""
    sr, t = _matrix.split(a)
    r = _matrix.project_rotation(sr)
    big = np.abs(sr).max(axis=(-2, -1))
    d = sr.shape[-1]
    with np.errstate(over="ignore"):  # a scale beyond the float range is refused below
        s = np.einsum("...ij,...ij->...", r, sr / np.where(big > 0, big, 1.0)[..., None, None]) / d * big
    bad = ~(s > 0.0)
    if bad.any():
        raise NotInGroupError(f"from_matrix: matrix at batch index {_first(bad)} has no positive scale")
    bad = ~np.isfinite(s)
    if bad.any():
        raise RangeError(f"from_matrix: the scale of the matrix at batch index {_first(bad)} overflows float64")
    return _matrix.assemble(r * s[..., None, None], t)


class _Similarity(LieGroup):
    """What Sim(3) and Sim(2) share: storage ``[[s·R, t], [0, 1]]`` with ``s = e^σ`` the
    tangent's last component, the kernels of ``_kernels`` and the rotations of ``_rotations``."""

    __slots__ = ()
    _kernels: Any
    _rotations: type[LieGroup]
    _compose = staticmethod(_matrix.h_compose)  # blocks [[Ma Mb, Ma tb + ta], [0, 1]] hold for M = sR
    _act = staticmethod(_matrix.h_act)

    @classmethod
    def _exp(cls, tau: FloatArray) -> FloatArray:
        _refuse_scale(tau[..., -1], cls._kernels.SIGMA_MAX)
        with np.errstate(over="ignore"):
            out = cls._kernels.exp(tau)
        bad = ~np.isfinite(out).all(axis=(-2, -1))
        if bad.any():
            raise RangeError(
                f"tau: the translation W(σ, θ)ρ at batch index {_first(bad)} overflows float64 (|ρ|·e^σ too large)"
            )
        return out

    @classmethod
    def _random(cls, rng: np.random.Generator, batch: tuple[int, ...]) -> FloatArray:
        """Random rotations (Haar), ``t ~ N(0, I)``, ``σ ~ N(0, 1)``."""
        r = cls._rotations._random(rng, batch) * np.exp(rng.standard_normal(batch))[..., None, None]
        return _matrix.assemble(r, rng.standard_normal(batch + (cls.point_dim,)))

    @classmethod
    def _validated(cls, a: FloatArray, tol: float, name: str) -> FloatArray:
        sr, t = _matrix.split(a)
        s = cls._kernels.scale(a)
        bad = ~(s > 0.0)
        if bad.any():
            raise NotInGroupError(f"{name}: matrix at batch index {_first(bad)} has a zero first column (scale s = 0)")
        r = sr / s[..., None, None]
        _matrix.check_rotation(r, tol, name)
        _matrix.check_last_row(a, tol, name)
        return _matrix.assemble(_matrix.polish_rotation(r) * s[..., None, None], t)

    @classmethod
    def _project(cls, a: FloatArray) -> FloatArray:
        return _project_similarity(a)

    @classmethod
    def from_parts(cls, rotation: LieGroup, translation: ArrayLike, scale: ArrayLike) -> Self:
        """``[[s·R, t], [0, 1]]`` from rotations, translations ``(..., d)`` and scales ``s > 0``."""
        s = as_batch(scale, (), "scale")
        if not (s > 0).all():
            raise NotInGroupError("from_parts: scales must be > 0")
        r = cls._rotations._same(rotation).as_matrix() * s[..., None, None]
        return cls._wrap(_matrix.assemble(r, as_batch(translation, (cls.point_dim,), "translation")))

    def rotation(self) -> LieGroup:
        """``R``."""
        d = self.point_dim
        return self._rotations._wrap(self._data[..., :d, :d] / self.scale()[..., None, None])

    def translation(self) -> FloatArray:
        """``t``, ``(..., d)`` (a read-only view)."""
        d = self.point_dim
        return self._data[..., :d, d]

    def scale(self) -> FloatArray:
        """``s = e^σ``, shape ``batch_shape``."""
        return self._kernels.scale(self._data)


class Sim3(_Similarity):
    """3-D similarities ``X·p = s R p + t``: ``(..., 4, 4)`` matrices ``[[s·R, t], [0, 1]]``,
    tangent ``(ρ, θ, σ)`` as ``(..., 7)`` with ``s = e^σ``; ``hat = [[θ^ + σI, ρ], [0, 0]]``.

    ``|σ| ≤ 700`` (``s`` between ~1e-304 and ~1e304); beyond it ``exp`` raises
    :class:`RangeError`. ``jr`` is numerically exact through doubling (see ``_sim3.jr``).
    """

    __slots__ = ()
    dim = 7
    point_dim = 3
    storage_shape = (4, 4)
    _kernels = _sim3
    _rotations = SO3

    _log = staticmethod(_sim3.log)
    _inverse = staticmethod(_sim3.inverse)
    _act_jac = staticmethod(_sim3.act_jac)
    _adjoint = staticmethod(_sim3.adjoint)
    _ad = staticmethod(_sim3.ad)
    _jr = staticmethod(_sim3.jr)
    _jr_inv = staticmethod(_sim3.jr_inv)
    _hat = staticmethod(_sim3.hat)
    _vee = staticmethod(_sim3.vee)


class Sim2(_Similarity):
    """Planar similarities ``X·p = s R p + t``: ``(..., 3, 3)`` matrices ``[[s·R, t], [0, 1]]``,
    tangent ``(ρx, ρy, θ, σ)`` as ``(..., 4)``; ``hat = [[θJ + σI, ρ], [0, 0]]``.

    ``|σ| ≤ 700``, else :class:`RangeError`. ``jr`` is numerically exact by doubling.
    """

    __slots__ = ()
    dim = 4
    point_dim = 2
    storage_shape = (3, 3)
    _kernels = _sim2
    _rotations = SO2

    _log = staticmethod(_sim2.log)
    _inverse = staticmethod(_sim2.inverse)
    _act_jac = staticmethod(_sim2.act_jac)
    _adjoint = staticmethod(_sim2.adjoint)
    _ad = staticmethod(_sim2.ad)
    _jr = staticmethod(_sim2.jr)
    _jr_inv = staticmethod(_sim2.jr_inv)
    _hat = staticmethod(_sim2.hat)
    _vee = staticmethod(_sim2.vee)


def _refuse_scale(sigma: FloatArray, limit: float) -> None:
    bad = ~(np.abs(sigma) <= limit)
    if bad.any():
        raise RangeError(
            f"tau: log-scale σ = {sigma[bad].flat[0]:g} at batch index {_first(bad)} is outside "
            f"[-{limit:g}, {limit:g}]: the scale e^σ is not representable"
        )


class SE23(LieGroup):
    """Extended poses SE₂(3): ``(..., 5, 5)`` matrices ``[[R, p, v], [0, 1, 0], [0, 0, 1]]``
    (position ``p``, velocity ``v``), tangent ``(ρ, ν, θ)`` as ``(..., 9)``; ``X·x = R x + p``."""

    __slots__ = ()
    dim = 9
    point_dim = 3
    storage_shape = (5, 5)

    _exp = staticmethod(_se23.exp)
    _log = staticmethod(_se23.log)
    _compose = staticmethod(_se23.compose)
    _inverse = staticmethod(_se23.inverse)
    _act = staticmethod(_se23.act)
    _act_jac = staticmethod(_se23.act_jac)
    _adjoint = staticmethod(_se23.adjoint)
    _ad = staticmethod(_se23.ad)
    _jr = staticmethod(_se23.jr)
    _jr_inv = staticmethod(_se23.jr_inv)
    _hat = staticmethod(_se23.hat)
    _vee = staticmethod(_se23.vee)

    @classmethod
    def _random(cls, rng: np.random.Generator, batch: tuple[int, ...]) -> FloatArray:
        """Haar rotations, ``p, v ~ N(0, I)``."""
        return _se23.assemble(SO3._random(rng, batch), *rng.standard_normal((2,) + batch + (3,)))

    @classmethod
    def _validated(cls, a: FloatArray, tol: float, name: str) -> FloatArray:
        r, p, v = _se23.split(a)
        _matrix.check_rotation(r, tol, name)
        last = np.abs(a[..., 3:, :] - np.eye(5)[3:]).max(axis=(-2, -1)) > tol
        if last.any():
            raise NotInGroupError(
                f"{name}: matrix at batch index {_first(last)} has last rows != [[0, 0, 0, 1, 0], [0, 0, 0, 0, 1]]"
            )
        return _se23.assemble(_matrix.polish_rotation(r), p, v)

    @classmethod
    def _project(cls, a: FloatArray) -> FloatArray:
        r, p, v = _se23.split(a)
        return _se23.assemble(_matrix.project_rotation(r), p, v)

    @classmethod
    def from_parts(cls, rotation: SO3, position: ArrayLike, velocity: ArrayLike) -> SE23:
        """``[[R, p, v], [0, 1, 0], [0, 0, 1]]``; batch axes broadcast."""
        r = SO3._same(rotation).as_matrix()
        p, v = as_batch(position, (3,), "position"), as_batch(velocity, (3,), "velocity")
        return cls._wrap(_se23.assemble(r, p, v))

    def rotation(self) -> SO3:
        """``R``, the rotation block, as an :class:`SO3` element of the same batch shape."""
        return SO3._wrap(self._data[..., :3, :3])

    def position(self) -> FloatArray:
        """``p``, ``(..., 3)`` (a read-only view)."""
        return self._data[..., :3, 3]

    def velocity(self) -> FloatArray:
        """``v``, ``(..., 3)`` (a read-only view)."""
        return self._data[..., :3, 4]
