"""The Stiefel manifold ``St(n, p) = {X ∈ R^{n×p} : XᵀX = I}`` and ``SO(n)`` in matrix form.

Both use the metric induced by the Frobenius inner product and ambient tangent
vectors (``n×p`` arrays), CONVENTIONS §6:

* ``proj_X(U) = U − X sym(XᵀU)``,
* ``Hess f(X)[V] = proj_X(∇²f(X)[V] − V sym(Xᵀ∇f(X)))``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.linalg

from ..lie import _matrix, _so3
from ..lie._checks import FloatArray
from .embedded import EmbeddedManifold, skew, sym
from .embedded import transpose as _t


def _qf(a: FloatArray) -> FloatArray:
    """The Q factor of ``A = QR`` with ``diag(R) > 0`` (unique for full-rank ``A``)."""
    q, r = np.linalg.qr(a)
    d = np.sign(np.diagonal(r, axis1=-2, axis2=-1))
    return q * np.where(d == 0, 1.0, d)[..., None, :]


def _polar(a: FloatArray) -> FloatArray:
    """The polar factor ``U Vᵀ`` of ``A = U S Vᵀ``: the nearest matrix with orthonormal columns."""
    u, _, vt = np.linalg.svd(a, full_matrices=False)
    return u @ vt


class Stiefel(EmbeddedManifold):
    """``St(n, p)``: ``n×p`` matrices with orthonormal columns.

    Parameters
    ----------
    retraction : {"qr", "polar"}
        ``R_X(V) = qf(X + V)`` (first order, cheapest) or the polar factor of
        ``X + V`` (second order).
    """

    def __init__(self, n: int, p: int, retraction: str = "qr") -> None:
        if not 1 <= int(p) <= int(n):
            raise ValueError(f"Stiefel: need 1 <= p <= n, got n={n}, p={p}")
        if retraction not in ("qr", "polar"):
            raise ValueError(f"Stiefel: retraction must be 'qr' or 'polar', got {retraction!r}")
        self.point_shape = (int(n), int(p))
        self.retraction = retraction

    def __repr__(self) -> str:
        n, p = self.point_shape
        return f"Stiefel({n}, {p}, retraction={self.retraction!r})"

    @property
    def dim(self) -> int:
        n, p = self.point_shape
        return n * p - p * (p + 1) // 2

    @property
    def typical_dist(self) -> float:
        return float(np.sqrt(self.point_shape[1]))

    def proj(self, x: FloatArray, u: FloatArray) -> FloatArray:
        return u - x @ sym(_t(x) @ u)

    def retr(self, x: FloatArray, v: FloatArray) -> FloatArray:
        return _qf(x + v) if self.retraction == "qr" else _polar(x + v)

    def exp(self, x: FloatArray, v: FloatArray) -> FloatArray:
        """Geodesic of the embedded metric (Edelman, Arias, Smith 1998, eq. 2.45)::

        Exp_X(V) = [X, V] · expm([[A, −S], [I, A]])[:, :p] · expm(−A),  A = XᵀV, S = VᵀV.
        """
        p = self.point_shape[1]
        a, s = _t(x) @ v, _t(v) @ v
        eye = np.broadcast_to(np.eye(p), a.shape)
        block = np.concatenate([np.concatenate([a, -s], -1), np.concatenate([eye, a], -1)], -2)
        e = scipy.linalg.expm(block)[..., :, :p]
        return np.concatenate([x, v], -1) @ e @ scipy.linalg.expm(-a)

    def ehess2rhess(self, x: FloatArray, egrad: FloatArray, ehess: FloatArray, v: FloatArray) -> FloatArray:
        return self.proj(x, ehess - v @ sym(_t(x) @ egrad))

    def _random_point(self, rng: np.random.Generator, batch: tuple[int, ...]) -> FloatArray:
        return _qf(rng.standard_normal(batch + self.point_shape))

    def random_tangent(self, x: FloatArray, rng: np.random.Generator | int | None = None) -> FloatArray:
        return self.unit(x, self.proj(x, np.random.default_rng(rng).standard_normal(np.shape(x))))

    def check_point(self, x: Any, name: str = "x") -> None:
        a = self._checked_array(x, name)
        gram = _t(a) @ a - np.eye(self.point_shape[1])
        self._require(np.abs(gram).max(axis=(-2, -1)), 1e-8, name, "XᵀX = I")


class SpecialOrthogonal(Stiefel):
    """``SO(n)`` as ``n×n`` rotation matrices, any ``n``, with tangent vectors ``RΩ``
    (``Ω`` skew) and the Frobenius metric ``⟨RΩ₁, RΩ₂⟩ = tr(Ω₁ᵀΩ₂)``.

    The retraction is the exponential ``R_R(V) = R expm(RᵀV)``, geodesic for this
    bi-invariant metric. For ``n = 2, 3`` it is computed by the SO2/SO3 kernels,
    so ``retr(R, R·hat(ω))`` equals ``SO3(R).rplus(ω)``; the gradients of the two
    agree up to the metric's factor 2 (``‖hat(ω)‖_F² = 2|ω|²``): the ambient
    gradient here is ``R·hat(g/2)`` for the SO3 coordinate gradient ``g``.
    """

    def __init__(self, n: int) -> None:
        super().__init__(n, n)

    def __repr__(self) -> str:
        return f"SpecialOrthogonal({self.point_shape[0]})"

    @property
    def dim(self) -> int:
        n = self.point_shape[0]
        return n * (n - 1) // 2

    @property
    def typical_dist(self) -> float:
        return float(np.pi * np.sqrt(self.point_shape[0]))

    def proj(self, x: FloatArray, u: FloatArray) -> FloatArray:
        """``R skew(Rᵀ U)``."""
        return x @ skew(_t(x) @ u)

    def _expm_skew(self, omega: FloatArray) -> FloatArray:
        n = self.point_shape[0]
        if n == 3:
            return _so3.exp(_so3.vee(omega))
        if n == 2:
            return _matrix.rotation2(0.5 * (omega[..., 1, 0] - omega[..., 0, 1]))
        return scipy.linalg.expm(skew(omega))

    def _logm_rotation(self, r: FloatArray) -> FloatArray:
        n = self.point_shape[0]
        if n == 3:
            return _so3.hat(_so3.log(r))
        if n == 2:
            angle = _matrix.angle2(r)
            return np.stack([np.stack([0 * angle, -angle], -1), np.stack([angle, 0 * angle], -1)], -2)
        flat = r.reshape((-1, n, n))  # a loop over matrices: log is not on any optimizer's hot path
        return skew(np.stack([np.real(scipy.linalg.logm(m)) for m in flat]).reshape(r.shape))

    def retr(self, x: FloatArray, v: FloatArray) -> FloatArray:
        return x @ self._expm_skew(_t(x) @ v)

    exp = retr

    def log(self, x: FloatArray, y: FloatArray) -> FloatArray:
        """``R logm(RᵀS)``, with the angles of ``RᵀS`` in ``[0, π]``."""
        return x @ self._logm_rotation(_t(x) @ y)

    def dist(self, x: FloatArray, y: FloatArray) -> Any:
        return self.norm(x, self.log(x, y))

    def transp(self, x: FloatArray, y: FloatArray, v: FloatArray) -> FloatArray:
        """``S RᵀV``: the same Lie-algebra element ``Ω = RᵀV`` at ``S`` (an isometry)."""
        return y @ (_t(x) @ v)

    def _random_point(self, rng: np.random.Generator, batch: tuple[int, ...]) -> FloatArray:
        """Haar-uniform: ``qf`` of a Gaussian matrix is Haar on O(n); flipping the first
        column where ``det < 0`` maps it to Haar on SO(n)."""
        q = _qf(rng.standard_normal(batch + self.point_shape))
        q[..., :, 0] *= np.sign(np.linalg.det(q))[..., None]
        return q

    def check_point(self, x: Any, name: str = "x") -> None:
        super().check_point(x, name)
        self._require(np.where(np.linalg.det(np.asarray(x, dtype=np.float64)) > 0, 0.0, np.inf), 0.0, name, "det R > 0")
