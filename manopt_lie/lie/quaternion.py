"""S³: unit quaternions ``(x, y, z, w)`` (Hamilton, scalar last) as a group, a view of SO(3).

``Exp(θ) = (sin(|θ|/2) u, cos(|θ|/2))`` with ``θ = |θ| u`` (Solà et al., eq. 101), so the
tangent is SO(3)'s and every Jacobian (``Jr``, ``Jl``, their inverses, ``Ad = R(q)``) is
SO(3)'s. S³ covers SO(3) twice: ``q`` and ``−q`` are the same rotation. ``Log`` takes the
shorter of the two, ``Log(q) = Log(−q)`` with ``|θ| ≤ π`` (through the representative with
``w ≥ 0``), and the matrix form is the rotation matrix ``R(q)`` — the same for ``q`` and ``−q``
— so comparisons of matrix forms, ``dist``, ``rminus`` and the Jacobians all see rotations.
``compose`` is the Hamilton product (no sign is normalized away: ``q₁ ⊗ q₂`` exactly).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..errors import NotInGroupError
from . import _matrix, _series, _so3
from ._checks import FloatArray
from .base import LieGroup
from .groups import SO3

__all__ = ["S3"]


def _exp_huge(w: FloatArray) -> FloatArray:
    u, _, s, c = _so3.polar(w)
    return np.concatenate([s[..., None] * u, c[..., None]], axis=-1)


@_so3.scale_safe(_exp_huge)
def _exp(w: FloatArray) -> FloatArray:
    """``(sin(θ/2)/θ · θ, cos(θ/2))`` (``lie._series.sinc_half``; huge angles through ``polar``)."""
    theta = np.sqrt(np.einsum("...i,...i->...", w, w))
    return np.concatenate([_series.sinc_half(theta)[..., None] * w, np.cos(0.5 * theta)[..., None]], axis=-1)


def _log(q: FloatArray) -> FloatArray:
    """``θ`` of the representative with ``w ≥ 0`` (the shorter of ``q``, ``−q``), ``|θ| ≤ π``."""
    return _so3.quaternion_log(q * np.where(q[..., 3:] < 0.0, -1.0, 1.0))


def _compose(a: FloatArray, b: FloatArray) -> FloatArray:
    """Hamilton product ``a ⊗ b`` in ``(x, y, z, w)`` order: ``(w_a v_b + w_b v_a + v_a × v_b, w_a w_b − v_a·v_b)``."""
    va, wa = a[..., :3], a[..., 3:]
    vb, wb = b[..., :3], b[..., 3:]
    v = wa * vb + wb * va + np.cross(va, vb)
    w = wa * wb - np.einsum("...i,...i->...", va, vb)[..., None]
    return np.concatenate([v, w], axis=-1)


def _inverse(q: FloatArray) -> FloatArray:
    """The conjugate ``(−v, w)``."""
    return np.concatenate([-q[..., :3], q[..., 3:]], axis=-1)


def _act(q: FloatArray, p: FloatArray) -> FloatArray:
    """``R(q) p = p + 2w v×p + 2 v×(v×p)``."""
    v, w = q[..., :3], q[..., 3:]
    vp = np.cross(v, p)
    return p + 2.0 * w * vp + 2.0 * np.cross(v, vp)


class S3(LieGroup):
    """Unit quaternions ``(..., 4)`` ``(x, y, z, w)``; tangent ``θ`` as ``(..., 3)`` (SO(3)'s).

    The matrix form (``as_matrix``, ``from_matrix``) is the rotation matrix ``R(q)``;
    ``from_matrix`` returns the representative with ``w ≥ 0``. ``as_quaternion()`` returns the
    stored quaternion as it is (either sign).
    """

    __slots__ = ()
    dim = 3
    point_dim = 3
    storage_shape = (4,)

    _exp = staticmethod(_exp)
    _log = staticmethod(_log)
    _compose = staticmethod(_compose)
    _inverse = staticmethod(_inverse)
    _act = staticmethod(_act)
    _hat = staticmethod(_so3.hat)
    _vee = staticmethod(_so3.vee)
    _jr = staticmethod(_so3.jr)
    _jr_inv = staticmethod(_so3.jr_inv)

    @staticmethod
    def _adjoint(q: FloatArray) -> FloatArray:
        return _so3.from_quaternion(q)

    @staticmethod
    def _act_jac(q: FloatArray, p: FloatArray) -> tuple[FloatArray, FloatArray]:
        r = _so3.from_quaternion(q)
        return _so3.act_jac_rotation(r, p), r

    @classmethod
    def _identity(cls, batch: tuple[int, ...]) -> FloatArray:
        return np.array(np.broadcast_to([0.0, 0.0, 0.0, 1.0], batch + (4,)))

    @classmethod
    def _random(cls, rng: np.random.Generator, batch: tuple[int, ...]) -> FloatArray:
        """Uniform on S³ (a normalized standard normal 4-vector)."""
        q = rng.standard_normal(batch + (4,))
        return q / np.linalg.norm(q, axis=-1, keepdims=True)

    @classmethod
    def _validated(cls, a: FloatArray, tol: float, name: str) -> FloatArray:
        norm = np.linalg.norm(a, axis=-1, keepdims=True)
        bad = ~(np.abs(norm[..., 0] - 1.0) <= tol)
        if bad.any():
            idx = tuple(int(i) for i in np.argwhere(bad)[0]) if bad.ndim else ()
            raise NotInGroupError(f"{name}: quaternion at batch index {idx} is not unit (| |q| - 1 | > {tol:g})")
        return a / norm

    @classmethod
    def _project(cls, a: FloatArray) -> FloatArray:
        """Normalized, scale-safely (divided by the largest component first); a zero quaternion is refused."""
        big = np.abs(a).max(axis=-1, keepdims=True)
        if (big == 0.0).any():
            raise NotInGroupError("S3: a zero quaternion is not a rotation")
        q = a / big
        return q / np.linalg.norm(q, axis=-1, keepdims=True)

    @classmethod
    def from_matrix(cls, m: ArrayLike, *, project: bool = False, tol: float = _matrix.DEFAULT_TOL) -> S3:
        """The quaternion (``w ≥ 0``) of rotation matrices, checked (or projected) as ``SO3.from_matrix`` does."""
        return cls._wrap(SO3.from_matrix(m, project=project, tol=tol).as_quaternion())

    def as_matrix(self) -> FloatArray:
        """The rotation matrix ``R(q)`` (equal for ``q`` and ``−q``), ``(..., 3, 3)``."""
        return _so3.from_quaternion(self._data)

    def as_quaternion(self) -> FloatArray:
        """The stored quaternion ``(x, y, z, w)`` (a read-only view; either sign)."""
        return self._data

    def to_rotation(self) -> SO3:
        """The rotation ``R(q)`` as an SO3 element."""
        return SO3._wrap(self.as_matrix())

    @classmethod
    def from_rotation(cls, rotation: SO3) -> S3:
        """The quaternion with ``w ≥ 0`` of an SO3 element."""
        return cls._wrap(SO3._same(rotation).as_quaternion())
