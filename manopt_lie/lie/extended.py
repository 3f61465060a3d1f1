"""Sim(3), Sim(2) and SE₂(3): similarities and extended poses, on the kernels of ``_sim3``/``_sim2``/``_se23``.

Storage and tangent ordering follow CONVENTIONS §2: ``Sim3`` as ``(..., 4, 4)`` matrices
``[[s·R, t], [0, 1]]`` with tangent ``(ρ, θ, σ)``; ``SE23`` as ``(..., 5, 5)`` matrices
``[[R, p, v], [0, 1, 0], [0, 0, 1]]`` with tangent ``(ρ, ν, θ)``.
"""

from __future__ import annotations

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


class Sim3(LieGroup):
    """3-D similarities ``X·p = s R p + t``: ``(..., 4, 4)`` matrices ``[[s·R, t], [0, 1]]``,
    tangent ``(ρ, θ, σ)`` as ``(..., 7)`` with ``s = e^σ``; ``hat = [[θ^ + σI, ρ], [0, 0]]``.

    ``|σ| ≤ 700`` (``s`` between ~1e-304 and ~1e304); beyond it ``exp`` raises
    :class:`RangeError`. ``jr`` is numerically exact through doubling (see ``_sim3.jr``).
    """

    __slots__ = ()
    dim = 7
    point_dim = 3
    storage_shape = (4, 4)

    _log = staticmethod(_sim3.log)
    _compose = staticmethod(_matrix.h_compose)  # blocks [[Ma Mb, Ma tb + ta], [0, 1]] hold for M = sR
    _inverse = staticmethod(_sim3.inverse)
    _act = staticmethod(_matrix.h_act)
    _act_jac = staticmethod(_sim3.act_jac)
    _adjoint = staticmethod(_sim3.adjoint)
    _ad = staticmethod(_sim3.ad)
    _jr = staticmethod(_sim3.jr)
    _jr_inv = staticmethod(_sim3.jr_inv)
    _hat = staticmethod(_sim3.hat)
    _vee = staticmethod(_sim3.vee)

    @staticmethod
    def _exp(tau: FloatArray) -> FloatArray:
        _refuse_scale(tau[..., 6], _sim3.SIGMA_MAX)
        with np.errstate(over="ignore"):
            out = _sim3.exp(tau)
        bad = ~np.isfinite(out).all(axis=(-2, -1))
        if bad.any():
            raise RangeError(
                f"tau: the translation W(σ, θ)ρ at batch index {_first(bad)} overflows float64 (|ρ|·e^σ too large)"
            )
        return out

    @classmethod
    def _identity(cls, batch: tuple[int, ...]) -> FloatArray:
        return np.array(np.broadcast_to(np.eye(4), batch + (4, 4)))

    @classmethod
    def _random(cls, rng: np.random.Generator, batch: tuple[int, ...]) -> FloatArray:
        """Haar rotations, ``t ~ N(0, I)``, ``σ ~ N(0, 1)``."""
        r = SO3._random(rng, batch) * np.exp(rng.standard_normal(batch))[..., None, None]
        return _matrix.assemble(r, rng.standard_normal(batch + (3,)))

    @classmethod
    def _validated(cls, a: FloatArray, tol: float, name: str) -> FloatArray:
        sr, t = _matrix.split(a)
        s = _sim3.scale(a)
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
    def from_parts(cls, rotation: SO3, translation: ArrayLike, scale: ArrayLike) -> Sim3:
        """``[[s·R, t], [0, 1]]`` from a rotation, translations ``(..., 3)`` and scales ``s > 0``."""
        s = as_batch(scale, (), "scale")
        if not (s > 0).all():
            raise NotInGroupError("from_parts: scales must be > 0")
        r = SO3._same(rotation).as_matrix() * s[..., None, None]
        return cls._wrap(_matrix.assemble(r, as_batch(translation, (3,), "translation")))

    def rotation(self) -> SO3:
        """``R``."""
        return SO3._wrap(self._data[..., :3, :3] / self.scale()[..., None, None])

    def translation(self) -> FloatArray:
        """``t``, ``(..., 3)`` (a read-only view)."""
        return self._data[..., :3, 3]

    def scale(self) -> FloatArray:
        """``s = e^σ``, shape ``batch_shape``."""
        return _sim3.scale(self._data)


def _refuse_scale(sigma: FloatArray, limit: float) -> None:
    bad = ~(np.abs(sigma) <= limit)
    if bad.any():
        raise RangeError(
            f"tau: log-scale σ = {sigma[bad].flat[0]:g} at batch index {_first(bad)} is outside "
            f"[-{limit:g}, {limit:g}]: the scale e^σ is not representable"
        )


class Sim2(LieGroup):
    """Planar similarities ``X·p = s R p + t``: ``(..., 3, 3)`` matrices ``[[s·R, t], [0, 1]]``,
    tangent ``(ρx, ρy, θ, σ)`` as ``(..., 4)``; ``hat = [[θJ + σI, ρ], [0, 0]]``.

    ``|σ| ≤ 700``, else :class:`RangeError`. ``jr`` is numerically exact by doubling.
    """

    __slots__ = ()
    dim = 4
    point_dim = 2
    storage_shape = (3, 3)

    _log = staticmethod(_sim2.log)
    _compose = staticmethod(_matrix.h_compose)
    _inverse = staticmethod(_sim2.inverse)
    _act = staticmethod(_matrix.h_act)
    _act_jac = staticmethod(_sim2.act_jac)
    _adjoint = staticmethod(_sim2.adjoint)
    _ad = staticmethod(_sim2.ad)
    _jr = staticmethod(_sim2.jr)
    _jr_inv = staticmethod(_sim2.jr_inv)
    _hat = staticmethod(_sim2.hat)
    _vee = staticmethod(_sim2.vee)

    @staticmethod
    def _exp(tau: FloatArray) -> FloatArray:
        _refuse_scale(tau[..., 3], _sim2.SIGMA_MAX)
        with np.errstate(over="ignore"):
            out = _sim2.exp(tau)
        bad = ~np.isfinite(out).all(axis=(-2, -1))
        if bad.any():
            raise RangeError(f"tau: the translation W(σ, θ)ρ at batch index {_first(bad)} overflows float64")
        return out

    @classmethod
    def _identity(cls, batch: tuple[int, ...]) -> FloatArray:
        return np.array(np.broadcast_to(np.eye(3), batch + (3, 3)))

    @classmethod
    def _random(cls, rng: np.random.Generator, batch: tuple[int, ...]) -> FloatArray:
        """Uniform angles, ``t ~ N(0, I)``, ``σ ~ N(0, 1)``."""
        r = SO2._random(rng, batch) * np.exp(rng.standard_normal(batch))[..., None, None]
        return _matrix.assemble(r, rng.standard_normal(batch + (2,)))

    @classmethod
    def _validated(cls, a: FloatArray, tol: float, name: str) -> FloatArray:
        sr, t = _matrix.split(a)
        s = _sim2.scale(a)
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
    def from_parts(cls, rotation: SO2, translation: ArrayLike, scale: ArrayLike) -> Sim2:
        """``[[s·R, t], [0, 1]]`` from a rotation, translations ``(..., 2)`` and scales ``s > 0``."""
        s = as_batch(scale, (), "scale")
        if not (s > 0).all():
            raise NotInGroupError("from_parts: scales must be > 0")
        r = SO2._same(rotation).as_matrix() * s[..., None, None]
        return cls._wrap(_matrix.assemble(r, as_batch(translation, (2,), "translation")))

    def rotation(self) -> SO2:
        """``R``."""
        return SO2._wrap(self._data[..., :2, :2] / self.scale()[..., None, None])

    def translation(self) -> FloatArray:
        """``t``, ``(..., 2)`` (a read-only view)."""
        return self._data[..., :2, 2]

    def scale(self) -> FloatArray:
        """``s = e^σ``, shape ``batch_shape``."""
        return _sim2.scale(self._data)


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
    def _identity(cls, batch: tuple[int, ...]) -> FloatArray:
        return np.array(np.broadcast_to(np.eye(5), batch + (5, 5)))

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
        return SO3._wrap(self._data[..., :3, :3])

    def position(self) -> FloatArray:
        """``p``, ``(..., 3)`` (a read-only view)."""
        return self._data[..., :3, 3]

    def velocity(self) -> FloatArray:
        """``v``, ``(..., 3)`` (a read-only view)."""
        return self._data[..., :3, 4]
