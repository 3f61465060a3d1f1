"""A Lie group of ``manopt_lie.lie`` as a Riemannian manifold (CONVENTIONS §6).

Points are group elements (any batch shape: ``Power`` uses ``(n,)``); tangent
vectors are Cartesian coordinates ``τ`` of shape ``(..., dim)`` with the
left-invariant metric ``⟨τ₁, τ₂⟩ = τ₁ᵀτ₂``; the retraction is ``R_X(τ) = X ⊕ τ``.

Derivatives come from the matrix embedding. With ``Eᵢ = hat(eᵢ)`` the
generators and ``hat*(M)ᵢ = ⟨Eᵢ, M⟩_F`` the adjoint of ``hat``:

* ambient form of ``τ``: ``X τ^``;
* ``grad f(X) = hat*(Xᵀ∇f(X))`` — for SO(n) this is ``vee(RᵀG − GᵀR)``;
* ``proj_X(U) = (hat*∘hat)⁻¹ hat*(XᵀU)``, the least-squares coordinates of ``U``;
* ``Hess f(X)[v] = hat*(Xᵀ∇²f(X)[Xv^]) + ½ hat*(M v^ᵀ + v^ᵀ M)``, ``M = Xᵀ∇f(X)``:
  the Hessian of the pullback ``τ ↦ f(X ⊕ τ)`` at 0 (its second term is the
  curvature of ``τ ↦ X Exp(τ)``, ``∂²/∂τᵢ∂τⱼ = X(EᵢEⱼ + EⱼEᵢ)/2``).

``geometry="product"`` treats SE(n) as SO(n) × Rⁿ (as Manopt and SymForce do):
``R_{(R,t)}(ρ, θ) = (R Exp(θ), t + ρ)`` with the translation increment in the
world frame; the formulas above then apply to the rotation block, and the
translation block is Euclidean.

``geometry="decoupled"`` keeps the group's tangent coordinates and metric but retracts
rotation and translation apart, ``R_{(R,t)}(ρ, θ) = (R Exp(θ), t + Rρ)`` (GTSAM's Pose3
retraction): its differential at 0 is that of ``X Exp(τ)``, so gradients and every right
Jacobian apply unchanged, while a long step moves the translation along a straight line
instead of the screw of ``Exp``, which keeps least squares from poor starts (landmark
SLAM from composed odometry) converging. Its pullback's curvature is the rotation
block's only: ``∂²/∂θᵢ∂θⱼ = R(EᵢEⱼ + EⱼEᵢ)/2``, nothing in ``ρ``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._kernels import rplus
from ..errors import ShapeError
from ..lie import SE2, SE3, LieGroup, RnGroup
from ..lie._checks import FloatArray, as_batch
from ..lie._matrix import assemble, split
from ..lie._series import HUGE
from .base import Manifold, coordinate_inner


def _t(a: FloatArray) -> FloatArray:
    return np.swapaxes(a, -1, -2)


class _Algebra:
    """``hat``, its adjoint ``hat*`` and the Gram matrix of the generators of a group."""

    def __init__(self, group: type[LieGroup]) -> None:
        self.hat = group.hat
        self.basis = group.hat(np.eye(group.dim))  # (dim, k, k): the generators Eᵢ
        self.gram_inv = np.linalg.inv(np.einsum("ijk,ljk->il", self.basis, self.basis))
        self.basis.flags.writeable = self.gram_inv.flags.writeable = False  # shared by every manifold of the group

    @staticmethod
    def of(group: type[LieGroup]) -> _Algebra:
        """The algebra of ``group``, built once (a problem's manifold is built with every problem)."""
        algebra = _ALGEBRAS.get(group)
        if algebra is None:
            algebra = _ALGEBRAS[group] = _Algebra(group)
        return algebra

    def adjoint_hat(self, m: FloatArray) -> FloatArray:
        """``hat*(M)ᵢ = ⟨Eᵢ, M⟩_F``."""
        return np.einsum("...jk,ijk->...i", m, self.basis)

    def coordinates(self, m: FloatArray) -> FloatArray:
        """Least-squares coordinates of ``M`` in the generators: ``(hat*∘hat)⁻¹ hat*(M)``."""
        return self.adjoint_hat(m) @ self.gram_inv

    def grad_and_hess(self, m: FloatArray, h: FloatArray, v: FloatArray) -> FloatArray:
        """``hat*(H) + ½ hat*(M v^ᵀ + v^ᵀ M)`` for ``M = XᵀG``, ``H = Xᵀ∇²f[·]``."""
        vh = self.hat(v)
        return self.adjoint_hat(h) + 0.5 * self.adjoint_hat(m @ _t(vh) + _t(vh) @ m)


_ALGEBRAS: dict[type[LieGroup], _Algebra] = {}


class LieGroupManifold(Manifold):
    """The group ``G`` with the left-invariant metric in Cartesian tangent coordinates.

    ``exp`` is the retraction ``X ⊕ τ`` and ``log(X, Y) = Y ⊖ X`` (the Riemannian
    exponential and logarithm for SO(n), Rⁿ and the product geometry; for SE(n)
    in the group geometry, the group's). ``transp`` is the identity on
    coordinates.

    Parameters
    ----------
    group : SO2, SO3, SE2, SE3 or Rn(n)
    geometry : {"group", "product", "decoupled"}
        ``"product"`` (SE2, SE3 only) uses SO(n) × Rⁿ: translation increments in
        the world frame. ``"decoupled"`` (SE2, SE3 only): the group's coordinates,
        retracted by ``(R Exp(θ), t + Rρ)`` (see the module doc).
    """

    def __init__(self, group: type[LieGroup], geometry: str = "group") -> None:
        if not (isinstance(group, type) and issubclass(group, LieGroup)):
            raise TypeError(f"LieGroupManifold: expected a LieGroup class such as SO3, got {group!r}")
        if geometry not in ("group", "product", "decoupled"):
            raise ValueError(
                f"LieGroupManifold: geometry must be 'group', 'product' or 'decoupled', got {geometry!r}"
            )
        if geometry != "group" and group not in (SE2, SE3):
            raise ValueError(f"LieGroupManifold: the {geometry} geometry is for SE2 and SE3")
        self.group = group
        self.geometry = geometry
        self._embedded = geometry != "product"  # the group's tangent coordinates X τ^
        self._euclidean = issubclass(group, RnGroup)  # Rⁿ's ambient space is Rⁿ itself
        self._algebra = _Algebra.of(group if self._embedded else group.rotation_group)  # type: ignore[attr-defined]
        if geometry == "decoupled":
            self._rotations = _Algebra.of(group.rotation_group)  # type: ignore[attr-defined]

    def __repr__(self) -> str:
        extra = "" if self.geometry == "group" else f", geometry={self.geometry!r}"
        return f"LieGroupManifold({self.group.__name__}{extra})"

    @property
    def dim(self) -> int:
        return self.group.dim

    def inner(self, x: LieGroup, u: FloatArray, v: FloatArray) -> Any:
        return np.einsum("...i,...i->...", u, v)

    def total_inner(self, x: LieGroup, u: FloatArray, v: FloatArray) -> float:
        """``Σ τ₁ᵀτ₂`` over the batch (one ``np.vdot``)."""
        return coordinate_inner(u, v)

    def retr(self, x: LieGroup, v: FloatArray) -> LieGroup:
        if self.geometry == "group":
            if type(x) in (SE2, SE3) and len(x.batch_shape) == 1 and len(x) > 1:
                t = x._tangent(v)
                # Compiled, or a small batch on CasADi's virtual machine; huge angles: the scale-safe kernels.
                y = rplus(type(x), x.as_matrix(), t) if t.shape == (len(x), x.dim) and np.abs(t).max() < HUGE else None
                return x.rplus(t) if y is None else x._wrap(y)
            return x.rplus(v)
        r, t = x.rotation(), x.translation()  # type: ignore[attr-defined]
        d = self.group.point_dim
        step = v[..., :d] if self.geometry == "product" else r.act(v[..., :d])
        return self.group._wrap(assemble(r.rplus(v[..., d:]).as_matrix(), t + step))

    exp = retr

    def log(self, x: LieGroup, y: LieGroup) -> FloatArray:
        if self.geometry == "group":
            return y.rminus(x)
        rot = y.rotation().rminus(x.rotation())  # type: ignore[attr-defined]
        shift = y.translation() - x.translation()  # type: ignore[attr-defined]
        if self.geometry == "decoupled":
            shift = x.rotation().inverse().act(shift)  # type: ignore[attr-defined]
        return np.concatenate([shift, rot], axis=-1)

    def dist(self, x: LieGroup, y: LieGroup) -> Any:
        return np.linalg.norm(self.log(x, y), axis=-1)

    def transp(self, x: LieGroup, y: LieGroup, v: FloatArray) -> FloatArray:
        return v

    # ---- the matrix embedding ----------------------------------------------------

    def _ambient(self, x: LieGroup, u: Any) -> FloatArray:
        shape = (self.group.dim,) if self._euclidean else x.as_matrix().shape[-2:]
        return as_batch(u, shape, "ambient vector")

    def to_ambient(self, x: LieGroup, v: FloatArray) -> FloatArray:
        """``X v^`` (product geometry: ``[[R θ^, ρ], [0, 0]]``; Rⁿ: ``v``)."""
        if self._euclidean:
            return v
        if self._embedded:
            return x.as_matrix() @ self.group.hat(v)
        d = self.group.point_dim
        r, _ = split(x.as_matrix())
        out = assemble(r @ self._algebra.hat(v[..., d:]), v[..., :d])
        out[..., d, d] = 0.0
        return out

    def _split_rotation(self, m: FloatArray) -> tuple[FloatArray, FloatArray]:
        d = self.group.point_dim
        return m[..., :d, :d], m[..., :d, d]

    def _pull_back(self, x: LieGroup, a: FloatArray, to_coordinates: Any) -> FloatArray:
        """``to_coordinates(Xᵀ A)`` (product geometry: ``(A_t, to_coordinates(Rᵀ A_R))``)."""
        if self._euclidean:
            return a
        if self._embedded:
            return to_coordinates(_t(x.as_matrix()) @ a)
        r, _ = split(x.as_matrix())
        a_r, a_t = self._split_rotation(a)
        return np.concatenate([a_t, to_coordinates(_t(r) @ a_r)], axis=-1)

    def proj(self, x: LieGroup, u: Any) -> FloatArray:
        return self._pull_back(x, self._ambient(x, u), self._algebra.coordinates)

    def egrad2rgrad(self, x: LieGroup, egrad: Any) -> FloatArray:
        return self._pull_back(x, self._ambient(x, egrad), self._algebra.adjoint_hat)

    def ehess2rhess(self, x: LieGroup, egrad: Any, ehess: Any, v: FloatArray) -> FloatArray:
        g, h = self._ambient(x, egrad), self._ambient(x, ehess)
        if self._euclidean:
            return h
        if self.geometry == "group":
            xt = _t(x.as_matrix())
            return self._algebra.grad_and_hess(xt @ g, xt @ h, v)
        d = self.group.point_dim
        if self.geometry == "decoupled":  # the group's first term, the rotation block's curvature
            xt = _t(x.as_matrix())
            out = self._algebra.adjoint_hat(xt @ h)
            rt = _t(split(x.as_matrix())[0])
            m = rt @ self._split_rotation(g)[0]
            vh = self._rotations.hat(v[..., d:])
            out[..., d:] += 0.5 * self._rotations.adjoint_hat(m @ _t(vh) + _t(vh) @ m)
            return out
        rt = _t(split(x.as_matrix())[0])
        (g_r, _), (h_r, h_t) = self._split_rotation(g), self._split_rotation(h)
        return np.concatenate([h_t, self._algebra.grad_and_hess(rt @ g_r, rt @ h_r, v[..., d:])], axis=-1)

    # ---- points and tangents -----------------------------------------------------

    def _random_point(self, rng: np.random.Generator, batch: tuple[int, ...]) -> LieGroup:
        return self.group.random(rng, batch)

    def random_tangent(self, x: LieGroup, rng: np.random.Generator | int | None = None) -> FloatArray:
        v = np.random.default_rng(rng).standard_normal(x.batch_shape + (self.dim,))
        return self.unit(x, v)

    def zero_vector(self, x: LieGroup) -> FloatArray:
        return np.zeros(x.batch_shape + (self.dim,))

    def check_point(self, x: Any, name: str = "x") -> None:
        """A finite element of the group (``x.validate``: an element built by hand or unpickled
        may hold ``nan`` or a non-rotation)."""
        if not isinstance(x, self.group):
            raise ShapeError(
                f"{name}: a point of {self!r} is a {self.group.__name__} element "
                f"(e.g. {self.group.__name__}.from_matrix(...)), got {type(x).__name__}"
            )
        x.validate(name=name)

    def batch_shape_of(self, x: LieGroup) -> tuple[int, ...]:
        return x.batch_shape
