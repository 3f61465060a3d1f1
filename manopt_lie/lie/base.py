"""The generic Lie group: the deduced API written once over each group's kernels.

A group subclass supplies the *minimal* kernels on raw arrays (``_exp``,
``_log``, ``_compose``, ``_inverse``, ``_act``, ``_act_jac``, ``_adjoint``,
``_jr``, ``_jr_inv``, ``_hat``, ``_vee``, ``_identity``, ``_random``,
``_validated``, ``_project``); this base derives everything else — ``rplus``,
``lplus``, ``rminus``, ``lminus``, ``between``, ``jl``, ``jl_inv``, ``dist``,
``interpolate`` and all Jacobians — from the blocks of CONVENTIONS §4 (Solà et
al., arXiv:1812.01537, eqs. 62–83).

Every ``jac=True`` returns *right* (local) Jacobians (CONVENTIONS §4),
``J = lim_{τ→0} (f(X ⊕ τ) ⊖ f(X)) / τ``, ``X ⊕ τ = X·Exp(τ)``, vectors perturbed
additively — ``lplus``/``lminus`` too, which also give *left* (global-frame) ones
with ``frame="left"``, ``J = lim (f(τ ⊕ X) ⊖ₗ f(X)) / τ``, ``τ ⊕ X = Exp(τ)·X``:
``J_left = Ad_{f(X)} · J_right · Ad_X⁻¹`` (``Ad`` of a vector space is ``I``).
Jacobians carry the batch axes of the result: shape ``(..., m, n)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar, Literal, TypeVar, overload

import numpy as np
from numpy.typing import ArrayLike

from ..errors import ShapeError
from . import _matrix
from ._blocks import blockwise
from ._checks import FloatArray, as_batch, broadcast_batch

G = TypeVar("G", bound="LieGroup")
Jac = FloatArray
Frame = Literal["right", "left"]
_Diff = tuple[FloatArray, Jac, Jac]  # a tangent difference and its two Jacobians


def _left(frame: str) -> bool:
    """Whether ``frame`` asks for left Jacobians; ``ValueError`` unless it is ``"right"`` or ``"left"``."""
    if frame not in ("right", "left"):
        raise ValueError(f"frame must be 'right' or 'left', got {frame!r}")
    return frame == "left"


def _bcast(j: FloatArray, batch: tuple[int, ...]) -> FloatArray:
    """``j`` broadcast to ``batch + j.shape[-2:]``, as a writable array."""
    shape = batch + j.shape[-2:]
    return j if j.shape == shape else np.array(np.broadcast_to(j, shape))


def _eye(n: int, batch: tuple[int, ...]) -> FloatArray:
    return np.array(np.broadcast_to(np.eye(n), batch + (n, n)))


def _unsupplied(*_: Any) -> Any:
    raise NotImplementedError("a kernel this group does not supply")


class LieGroup:
    """A batch of elements of a matrix Lie group, wrapping one read-only array.

    Class attributes
    ----------------
    dim : int
        Dimension of the tangent space (degrees of freedom).
    storage_shape : tuple of int
        Trailing shape of the stored array for one element.
    point_dim : int
        Dimension of the points the group acts on.
    """

    __slots__ = ("_data",)
    dim: ClassVar[int]
    storage_shape: ClassVar[tuple[int, ...]]
    point_dim: ClassVar[int]
    _data: FloatArray

    # ---- construction -------------------------------------------------------------

    def __init__(self, data: ArrayLike) -> None:
        """Wrap an array of elements, checking shape, finiteness and membership
        (as :meth:`from_matrix` with its defaults).

        The array is copied. Use :meth:`from_matrix` to choose the tolerance
        or to project onto the group.
        """
        a = self._checked(data, project=False, tol=_matrix.DEFAULT_TOL, name=type(self).__name__)
        object.__setattr__(self, "_data", a.copy() if np.may_share_memory(a, data) else a)
        self._data.flags.writeable = False

    @classmethod
    def _wrap(cls: type[G], data: FloatArray) -> G:
        """Wrap a kernel's output without checks or copies (internal)."""
        out = object.__new__(cls)
        data.flags.writeable = False
        object.__setattr__(out, "_data", data)
        return out

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(f"{type(self).__name__} elements are immutable")

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self)._wrap, (np.array(self._data),))

    @classmethod
    def _checked(cls, data: ArrayLike, *, project: bool, tol: float, name: str) -> FloatArray:
        a = as_batch(data, cls.storage_shape, name)
        return cls._project(a) if project else cls._validated(a, tol, name)

    @classmethod
    def from_matrix(cls: type[G], m: ArrayLike, *, project: bool = False, tol: float = _matrix.DEFAULT_TOL) -> G:
        """Element(s) from matrices ``(..., k, k)`` (``k`` = :meth:`as_matrix` size).

        A matrix accepted within ``tol`` is re-orthonormalized (two Newton steps
        toward its polar factor), so stored rotations are orthonormal to machine
        precision.

        Parameters
        ----------
        m
            Rotation or homogeneous matrices, any leading batch axes.
        project
            Snap each matrix to the nearest group element (rotation block by
            SVD, ``U diag(1, …, det UVᵀ) Vᵀ``; homogeneous last row reset)
            instead of validating it.
        tol
            Largest accepted entry of ``|RᵀR − I|`` and of the last-row error.

        Raises
        ------
        ShapeError, NonFiniteError, NotInGroupError
        """
        a = cls._checked(cls._matrix_to_data(m), project=project, tol=tol, name="from_matrix")
        return cls._wrap(a.copy() if np.may_share_memory(a, m) else a)

    @classmethod
    def _matrix_to_data(cls, m: ArrayLike) -> ArrayLike:
        return m

    def validate(self: G, tol: float = _matrix.DEFAULT_TOL, name: str | None = None) -> G:
        """``self``, after checking its stored array as :meth:`from_matrix` does: finite, and in
        the group within ``tol`` — for elements that did not come through a constructor
        (``check_point`` of a manifold, data unpickled or wrapped by hand).

        Raises
        ------
        NonFiniteError, NotInGroupError
        """
        name = name or type(self).__name__
        self._verify(as_batch(self._data, self.storage_shape, name), tol, name)
        return self

    @classmethod
    def _verify(cls, a: FloatArray, tol: float, name: str) -> None:
        """Raise unless ``a`` is in the group within ``tol``: :meth:`_validated` without its polish
        (groups whose polish is a separate step say so by overriding this)."""
        cls._validated(a, tol, name)

    def as_matrix(self) -> FloatArray:
        """The matrix form, shape ``(..., k, k)`` (a read-only view where stored as such)."""
        return self._data

    @property
    def data(self) -> FloatArray:
        """The stored array, shape ``batch_shape + storage_shape`` (read-only)."""
        return self._data

    @classmethod
    def identity(cls: type[G], batch_shape: tuple[int, ...] = ()) -> G:
        """The identity element, broadcast to ``batch_shape``."""
        return cls._wrap(cls._identity(tuple(batch_shape)))

    @classmethod
    def random(cls: type[G], rng: np.random.Generator | int | None, batch_shape: tuple[int, ...] = ()) -> G:
        """Random elements: Haar-uniform rotations; translations ``~ N(0, I)``.

        ``rng`` is a ``numpy.random.Generator`` or a seed (never the global RNG).
        """
        return cls._wrap(cls._random(np.random.default_rng(rng), tuple(batch_shape)))

    # ---- batch handling -----------------------------------------------------------

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """The leading batch axes: the stored array's shape without :attr:`storage_shape`."""
        return self._data.shape[: self._data.ndim - len(self.storage_shape)]

    def __len__(self) -> int:
        if not self.batch_shape:
            raise TypeError(f"len() of an unbatched {type(self).__name__} element")
        return self.batch_shape[0]

    def __getitem__(self: G, index: Any) -> G:
        """Index the batch axes only, as NumPy would index an array of that shape."""
        if type(index) is np.ndarray and index.dtype.kind in "iu" and self._data.ndim > len(self.storage_shape):
            # An integer array indexes the first batch axis alone (a factor's gather of its
            # variables): no probe for indices past the batch axes.
            return self._wrap(self._data[index])
        idx = index if isinstance(index, tuple) else (index,)
        np.broadcast_to(np.empty(()), self.batch_shape)[idx]  # IndexError past the batch axes
        tail = (slice(None),) * len(self.storage_shape) if any(i is Ellipsis for i in idx) else (Ellipsis,)
        return self._wrap(self._data[idx + tail])

    def reshape(self: G, batch_shape: tuple[int, ...]) -> G:
        """The same elements with the batch axes reshaped to ``batch_shape`` (as ``ndarray.reshape``)."""
        return self._wrap(self._data.reshape(tuple(batch_shape) + self.storage_shape))

    def broadcast_to(self: G, batch_shape: tuple[int, ...]) -> G:
        """The elements broadcast to the batch shape ``batch_shape`` (a read-only view, as ``np.broadcast_to``)."""
        return self._wrap(np.broadcast_to(self._data, tuple(batch_shape) + self.storage_shape))

    @classmethod
    def _batch_axis(cls, axis: int) -> int:
        return axis - len(cls.storage_shape) if axis < 0 else axis

    @classmethod
    def stack(cls: type[G], elements: Sequence[G], axis: int = 0) -> G:
        """Stack elements of equal batch shape along a new batch axis."""
        return cls._join(np.stack, elements, axis)

    @classmethod
    def concatenate(cls: type[G], elements: Sequence[G], axis: int = 0) -> G:
        """Join elements along an existing batch axis."""
        if any(not e.batch_shape for e in elements):
            raise ShapeError("concatenate: elements need at least one batch axis")
        return cls._join(np.concatenate, elements, axis)

    @classmethod
    def _join(cls: type[G], join: Any, elements: Sequence[G], axis: int) -> G:
        arrays = [cls._same(e)._data for e in elements]
        try:
            return cls._wrap(join(arrays, axis=cls._batch_axis(axis)))
        except ValueError as err:
            raise ShapeError(f"{join.__name__}: batch shapes {[e.batch_shape for e in elements]}: {err}") from None

    def _blocks(self, kernel: Any, *elements: FloatArray) -> FloatArray:
        """``kernel(*elements)`` on stored arrays, evaluated block by block (see ``_blocks``)."""
        return blockwise(kernel, elements, (len(self.storage_shape),) * len(elements))

    def _operand(self, other: Any) -> FloatArray:
        """The array of a second operand: same group, batch shape broadcastable with ours."""
        broadcast_batch(self.batch_shape, self._same(other).batch_shape)
        return other._data

    @classmethod
    def _same(cls: type[G], other: Any) -> G:
        if type(other) is not cls:
            raise TypeError(f"expected a {cls.__name__} element, got {type(other).__name__}")
        return other

    def __repr__(self) -> str:
        if self._data.size <= 16:
            body = np.array2string(self._data, precision=4, separator=", ", prefix="    ")
            return f"{type(self).__name__}(batch_shape={self.batch_shape},\n    {body})"
        return f"{type(self).__name__}(batch_shape={self.batch_shape})"

    # ---- Lie algebra --------------------------------------------------------------

    @classmethod
    def _tangent(cls, tau: ArrayLike, name: str = "tau") -> FloatArray:
        return as_batch(tau, (cls.dim,), name)

    @staticmethod
    def _tangent_map(kernel: Any, tau: FloatArray) -> FloatArray:
        """``kernel(tau)`` for a kernel of tangents, evaluated block by block."""
        return blockwise(kernel, (tau,), (1,))

    @classmethod
    def hat(cls, tau: ArrayLike) -> FloatArray:
        """``τ^``: tangent coordinates ``(..., dim)`` to the Lie algebra matrix."""
        return cls._hat(cls._tangent(tau))

    @classmethod
    def vee(cls, m: ArrayLike) -> FloatArray:
        """``M^∨``: Lie algebra matrices to tangent coordinates (inverse of :meth:`hat`)."""
        return cls._vee(as_batch(m, cls._hat(np.zeros(cls.dim)).shape, "m"))

    @classmethod
    def jr(cls, tau: ArrayLike) -> FloatArray:
        """Right Jacobian: ``Exp(τ + δ) ≈ Exp(τ) Exp(Jr(τ) δ)`` (eqs. 67–68), ``(..., dim, dim)``."""
        return cls._tangent_map(cls._jr, cls._tangent(tau))

    @classmethod
    def jl(cls, tau: ArrayLike) -> FloatArray:
        """Left Jacobian: ``Exp(τ + δ) ≈ Exp(Jl(τ) δ) Exp(τ)``; ``Jl(τ) = Jr(−τ)`` (eqs. 71–72, 76)."""
        return cls._tangent_map(cls._jr, -cls._tangent(tau))

    @classmethod
    def jr_inv(cls, tau: ArrayLike) -> FloatArray:
        """``Jr(τ)⁻¹`` in closed form."""
        return cls._tangent_map(cls._jr_inv, cls._tangent(tau))

    @classmethod
    def jl_inv(cls, tau: ArrayLike) -> FloatArray:
        """``Jl(τ)⁻¹ = Jr(−τ)⁻¹``."""
        return cls._tangent_map(cls._jr_inv, -cls._tangent(tau))

    @classmethod
    def ad(cls, tau: ArrayLike) -> FloatArray:
        """Small adjoint ``ad_τ``, ``ad_τ σ = [τ^, σ^]^∨`` (``= d/dt Ad_{Exp(tτ)}`` at 0; Solà eq. 32),
        ``(..., dim, dim)``."""
        return cls._tangent_map(cls._ad, cls._tangent(tau))

    @classmethod
    def _ad(cls, tau: FloatArray) -> FloatArray:
        """Generic ``ad``: column ``k`` is ``[τ^, E_k]^∨`` for the generators ``E_k = hat(e_k)``."""
        basis = cls._hat(np.eye(cls.dim))
        a = cls._hat(tau)[..., None, :, :]
        return np.swapaxes(cls._vee(a @ basis - basis @ a), -1, -2)

    @classmethod
    def bch(cls, tau: ArrayLike, sigma: ArrayLike, order: int = 2) -> FloatArray:
        """Baker–Campbell–Hausdorff: ``Log(Exp(τ)·Exp(σ)) ≈ τ + σ + ½ ad_τ σ``, with ``order=3``
        also ``+ (ad_τ ad_τ σ + ad_σ ad_σ τ)/12``; the error is ``O(|τ|, |σ|)^{order+1}``."""
        if order not in (1, 2, 3):
            raise ValueError(f"bch: order must be 1, 2 or 3, got {order!r}")
        t, s = cls._tangent(tau), cls._tangent(sigma, "sigma")
        out = t + s
        if order >= 2:
            ts = _matrix.matvec(cls.ad(t), s)
            out = out + 0.5 * ts
            if order == 3:
                out = out + (_matrix.matvec(cls.ad(t), ts) - _matrix.matvec(cls.ad(s), ts)) / 12.0
        return out

    # ---- minimal API --------------------------------------------------------------

    @overload
    @classmethod
    def exp(cls: type[G], tau: ArrayLike, jac: Literal[False] = ...) -> G: ...
    @overload
    @classmethod
    def exp(cls: type[G], tau: ArrayLike, jac: Literal[True]) -> tuple[G, Jac]: ...
    @classmethod
    def exp(cls: type[G], tau: ArrayLike, jac: bool = False) -> G | tuple[G, Jac]:
        """``Exp(τ) = exp(τ^)``, batch shape ``tau.shape[:-1]``; Jacobian ``Jr(τ)``."""
        t = cls._tangent(tau)
        x = cls._wrap(blockwise(cls._exp, (t,), (1,)))
        return (x, cls._tangent_map(cls._jr, t)) if jac else x

    @overload
    def log(self, jac: Literal[False] = ...) -> FloatArray: ...
    @overload
    def log(self, jac: Literal[True]) -> tuple[FloatArray, Jac]: ...
    def log(self, jac: bool = False) -> FloatArray | tuple[FloatArray, Jac]:
        """``Log(X)``, shape ``(..., dim)``; Jacobian ``Jr(Log X)⁻¹`` (eq. 79)."""
        tau = self._blocks(self._log, self._data)
        return (tau, self._tangent_map(self._jr_inv, tau)) if jac else tau

    @overload
    def compose(self: G, other: G, jac: Literal[False] = ...) -> G: ...
    @overload
    def compose(self: G, other: G, jac: Literal[True]) -> tuple[G, Jac, Jac]: ...
    def compose(self: G, other: G, jac: bool = False) -> G | tuple[G, Jac, Jac]:
        """``X·Y``; Jacobians ``Ad_Y⁻¹`` wrt ``X`` and ``I`` wrt ``Y`` (eqs. 65–66)."""
        b = self._operand(other)
        z = self._wrap(self._blocks(self._compose, self._data, b))
        if not jac:
            return z
        return z, _bcast(self._adjoint(self._inverse(b)), z.batch_shape), _eye(self.dim, z.batch_shape)

    def __matmul__(self: G, other: G) -> G:
        return self.compose(other)

    @overload
    def inverse(self: G, jac: Literal[False] = ...) -> G: ...
    @overload
    def inverse(self: G, jac: Literal[True]) -> tuple[G, Jac]: ...
    def inverse(self: G, jac: bool = False) -> G | tuple[G, Jac]:
        """``X⁻¹``; Jacobian ``−Ad_X`` (eq. 62)."""
        xi = self._wrap(self._inverse(self._data))
        return (xi, -self._adjoint(self._data)) if jac else xi

    @overload
    def act(self, p: ArrayLike, jac: Literal[False] = ...) -> FloatArray: ...
    @overload
    def act(self, p: ArrayLike, jac: Literal[True]) -> tuple[FloatArray, Jac, Jac]: ...
    def act(self, p: ArrayLike, jac: bool = False) -> FloatArray | tuple[FloatArray, Jac, Jac]:
        """Group action on points ``p`` of shape ``(..., point_dim)``; Jacobians wrt ``X`` and ``p``."""
        pts = as_batch(p, (self.point_dim,), "p")
        batch = broadcast_batch(self.batch_shape, pts.shape[:-1])
        q = blockwise(self._act, (self._data, pts), (len(self.storage_shape), 1))
        if not jac:
            return q
        j_x, j_p = self._act_jac(self._data, pts)
        return q, _bcast(j_x, batch), _bcast(j_p, batch)

    def adjoint(self) -> FloatArray:
        """``Ad_X``, with ``Ad_X τ = (X τ^ X⁻¹)^∨``, shape ``(..., dim, dim)``."""
        return self._adjoint(self._data)

    # ---- deduced API --------------------------------------------------------------

    @overload
    def rplus(self: G, tau: ArrayLike, jac: Literal[False] = ...) -> G: ...
    @overload
    def rplus(self: G, tau: ArrayLike, jac: Literal[True]) -> tuple[G, Jac, Jac]: ...
    def rplus(self: G, tau: ArrayLike, jac: bool = False) -> G | tuple[G, Jac, Jac]:
        """``X ⊕ τ = X·Exp(τ)``; Jacobians ``Ad_{Exp τ}⁻¹`` wrt ``X``, ``Jr(τ)`` wrt ``τ`` (eqs. 80–81)."""
        t = self._tangent(tau)
        broadcast_batch(self.batch_shape, t.shape[:-1])
        if not jac:
            kernel = lambda a, d: self._compose(a, self._exp(d))
            return self._wrap(blockwise(kernel, (self._data, t), (len(self.storage_shape), 1)))
        e = self._exp(t)
        y = self._wrap(self._compose(self._data, e))
        return (
            y,
            _bcast(self._adjoint(self._inverse(e)), y.batch_shape),
            _bcast(self._tangent_map(self._jr, t), y.batch_shape),
        )

    @overload
    def rminus(self, other: LieGroup, jac: Literal[False] = ...) -> FloatArray: ...
    @overload
    def rminus(self, other: LieGroup, jac: Literal[True]) -> _Diff: ...
    def rminus(self, other: LieGroup, jac: bool = False) -> FloatArray | _Diff:
        """``Y ⊖ X = Log(X⁻¹·Y)`` for ``Y = self``, ``X = other``; Jacobians
        ``Jr(τ)⁻¹`` wrt ``Y`` and ``−Jl(τ)⁻¹`` wrt ``X`` (eqs. 82–83)."""
        x = self._operand(other)
        if x.ndim == len(self.storage_shape) and self._data.size >= _matrix.ONE_PRODUCT * x.size:
            # One X against a batch: Log(X⁻¹Y) = Ad_{X⁻¹} Log(Y X⁻¹) (conjugation), whose product
            # has the single factor on the right (one BLAS product, see _matrix.product).
            x_inv = self._inverse(x)
            tau = self._blocks(lambda b: self._log(self._compose(b, x_inv)), self._data) @ self._adjoint(x_inv).T
        else:
            tau = self._blocks(lambda b, a: self._log(self._compose(self._inverse(a), b)), self._data, x)
        if not jac:
            return tau
        return tau, self._tangent_map(self._jr_inv, tau), -self._tangent_map(self._jr_inv, -tau)

    @overload
    def lplus(self: G, tau: ArrayLike, jac: Literal[False] = ..., *, frame: Frame = ...) -> G: ...
    @overload
    def lplus(self: G, tau: ArrayLike, jac: Literal[True], *, frame: Frame = ...) -> tuple[G, Jac, Jac]: ...
    def lplus(self: G, tau: ArrayLike, jac: bool = False, *, frame: Frame = "right") -> G | tuple[G, Jac, Jac]:
        """``Y = τ ⊕ X = Exp(τ)·X``; Jacobians wrt ``X`` and ``τ``: right (default) ``J_X = I``,
        ``J_τ = Ad_Y⁻¹ Jl(τ)``, as ``Exp(τ + δ)·X·Exp(ε) ≈ Y·Exp(ε + Ad_Y⁻¹ Jl(τ) δ)``; ``frame="left"``
        ``J_X = Ad_{Exp τ}``, ``J_τ = Jl(τ)``, as ``Exp(τ + δ)·Exp(ε)·X ≈ Exp(Ad_{Exp τ} ε + Jl(τ) δ)·Y``.
        Raises ``ValueError`` for any other ``frame``."""
        left = _left(frame)
        t = self._tangent(tau)
        broadcast_batch(self.batch_shape, t.shape[:-1])
        if not jac:
            kernel = lambda a, d: self._compose(self._exp(d), a)
            return self._wrap(blockwise(kernel, (self._data, t), (len(self.storage_shape), 1)))
        e = self._exp(t)
        y = self._wrap(self._compose(e, self._data))
        j_t = self._tangent_map(self._jr, -t)  # Jl(τ)
        if left:
            return y, _bcast(self._adjoint(e), y.batch_shape), _bcast(j_t, y.batch_shape)
        return y, _eye(self.dim, y.batch_shape), _bcast(self._adjoint(self._inverse(y._data)) @ j_t, y.batch_shape)

    @overload
    def lminus(self, other: LieGroup, jac: Literal[False] = ..., *, frame: Frame = ...) -> FloatArray: ...
    @overload
    def lminus(self, other: LieGroup, jac: Literal[True], *, frame: Frame = ...) -> _Diff: ...
    def lminus(self, other: LieGroup, jac: bool = False, *, frame: Frame = "right") -> FloatArray | _Diff:
        """``τ = Y ⊖ₗ X = Log(Y·X⁻¹)`` for ``Y = self``, ``X = other``; Jacobians wrt ``Y`` and ``X``:
        right (default) ``J_Y = Jl(τ)⁻¹ Ad_Y``, ``J_X = −Jr(τ)⁻¹ Ad_X``; ``frame="left"`` (along ``Exp(ε)·Y``,
        ``Exp(ε)·X``) ``J_Y = Jl(τ)⁻¹``, ``J_X = −Jr(τ)⁻¹``. Raises ``ValueError`` for any other ``frame``."""
        left = _left(frame)
        x = self._operand(other)
        tau = self._blocks(lambda b, a: self._log(self._compose(b, self._inverse(a))), self._data, x)
        if not jac:
            return tau
        j_y, j_x = self._tangent_map(self._jr_inv, -tau), -self._tangent_map(self._jr_inv, tau)
        if left:
            return tau, j_y, j_x
        return tau, j_y @ self._adjoint(self._data), j_x @ self._adjoint(x)

    @overload
    def between(self: G, other: G, jac: Literal[False] = ...) -> G: ...
    @overload
    def between(self: G, other: G, jac: Literal[True]) -> tuple[G, Jac, Jac]: ...
    def between(self: G, other: G, jac: bool = False) -> G | tuple[G, Jac, Jac]:
        """``X⁻¹·Y`` for ``X = self``, ``Y = other``; Jacobians ``−Ad_{X⁻¹Y}⁻¹`` wrt
        ``X`` and ``I`` wrt ``Y``."""
        z = self._wrap(self._blocks(lambda a, b: self._compose(self._inverse(a), b), self._data, self._operand(other)))
        if not jac:
            return z
        j_x = -self._adjoint(self._inverse(z._data))
        return z, j_x, _eye(self.dim, z.batch_shape)

    def dist(self, other: LieGroup) -> FloatArray:
        """Geodesic distance ``|Y ⊖ X|`` (Euclidean norm of the tangent coordinates)."""
        return np.linalg.norm(other.rminus(self), axis=-1)

    def chordal_dist(self, other: LieGroup) -> FloatArray:
        """Chordal distance ``‖X − Y‖_F`` of the matrix forms."""
        self._operand(other)
        d = self.as_matrix() - other.as_matrix()
        return np.sqrt(np.einsum("...ij,...ij->...", d, d))

    def interpolate(self: G, other: G, s: ArrayLike) -> G:
        """``X ⊕ s·(Y ⊖ X)``: ``s = 0`` gives ``X``, ``s = 1`` gives ``Y``; ``s`` broadcasts
        against the batch axes."""
        return self.rplus(np.asarray(s, dtype=np.float64)[..., None] * other.rminus(self))

    # ---- kernels every group supplies (on raw arrays; see the module docstring) -------
    # static: _exp(tau), _log(data), _compose(a, b), _inverse(a), _act(a, p),
    #   _act_jac(a, p) -> (J_x, J_p), _adjoint(a), _jr(tau), _jr_inv(tau), _hat(tau), _vee(m);
    # class methods: _identity(batch), _random(rng, batch), _project(a) and
    #   _validated(a, tol, name), which checks ``a`` is in the group within ``tol`` and polishes it
    #   (optionally _verify(a, tol, name): the check alone, for ``validate``).

    _exp = _log = _compose = _inverse = _act = _act_jac = _adjoint = staticmethod(_unsupplied)
    _jr = _jr_inv = _hat = _vee = staticmethod(_unsupplied)
    _random = _validated = _project = classmethod(_unsupplied)

    @classmethod
    def _identity(cls, batch: tuple[int, ...]) -> FloatArray:
        """The identity matrix, for the groups stored as square matrices (the others override it)."""
        n = cls.storage_shape[-1]
        return np.array(np.broadcast_to(np.eye(n), batch + (n, n)))
