"""SO(2), SO(3), SE(2), SE(3): thin classes binding the array kernels to :class:`LieGroup`.

Storage and tangent ordering follow CONVENTIONS §2: rotations as matrices,
rigid motions as homogeneous matrices, tangents translation first ``(ρ, θ)``.
"""

from __future__ import annotations

from typing import ClassVar, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from ..errors import NotInGroupError
from . import _matrix, _se2, _se3, _so2, _so3
from ._checks import FloatArray, as_batch
from .base import LieGroup

T = TypeVar("T", bound="_TransformGroup")

__all__ = ["SO2", "SO3", "SE2", "SE3"]


def _refuse(bad: np.ndarray, why: str) -> None:
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0]) if bad.ndim else ()
        raise NotInGroupError(f"from_quaternion: quaternion at batch index {idx} is {why}")


class _RotationGroup(LieGroup):
    """SO(n) stored as ``(..., n, n)`` rotation matrices."""

    __slots__ = ()
    point_dim: ClassVar[int]

    _compose = staticmethod(_matrix.compose_rotations)
    _act = staticmethod(_matrix.rotate_vectors)

    @staticmethod
    def _inverse(a: FloatArray) -> FloatArray:
        return np.swapaxes(a, -1, -2)

    @classmethod
    def _verify(cls, a: FloatArray, tol: float, name: str) -> None:
        _matrix.check_rotation(a, tol, name)

    @classmethod
    def _validated(cls, a: FloatArray, tol: float, name: str) -> FloatArray:
        cls._verify(a, tol, name)
        return _matrix.polish_rotation(a)

    @classmethod
    def _project(cls, a: FloatArray) -> FloatArray:
        return _matrix.project_rotation(a)


class _TransformGroup(LieGroup):
    """SE(n) stored as ``(..., n+1, n+1)`` homogeneous matrices ``[[R, t], [0, 1]]``."""

    __slots__ = ()
    rotation_group: ClassVar[type[_RotationGroup]]

    _compose = staticmethod(_matrix.h_compose)
    _inverse = staticmethod(_matrix.h_inverse)
    _act = staticmethod(_matrix.h_act)

    @classmethod
    def _random(cls, rng: np.random.Generator, batch: tuple[int, ...]) -> FloatArray:
        r = cls.rotation_group._random(rng, batch)
        return _matrix.assemble(r, rng.standard_normal(batch + (cls.point_dim,)))

    @classmethod
    def _verify(cls, a: FloatArray, tol: float, name: str) -> None:
        _matrix.check_rotation(_matrix.split(a)[0], tol, name)
        _matrix.check_last_row(a, tol, name)

    @classmethod
    def _validated(cls, a: FloatArray, tol: float, name: str) -> FloatArray:
        cls._verify(a, tol, name)
        r, t = _matrix.split(a)
        return _matrix.assemble(_matrix.polish_rotation(r), t)

    @classmethod
    def _project(cls, a: FloatArray) -> FloatArray:
        r, t = _matrix.split(a)
        return _matrix.assemble(_matrix.project_rotation(r), t)

    @classmethod
    def from_rotation_translation(cls: type[T], rotation: _RotationGroup, translation: ArrayLike) -> T:
        """``[[R, t], [0, 1]]`` from a rotation element and translations ``(..., n)``;
        batch axes broadcast."""
        r = cls.rotation_group._same(rotation).as_matrix()
        t = as_batch(translation, (cls.point_dim,), "translation")
        return cls._wrap(_matrix.assemble(r, t))

    def rotation(self) -> _RotationGroup:
        """The rotation part, as an element of the rotation group (a view)."""
        return self.rotation_group._wrap(_matrix.split(self._data)[0])

    def translation(self) -> FloatArray:
        """The translation part ``t``, shape ``(..., n)`` (a read-only view)."""
        return _matrix.split(self._data)[1]


class SO2(_RotationGroup):
    """Planar rotations: ``(..., 2, 2)`` matrices, tangent ``θ`` as ``(..., 1)``.

    Commutative, so ``Ad = Jr = Jl = 1``.
    """

    __slots__ = ()
    dim = 1
    point_dim = 2
    storage_shape = (2, 2)

    _exp = staticmethod(_so2.exp)
    _log = staticmethod(_so2.log)
    _hat = staticmethod(_so2.hat)
    _vee = staticmethod(_so2.vee)
    _act_jac = staticmethod(_so2.act_jac)

    @staticmethod
    def _adjoint(a: FloatArray) -> FloatArray:
        return _so2.ones(a, a.ndim - 2)

    @staticmethod
    def _jr(tau: FloatArray) -> FloatArray:
        return _so2.ones(tau, tau.ndim - 1)

    _jr_inv = _jr

    @classmethod
    def _random(cls, rng: np.random.Generator, batch: tuple[int, ...]) -> FloatArray:
        return _matrix.rotation2(rng.uniform(-np.pi, np.pi, batch))

    @classmethod
    def from_angle(cls, theta: ArrayLike) -> SO2:
        """Rotation by ``θ`` (radians), batch shape ``θ.shape``."""
        return cls.exp(np.asarray(theta, dtype=np.float64)[..., None])

    def angle(self) -> FloatArray:
        """The angle in ``(−π, π]``, shape ``batch_shape``."""
        return _matrix.angle2(self._data)


class SO3(_RotationGroup):
    """Spatial rotations: ``(..., 3, 3)`` matrices, tangent ``θu`` as ``(..., 3)``."""

    __slots__ = ()
    dim = 3
    point_dim = 3
    storage_shape = (3, 3)

    _exp = staticmethod(_so3.exp)
    _log = staticmethod(_so3.log)
    _hat = staticmethod(_so3.hat)
    _vee = staticmethod(_so3.vee)
    _jr = staticmethod(_so3.jr)
    _jr_inv = staticmethod(_so3.jr_inv)

    @staticmethod
    def _adjoint(a: FloatArray) -> FloatArray:
        return a

    @staticmethod
    def _act_jac(a: FloatArray, p: FloatArray) -> tuple[FloatArray, FloatArray]:
        return _so3.act_jac_rotation(a, p), a

    @classmethod
    def _random(cls, rng: np.random.Generator, batch: tuple[int, ...]) -> FloatArray:
        # A normalized standard normal 4-vector is uniform on S³, hence Haar on SO(3).
        q = rng.standard_normal(batch + (4,))
        return _so3.from_quaternion(q / np.linalg.norm(q, axis=-1, keepdims=True))

    @classmethod
    def from_quaternion(cls, q: ArrayLike, *, normalize: bool = False, tol: float = _matrix.DEFAULT_TOL) -> SO3:
        """Rotations from Hamilton quaternions ``(x, y, z, w)`` (scalar last), ``(..., 4)``.

        The quaternion must have unit norm within ``tol`` unless ``normalize=True``;
        it is normalized either way, so the result is exactly orthonormal. Normalization is
        scale-safe: a quaternion whose largest component is outside ``[1e-100, 1e100]`` is
        divided by that component first, so that its squares neither underflow nor overflow.

        Raises
        ------
        NotInGroupError
            For a non-unit quaternion without ``normalize=True``, and for a zero quaternion.
        """
        quat = as_batch(q, (4,), "q")
        big = np.abs(quat).max(axis=-1, keepdims=True)
        _refuse(big[..., 0] == 0.0, "zero")
        scale = np.where((big >= 1e-100) & (big <= 1e100), 1.0, big)
        quat = quat / scale  # exact where scale = 1: the plain path, bit for bit
        norm = np.linalg.norm(quat, axis=-1, keepdims=True)
        if not normalize:
            off = ~(np.abs(norm * scale - 1.0)[..., 0] <= tol)
            _refuse(off, f"not unit (| |q| - 1 | > {tol:g}); pass normalize=True")
        return cls._wrap(_so3.from_quaternion(quat / norm))

    def as_quaternion(self) -> FloatArray:
        """Hamilton quaternion ``(x, y, z, w)`` with ``w ≥ 0``, shape ``(..., 4)``."""
        return _so3.to_quaternion(self._data)


class SE2(_TransformGroup):
    """Planar rigid motions: ``(..., 3, 3)`` homogeneous matrices, tangent ``(ρx, ρy, θ)``."""

    __slots__ = ()
    dim = 3
    point_dim = 2
    storage_shape = (3, 3)
    rotation_group = SO2

    _exp = staticmethod(_se2.exp)
    _log = staticmethod(_se2.log)
    _hat = staticmethod(_se2.hat)
    _vee = staticmethod(_se2.vee)
    _adjoint = staticmethod(_se2.adjoint)
    _jr = staticmethod(_se2.jr)
    _jr_inv = staticmethod(_se2.jr_inv)
    _act_jac = staticmethod(_se2.act_jac)


class SE3(_TransformGroup):
    """Rigid motions: ``(..., 4, 4)`` homogeneous matrices, tangent ``(ρ, θ)`` as ``(..., 6)``."""

    __slots__ = ()
    dim = 6
    point_dim = 3
    storage_shape = (4, 4)
    rotation_group = SO3

    _exp = staticmethod(_se3.exp)
    _log = staticmethod(_se3.log)
    _hat = staticmethod(_se3.hat)
    _vee = staticmethod(_se3.vee)
    _adjoint = staticmethod(_se3.adjoint)
    _jr = staticmethod(_se3.jr)
    _jr_inv = staticmethod(_se3.jr_inv)
    _act_jac = staticmethod(_se3.act_jac)

    @classmethod
    def from_translation_quaternion(
        cls, translation: ArrayLike, q: ArrayLike, *, normalize: bool = False, tol: float = _matrix.DEFAULT_TOL
    ) -> SE3:
        """From translations ``(..., 3)`` and quaternions ``(x, y, z, w)`` ``(..., 4)``
        (the ``VERTEX_SE3:QUAT`` layout); see :meth:`SO3.from_quaternion`."""
        return cls.from_rotation_translation(SO3.from_quaternion(q, normalize=normalize, tol=tol), translation)
