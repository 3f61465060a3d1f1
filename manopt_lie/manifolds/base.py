"""The ``Manifold`` interface: the geometry an optimizer needs (CONVENTIONS §6).

A manifold object holds no points; its methods take them, base point first
(``retr(x, v)``, ``egrad2rgrad(x, g)``). Points are arrays or group elements;
tangent vectors are arrays (or :class:`ProductVector` for products), so the
optimizers' vector arithmetic (``u + v``, ``a * v``) is NumPy's and copies
nothing it does not have to.

Every operation also accepts points and tangent vectors with extra *leading
batch axes* and acts on each point independently; :meth:`inner` (and
:meth:`norm`, :meth:`dist`) then return one value per point. This is what lets
:class:`~manopt_lie.manifolds.Power` evaluate ``k`` copies in one vectorized call.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np

Point = Any
Tangent = Any


def coordinate_inner(u: Any, v: Any) -> float:
    """``Σᵢ uᵢvᵢ`` over every entry of two arrays (``np.vdot``; broadcast if the shapes differ):
    :meth:`Manifold.total_inner` for a metric that is Euclidean in the stored coordinates."""
    if type(u) is np.ndarray and type(v) is np.ndarray and u.shape == v.shape:  # the hot path
        return float(np.vdot(u, v))
    if np.shape(u) == np.shape(v):
        return float(np.vdot(u, v))
    return float(np.sum(np.multiply(u, v)))


class MissingOperationError(NotImplementedError):
    """An optional manifold operation that this manifold does not provide."""


class Manifold(ABC):
    """Base class of Riemannian manifolds.

    Required: :attr:`dim`, :meth:`inner`, :meth:`proj`, :meth:`retr`,
    :meth:`random_point`, :meth:`random_tangent`, :meth:`zero_vector`
    (:meth:`norm` derives from :meth:`inner`). Optional, raising
    :class:`MissingOperationError` unless overridden: :meth:`egrad2rgrad`,
    :meth:`ehess2rhess`, :meth:`exp`, :meth:`log`, :meth:`transp`, :meth:`dist`.
    """

    @property
    @abstractmethod
    def dim(self) -> int:
        """The manifold's dimension (degrees of freedom)."""

    @property
    def typical_dist(self) -> float:
        """A typical distance between points, to scale trust regions (``√dim`` unless known)."""
        return float(np.sqrt(self.dim))

    # ---- required ----------------------------------------------------------------

    @abstractmethod
    def inner(self, x: Point, u: Tangent, v: Tangent) -> Any:
        """The metric ``⟨u, v⟩_x`` (one value per point of a batch)."""

    def norm(self, x: Point, v: Tangent) -> Any:
        """``‖v‖_x = √⟨v, v⟩_x``."""
        return np.sqrt(self.inner(x, v, v))

    def total_inner(self, x: Point, u: Tangent, v: Tangent) -> float:
        """``Σ_b ⟨u_b, v_b⟩_{x_b}``: the metric summed over any batch, as a float — the
        scalar product of the optimizers, for which a batch of points is one point of a
        power manifold.

        The default sums :meth:`inner`; manifolds whose metric is the Euclidean one of
        their stored coordinates (embedded manifolds, Lie groups in Cartesian tangent
        coordinates) override it by one ``np.vdot`` over all entries, a single BLAS call
        instead of a reduction per batch axis.
        """
        return float(np.sum(self.inner(x, u, v)))

    @abstractmethod
    def proj(self, x: Point, u: Any) -> Tangent:
        """Orthogonal projection of an ambient vector ``u`` onto the tangent space at ``x``."""

    @abstractmethod
    def retr(self, x: Point, v: Tangent) -> Point:
        """Retraction ``R_x(v)``: ``R_x(0) = x`` and ``d/dt R_x(t v)|₀ = v``."""

    def random_point(self, rng: np.random.Generator | int | None = None) -> Point:
        """A random point (uniform where the manifold is compact)."""
        return self._random_point(np.random.default_rng(rng), ())

    @abstractmethod
    def _random_point(self, rng: np.random.Generator, batch: tuple[int, ...]) -> Point:
        """Random points with leading batch axes ``batch``."""

    @abstractmethod
    def random_tangent(self, x: Point, rng: np.random.Generator | int | None = None) -> Tangent:
        """A random tangent vector at ``x`` with unit norm (per point of a batch)."""

    @abstractmethod
    def zero_vector(self, x: Point) -> Tangent:
        """The zero tangent vector at ``x``."""

    tangent_ndim: int = 1
    """Number of trailing axes of one point's tangent vector (batch axes precede them)."""

    def scale(self, v: Tangent, s: Any) -> Tangent:
        """``s·v`` with one scalar per point of a batch (``s`` has the batch shape)."""
        s = np.asarray(s, dtype=np.float64)
        return v * s.reshape(s.shape + (1,) * self.tangent_ndim)

    def unit(self, x: Point, v: Tangent) -> Tangent:
        """``v / ‖v‖_x`` per point (zero vectors stay zero)."""
        n = np.asarray(self.norm(x, v))
        return self.scale(v, np.where(n > 0, 1.0 / np.where(n > 0, n, 1.0), 0.0))

    def to_ambient(self, x: Point, v: Tangent) -> Any:
        """The tangent vector ``v`` as a vector of the embedding space (the identity
        for embedded manifolds; ``X·τ^`` for Lie groups in tangent coordinates).
        Euclidean Hessians are evaluated along this direction."""
        return v

    @abstractmethod
    def check_point(self, x: Point, name: str = "x") -> None:
        """Raise a ``ValueError`` subclass unless ``x`` is a finite point of this manifold
        (leading batch axes allowed)."""

    @abstractmethod
    def batch_shape_of(self, x: Point) -> tuple[int, ...]:
        """The leading batch axes of a (batch of) point(s)."""

    # ---- optional ----------------------------------------------------------------

    def _missing(self, op: str) -> MissingOperationError:
        return MissingOperationError(f"{self!r} does not implement {op}")

    def egrad2rgrad(self, x: Point, egrad: Any) -> Tangent:
        """Riemannian gradient from the Euclidean gradient ``egrad`` of a smooth
        extension of the cost to the embedding space."""
        raise self._missing("egrad2rgrad")

    def ehess2rhess(self, x: Point, egrad: Any, ehess: Any, v: Tangent) -> Tangent:
        """Riemannian Hessian applied to ``v`` from the Euclidean gradient and the
        Euclidean Hessian applied to ``to_ambient(x, v)``."""
        raise self._missing("ehess2rhess")

    def exp(self, x: Point, v: Tangent) -> Point:
        """Exponential map."""
        raise self._missing("exp")

    def log(self, x: Point, y: Point) -> Tangent:
        """Logarithm: the tangent ``v`` at ``x`` with ``exp(x, v) = y``."""
        raise self._missing("log")

    def transp(self, x: Point, y: Point, v: Tangent) -> Tangent:
        """Vector transport of ``v`` from the tangent space at ``x`` to that at ``y``."""
        raise self._missing("transp")

    def dist(self, x: Point, y: Point) -> Any:
        """Riemannian distance."""
        raise self._missing("dist")

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"
