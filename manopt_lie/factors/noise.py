"""Gaussian noise models that whiten residuals and Jacobians, vectorized over edges.

A factor's residual ``r`` (``k`` entries per edge) is modelled as ``r ~ N(0, Σ)``, so its
negative log-likelihood is ``½ rᵀ Ω r`` with the information ``Ω = Σ⁻¹``. A noise model
holds a square root ``R`` of the information, ``RᵀR = Ω``, computed once at construction,
and *whitens*

    r ↦ R r,        J ↦ R J,

so that ``‖R r‖² = rᵀ Ω r`` and the least-squares machinery sees unit noise. The models
follow GTSAM's ``noiseModel`` family:

=========================  ======================  ====================================
model                      given                   ``R``
=========================  ======================  ====================================
``Information(Ω)``         ``Ω``                   ``Lᵀ``, ``Ω = L Lᵀ`` (Cholesky)
``Covariance(Σ)``          ``Σ``                   ``C⁻¹``, ``Σ = C Cᵀ`` (Cholesky)
``Diagonal(σ)``            ``σ₁ … σ_k``            ``diag(1/σ)``
``Isotropic(σ, k)``        ``σ``                   ``I/σ``
``Unit(k)``                —                       ``I``
=========================  ======================  ====================================

``Information(Σ⁻¹)`` and ``Covariance(Σ)`` whiten to residuals that differ by an
orthogonal factor (``Lᵀ`` and ``C⁻¹`` are two square roots of the same ``Ω``): the cost,
the gradient ``JᵀΩr`` and the Gauss-Newton matrix ``JᵀΩJ`` are the same, and so is every
robust loss, which sees only ``‖R r‖²``. (GTSAM's ``Covariance`` takes the same ``C⁻¹``.)

Each model is either **shared** by all edges (``Ω`` of shape ``(k, k)``, ``σ`` of shape
``(k,)`` or a scalar) or given **per edge** (``(m, k, k)``, ``(m, k)``, ``(m,)``), and a
factor checks the model against its ``m`` edges and residual dimension ``k``.

Invalid models raise a :class:`NoiseModelError` (a ``ValueError``) naming the edges:
wrong shapes (:class:`NoiseShapeError`, also a :class:`~manopt_lie.errors.ShapeError`),
non-finite entries (:class:`NonFiniteNoiseError`, also a
:class:`~manopt_lie.errors.NonFiniteError`), matrices that are not symmetric positive
definite or sigmas that are not positive (:class:`IndefiniteNoiseError`, also an
:class:`~manopt_lie.errors.IndefiniteMatrixError`). Symmetry is checked to
``max|Ω − Ωᵀ| ≤ 1e-9·max|Ω|`` and the symmetric part is used. Zero sigmas (GTSAM's
*constrained* models) are refused: hold such variables fixed instead.
"""

from __future__ import annotations

from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import IndefiniteMatrixError, NonFiniteError, ShapeError

__all__ = [
    "NoiseModel",
    "Gaussian",
    "Information",
    "Covariance",
    "Diagonal",
    "Isotropic",
    "Unit",
    "NoiseModelError",
    "NoiseShapeError",
    "NonFiniteNoiseError",
    "IndefiniteNoiseError",
]

FloatArray = NDArray[np.float64]

SYMMETRY_RTOL = 1e-9


class NoiseModelError(ValueError):
    """A noise model that cannot be used (the message names the model and the edges)."""


class NoiseShapeError(NoiseModelError, ShapeError):
    """A noise model of the wrong shape, or of the wrong size for its factor."""


class NonFiniteNoiseError(NoiseModelError, NonFiniteError):
    """A noise model with ``nan`` or ``inf`` entries (or whose square root overflows)."""


class IndefiniteNoiseError(NoiseModelError, IndefiniteMatrixError):
    """A matrix that is not symmetric positive definite, or a sigma that is not positive."""


def _which(bad: NDArray[np.bool_], shared: bool) -> str:
    """``"edges 3, 7"`` for per-edge models, ``"the shared model"`` otherwise."""
    if shared:
        return "the shared model"
    edges = np.flatnonzero(bad)
    listed = ", ".join(str(e) for e in edges[:10]) + (f" and {edges.size - 10} more" if edges.size > 10 else "")
    return f"edge {listed}" if edges.size == 1 else f"edges {listed}"


def _array(value: ArrayLike, owner: str) -> FloatArray:
    try:
        return np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise NoiseShapeError(f"{owner}: expected a float array, got {type(value).__name__}: {err}") from None


def _finite(a: FloatArray, owner: str, shared: bool, axes: tuple[int, ...]) -> None:
    bad = ~np.isfinite(a).all(axis=axes) if axes else ~np.isfinite(a)
    if np.any(bad):
        raise NonFiniteNoiseError(f"{owner}: non-finite entries in {_which(np.atleast_1d(bad), shared)}")


class NoiseModel:
    """Gaussian noise ``N(0, Σ)`` on ``k``-vector residuals, shared or one per edge.

    Attributes
    ----------
    dim : int
        The residual dimension ``k``.
    edges : int or None
        The number of edges ``m`` of a per-edge model; ``None`` for a shared one.
    """

    __slots__ = ("dim", "edges")
    dim: int
    edges: int | None

    def whiten(self, r: FloatArray) -> FloatArray:
        """``R r`` for residuals ``(m, k)``."""
        raise NotImplementedError

    def whiten_jacobian(self, j: FloatArray) -> FloatArray:
        """``R J`` for Jacobians ``(m, k, d)``."""
        raise NotImplementedError

    @property
    def sqrt_information(self) -> FloatArray:
        """``R`` with ``RᵀR = Ω``: ``(k, k)`` if shared, else ``(m, k, k)``."""
        raise NotImplementedError

    @property
    def common_sqrt_information(self) -> FloatArray | None:
        """The one ``R`` (``(k, k)``) that whitens every edge — a shared model's, or the matrix that
        every edge of a per-edge model repeats — else ``None``. A kernel given it whitens all
        edges by one product instead of one per edge."""
        r = self.sqrt_information
        return r if r.ndim == 2 else None

    @property
    def information(self) -> FloatArray:
        """``Ω = RᵀR``: ``(k, k)`` if shared, else ``(m, k, k)``."""
        r = self.sqrt_information
        return np.swapaxes(r, -1, -2) @ r

    @property
    def covariance(self) -> FloatArray:
        """``Σ = Ω⁻¹ = R⁻¹R⁻ᵀ``: ``(k, k)`` if shared, else ``(m, k, k)``."""
        # cast: NumPy's stubs type linalg results floating[Any]; float64 in, float64 out.
        r_inv = cast(FloatArray, np.linalg.inv(self.sqrt_information))
        return r_inv @ np.swapaxes(r_inv, -1, -2)

    def squared_mahalanobis(self, r: FloatArray) -> FloatArray:
        """``rᵀ Ω r = ‖R r‖²`` per edge, ``(m,)``."""
        w = self.whiten(np.asarray(r, dtype=np.float64))
        return np.einsum("...i,...i->...", w, w)

    def bind(self, m: int, k: int, name: str) -> NoiseModel:
        """``self``, checked for a factor ``name`` of ``m`` edges with ``k``-vector residuals.

        Raises
        ------
        NoiseShapeError
            If the dimension is not ``k`` or a per-edge model does not have ``m`` edges.
        """
        if self.dim != k:
            raise NoiseShapeError(
                f"{name}: a noise model of dimension {self.dim} for residuals of dimension {k} ({self!r})"
            )
        if self.edges is not None and self.edges != m:
            raise NoiseShapeError(f"{name}: a noise model for {self.edges} edges on a factor of {m} edges")
        return self

    def __repr__(self) -> str:
        size = "shared" if self.edges is None else f"{self.edges} edges"
        return f"{type(self).__name__}(dim={self.dim}, {size})"


class Gaussian(NoiseModel):
    """A full Gaussian model from a square root ``R`` of the information (``RᵀR = Ω``).

    Build it with :class:`Information` or :class:`Covariance`; this base takes ``R`` as
    given (``(k, k)`` or ``(m, k, k)``, assumed invertible).
    """

    __slots__ = ("_one", "_r")

    def __init__(self, sqrt_information: ArrayLike) -> None:
        r = _array(sqrt_information, type(self).__name__)
        if r.ndim not in (2, 3) or r.shape[-1] != r.shape[-2] or r.shape[-1] == 0:
            raise NoiseShapeError(f"{type(self).__name__}: expected a (k, k) or (m, k, k) matrix, got {r.shape}")
        _finite(r, type(self).__name__, r.ndim == 2, (-2, -1) if r.ndim == 3 else ())
        r.flags.writeable = False
        self._r = r
        # Per-edge matrices that are all one (synthetic graphs, smallGrid3D): that one, kept for the products.
        self._one = r if r.ndim == 2 else r[0] if len(r) and (r == r[0]).all() else None
        self.dim = r.shape[-1]
        self.edges = r.shape[0] if r.ndim == 3 else None

    def whiten(self, r: FloatArray) -> FloatArray:
        if self._one is not None:
            return r @ self._one.T
        return np.einsum("eij,ej->ei", self._r, r)

    def whiten_jacobian(self, j: FloatArray) -> FloatArray:
        return (self._r if self._one is None else self._one) @ j

    @property
    def common_sqrt_information(self) -> FloatArray | None:
        return self._one

    @property
    def sqrt_information(self) -> FloatArray:
        return self._r


def _spd_cholesky(a: FloatArray, owner: str, what: str) -> FloatArray:
    """The lower Cholesky factor of each (checked) symmetric positive definite matrix."""
    if a.ndim not in (2, 3) or a.shape[-1] != a.shape[-2] or a.shape[-1] == 0:
        raise NoiseShapeError(f"{owner}: expected a {what} of shape (k, k) or (m, k, k), got {a.shape}")
    shared = a.ndim == 2
    axes = (-2, -1)
    _finite(a, owner, shared, axes if not shared else ())
    scale = np.max(np.abs(a), axis=axes)
    with np.errstate(over="ignore"):  # entries near the float range: a skew of inf is still > 1e-9·scale
        skew = np.max(np.abs(a - np.swapaxes(a, -1, -2)), axis=axes)
    asymmetric = skew > SYMMETRY_RTOL * scale
    if np.any(asymmetric):
        raise IndefiniteNoiseError(
            f"{owner}: the {what} of {_which(np.atleast_1d(asymmetric), shared)} is not symmetric "
            f"(max|A − Aᵀ| > {SYMMETRY_RTOL:g}·max|A|)"
        )
    sym = 0.5 * a + 0.5 * np.swapaxes(a, -1, -2)  # (a + aᵀ)/2 would overflow near the float range
    try:
        lower = cast(FloatArray, np.linalg.cholesky(sym))  # cast: as in covariance (float64 in, out)
    except np.linalg.LinAlgError:
        lower = None
    if lower is not None:
        overflow = ~np.isfinite(lower).all(axis=axes)
        if np.any(overflow):
            raise NonFiniteNoiseError(
                f"{owner}: the square root of {_which(np.atleast_1d(overflow), shared)} overflows the float range"
            )
        return lower
    # Which ones: eigenvalues of the max-abs-scaled matrices (no overflow), only on failure.
    safe = np.where(scale > 0, scale, 1.0)
    ratio = np.atleast_1d(np.linalg.eigvalsh(sym / safe[..., None, None])[..., 0])
    bad = ratio <= a.shape[-1] * np.finfo(float).eps  # indefinite, singular, or so to round-off
    if not np.any(bad):  # Cholesky refused a matrix just above that line: name the worst one
        bad = ratio == ratio.min()
    with np.errstate(over="ignore"):
        smallest = float(ratio[np.argmax(bad)] * np.atleast_1d(safe)[np.argmax(bad)])
    raise IndefiniteNoiseError(
        f"{owner}: the {what} of {_which(bad, shared)} is not positive definite (smallest eigenvalue {smallest:.3g})"
    )


class Information(Gaussian):
    """Gaussian noise given by its information matrix ``Ω`` (GTSAM's ``Gaussian.Information``).

    Parameters
    ----------
    information : array ``(k, k)`` (shared) or ``(m, k, k)`` (per edge)
        Symmetric positive definite; ``R = Lᵀ`` with ``Ω = L Lᵀ`` (Cholesky), so
        ``‖R r‖² = rᵀΩr``. A g2o edge's information matrix, for instance (already in the
        ``(ρ, θ)`` order of the tangents here).

    Raises
    ------
    NoiseShapeError, NonFiniteNoiseError, IndefiniteNoiseError
        Naming the edges.
    """

    __slots__ = ()

    def __init__(self, information: ArrayLike) -> None:
        lower = _spd_cholesky(_array(information, "Information"), "Information", "information matrix")
        super().__init__(np.swapaxes(lower, -1, -2))


class Covariance(Gaussian):
    """Gaussian noise given by its covariance ``Σ`` (GTSAM's ``Gaussian.Covariance``).

    Parameters
    ----------
    covariance : array ``(k, k)`` (shared) or ``(m, k, k)`` (per edge)
        Symmetric positive definite; ``R = C⁻¹`` with ``Σ = C Cᵀ`` (Cholesky), so
        ``RᵀR = C⁻ᵀC⁻¹ = Σ⁻¹`` — no explicit inverse of ``Σ``.

    Raises
    ------
    NoiseShapeError, NonFiniteNoiseError, IndefiniteNoiseError
        Naming the edges.
    """

    __slots__ = ()

    def __init__(self, covariance: ArrayLike) -> None:
        lower = _spd_cholesky(_array(covariance, "Covariance"), "Covariance", "covariance")
        with np.errstate(over="ignore"):
            r = np.linalg.inv(lower)
        bad = ~np.isfinite(r).all(axis=(-2, -1))
        if np.any(bad):
            which = _which(np.atleast_1d(bad), lower.ndim == 2)
            raise NonFiniteNoiseError(f"Covariance: the information of {which} overflows the float range")
        super().__init__(r)


class Diagonal(NoiseModel):
    """Independent noise with standard deviations ``σ`` (GTSAM's ``Diagonal.Sigmas``):
    ``R = diag(1/σ)``, ``Ω = diag(1/σ²)``.

    Parameters
    ----------
    sigmas : array ``(k,)`` (shared) or ``(m, k)`` (per edge)
        Positive and finite, in the order of the factor's residual.

    Raises
    ------
    NoiseShapeError, NonFiniteNoiseError, IndefiniteNoiseError
        Naming the edges.
    """

    __slots__ = ("_inv", "_sigmas")
    _sigmas: FloatArray  # σ, trailing axis k (or 1 for isotropic models)
    _inv: FloatArray  # 1/σ, likewise

    def __init__(self, sigmas: ArrayLike) -> None:
        s = _array(sigmas, type(self).__name__)
        if s.ndim not in (1, 2) or s.shape[-1] == 0:
            raise NoiseShapeError(f"{type(self).__name__}: expected sigmas of shape (k,) or (m, k), got {s.shape}")
        self._set(s, s.shape[-1], s.ndim == 1)

    def _set(self, s: FloatArray, dim: int, shared: bool) -> None:
        owner = type(self).__name__
        _finite(s, owner, shared, () if shared else (-1,))
        bad = ~(s > 0).all(axis=-1) if s.ndim else ~np.atleast_1d(s > 0)
        if np.any(bad):
            which = _which(np.atleast_1d(bad), shared)
            raise IndefiniteNoiseError(f"{owner}: sigmas must be positive; not so in {which}")
        with np.errstate(over="ignore"):
            inv = 1.0 / s
        if not np.isfinite(inv).all():
            raise NonFiniteNoiseError(f"{owner}: 1/σ overflows the float range (sigmas below {np.min(s):.3g})")
        s = s.copy()
        inv.flags.writeable = s.flags.writeable = False
        self._inv, self._sigmas = inv, s
        self.dim = dim
        self.edges = None if shared else s.shape[0]

    @property
    def sigmas(self) -> FloatArray:
        """``σ``: ``(k,)`` if shared, else ``(m, k)``."""
        shape = (self.dim,) if self.edges is None else (self.edges, self.dim)
        return np.broadcast_to(self._sigmas, shape).copy()

    def whiten(self, r: FloatArray) -> FloatArray:
        return r / self._sigmas

    def whiten_jacobian(self, j: FloatArray) -> FloatArray:
        return j / self._sigmas[..., :, None]

    @property
    def sqrt_information(self) -> FloatArray:
        return np.einsum("...i,ij->...ij", np.broadcast_to(self._inv, self.sigmas.shape), np.eye(self.dim))


class Isotropic(Diagonal):
    """The same standard deviation ``σ`` on all ``k`` entries (GTSAM's ``Isotropic.Sigma``):
    ``R = I/σ``.

    Parameters
    ----------
    sigma : float (shared) or array ``(m,)`` (per edge)
        Positive and finite.
    dim : int
        The residual dimension ``k``.
    """

    __slots__ = ()

    def __init__(self, sigma: ArrayLike, dim: int) -> None:
        if isinstance(dim, bool) or not isinstance(dim, (int, np.integer)) or dim < 1:
            raise NoiseShapeError(f"Isotropic: dim must be a positive integer, got {dim!r}")
        s = _array(sigma, "Isotropic")
        if s.ndim > 1:
            raise NoiseShapeError(f"Isotropic: expected a scalar sigma or one per edge (m,), got {s.shape}")
        self._set(s[..., None] if s.ndim else s.reshape(1), int(dim), s.ndim == 0)


class Unit(NoiseModel):
    """Unit noise, ``Σ = I`` (GTSAM's ``Unit.Create``): residuals as they are."""

    __slots__ = ()

    def __init__(self, dim: int) -> None:
        if isinstance(dim, bool) or not isinstance(dim, (int, np.integer)) or dim < 1:
            raise NoiseShapeError(f"Unit: dim must be a positive integer, got {dim!r}")
        self.dim, self.edges = int(dim), None

    def whiten(self, r: FloatArray) -> FloatArray:
        return r

    def whiten_jacobian(self, j: FloatArray) -> FloatArray:
        return j

    @property
    def sqrt_information(self) -> FloatArray:
        return np.eye(self.dim)


def as_noise_model(noise: NoiseModel | None, m: int, k: int, name: str) -> NoiseModel:
    """``noise`` checked for a factor of ``m`` edges and ``k``-vector residuals; ``None`` is
    :class:`Unit` noise."""
    if noise is None:
        return Unit(k)
    if not isinstance(noise, NoiseModel):
        raise TypeError(
            f"{name}: noise must be a NoiseModel (Information, Covariance, Diagonal, Isotropic, Unit) or None, "
            f"got {type(noise).__name__}"
        )
    return noise.bind(m, k, name)
