"""Named blocks of variables — ``Power(M₁, n₁) × Power(M₂, n₂) × …`` — with one flat tangent.

The variables of a factor graph come in kinds: poses in SE(3), landmarks in R³, a
calibration in SE(3)… :class:`Blocks` is the product of one :class:`~.Power` per kind,
each of a manifold with vector tangents (``d_k`` coordinates per variable). A point is
a :class:`Values` — the blocks' points, by position or by name (``x["landmarks"]``) — and
a tangent vector is **one flat array** of ``Σ n_k d_k`` coordinates, block after block,
variable after variable: the layout of the least-squares normal equations, so the
optimizers' vector arithmetic stays NumPy's and a sparse solve's step is a tangent
vector as it is. The metric is the sum of the blocks' metrics.

A point is one point of the product: no extra leading batch axes.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import ShapeError
from .base import Manifold, Point, Tangent
from .product import Power

FloatArray = NDArray[np.float64]

__all__ = ["Blocks", "Values"]


class Values(tuple):  # type: ignore[type-arg]
    """A point of :class:`Blocks`: the blocks' points in order, also by name.

    ``x["poses"]`` or ``x[0]``; ``x.names``; ``dict(x.items())``. Immutable like a tuple
    (so optimizers and caches treat it as one, part by part).
    """

    names: tuple[str, ...]

    def __new__(cls, names: tuple[str, ...], parts: Any) -> Values:
        parts = tuple(parts)
        if len(parts) != len(names):
            raise ValueError(f"Values: {len(names)} names {names} for {len(parts)} parts")
        self = super().__new__(cls, parts)
        self.names = tuple(names)
        return self

    def __getitem__(self, key: Any) -> Any:  # type: ignore[override]
        if isinstance(key, str):
            try:
                return tuple.__getitem__(self, self.names.index(key))
            except ValueError:
                raise KeyError(f"no block named {key!r}; blocks: {', '.join(self.names)}") from None
        return tuple.__getitem__(self, key)

    def items(self) -> Iterator[tuple[str, Any]]:
        """``(name, value)`` per block, in order, as ``dict.items``."""
        return zip(self.names, self, strict=True)

    def replace(self, **parts: Any) -> Values:
        """A copy with the named blocks replaced."""
        unknown = set(parts) - set(self.names)
        if unknown:
            raise KeyError(f"no blocks named {sorted(unknown)}; blocks: {', '.join(self.names)}")
        return Values(self.names, (parts.get(name, part) for name, part in self.items()))

    def __repr__(self) -> str:
        return "Values(" + ", ".join(f"{n}={p!r}" for n, p in self.items()) + ")"

    def __reduce__(self) -> tuple[Any, ...]:
        return (Values, (self.names, tuple(self)))


class Blocks(Manifold):
    """``Power(M₁, n₁) × … × Power(M_K, n_K)``, blocks named, tangent vectors flat.

    Parameters
    ----------
    blocks : mapping ``name → Power(M, n)``
        In order. Each ``M`` must have vector tangents (``M.tangent_ndim == 1``), e.g.
        ``LieGroupManifold(SE3)`` (``d = 6``), ``LieGroupManifold(Rn(3))`` or ``Euclidean(3)``.

    Attributes
    ----------
    names : tuple of str
    sizes : tuple of int
        ``n_k`` per block.
    dims : int array ``(Σ n_k,)``
        The tangent dimension of every variable, block after block (what
        :class:`~manopt_lie.linalg.BlockStructure` takes).
    offsets : dict ``name → int``
        The global index of each block's first variable.
    """

    def __init__(self, blocks: Mapping[str, Power]) -> None:
        if not blocks:
            raise ValueError("Blocks: give at least one block")
        for name, power in blocks.items():
            if not isinstance(name, str) or not name:
                raise TypeError(f"Blocks: block names must be non-empty strings, got {name!r}")
            if not isinstance(power, Power) or len(power.shape) != 1 or power.manifold.tangent_ndim != 1:
                raise TypeError(f"Blocks: block {name!r} must be Power(M, n) with vector tangents, got {power!r}")
        self.blocks: dict[str, Power] = dict(blocks)
        self.names = tuple(self.blocks)
        self.sizes = tuple(p.shape[0] for p in self.blocks.values())
        self.block_dims = tuple(p.manifold.dim for p in self.blocks.values())
        self.dims = np.repeat(np.array(self.block_dims, dtype=np.int64), self.sizes)
        starts = np.cumsum([0, *self.sizes])
        self.offsets = {name: int(s) for name, s in zip(self.names, starts[:-1], strict=True)}
        ends = np.cumsum([0, *(n * d for n, d in zip(self.sizes, self.block_dims, strict=True))])
        self._slices = [slice(int(a), int(b)) for a, b in itertools.pairwise(ends)]
        self.size = int(ends[-1])

    def __repr__(self) -> str:
        return "Blocks(" + ", ".join(f"{n}={p!r}" for n, p in self.blocks.items()) + ")"

    # ---- layout ------------------------------------------------------------------------

    def split(self, v: Tangent) -> list[FloatArray]:
        """The flat tangent ``v`` as one ``(n_k, d_k)`` array per block (views, no copies)."""
        v = np.asarray(v, dtype=np.float64)
        if v.shape != (self.size,):
            raise ShapeError(f"{self!r}: a tangent vector has shape ({self.size},), got {v.shape}")
        return [v[s].reshape(n, d) for s, n, d in zip(self._slices, self.sizes, self.block_dims, strict=True)]

    def join(self, parts: Any) -> FloatArray:
        """One flat tangent from per-block ``(n_k, d_k)`` arrays."""
        parts = list(parts)
        if len(parts) != len(self.names):
            raise ShapeError(f"{self!r}: need {len(self.names)} blocks, got {len(parts)}")
        return np.concatenate([np.asarray(p, dtype=np.float64).reshape(-1) for p in parts])

    def values(self, *parts: Any, **named: Any) -> Values:
        """A point from the blocks' points, in order or by name."""
        if parts and named:
            raise TypeError("Blocks.values: give the parts in order or by name, not both")
        if named:
            missing = [n for n in self.names if n not in named]
            if missing or len(named) != len(self.names):
                raise KeyError(f"Blocks.values: need exactly the blocks {self.names}, got {tuple(named)}")
            parts = tuple(named[n] for n in self.names)
        return Values(self.names, parts)

    def _parts(self, x: Point, name: str = "x") -> Values:
        if not isinstance(x, tuple) or len(x) != len(self.names):
            raise ShapeError(
                f"{name}: a point of {self!r} is Values of {len(self.names)} blocks, got {type(x).__name__}"
            )
        return x if isinstance(x, Values) else Values(self.names, x)

    def _each(self, op: str, x: Point, *tangents: Tangent) -> list[Any]:
        xs = self._parts(x)
        split = [self.split(t) for t in tangents]
        powers = self.blocks.values()
        return [getattr(p, op)(xk, *(s[k] for s in split)) for k, (p, xk) in enumerate(zip(powers, xs, strict=True))]

    # ---- the manifold --------------------------------------------------------------------

    @property
    def dim(self) -> int:
        return sum(p.dim for p in self.blocks.values())

    @property
    def typical_dist(self) -> float:
        return float(np.sqrt(sum(p.typical_dist**2 for p in self.blocks.values())))

    tangent_ndim = 1

    def inner(self, x: Point, u: Tangent, v: Tangent) -> Any:
        return float(sum(np.sum(value) for value in self._each("inner", x, u, v)))

    def scale(self, v: Tangent, s: Any) -> Tangent:
        return np.asarray(v) * float(s)

    def proj(self, x: Point, u: Any) -> Tangent:
        xs = self._parts(x)
        return self.join(p.proj(xk, uk) for p, xk, uk in zip(self.blocks.values(), xs, u, strict=True))

    def retr(self, x: Point, v: Tangent) -> Point:
        return Values(self.names, self._each("retr", x, v))

    def exp(self, x: Point, v: Tangent) -> Point:
        return Values(self.names, self._each("exp", x, v))

    def log(self, x: Point, y: Point) -> Tangent:
        xs, ys = self._parts(x), self._parts(y, "y")
        return self.join(p.log(xk, yk) for p, xk, yk in zip(self.blocks.values(), xs, ys, strict=True))

    def dist(self, x: Point, y: Point) -> Any:
        xs, ys = self._parts(x), self._parts(y, "y")
        return float(np.sqrt(sum(p.dist(a, b) ** 2 for p, a, b in zip(self.blocks.values(), xs, ys, strict=True))))

    def transp(self, x: Point, y: Point, v: Tangent) -> Tangent:
        xs, ys = self._parts(x), self._parts(y, "y")
        parts = self.split(v)
        return self.join(
            p.transp(a, b, vk) for p, a, b, vk in zip(self.blocks.values(), xs, ys, parts, strict=True)
        )

    def _random_point(self, rng: np.random.Generator, batch: tuple[int, ...]) -> Point:
        if batch:
            raise ShapeError(f"{self!r}: points have no batch axes")
        return Values(self.names, (p._random_point(rng, ()) for p in self.blocks.values()))

    def random_tangent(self, x: Point, rng: np.random.Generator | int | None = None) -> Tangent:
        rng = np.random.default_rng(rng)
        xs = self._parts(x)
        v = self.join(p.random_tangent(xk, rng) for p, xk in zip(self.blocks.values(), xs, strict=True))
        return v / np.sqrt(self.inner(x, v, v))

    def zero_vector(self, x: Point) -> Tangent:
        return np.zeros(self.size)

    def to_ambient(self, x: Point, v: Tangent) -> Any:
        return tuple(self._each("to_ambient", x, v))

    def egrad2rgrad(self, x: Point, egrad: Any) -> Tangent:
        xs = self._parts(x)
        return self.join(p.egrad2rgrad(xk, gk) for p, xk, gk in zip(self.blocks.values(), xs, egrad, strict=True))

    def ehess2rhess(self, x: Point, egrad: Any, ehess: Any, v: Tangent) -> Tangent:
        xs = self._parts(x)
        parts = self.split(v)
        return self.join(
            p.ehess2rhess(xk, gk, hk, vk)
            for p, xk, gk, hk, vk in zip(self.blocks.values(), xs, egrad, ehess, parts, strict=True)
        )

    def check_point(self, x: Point, name: str = "x") -> None:
        xs = self._parts(x, name)
        for (block, power), xk in zip(self.blocks.items(), xs, strict=True):
            power.check_point(xk, f"{name}[{block!r}]")
            if power.batch_shape_of(xk) != ():
                raise ShapeError(f"{name}[{block!r}]: a point of {self!r} has no batch axes")

    def batch_shape_of(self, x: Point) -> tuple[int, ...]:
        return ()
