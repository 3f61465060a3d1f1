"""The rank-``p`` relaxation as an optimization problem: ``min tr(Y Q Yᵀ)`` over
``Y ∈ St(p, d)ⁿ`` on ``Power(Stiefel(p, d), n)``, its preconditioner on the horizontal
space of the gauge orbit, and the escape from a saddle to rank ``p + 1``."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from manopt_lie.manifolds import Power, Stiefel
from manopt_lie.optim import Problem

from .certificate import Certificate
from .data import Relaxation, stacked, unstacked
from .rounding import lift

FloatArray = NDArray[np.float64]


class _Cost:
    """``f(Y)`` (:meth:`Relaxation.cost`, summed edge by edge) and its derivatives
    ``2YQ``, ``V ↦ 2VQ`` (through :meth:`Relaxation.q`)."""

    def __init__(self, rel: Relaxation) -> None:
        self.rel = rel

    def cost(self, y: FloatArray) -> float:
        return self.rel.cost(y)

    def egrad(self, y: FloatArray) -> FloatArray:
        return 2.0 * unstacked(self.rel.q(stacked(y)), self.rel.n)

    def ehess(self, y: FloatArray, u: FloatArray) -> FloatArray:
        return 2.0 * unstacked(self.rel.q(stacked(u)), self.rel.n)


def relaxation_problem(rel: Relaxation, p: int, *, retraction: str = "qr") -> Problem:
    """The rank-``p`` relaxation as a :class:`~manopt_lie.optim.Problem` on
    ``Power(Stiefel(p, d, retraction), n)``: ``f(Y) = tr(Y Q Yᵀ)``, ``egrad = 2YQ``,
    ``ehess[V] = 2VQ`` (as arrays ``(n, p, d)``); Stiefel's ``egrad2rgrad``/``ehess2rhess``
    make them Riemannian. The QR retraction is the cheapest; the polar one is second order
    (what a Hessian check along the retraction needs away from critical points)."""
    f = _Cost(rel)
    return Problem(Power(Stiefel(p, rel.d, retraction), rel.n), f.cost, egrad=f.egrad, ehess=f.ehess)


def horizontal(y: FloatArray, z: FloatArray) -> FloatArray:
    """The part of a tangent vector ``z`` at ``Y`` orthogonal to the gauge orbit ``{UY : U ∈ O(p)}``.

    ``f(UY) = f(Y)``, so the Hessian is singular along the *vertical* vectors ``ΩY``
    (``Ω`` skew, the same for all blocks); a truncated CG step that picks them up runs to
    the trust region's boundary along them and, near round-off, wanders along the orbit.
    The vertical part of ``z`` is ``ΩY`` with ``ΩG + GΩ = A − Aᵀ`` for ``G = Σ Y_iY_iᵀ``,
    ``A = Σ z_iY_iᵀ`` (solved in the eigenbasis of ``G``; directions that do not move ``Y``,
    ``g_a + g_b = 0``, are left out).
    """
    g = np.tensordot(y, y, axes=([0, 2], [0, 2]))
    a = np.tensordot(z, y, axes=([0, 2], [0, 2]))
    w, u = np.linalg.eigh(g)
    b = u.T @ (a - a.T) @ u
    denom = w[:, None] + w[None, :]
    omega = u @ np.where(denom > 1e-12 * max(w[-1], 1e-300), b / np.where(denom > 0, denom, 1.0), 0.0) @ u.T
    return z - omega @ y


def preconditioner(rel: Relaxation, manifold: Power, *, regularized: bool = True) -> Any:
    """SE-Sync's regularized Cholesky preconditioner ``(Q + λI)⁻¹`` on the horizontal space
    (:func:`horizontal`), a symmetric positive definite callable ``(Y, r) ↦ z`` for
    :class:`~manopt_lie.optim.TrustRegion`:

        z = hor(proj((Q + λI)⁻¹ hor(r))) + c·ver(r),     ver = I − hor,

    with ``c`` a thousandth of the horizontal scale ``1/‖Q‖``: the trust region's norm
    ``‖η‖_P`` then makes steps along the gauge orbit (where the Hessian vanishes) a thousand
    times costlier, so truncated CG does not run along it. With ``regularized=False`` the
    horizontal part is the identity (``c = 10⁻³``).
    """
    c = 1e-3 / rel.scale if regularized else 1e-3

    def apply(y: FloatArray, r: FloatArray) -> FloatArray:
        h = horizontal(y, r)
        z = manifold.proj(y, unstacked(rel.precondition(stacked(h)), rel.n)) if regularized else h
        return horizontal(y, z) + c * (r - h)

    return apply


def escape_saddle(
    rel: Relaxation, problem: Problem, y: FloatArray, certificate: Certificate, grad_tol: float
) -> tuple[FloatArray, float] | None:
    """Leave the saddle ``Y`` (rank ``p``) along ``Ẏ = e_{p+1} vᵀ`` at ``[Y; 0]`` (rank ``p + 1``).

    ``v`` is the certificate's unit eigenvector with ``θ = vᵀSv < 0``; ``Ẏ`` is tangent
    at ``[Y; 0]`` with ``⟨Ẏ, Hess f[Ẏ]⟩ = 2θ`` and ``⟨grad f, Ẏ⟩ = 0``, so
    ``f(R(αẎ)) ≈ f(Y) + θα²``. Backtracking (halving) from ``α = √n`` keeps the first
    step that decreases ``f`` and leaves a gradient above ``grad_tol`` (SE-Sync's rule);
    failing that, the best decrease found; ``None`` if nothing decreases ``f``.

    Returns
    -------
    (Y₊, α) or None
    """
    n, p, _ = y.shape
    manifold = problem.manifold
    y_aug = lift(y, p + 1)
    y_dot = np.zeros_like(y_aug)
    y_dot[:, p, :] = certificate.eigenvector
    f0 = rel.cost(y)
    alpha, best = math.sqrt(n), None
    while alpha >= 1e-6:
        trial = manifold.retr(y_aug, alpha * y_dot)
        f = problem.cost(trial)
        if f < f0 - 1e-12 * abs(f0):
            grad_norm = float(np.sqrt(np.sum(manifold.inner(trial, g := problem.grad(trial), g))))
            if grad_norm > grad_tol:
                return trial, alpha
            if best is None or f < best[0]:
                best = (f, trial, alpha)
        alpha /= 2.0
    return None if best is None else (best[1], best[2])
