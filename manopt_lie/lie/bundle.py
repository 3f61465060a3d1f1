"""Direct products of Lie groups: ``Bundle(G₁, G₂, …)`` as one group class (manif's ``Bundle``).

An element stores the parts' arrays flattened and concatenated, ``(..., Σ|Gᵢ storage|)``;
the tangent is the concatenation ``(τ₁, τ₂, …)`` and the points acted on are the
concatenation of the parts' points. Every operation acts part by part, so ``Ad``, ``Jr``,
``Jr⁻¹``, ``ad`` and the Jacobians of ``act`` are block diagonal (Solà et al., §IV-H, the
"composite manifold"). The matrix form is the block-diagonal matrix of the parts' matrix
forms (``Rn`` parts as ``[[I, v], [0, 1]]``), a faithful representation: ``hat`` and
``vee`` are block diagonal too, so ``LieGroupManifold(Bundle(...))`` embeds it like any
matrix group. ``Bundle(G₁, G₂) is Bundle(G₁, G₂)``.
"""

from __future__ import annotations

import itertools
from functools import cache
from math import prod
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ..errors import NotInGroupError, ShapeError
from ._checks import FloatArray, as_batch
from .base import LieGroup
from .rn import Rn, RnGroup

__all__ = ["Bundle", "BundleGroup"]


def _offsets(sizes: tuple[int, ...]) -> list[tuple[int, int]]:
    ends = np.cumsum((0,) + sizes)
    return [(int(a), int(b)) for a, b in itertools.pairwise(ends)]


def block_diag(blocks: list[FloatArray]) -> FloatArray:
    """Block-diagonal matrices ``(..., Σmᵢ, Σnᵢ)`` from ``(..., mᵢ, nᵢ)``, batch axes broadcast."""
    batch = np.broadcast_shapes(*(b.shape[:-2] for b in blocks))
    rows, cols = _offsets(tuple(b.shape[-2] for b in blocks)), _offsets(tuple(b.shape[-1] for b in blocks))
    out = np.zeros(batch + (rows[-1][1], cols[-1][1]))
    for b, (r0, r1), (c0, c1) in zip(blocks, rows, cols, strict=True):
        out[..., r0:r1, c0:c1] = b
    return out


class BundleGroup(LieGroup):
    """Base of the ``Bundle(...)`` classes; use :func:`Bundle` to get one.

    Class attributes
    ----------------
    parts : tuple of LieGroup classes
        The factors, in order.
    """

    __slots__ = ()
    parts: ClassVar[tuple[type[LieGroup], ...]]
    _data_slices: ClassVar[list[tuple[int, int]]]
    _tangent_slices: ClassVar[list[tuple[int, int]]]
    _point_slices: ClassVar[list[tuple[int, int]]]
    _matrix_slices: ClassVar[list[tuple[int, int]]]

    # ---- packing ----------------------------------------------------------------------

    @classmethod
    def _unpack(cls, a: FloatArray) -> list[FloatArray]:
        batch = a.shape[:-1]
        return [
            a[..., i:j].reshape(batch + g.storage_shape) for g, (i, j) in zip(cls.parts, cls._data_slices, strict=True)
        ]

    @classmethod
    def _pack(cls, arrays: list[FloatArray]) -> FloatArray:
        batch = np.broadcast_shapes(
            *(x.shape[: x.ndim - len(g.storage_shape)] for g, x in zip(cls.parts, arrays, strict=True))
        )
        flat = [
            np.broadcast_to(x, batch + g.storage_shape).reshape(batch + (-1,))
            for g, x in zip(cls.parts, arrays, strict=True)
        ]
        return np.concatenate(flat, axis=-1)

    @staticmethod
    def _pieces(v: FloatArray, slices: list[tuple[int, int]]) -> list[FloatArray]:
        return [v[..., i:j] for i, j in slices]

    # ---- kernels, part by part -------------------------------------------------------------

    @classmethod
    def _exp(cls, tau: FloatArray) -> FloatArray:
        return cls._pack([g._exp(t) for g, t in zip(cls.parts, cls._pieces(tau, cls._tangent_slices), strict=True)])

    @classmethod
    def _log(cls, a: FloatArray) -> FloatArray:
        return np.concatenate([g._log(x) for g, x in zip(cls.parts, cls._unpack(a), strict=True)], axis=-1)

    @classmethod
    def _compose(cls, a: FloatArray, b: FloatArray) -> FloatArray:
        return cls._pack([g._compose(x, y) for g, x, y in zip(cls.parts, cls._unpack(a), cls._unpack(b), strict=True)])

    @classmethod
    def _inverse(cls, a: FloatArray) -> FloatArray:
        return cls._pack([g._inverse(x) for g, x in zip(cls.parts, cls._unpack(a), strict=True)])

    @classmethod
    def _act(cls, a: FloatArray, p: FloatArray) -> FloatArray:
        pieces = zip(cls.parts, cls._unpack(a), cls._pieces(p, cls._point_slices), strict=True)
        outs = [g._act(x, q) for g, x, q in pieces]
        batch = np.broadcast_shapes(*(o.shape[:-1] for o in outs))
        return np.concatenate([np.broadcast_to(o, batch + o.shape[-1:]) for o in outs], axis=-1)

    @classmethod
    def _act_jac(cls, a: FloatArray, p: FloatArray) -> tuple[FloatArray, FloatArray]:
        pieces = zip(cls.parts, cls._unpack(a), cls._pieces(p, cls._point_slices), strict=True)
        jacs = [g._act_jac(x, q) for g, x, q in pieces]
        return block_diag([j[0] for j in jacs]), block_diag([j[1] for j in jacs])

    @classmethod
    def _adjoint(cls, a: FloatArray) -> FloatArray:
        return block_diag([g._adjoint(x) for g, x in zip(cls.parts, cls._unpack(a), strict=True)])

    @classmethod
    def _tangent_blocks(cls, kernel: str, tau: FloatArray) -> FloatArray:
        return block_diag(
            [getattr(g, kernel)(t) for g, t in zip(cls.parts, cls._pieces(tau, cls._tangent_slices), strict=True)]
        )

    @classmethod
    def _jr(cls, tau: FloatArray) -> FloatArray:
        return cls._tangent_blocks("_jr", tau)

    @classmethod
    def _jr_inv(cls, tau: FloatArray) -> FloatArray:
        return cls._tangent_blocks("_jr_inv", tau)

    @classmethod
    def _ad(cls, tau: FloatArray) -> FloatArray:
        return cls._tangent_blocks("_ad", tau)

    @classmethod
    def _hat(cls, tau: FloatArray) -> FloatArray:
        return cls._tangent_blocks("_hat", tau)

    @classmethod
    def _vee(cls, m: FloatArray) -> FloatArray:
        blocks = [m[..., i:j, i:j] for i, j in cls._matrix_slices]
        return np.concatenate([g._vee(b) for g, b in zip(cls.parts, blocks, strict=True)], axis=-1)

    @classmethod
    def _identity(cls, batch: tuple[int, ...]) -> FloatArray:
        return cls._pack([g._identity(batch) for g in cls.parts])

    @classmethod
    def _random(cls, rng: np.random.Generator, batch: tuple[int, ...]) -> FloatArray:
        return cls._pack([g._random(rng, batch) for g in cls.parts])

    @classmethod
    def _validated(cls, a: FloatArray, tol: float, name: str) -> FloatArray:
        return cls._pack(
            [
                g._validated(x, tol, f"{name} (part {k})")
                for k, (g, x) in enumerate(zip(cls.parts, cls._unpack(a), strict=True))
            ]
        )

    @classmethod
    def _project(cls, a: FloatArray) -> FloatArray:
        return cls._pack([g._project(x) for g, x in zip(cls.parts, cls._unpack(a), strict=True)])

    # ---- matrix form and parts -----------------------------------------------------------

    @classmethod
    def _matrix_to_data(cls, m: ArrayLike) -> FloatArray:
        """The parts' data from the diagonal blocks of a block-diagonal matrix (other entries must be 0)."""
        k = cls._matrix_slices[-1][1]
        mat = as_batch(m, (k, k), "from_matrix")
        off = mat.copy()
        parts = []
        for g, (i, j) in zip(cls.parts, cls._matrix_slices, strict=True):
            parts.append(as_batch(g._matrix_to_data(mat[..., i:j, i:j]), g.storage_shape, "from_matrix"))
            off[..., i:j, i:j] = 0.0
        if np.abs(off).max(initial=0.0) > 0.0:
            raise NotInGroupError(f"from_matrix: not block diagonal over the parts of {cls.__name__}")
        return cls._pack(parts)

    def as_matrix(self) -> FloatArray:
        """The block-diagonal matrix of the parts' matrix forms."""
        return block_diag([np.asarray(x.as_matrix()) for x in self.split()])

    def split(self) -> tuple[LieGroup, ...]:
        """The parts, as elements of their groups (views)."""
        return tuple(g._wrap(x) for g, x in zip(self.parts, self._unpack(self._data), strict=True))

    @classmethod
    def from_parts(cls, *elements: LieGroup) -> BundleGroup:
        """The element ``(X₁, X₂, …)``; batch shapes broadcast."""
        if len(elements) != len(cls.parts):
            raise ShapeError(f"from_parts: {cls.__name__} has {len(cls.parts)} parts, got {len(elements)} elements")
        return cls._wrap(cls._pack([g._same(x)._data for g, x in zip(cls.parts, elements, strict=True)]))

    def __reduce__(self) -> tuple[Any, ...]:
        return (_rebuild, (_spec(type(self)), np.array(self._data)))


def Bundle(*parts: type[LieGroup]) -> type[BundleGroup]:
    """The direct product ``G₁ × G₂ × …`` as a :class:`LieGroup` class (one class per tuple of parts).

    Raises
    ------
    TypeError
        If a part is not a LieGroup class, or no part is given.
    """
    if not parts or not all(isinstance(g, type) and issubclass(g, LieGroup) for g in parts):
        raise TypeError(f"Bundle: expected one or more LieGroup classes, got {parts!r}")
    return _bundle_class(tuple(parts))


@cache
def _bundle_class(parts: tuple[type[LieGroup], ...]) -> type[BundleGroup]:
    def sizes(f: Any) -> list[tuple[int, int]]:
        return _offsets(tuple(f(g) for g in parts))

    matrix = [g.hat(np.zeros(g.dim)).shape[-1] for g in parts]
    attrs = {
        "__slots__": (),
        "__module__": __name__,
        "parts": parts,
        "dim": sum(g.dim for g in parts),
        "point_dim": sum(g.point_dim for g in parts),
        "storage_shape": (sum(prod(g.storage_shape) for g in parts),),
        "_data_slices": sizes(lambda g: prod(g.storage_shape)),
        "_tangent_slices": sizes(lambda g: g.dim),
        "_point_slices": sizes(lambda g: g.point_dim),
        "_matrix_slices": _offsets(tuple(matrix)),
    }
    return type(f"Bundle[{', '.join(g.__name__ for g in parts)}]", (BundleGroup,), attrs)


def _spec(g: type[LieGroup]) -> Any:
    """A picklable recipe for a group class (``Rn(n)`` and bundles are made on the fly)."""
    if issubclass(g, RnGroup):
        return ("Rn", g.dim)
    if issubclass(g, BundleGroup):
        return ("Bundle", tuple(_spec(p) for p in g.parts))
    return g


def _from_spec(spec: Any) -> type[LieGroup]:
    if isinstance(spec, tuple):
        return Rn(spec[1]) if spec[0] == "Rn" else Bundle(*(_from_spec(p) for p in spec[1]))
    return spec


def _rebuild(spec: Any, data: FloatArray) -> LieGroup:
    return _from_spec(spec)._wrap(data)
