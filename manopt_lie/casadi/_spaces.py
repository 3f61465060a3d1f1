"""The manifolds symbolic costs run on, and how their points enter CasADi (a :class:`~._compile.Kind` each).

* **Charts** — ``LieGroupManifold(G)`` and ``Power(LieGroupManifold(G), n)`` for a group
  with a symbolic twin (SO2, SO3, SE2, SE3, Sim3, SE23, Bundles): the user gets the
  element matrix; derivatives are taken through ``X ⊕ δ`` (or the product geometry's
  ``(R ⊕ θ, t + ρ)``), giving the Riemannian gradient and the pullback Hessian directly.
* **Ambient** — every manifold whose points are arrays of at most two axes
  (``Euclidean(n)``, ``Euclidean(m, n)``, ``Sphere(n)``, ``Stiefel(n, p)``,
  ``Grassmann(n, p)``, ``SpecialOrthogonal(n)``, and ``LieGroupManifold(Rn(n))``), one
  point or a ``Power`` of them, and ``Product``\\ s of single points (Lie-group factors
  included, through their matrix embedding): the user gets the point as an ``n×1``
  column or an ``n×p`` matrix; CasADi gives the Euclidean gradient and Hessian-vector
  products, which the manifold converts (``egrad2rgrad``, ``ehess2rhess``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from ..errors import ShapeError
from ..lie import LieGroup, RnGroup
from ..manifolds import LieGroupManifold, Power, Product
from ..manifolds.base import Manifold
from ..manifolds.embedded import EmbeddedManifold
from ._compile import Kind, Matrix
from .lie import SymbolicGroup
from .twins import symbolic

__all__ = ["Part", "Space", "space_of"]

FloatArray = NDArray[np.float64]
SUPPORTED = (
    "LieGroupManifold(G), Euclidean(n) or (m, n), Sphere(n), Stiefel(n, p), Grassmann(n, p), SpecialOrthogonal(n), "
    "a Power(M, n) of one of these, or a Product of single ones"
)


def _chart(sym: type[SymbolicGroup], geometry: str) -> Any:
    """The retraction ``X ⊕ δ``, or ``(R ⊕ θ, t + ρ)`` in the product geometry."""
    if geometry == "group":
        return sym.rplus
    s = cast(Any, sym)
    d = s.point_dim

    def product(x: Matrix, delta: Matrix) -> Matrix:
        return s.from_rotation_translation(
            s.rotation.rplus(s.rotation_part(x), delta[d:]), s.translation(x) + delta[:d]
        )

    return product


@dataclass(frozen=True)
class Part:
    """One array of variables: ``n`` points of ``base`` (batch axes ``()`` for a single point)."""

    base: Manifold
    kind: Kind
    n: int
    single: bool
    group: type[LieGroup] | None = None  # points are elements of this group (else arrays)

    @property
    def batch(self) -> tuple[int, ...]:
        return () if self.single else (self.n,)

    @property
    def ambient_shape(self) -> tuple[int, ...]:
        """The shape of one point's ambient (embedding) array: what ``egrad`` returns."""
        if self.group is not None and issubclass(self.group, RnGroup):
            return (self.kind.size,)
        if isinstance(self.base, EmbeddedManifold):
            return self.base.point_shape
        return self.kind.shape

    def flat(self, x: Any, what: str = "point", batch: tuple[int, ...] | None = None) -> FloatArray:
        """The points (batch shape ``batch``, by default :attr:`batch`) as a C-contiguous
        ``(N, size)`` array of row-major entries."""
        batch = self.batch if batch is None else batch
        if self.group is not None:
            if not isinstance(x, LieGroup) or type(x) is not self.group:
                raise TypeError(f"expected a {self.group.__name__} element, got {type(x).__name__}")
            if x.batch_shape != batch:
                raise ShapeError(
                    f"expected a {self.group.__name__} element of batch shape {batch}, got {x.batch_shape}"
                )
            a = x.data if issubclass(self.group, RnGroup) else x.as_matrix()
        else:
            a = np.asarray(x, dtype=np.float64)
            want = batch + self.ambient_shape
            if a.shape != want:
                raise ShapeError(f"{what}: expected an array of shape {want} for {self.base!r}, got {a.shape}")
        return np.ascontiguousarray(a, dtype=np.float64).reshape(-1, self.kind.size)

    def rows(self, v: Any, what: str) -> FloatArray:
        """A tangent (charts) or ambient vector of these points as ``(n, dim)``."""
        a = np.asarray(v, dtype=np.float64)
        shape = self.batch + ((self.kind.dim,) if self.kind.chart is not None else self.ambient_shape)
        if a.shape != shape:
            raise ShapeError(f"{what}: expected shape {shape}, got {a.shape}")
        return np.ascontiguousarray(a).reshape(self.n, self.kind.dim)

    def shaped(self, rows: FloatArray) -> FloatArray:
        """``(n, dim)`` back to the tangent (charts) or ambient shape of the points."""
        return rows.reshape(self.batch + ((self.kind.dim,) if self.kind.chart is not None else self.ambient_shape))


@dataclass(frozen=True)
class Space:
    """The variable arrays of a supported manifold: one part, or one per factor of a product."""

    manifold: Manifold
    parts: tuple[Part, ...]
    product: bool

    @property
    def chart(self) -> bool:
        return self.parts[0].kind.chart is not None

    @property
    def n(self) -> int:
        return self.parts[0].n

    def flats(self, x: Any) -> list[FloatArray]:
        if not self.product:
            return [self.parts[0].flat(x)]
        if not isinstance(x, tuple) or len(x) != len(self.parts):
            raise ShapeError(
                f"a point of {self.manifold!r} is a tuple of {len(self.parts)} parts, got {type(x).__name__}"
            )
        return [p.flat(xi, f"x[{i}]") for i, (p, xi) in enumerate(zip(self.parts, x, strict=True))]

    def rows(self, v: Any, what: str) -> list[FloatArray]:
        if not self.product:
            return [self.parts[0].rows(v, what)]
        if not isinstance(v, tuple) or len(v) != len(self.parts):
            raise ShapeError(f"{what}: expected a tuple of {len(self.parts)} parts, got {type(v).__name__}")
        return [p.rows(vi, f"{what}[{i}]") for i, (p, vi) in enumerate(zip(self.parts, v, strict=True))]

    def shaped(self, rows: list[FloatArray]) -> Any:
        out = [p.shaped(r) for p, r in zip(self.parts, rows, strict=True)]
        return tuple(out) if self.product else out[0]

    def zeros(self) -> list[FloatArray]:
        return [np.zeros((p.n, p.kind.dim)) for p in self.parts]


def _kind(base: Manifold, caller: str, *, chart: bool) -> tuple[Kind, type[LieGroup] | None]:
    if isinstance(base, LieGroupManifold):
        group = base.group
        if issubclass(group, RnGroup):
            return Kind(f"a point of {base!r}", (group.dim, 1), group.dim), group
        try:
            sym = symbolic(group)
        except TypeError as err:
            raise TypeError(f"{caller}: {err}") from None
        k = sym.size
        if chart:
            return Kind(
                f"a {group.__name__} element", (k, k), sym.dim, _chart(sym, base.geometry), sym.from_matrix
            ), group
        return Kind(f"a {group.__name__} element", (k, k), k * k, None, sym.from_matrix), group
    if isinstance(base, EmbeddedManifold) and len(base.point_shape) <= 2:
        shape = base.point_shape if len(base.point_shape) == 2 else (base.point_shape[0], 1)
        return Kind(f"a point of {base!r}", (int(shape[0]), int(shape[1])), int(shape[0] * shape[1])), None
    if isinstance(base, EmbeddedManifold):
        raise TypeError(f"{caller}: {base!r} has points of {len(base.point_shape)} axes; CasADi matrices have two")
    raise TypeError(f"{caller}: need {SUPPORTED}, got {base!r}")


def space_of(manifold: Any, caller: str) -> Space:
    """The :class:`Space` of ``manifold``.

    Raises
    ------
    TypeError
        For an unsupported manifold (naming the supported ones).
    """
    if isinstance(manifold, Product):
        parts = []
        for i, m in enumerate(manifold.manifolds):
            if isinstance(m, (Power, Product)):
                raise TypeError(
                    f"{caller}: factor {i} of {manifold!r} is {m!r}; the factors of a Product must be single "
                    "manifolds (not Powers or Products)"
                )
            kind, group = _kind(m, caller, chart=False)
            parts.append(Part(m, kind, 1, True, group))
        return Space(manifold, tuple(parts), True)
    base, n, single = manifold, 1, True
    if isinstance(manifold, Power):
        if len(manifold.shape) != 1:
            raise TypeError(f"{caller}: need Power(M, n) with an integer n, got {manifold!r}")
        base, n, single = manifold.manifold, manifold.shape[0], False
        if isinstance(base, Product):
            raise TypeError(f"{caller}: Power of a Product is not supported; use a Product of Powers' factors")
    if not isinstance(base, Manifold):
        raise TypeError(f"{caller}: need {SUPPORTED}, got {manifold!r}")
    kind, group = _kind(base, caller, chart=True)
    return Space(manifold, (Part(base, kind, n, single, group),), False)
