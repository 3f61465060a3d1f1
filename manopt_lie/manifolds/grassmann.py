"""The Grassmann manifold ``Gr(n, p)``: the ``p``-dimensional subspaces of ``Rⁿ``.

A subspace is stored as an ``n×p`` matrix ``X`` with orthonormal columns spanning it
(any of them: ``X`` and ``XQ``, ``Q`` orthogonal, are the same point). Tangent vectors
are *horizontal* ``n×p`` matrices, ``XᵀV = 0``, with the Frobenius metric — the
quotient geometry ``St(n, p)/O(p)`` of Edelman, Arias and Smith (1998) and Absil,
Mahony and Sepulchre (2008, §3.6):

* ``proj_X(U) = U − X XᵀU`` (also the Riemannian gradient of ``∇f̄``);
* ``Hess f(X)[V] = proj_X(∇²f̄(X)[V]) − V sym(Xᵀ∇f̄(X))``;
* ``Exp_X(V) = X W cos(Σ) Wᵀ + U sin(Σ) Wᵀ`` for the thin SVD ``V = U Σ Wᵀ``;
* ``dist(X, Y) = ‖θ‖``, ``θ`` the principal angles between the subspaces.

A cost must be invariant, ``f̄(XQ) = f̄(X)``, for it to be a function of the subspace
(``tr(XᵀAX)`` is; ``Xᵀ∇f̄(X)`` is then symmetric, and ``sym`` changes nothing). The
``sym`` keeps the Hessian symmetric, and equal to the Hessian of ``f̄∘R_X`` for the polar
retraction, also for costs that are not.
"""

from __future__ import annotations

from typing import Any, cast

import numpy as np

from ..lie._checks import FloatArray
from .embedded import EmbeddedManifold, sym
from .stiefel import _polar, _qf, _t


def _principal(x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Cosines and sines of the principal angles between ``span X`` and ``span Y``, matched
    (both computed, so that small and large angles keep their digits: Björck and Golub 1973)."""
    cos = np.linalg.svd(_t(x) @ y, compute_uv=False)  # descending: angles ascending
    sin = np.linalg.svd(y - x @ (_t(x) @ y), compute_uv=False)[..., ::-1]  # ascending
    return np.clip(cos, 0.0, 1.0), np.clip(sin, 0.0, 1.0)


class Grassmann(EmbeddedManifold):
    """``Gr(n, p)``: ``p``-dimensional subspaces of ``Rⁿ``, as ``n×p`` orthonormal bases.

    Parameters
    ----------
    n, p : int
        ``1 ≤ p ≤ n``.
    retraction : {"qr", "polar"}
        ``R_X(V) = qf(X + V)`` or the polar factor of ``X + V`` — the same subspace,
        ``span(X + V)``, in two bases; the polar one is the nearer to ``X + V``.
        Both agree with ``Exp`` to second order on invariant costs; for the pullback
        of a non-invariant extension (as the tests use), the polar one.
    """

    def __init__(self, n: int, p: int, retraction: str = "qr") -> None:
        if not 1 <= int(p) <= int(n):
            raise ValueError(f"Grassmann: need 1 <= p <= n, got n={n}, p={p}")
        if retraction not in ("qr", "polar"):
            raise ValueError(f"Grassmann: retraction must be 'qr' or 'polar', got {retraction!r}")
        self.point_shape = (int(n), int(p))
        self.retraction = retraction

    def __repr__(self) -> str:
        n, p = self.point_shape
        return f"Grassmann({n}, {p}, retraction={self.retraction!r})"

    @property
    def dim(self) -> int:
        n, p = self.point_shape
        return p * (n - p)

    @property
    def typical_dist(self) -> float:
        """``√p·π/2``, the diameter (every principal angle is at most ``π/2``)."""
        return float(np.sqrt(self.point_shape[1]) * np.pi / 2)

    def proj(self, x: FloatArray, u: FloatArray) -> FloatArray:
        """``U − X XᵀU``: the horizontal part of ``U``."""
        return u - x @ (_t(x) @ u)

    def retr(self, x: FloatArray, v: FloatArray) -> FloatArray:
        return _qf(x + v) if self.retraction == "qr" else _polar(x + v)

    def ehess2rhess(self, x: FloatArray, egrad: FloatArray, ehess: FloatArray, v: FloatArray) -> FloatArray:
        """``proj_X(∇²f̄(X)[V]) − V sym(Xᵀ∇f̄(X))``."""
        return self.proj(x, ehess) - v @ sym(_t(x) @ egrad)

    def exp(self, x: FloatArray, v: FloatArray) -> FloatArray:
        """``X W cos(Σ) Wᵀ + U sin(Σ) Wᵀ`` for ``V = U Σ Wᵀ`` (Edelman, Arias, Smith 1998, Thm. 2.3),
        re-orthonormalized (``qf``: the same subspace, columns orthonormal to round-off)."""
        u, s, wt = np.linalg.svd(v, full_matrices=False)
        y = (x @ (_t(wt) * np.cos(s)[..., None, :]) + u * np.sin(s)[..., None, :]) @ wt
        return _qf(y)

    def log(self, x: FloatArray, y: FloatArray) -> FloatArray:
        """The horizontal ``V`` at ``X`` with ``span Exp_X(V) = span Y``: with
        ``(I − XXᵀ) Y (XᵀY)⁻¹ = U tan(Σ) Wᵀ`` (thin SVD), ``V = U Σ Wᵀ`` — for subspaces
        with no principal angle of ``π/2`` (``XᵀY`` invertible)."""
        ytx = _t(y) @ x
        # Bᵀ = (YᵀX)⁻¹ Yᵀ(I − XXᵀ); cast: NumPy's stubs type solve's result floating[Any] (float64 here).
        b = cast(FloatArray, np.linalg.solve(ytx, _t(y) - ytx @ _t(x)))
        u, s, wt = np.linalg.svd(_t(b), full_matrices=False)
        return (u * np.arctan(s)[..., None, :]) @ wt

    def dist(self, x: FloatArray, y: FloatArray) -> Any:
        """``‖θ‖₂`` over the principal angles ``θᵢ = atan2(sin θᵢ, cos θᵢ)``."""
        cos, sin = _principal(x, y)
        return np.linalg.norm(np.arctan2(sin, cos), axis=-1)

    def transp(self, x: FloatArray, y: FloatArray, v: FloatArray) -> FloatArray:
        """Projection onto the horizontal space at ``Y``: ``V − Y YᵀV``."""
        return self.proj(y, v)

    def _random_point(self, rng: np.random.Generator, batch: tuple[int, ...]) -> FloatArray:
        """Uniform on ``Gr(n, p)``: the span of a Gaussian matrix, by ``qf``."""
        return _qf(rng.standard_normal(batch + self.point_shape))

    def random_tangent(self, x: FloatArray, rng: np.random.Generator | int | None = None) -> FloatArray:
        """A random unit horizontal vector (zero on ``Gr(n, n)``, a single point)."""
        if self.dim == 0:
            return np.zeros(np.shape(x))
        return self.unit(x, self.proj(x, np.random.default_rng(rng).standard_normal(np.shape(x))))

    def check_point(self, x: Any, name: str = "x") -> None:
        a = self._checked_array(x, name)
        gram = _t(a) @ a - np.eye(self.point_shape[1])
        self._require(np.abs(gram).max(axis=(-2, -1)), 1e-8, name, "XᵀX = I")
