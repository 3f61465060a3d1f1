"""The two costs of relative measurements ``Z_e ≈ X_i⁻¹ X_j`` (CONVENTIONS §8), shared
by pose graphs (SE(d)) and rotation averaging (SO(d)).

- **geodesic**: ``½ Σ_e r_eᵀ Ω_e r_e`` with ``r_e = Log(Z_e⁻¹ X_i⁻¹ X_j)``;
- **chordal**: ``Σ_e ‖(X_j − X_i Z_e) W_e‖_F²`` on the top ``d`` rows ``X = [R t]``
  of the matrices, ``W_e = diag(√κ_e I_d, √τ_e)`` — i.e.
  ``κ‖R_j − R_i R̃‖² + τ‖t_j − t_i − R_i t̃‖²`` (for rotations ``W_e = √κ_e I``).

Each comes as a :class:`~manopt_lie.optim.Factor` (residual and right Jacobians
of all edges in one vectorized call) for :class:`~manopt_lie.optim.LeastSquaresProblem`.
The chordal cost is a quadratic form ``f(X) = tr(X Q Xᵀ)`` of the stacked
``X = [X_1 … X_n]``, so :class:`ChordalHessian` gives its exact Riemannian
Hessian from the Euclidean ``∇f = 2XQ`` and ``∇²f[V] = 2VQ``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from manopt_lie.factors import Gaussian, between_factor
from manopt_lie.lie.base import LieGroup
from manopt_lie.manifolds import Power
from manopt_lie.optim import Factor
from manopt_lie.optim.losses import RobustLoss

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


class InformationMatrixError(ValueError):
    """Information matrices a cost cannot use (the message names the edges)."""


class IndefiniteInformationError(InformationMatrixError):
    """Information matrices that are not positive definite, where the cost needs them to be."""


def _rows(x: LieGroup) -> FloatArray:
    """The top ``d`` rows ``[R t]`` of the matrices (for rotations, ``R`` itself)."""
    m = x.as_matrix()
    return m[..., : x.point_dim, :]  # type: ignore[attr-defined]


# ---- information matrices --------------------------------------------------------------


def _symmetric(a: FloatArray) -> FloatArray:
    return 0.5 * a + 0.5 * np.swapaxes(a, -1, -2)  # (a + aᵀ)/2 would overflow near the float range


def eigenvalues(information: FloatArray) -> FloatArray:
    """The eigenvalues, ascending, of each symmetric part ``(Ω + Ωᵀ)/2``, ``(m, k)``.

    Each matrix is scaled by its largest absolute entry before the decomposition, so
    entries near the float range (``1e308``) neither overflow nor stall ``eigvalsh``;
    the eigenvalues are scaled back (and may then be ``±inf``). Never warns or raises.
    """
    a = _symmetric(np.asarray(information, dtype=np.float64))
    with np.errstate(all="ignore"):
        scale = np.max(np.abs(a), axis=(-1, -2))
        ok = np.isfinite(scale) & (scale > 0)
        safe = np.where(ok, scale, 1.0)
        lam = np.linalg.eigvalsh(np.where(ok[..., None, None], a / safe[..., None, None], 0.0))
        lam = lam * safe[..., None]
    lam[~np.isfinite(scale)] = np.nan
    return np.asarray(lam)


def nearest_positive_definite(information: FloatArray, rel_floor: float = 1e-9) -> FloatArray:
    """The symmetric part of each ``Ω`` with eigenvalues clipped at ``rel_floor · λ_max``
    (Higham's nearest symmetric positive semidefinite matrix, kept definite)."""
    lam, v = np.linalg.eigh(_symmetric(information))
    floor = rel_floor * np.maximum(lam[..., -1:], np.finfo(float).tiny)
    return np.einsum("...ij,...j,...kj->...ik", v, np.maximum(lam, floor), v)


def indefinite_edges(information: FloatArray) -> IntArray:
    """Indices of edges whose (symmetrized) ``Ω`` is not positive definite: indefinite,
    singular (an eigenvalue ``≤ 0``) or beyond the float range."""
    lam = eigenvalues(information)
    return np.flatnonzero(~(np.isfinite(lam).all(axis=-1) & (lam[..., 0] > 0.0)))


def asymmetric_edges(information: FloatArray, rtol: float = 1e-12) -> IntArray:
    """Indices of edges whose ``Ω`` is not symmetric beyond round-off: ``max|Ω − Ωᵀ| > rtol·max|Ω|``."""
    info = np.asarray(information, dtype=np.float64)
    with np.errstate(all="ignore"):
        scale = np.max(np.abs(info), axis=(-1, -2), initial=0.0)
        skew = np.max(np.abs(info - np.swapaxes(info, -1, -2)), axis=(-1, -2), initial=0.0)
    return np.flatnonzero(skew > rtol * scale)


def _named(edges: IntArray, edge_names: Any) -> str:
    names = [str(edge_names[e]) if edge_names is not None else str(e) for e in edges[:10]]
    return ", ".join(names) + (f" and {edges.size - 10} more" if edges.size > 10 else "")


def information_sqrt(information: FloatArray, edge_names: Any = None, *, repair: bool = False) -> FloatArray:
    """``Lᵀ`` with ``Ω = L Lᵀ`` (Cholesky), so ``‖Lᵀ r‖² = rᵀ Ω r``.

    Raises
    ------
    InformationMatrixError
        For matrices that are not symmetric beyond round-off, and
        :class:`IndefiniteInformationError` for those that are not positive definite
        (indefinite or singular), naming the edges (``edge_names[e]`` if given) — unless
        ``repair`` symmetrizes them and replaces the indefinite ones by
        :func:`nearest_positive_definite`.
    """
    information = np.asarray(information, dtype=np.float64)
    # Exactly symmetric matrices (g2o files store one triangle) need neither the round-off
    # test nor the symmetric part: one comparison instead (0.2 against 2.9 ms on garage).
    if not np.array_equal(information, np.swapaxes(information, -1, -2)):
        asymmetric = asymmetric_edges(information)
        if not repair and asymmetric.size:
            raise InformationMatrixError(
                f"{asymmetric.size} edges have information matrices that are not symmetric: "
                f"{_named(asymmetric, edge_names)}; pass repair_information=True to use their symmetric parts"
            )
        information = _symmetric(information)
    root = _all_cholesky(information)
    if root is not None:  # the common case: every one positive definite, one batched factorization
        return np.swapaxes(root, -1, -2)
    bad = indefinite_edges(information)
    if not repair and bad.size:
        raise IndefiniteInformationError(
            f"{bad.size} edges have information matrices that are not positive definite (indefinite or singular): "
            f"{_named(bad, edge_names)}; pass repair_information=True to use the nearest positive definite ones"
        )
    information = information.copy()  # never the caller's array
    information[bad] = nearest_positive_definite(information[bad])
    return np.swapaxes(np.linalg.cholesky(information), -1, -2)


def _all_cholesky(information: FloatArray) -> FloatArray | None:
    """The Cholesky factors of symmetric matrices if every one has them, finite and with a
    positive diagonal (LAPACK's positive pivots), else ``None``: a batched factorization costs
    a fifth of the eigenvalues that tell which matrices fail (:func:`indefinite_edges`)."""
    try:
        with np.errstate(all="ignore"):
            root = np.asarray(np.linalg.cholesky(information), dtype=np.float64)
    except np.linalg.LinAlgError:
        return None
    diagonal = np.diagonal(root, axis1=-2, axis2=-1)
    return root if np.isfinite(root).all() and (diagonal > 0).all() else None


def _trace_of_inverse(blocks: FloatArray) -> FloatArray:
    """``tr(A⁻¹) = Σ 1/λ`` of each symmetric block, ``nan`` where it is singular (an eigenvalue
    below ``k·ε·max|λ|``) or non-finite."""
    lam = eigenvalues(blocks)
    with np.errstate(all="ignore"):
        size = np.max(np.abs(lam), axis=-1, keepdims=True)
        singular = ~np.isfinite(lam).all(axis=-1) | (np.abs(lam) <= lam.shape[-1] * np.finfo(float).eps * size).any(-1)
        return np.where(singular, np.nan, np.sum(1.0 / lam, axis=-1))


def se_sync_weights(information: FloatArray, d: int) -> tuple[FloatArray, FloatArray]:
    """SE-Sync's isotropic weights ``(κ, τ)`` from information matrices in ``(ρ, θ)`` order:
    ``τ = d / tr(Ω_tt⁻¹)``; ``κ = Ω_θθ`` in 2-D, ``3 / (2 tr(Ω_RR⁻¹))`` in 3-D. Edges whose
    blocks are singular get ``nan``, which the chordal cost refuses, naming them."""
    with np.errstate(all="ignore"):
        tau = d / _trace_of_inverse(information[:, :d, :d])
        if d == 2:
            kappa = information[:, 2, 2].copy()
        else:
            kappa = 3.0 / (2.0 * _trace_of_inverse(information[:, 3:, 3:]))
    # tr(Ω⁻¹) = 0 (an indefinite block such as diag(1, −1)) would give an infinite weight.
    return np.where(np.isfinite(kappa), kappa, np.nan), np.where(np.isfinite(tau), tau, np.nan)


# ---- the geodesic cost -------------------------------------------------------------------


def geodesic_residuals(x: LieGroup, edges: IntArray, measurements: LieGroup) -> FloatArray:
    """``r_e = Log(Z_e⁻¹ X_i⁻¹ X_j)``, shape ``(m, dim)``."""
    return x[edges[:, 0]].between(x[edges[:, 1]]).rminus(measurements)


def geodesic_cost(x: LieGroup, edges: IntArray, measurements: LieGroup, information: FloatArray) -> float:
    """``½ Σ r_eᵀ Ω_e r_e``."""
    r = geodesic_residuals(x, edges, measurements)
    return 0.5 * float(np.einsum("ei,eij,ej->", r, information, r))


def geodesic_factor(
    edges: IntArray,
    measurements: LieGroup,
    sqrt_information: FloatArray,
    loss: RobustLoss | str | None = None,
    name: str = "geodesic",
) -> Factor:
    """Whitened residuals ``Lᵀ r_e``, ``r_e = Log(Z_e⁻¹ X_i⁻¹ X_j)``: the library's
    :func:`~manopt_lie.factors.between_factor` with the square root ``Lᵀ`` of ``Ω = L Lᵀ``
    (:func:`information_sqrt`) as its noise model."""
    return between_factor(edges, measurements, Gaussian(sqrt_information), loss=loss, name=name)


# ---- the chordal cost ----------------------------------------------------------------------


def chordal_cost(x: LieGroup, edges: IntArray, measurements: LieGroup, weights: FloatArray) -> float:
    """``Σ_e ‖(X_j − X_i Z_e) W_e‖_F²`` with ``W_e = diag(weights[e])``."""
    xr = _rows(x)
    e = (xr[edges[:, 1]] - xr[edges[:, 0]] @ measurements.as_matrix()) * weights[:, None, :]
    return float(np.einsum("eij,eij->", e, e))


def chordal_factor(
    edges: IntArray,
    measurements: LieGroup,
    weights: FloatArray,
    loss: RobustLoss | str | None = None,
    name: str = "chordal",
) -> Factor:
    """Residuals ``√2 vec((X_j − X_i Z) W)`` (so ``½‖r‖²`` is the chordal term) with
    right Jacobians ``∂r/∂δ_jᵏ = √2 vec(X_j E_k W)``, ``∂r/∂δ_iᵏ = −√2 vec(X_i E_k Z W)``
    for the generators ``E_k``."""
    group = type(measurements)
    z = measurements.as_matrix()
    w = np.sqrt(2.0) * weights[:, None, :]  # (m, 1, c): scales columns
    zw = z * w
    dim, c = group.dim, z.shape[-1]
    basis = group.hat(np.eye(dim)).transpose(1, 0, 2).reshape(c, dim * c)  # [E_0 … E_K−1] side by side

    def residual(xi: LieGroup, xj: LieGroup, jac: bool = False) -> Any:
        ri, rj = _rows(xi), _rows(xj)
        m, d = ri.shape[:2]
        r = (rj * w - ri @ zw).reshape(m, -1)
        if not jac:
            return r
        # X E_k for every k in one matmul: (m, d, K, c), then the right factors W and Z W.
        j_j = ((rj @ basis).reshape(m, d, dim, c) * w[:, :, None, :]).transpose(0, 1, 3, 2).reshape(m, -1, dim)
        j_i = -np.einsum("eakc,ecf->eafk", (ri @ basis).reshape(m, d, dim, c), zw, optimize=True).reshape(m, -1, dim)
        return r, [j_i, j_j]

    return Factor(edges, residual, loss, name, residual_dim=group.point_dim * c)  # d rows of c columns


def chordal_quadratic_form(n: int, edges: IntArray, measurements: LieGroup, weights: FloatArray) -> sp.csr_matrix:
    """``Q`` with ``Σ_e ‖(X_j − X_i Z_e) W_e‖_F² = tr(X Q Xᵀ)`` for the stacked top rows
    ``X = [X_1 … X_n]`` (``d × nc``):
    ``Q = Σ_e (e_j ⊗ I − e_i ⊗ Z_e) W_e² (e_j ⊗ I − e_i ⊗ Z_e)ᵀ``, ``nc × nc``
    (for rotations the connection Laplacian of SE-Sync and Shonan averaging)."""
    c = weights.shape[1]
    z, w2 = measurements.as_matrix(), weights**2
    zw2 = z * w2[:, None, :]  # Z W²
    blocks = [
        (edges[:, 1], edges[:, 1], np.einsum("ij,ei->eij", np.eye(c), w2)),
        (edges[:, 0], edges[:, 0], zw2 @ np.swapaxes(z, 1, 2)),
        (edges[:, 0], edges[:, 1], -zw2),
        (edges[:, 1], edges[:, 0], -np.swapaxes(zw2, 1, 2)),
    ]
    a = np.arange(c)
    shape = (len(edges), c, c)
    rows = np.concatenate([np.broadcast_to(b[:, None, None] * c + a[:, None], shape).ravel() for b, _, _ in blocks])
    cols = np.concatenate([np.broadcast_to(b[:, None, None] * c + a, shape).ravel() for _, b, _ in blocks])
    vals = np.concatenate([v.ravel() for _, _, v in blocks])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n * c, n * c))


def quadratic_form_gradient(q: sp.spmatrix, rows: FloatArray) -> FloatArray:
    """``2 V Q`` (the Euclidean gradient of ``tr(V Q Vᵀ)``) for blocks ``V`` of shape
    ``(n, d, c)``, returned as ``(n, d, c)``."""
    n, d, c = rows.shape
    return 2.0 * (q @ rows.transpose(0, 2, 1).reshape(n * c, d)).reshape(n, c, d).transpose(0, 2, 1)


class ChordalHessian:
    """The exact Riemannian Hessian of the chordal cost on ``Power(G, n)``.

    ``f(X) = tr(X Q Xᵀ)`` (:func:`chordal_quadratic_form`), so ``∇f = 2XQ`` and
    ``∇²f[V] = 2VQ``; the manifold turns them into ``Hess f(X)[v]`` (its
    ``ehess2rhess``). Fixed variables see the identity, as in the Gauss-Newton model.
    """

    def __init__(
        self, manifold: Power, edges: IntArray, measurements: LieGroup, weights: FloatArray, fixed: IntArray
    ) -> None:
        n, c = manifold.shape[0], weights.shape[1]
        self.Q = chordal_quadratic_form(n, edges, measurements, weights)
        self.manifold, self.n, self.c = manifold, n, c
        self.fixed = np.asarray(fixed, dtype=np.int64)

    def _times_2q(self, v: FloatArray) -> FloatArray:
        """``2 V Q`` for ``V`` of shape ``(n, d, c)``, zero-padded to ``(n, c, c)`` matrices."""
        n, d, c = v.shape
        out = np.zeros((n, c, c))
        out[:, :d, :] = quadratic_form_gradient(self.Q, v)
        return out

    def egrad(self, x: LieGroup) -> FloatArray:
        return self._times_2q(_rows(x))

    def __call__(self, x: LieGroup, v: FloatArray) -> FloatArray:
        v = np.array(v, dtype=np.float64)
        v_fixed = v[self.fixed].copy()
        v[self.fixed] = 0.0
        d = x.point_dim  # type: ignore[attr-defined]
        ehess = self._times_2q(self.manifold.to_ambient(x, v)[:, :d, :])
        out = self.manifold.ehess2rhess(x, self.egrad(x), ehess, v)
        out[self.fixed] = v_fixed
        return out
