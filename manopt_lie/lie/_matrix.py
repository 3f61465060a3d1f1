"""Kernels shared by the matrix groups: rotations and homogeneous transforms.

A homogeneous transform of dimension ``d`` is ``T = [[R, t], [0, 1]]`` of shape
``(..., d+1, d+1)``; its blocks are read and written directly, never through a
``(d+1)×(d+1)`` matrix product, which would multiply by the constant last row.
"""

from __future__ import annotations

from functools import cache

import numpy as np
from numpy.typing import NDArray

from ..errors import NotInGroupError
from . import _one
from ._checks import FloatArray

# Largest |RᵀR − I| entry, and |last row − [0 … 0 1]| entry, accepted by ``from_matrix``.
DEFAULT_TOL = 1e-6


def matvec(m: FloatArray, v: FloatArray) -> FloatArray:
    """``M v`` over batch axes."""
    return np.einsum("...ij,...j->...i", m, v)


ONE_PRODUCT = 64
"""Batches from which one matrix against many (:func:`product`, :func:`rotate_vectors`) is one BLAS call."""


COMPONENTS = 2048
"""Batches from which :func:`rotate_vectors` writes ``R v`` out per component: below, the products
``R ∘ v`` summed along rows in one reduction are faster (11 vectors: 5.5 against 22 µs), and their
``(…, d, d)`` temporary is small."""


def _unbroadcast(m: FloatArray) -> FloatArray:
    """``m`` itself, or its one matrix if its batch axes are a broadcast (zero strides, as
    ``blockwise`` passes a single element against a batch)."""
    if m.ndim > 2 and not any(m.strides[:-2]):
        return m[(0,) * (m.ndim - 2)]
    return m


@_one.fast(_one.rotate_vectors, 2, 1, small=0)
def rotate_vectors(r: FloatArray, v: FloatArray) -> FloatArray:
    """``R v`` for ``d ≤ 3``, written out per component in large batches (faster than ``einsum``),
    as one row-wise reduction below :data:`COMPONENTS` elements. One ``R``
    against a batch of at least :data:`ONE_PRODUCT` vectors (a point cloud moved by one pose) is
    one BLAS product of the stacked rows, ``V Rᵀ``."""
    d = r.shape[-1]
    one = _unbroadcast(r)
    if one.ndim == 2 and v.ndim > 1 and v.size >= ONE_PRODUCT * d:
        if np.broadcast_shapes(r.shape[:-2], v.shape[:-1]) == v.shape[:-1]:  # v holds the whole batch
            return (v.reshape(-1, d) @ one.T).reshape(v.shape)
    if max(r.size // (d * d), v.size // d) < COMPONENTS:  # two calls, not d² products and sums
        return np.add.reduce(r * v[..., None, :], axis=-1)  # the same sums in the same order: the same bits
    return np.stack([sum(r[..., i, j] * v[..., j] for j in range(d)) for i in range(d)], axis=-1)


def product(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a @ b`` over batch axes. A right factor without batch axes (or broadcast to them, with
    zero strides, as ``blockwise`` passes it) against a batch of at least :data:`ONE_PRODUCT`
    matrices is one BLAS product of the stacked rows, ``(…·d, d) @ (d, k)``: NumPy's batched
    ``matmul`` calls BLAS once per 3×3 block, about ten times slower."""
    b = _unbroadcast(b)
    if b.ndim == 2 and a.ndim > 2 and a.size >= ONE_PRODUCT * a.shape[-1] * a.shape[-2]:
        return (a.reshape(-1, a.shape[-1]) @ b).reshape(a.shape[:-1] + b.shape[-1:])
    return np.matmul(a, b)


compose_rotations = product


def assemble(r: FloatArray, t: FloatArray) -> FloatArray:
    """``[[R, t], [0, 1]]`` broadcast over the batch axes of ``R`` and ``t``."""
    d = r.shape[-1]
    batch = r.shape[:-2] if r.shape[:-2] == t.shape[:-1] else np.broadcast_shapes(r.shape[:-2], t.shape[:-1])
    out = np.zeros(batch + (d + 1, d + 1))
    out[..., :d, :d] = r
    out[..., :d, d] = t
    out[..., d, d] = 1.0
    return out


def split(m: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``(R, t)`` views of a homogeneous matrix."""
    d = m.shape[-1] - 1
    return m[..., :d, :d], m[..., :d, d]


@_one.fast(_one.h_compose, 2, 2, floats=False, small=0)
def h_compose(a: FloatArray, b: FloatArray) -> FloatArray:
    """``[[Ra Rb, Ra tb + ta], [0, 1]]``."""
    ra, ta = split(a)
    rb, tb = split(b)
    return assemble(product(ra, rb), rotate_vectors(ra, tb) + ta)


@_one.fast(_one.h_inverse, 2, small=0)
def h_inverse(m: FloatArray) -> FloatArray:
    """``[[Rᵀ, −Rᵀt], [0, 1]]``."""
    r, t = split(m)
    rt = np.swapaxes(r, -1, -2)
    return assemble(rt, -rotate_vectors(rt, t))


@_one.fast(_one.h_act, 2, 1, small=0)
def h_act(m: FloatArray, p: FloatArray) -> FloatArray:
    """``R p + t``."""
    r, t = split(m)
    return rotate_vectors(r, p) + t


@cache
def _gram_pairs(d: int) -> tuple[NDArray[np.intp], NDArray[np.intp], FloatArray]:
    """For the entries ``(i, j)``, ``i ≤ j``, of ``RᵀR``: the flat positions of column ``i`` and of
    column ``j`` of a ``d × d`` matrix, side by side, and ``I``'s entries there."""
    i, j = np.triu_indices(d)
    rows = np.arange(d) * d
    return (rows + i[:, None]).ravel(), (rows + j[:, None]).ravel(), (i == j).astype(np.float64)


def orthonormality_error(r: FloatArray) -> FloatArray:
    """``max |RᵀR − I|`` per batch element, from the ``d(d+1)/2`` column products ``cᵢ·cⱼ`` as one
    gather, product and row sum (NumPy's batched ``matmul`` of 3×3 matrices costs ~150 ns each)."""
    d = r.shape[-1]
    batch = r.shape[:-2]
    left, right, eye = _gram_pairs(d)
    flat = r.reshape(batch + (d * d,))
    gram = np.add.reduce((flat[..., left] * flat[..., right]).reshape(batch + (eye.size, d)), axis=-1)
    return np.abs(gram - eye).max(axis=-1)  # type: ignore[no-any-return]


def determinant(r: FloatArray) -> FloatArray:
    """``det R`` per batch element, written out for ``d ≤ 3`` (LAPACK's per matrix otherwise)."""
    d = r.shape[-1]
    if d == 2:
        return r[..., 0, 0] * r[..., 1, 1] - r[..., 0, 1] * r[..., 1, 0]  # type: ignore[no-any-return]
    if d == 3:
        a, b, c = r[..., 0, :], r[..., 1, :], r[..., 2, :]
        minor = [b[..., 1] * c[..., 2] - b[..., 2] * c[..., 1], b[..., 2] * c[..., 0] - b[..., 0] * c[..., 2],
                 b[..., 0] * c[..., 1] - b[..., 1] * c[..., 0]]  # fmt: skip
        return a[..., 0] * minor[0] + a[..., 1] * minor[1] + a[..., 2] * minor[2]  # type: ignore[no-any-return]
    return np.linalg.det(r)  # type: ignore[no-any-return]


def rotation_error(r: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``(max |RᵀR − I|, det R)`` per batch element."""
    return orthonormality_error(r), determinant(r)


def check_rotation(r: FloatArray, tol: float, name: str) -> None:
    """Raise :class:`NotInGroupError` unless every ``R`` is orthonormal within ``tol``
    with ``det R > 0``, naming the first offending batch index."""
    err, det = rotation_error(r)
    for bad, why in ((err > tol, f"not orthonormal (|RᵀR − I| > {tol:g})"), (det <= 0, "a reflection (det R < 0)")):
        if bad.any():
            idx = tuple(int(i) for i in np.argwhere(bad)[0]) if bad.ndim else ()
            raise NotInGroupError(
                f"{name}: matrix at batch index {idx} is {why}; pass project=True to snap it to the nearest rotation"
            )


def polish_rotation(r: FloatArray) -> FloatArray:
    """Newton's iteration for the polar factor, ``R ← ½ R (3I − RᵀR)``, to machine precision.

    Quadratically convergent near SO(n) (an orthonormality error of 1e-6 is gone
    in two steps); exact rotations are returned after one check.
    """
    eye = np.eye(r.shape[-1])
    for _ in range(8):
        if orthonormality_error(r).max(initial=0.0) <= 1e-15:
            break
        r = 0.5 * r @ (3.0 * eye - np.swapaxes(r, -1, -2) @ r)
    return r


def check_last_row(m: FloatArray, tol: float, name: str) -> None:
    d = m.shape[-1] - 1
    target = np.zeros(d + 1)
    target[d] = 1.0
    bad = np.abs(m[..., d, :] - target).max(axis=-1) > tol
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0]) if bad.ndim else ()
        raise NotInGroupError(f"{name}: homogeneous matrix at batch index {idx} has last row != [0, ..., 0, 1]")


def project_rotation(m: FloatArray) -> FloatArray:
    """Nearest rotation in Frobenius norm: ``U diag(1, …, 1, det(UVᵀ)) Vᵀ`` of ``M = U S Vᵀ``,
    the maximizer of ``tr(RᵀM)`` over SO(n).

    Each matrix is divided by its largest entry first (the polar factor does not change
    under positive scaling), so that nothing over- or underflows. The zero matrix projects
    to the identity.

    Computed without an SVD where that is exact and faster: 2×2 in closed form, ``R(θ)``
    with ``θ = atan2(m₁₀ − m₀₁, m₀₀ + m₁₁)`` (12× a batched SVD at 10³ matrices); batches of
    :data:`POLAR_BATCH` or more 3×3 matrices of positive determinant by Newton's iteration
    for the polar factor (:func:`_polar3`, 2.1–2.7×); the rest (smaller batches, larger
    matrices, ``det M`` not clearly positive, non-finite) by the SVD.
    """
    big = np.abs(m).max(axis=(-2, -1), keepdims=True, initial=0.0)
    m = np.where(big == 0.0, np.eye(m.shape[-1]), m / np.where(big == 0.0, 1.0, big))
    if m.shape[-1] == 2 and np.isfinite(m).all():
        return rotation2(np.arctan2(m[..., 1, 0] - m[..., 0, 1], m[..., 0, 0] + m[..., 1, 1]))
    if m.shape[-1] != 3 or m.size < 9 * POLAR_BATCH or not np.isfinite(m).all():
        return _project_svd(m)
    out = _polar3(m)
    rest = ~(orthonormality_error(out) <= 1e-13)  # not clearly of positive determinant, or not converged
    if rest.any():
        out[rest] = _project_svd(m[rest])
    return out


def _project_svd(m: FloatArray) -> FloatArray:
    u, _, vt = np.linalg.svd(m)
    d = np.sign(np.linalg.det(u @ vt))
    d = np.where(d == 0, 1.0, d)
    u = u.copy()
    u[..., :, -1] *= d[..., None]
    return u @ vt


POLAR_BATCH = 256
"""3×3 batches from which Newton's iteration (:func:`_polar3`: ~0.4 ms of fixed cost, then
0.6 µs a matrix) is faster than the SVD (~2.3 µs a matrix)."""

POLAR_DETERMINANT = 1e-6
"""3×3 matrices with ``det M ≤ POLAR_DETERMINANT·(‖M‖_F/√3)³`` (nearly singular, or reflections)
are projected by the SVD: Newton's iteration would converge slowly or to ``det = −1``."""


def _polar3(m: FloatArray) -> FloatArray:
    """The orthogonal polar factor of 3×3 matrices by Newton's iteration, scaled while far
    (Higham): ``X ← ½(γX + X⁻ᵀ/γ)``, ``γ = (‖X⁻¹‖_F/‖X‖_F)^½``, with ``X⁻ᵀ`` from the cross
    products of the columns (``det X · X⁻ᵀ = [b×c, c×a, a×b]``, ``det X = a·(b×c)``). Quadratic
    near the answer: 5 steps from a rotation perturbed by 5 %, 7 from a random matrix. Elements
    that do not qualify (:data:`POLAR_DETERMINANT`) come back as ``nan``, for the SVD."""
    x = m
    for step in range(12):
        a, b, c = x[..., :, 0], x[..., :, 1], x[..., :, 2]
        cof = np.stack([np.cross(b, c), np.cross(c, a), np.cross(a, b)], axis=-1)
        det = np.einsum("...i,...i->...", a, cof[..., :, 0])
        norm2 = np.einsum("...ij,...ij->...", x, x)
        if step == 0:  # the rest stay at the identity, whose step is 0
            ok = det > POLAR_DETERMINANT * (norm2 / 3.0) ** 1.5
            if not ok.all():
                x = np.where(ok[..., None, None], x, np.eye(3))
                continue
        inv_t = cof / det[..., None, None]
        if step < 6:
            gamma = np.sqrt(np.sqrt(np.einsum("...ij,...ij->...", inv_t, inv_t) / norm2))[..., None, None]
            new = 0.5 * (gamma * x + inv_t / gamma)
        else:
            new = 0.5 * (x + inv_t)
        change = np.abs(new - x).max(initial=0.0)
        x = new
        if change <= 1e-14:
            break
    return np.where(ok[..., None, None], x, np.nan)


def skew2(v: FloatArray) -> FloatArray:
    """``J v`` with ``J = [[0, −1], [1, 0]]`` (rotation of a plane vector by +90°)."""
    return np.stack([-v[..., 1], v[..., 0]], axis=-1)


@_one.fast(_one.rotation2, 0, small=0)
def rotation2(theta: FloatArray) -> FloatArray:
    """``[[cos θ, −sin θ], [sin θ, cos θ]]``."""
    c, s = np.cos(theta), np.sin(theta)
    out = np.empty(theta.shape + (2, 2))
    out[..., 0, 0], out[..., 0, 1] = c, -s
    out[..., 1, 0], out[..., 1, 1] = s, c
    return out


@_one.fast(_one.angle2, 2, small=0)
def angle2(r: FloatArray) -> FloatArray:
    """Angle ``∈ (−π, π]`` of a planar rotation."""
    return np.arctan2(r[..., 1, 0], r[..., 0, 0])


def hconcat(*blocks: FloatArray) -> FloatArray:
    """Concatenate matrices ``(..., m, nᵢ)`` along columns, broadcasting batch axes only."""
    batch = np.broadcast_shapes(*(b.shape[:-2] for b in blocks))
    return np.concatenate([np.broadcast_to(b, batch + b.shape[-2:]) for b in blocks], axis=-1)
